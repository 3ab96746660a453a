"""Numba kernels: an AABB tree over triangles, exact closest point, pseudo-normal sign, ray casts.

Everything here works on plain arrays so that one compiled call answers one query. Numba's
dispatch types every argument on every call (~50 ns per array), so the per-sample entry points
:func:`query_packed` and :func:`follow_packed` take all tables as one buffer (:func:`pack_tables`).
All kernels are ``cache=True``: the first compile takes seconds, later processes load it from
``__pycache__``.

Searches: :func:`closest` is best-first (a min-queue on a lower bound of the distance to a node:
the larger of the distances to its AABB and to its slab), so it opens only nodes that could hold
something nearer than the answer; :func:`raycast` is front to back. Lines marked ``# count:``
are what ``bench/bench_contact.py --counts`` counts (work per query, independent of load).

Tables (built by :func:`build_tables`, triangles stored in tree-leaf order):

- ``tri`` (F, 16) float64: a(0:3) b(3:6) c(6:9) corners, unit normal n(9:12) (zeros if
  degenerate), degenerate flag (12), corner angles at a, b, c (13:16) [rad].
- ``box`` (N, 11) float64: node bounds (min xyz 0:3, max xyz 3:6) and a slab along the node's
  mean normal: unit n (6:9), min and max of n . x over its triangles (9, 10). The slab is what
  prunes on a curved shell: an AABB of a tilted patch is as thick as the patch is wide, the slab
  only as thick as the patch is curved, so a probe deep under the surface does not see the
  boxes of every patch around its closest point as "maybe as close".
- ``node`` (N, 2) int64: internal node -> (left, right); leaf -> (first, -count) into ``tri``.

Region codes of a closest point on a triangle: FACE 0, vertex A/B/C 1/2/3, edge AB/BC/CA 4/5/6.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

FACE, VA, VB, VC, EAB, EBC, ECA = 0, 1, 2, 3, 4, 5, 6
LEAF_SIZE = 8  # measured: 8 beats 2 and 4 by ~10 % on the 80k dome; 16 is no better
# Closest-point bounds use the node slab as well as the AABB (False: AABB only; with best-first
# traversal that was 2.5x slower on the 80k dome).
_SLAB_BOUND = True
_STACK = 128  # a median-split tree over 2^40 faces is 40 deep; two pushes per level

# error_model='numpy': a division by zero gives inf/nan instead of raising (used in ray slabs).
_jit = nb.njit(cache=True, nogil=True, error_model='numpy')


# ---------------------------------------------------------------------------------------------
# Building
# ---------------------------------------------------------------------------------------------

@_jit
def _build_tree(lo, hi, leaf_size):
    """Median-split AABB tree over boxes ``lo``/``hi`` (F, 3). Returns (box, node, order)."""
    F = lo.shape[0]
    cen = 0.5 * (lo + hi)
    order = np.arange(F)
    max_nodes = max(1, 2 * F)
    box = np.empty((max_nodes, 6))
    node = np.empty((max_nodes, 2), np.int64)
    st_node = np.empty(_STACK, np.int64)
    st_s = np.empty(_STACK, np.int64)
    st_e = np.empty(_STACK, np.int64)
    top = 0
    st_node[0], st_s[0], st_e[0] = 0, 0, F
    top = 1
    n_nodes = 1
    while top > 0:
        top -= 1
        i, s, e = st_node[top], st_s[top], st_e[top]
        bmin = np.full(3, np.inf)
        bmax = np.full(3, -np.inf)
        cmin = np.full(3, np.inf)
        cmax = np.full(3, -np.inf)
        for k in range(s, e):
            t = order[k]
            for j in range(3):
                bmin[j] = min(bmin[j], lo[t, j])
                bmax[j] = max(bmax[j], hi[t, j])
                cmin[j] = min(cmin[j], cen[t, j])
                cmax[j] = max(cmax[j], cen[t, j])
        for j in range(3):
            box[i, j] = bmin[j]
            box[i, 3 + j] = bmax[j]
        ext = cmax - cmin
        axis = int(np.argmax(ext))
        if e - s <= leaf_size or ext[axis] <= 0.0:  # small, or all centroids coincide
            node[i, 0] = s
            node[i, 1] = -(e - s)
            continue
        sub = order[s:e].copy()
        keys = np.empty(e - s)
        for k in range(e - s):
            keys[k] = cen[sub[k], axis]
        idx = np.argsort(keys, kind='mergesort')  # stable: the tree is deterministic
        for k in range(e - s):
            order[s + k] = sub[idx[k]]
        m = (s + e) // 2
        left, right = n_nodes, n_nodes + 1
        n_nodes += 2
        node[i, 0] = left
        node[i, 1] = right
        st_node[top], st_s[top], st_e[top] = right, m, e
        st_node[top + 1], st_s[top + 1], st_e[top + 1] = left, s, m
        top += 2
    return box[:n_nodes].copy(), node[:n_nodes].copy(), order


def _corner_angles(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Interior angles (F, 3) [rad] at a, b, c; 0 where an adjacent edge has zero length."""
    def angle(p, q, r):  # angle at p between p->q and p->r, atan2 form (accurate near 0 and pi)
        u, v = q - p, r - p
        return np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), np.einsum('ij,ij->i', u, v))
    return np.column_stack([angle(a, b, c), angle(b, c, a), angle(c, a, b)])


def build_tables(vertices: np.ndarray, faces: np.ndarray, degenerate_rtol: float = 1e-12):
    """Pack a triangle mesh into the kernel tables.

    Args:
        vertices: (V, 3) float64 [m].
        faces: (F, 3) int indices into ``vertices``.
        degenerate_rtol: a face is degenerate (zero area) when its height is below this fraction of
            its longest edge; such faces keep their points (as segments) but have no normal.

    Returns:
        ``(tri, box, node, order)``; ``order[k]`` is the caller's face index of ``tri[k]``.
    """
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    cr = np.cross(b - a, c - a)
    dbl_area = np.linalg.norm(cr, axis=1)
    longest = np.max(np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                               np.linalg.norm(a - c, axis=1)]), axis=0)
    # height = 2*area / longest edge; compare height with rtol * longest.
    deg = dbl_area <= degenerate_rtol * longest * longest
    n = np.zeros_like(cr)
    n[~deg] = cr[~deg] / dbl_area[~deg, None]
    ang = _corner_angles(a, b, c)
    ang[deg] = 0.0
    tri = np.column_stack([a, b, c, n, deg.astype(np.float64), ang])
    # Pad the boxes a hair (1e-9 of the mesh size): pruning stays conservative for rays that graze
    # a flat box or hit an edge within the widened barycentric bounds of `raycast`.
    pad = 1e-9 * max(float(np.ptp(vertices, axis=0).max()), 1e-300)
    lo = np.minimum(np.minimum(a, b), c) - pad
    hi = np.maximum(np.maximum(a, b), c) + pad
    box, node, order = _build_tree(np.ascontiguousarray(lo), np.ascontiguousarray(hi), LEAF_SIZE)
    tri = np.ascontiguousarray(tri[order])
    box = _add_slabs(tri, np.ascontiguousarray(cr[order]), box, node, pad)
    return tri, box, node, order


@_jit
def _add_slabs(tri, cr, box, node, pad):
    """Append the slab columns (6:11) to ``box`` (N, 6): normal = the node's area-weighted mean
    face normal (``cr`` (F, 3): twice-area normals in tree order), extent over its corners."""
    N = box.shape[0]
    F = tri.shape[0]
    out = np.empty((N, 11))
    out[:, 0:6] = box
    # Row ranges: a leaf is (first, -count); an internal node covers its children's ranges, which
    # are adjacent, and children have larger indices than their parent.
    start = np.empty(N, np.int64)
    stop = np.empty(N, np.int64)
    for i in range(N - 1, -1, -1):
        if node[i, 1] < 0:
            start[i], stop[i] = node[i, 0], node[i, 0] - node[i, 1]
        else:
            start[i], stop[i] = start[node[i, 0]], stop[node[i, 1]]
    csum = np.zeros((F + 1, 3))
    for k in range(F):
        for j in range(3):
            csum[k + 1, j] = csum[k, j] + cr[k, j]
    for i in range(N):
        s, e = start[i], stop[i]
        nx = csum[e, 0] - csum[s, 0]
        ny = csum[e, 1] - csum[s, 1]
        nz = csum[e, 2] - csum[s, 2]
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        if nn > 0.0:
            nx, ny, nz = nx / nn, ny / nn, nz / nn
        else:  # normals cancel (or all degenerate): any unit vector gives a valid, loose slab
            nx, ny, nz = 1.0, 0.0, 0.0
        hmin, hmax = np.inf, -np.inf
        for k in range(s, e):
            for c in range(3):
                h = nx * tri[k, 3 * c] + ny * tri[k, 3 * c + 1] + nz * tri[k, 3 * c + 2]
                hmin = min(hmin, h)
                hmax = max(hmax, h)
        out[i, 6], out[i, 7], out[i, 8] = nx, ny, nz
        # The pad (1e-9 of the mesh size, as for the boxes) covers the rounding of n . x.
        out[i, 9], out[i, 10] = hmin - pad, hmax + pad
    return out


# ---------------------------------------------------------------------------------------------
# Closest point on one triangle (Ericson, Real-Time Collision Detection, sec. 5.1.5)
# ---------------------------------------------------------------------------------------------

@_jit
def _closest_on_segment(px, py, pz, ax, ay, az, bx, by, bz):
    """Closest point on segment ab; returns (t, d2) with the point a + t (b - a)."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    ee = ex * ex + ey * ey + ez * ez
    t = 0.0
    if ee > 0.0:
        t = ((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / ee
        t = min(1.0, max(0.0, t))
    qx, qy, qz = ax + t * ex - px, ay + t * ey - py, az + t * ez - pz
    return t, qx * qx + qy * qy + qz * qz


@_jit
def closest_on_triangle(tri, k, px, py, pz):
    """Closest point of row ``k`` of ``tri`` to p.

    Returns ``(qx, qy, qz, u, v, w, region)`` with q = u a + v b + w c (barycentric, sum 1).
    Degenerate rows are treated as their three edges (Ericson's face formula divides by the area).
    """
    ax, ay, az = tri[k, 0], tri[k, 1], tri[k, 2]
    bx, by, bz = tri[k, 3], tri[k, 4], tri[k, 5]
    cx, cy, cz = tri[k, 6], tri[k, 7], tri[k, 8]
    if tri[k, 12] != 0.0:
        t1, e1 = _closest_on_segment(px, py, pz, ax, ay, az, bx, by, bz)
        t2, e2 = _closest_on_segment(px, py, pz, bx, by, bz, cx, cy, cz)
        t3, e3 = _closest_on_segment(px, py, pz, cx, cy, cz, ax, ay, az)
        if e1 <= e2 and e1 <= e3:
            u, v, w, reg = 1.0 - t1, t1, 0.0, EAB
        elif e2 <= e3:
            u, v, w, reg = 0.0, 1.0 - t2, t2, EBC
        else:
            u, v, w, reg = t3, 0.0, 1.0 - t3, ECA
        if u == 1.0:
            reg = VA
        elif v == 1.0:
            reg = VB
        elif w == 1.0:
            reg = VC
        return (u * ax + v * bx + w * cx, u * ay + v * by + w * cy, u * az + v * bz + w * cz,
                u, v, w, reg)
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, 1.0, 0.0, 0.0, VA
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz, 0.0, 1.0, 0.0, VB
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, 1.0 - v, v, 0.0, EAB
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz, 0.0, 0.0, 1.0, VC
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz, 1.0 - w, 0.0, w, ECA
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return (bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz),
                0.0, 1.0 - w, w, EBC)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    # Rounding can leave u = 1 - v - w at -1e-17; report barycentrics that are never negative.
    return (ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w,
            max(0.0, 1.0 - v - w), max(0.0, v), max(0.0, w), FACE)


@_jit
def _box_d2(box, i, px, py, pz):
    """Lower bound of the squared distance from p to the triangles of node ``i`` (0 inside): the
    larger of the squared distances to its AABB and to its slab (both hold all its triangles)."""
    dx = max(box[i, 0] - px, 0.0, px - box[i, 3])
    dy = max(box[i, 1] - py, 0.0, py - box[i, 4])
    dz = max(box[i, 2] - pz, 0.0, pz - box[i, 5])
    if not _SLAB_BOUND:
        return dx * dx + dy * dy + dz * dz
    h = box[i, 6] * px + box[i, 7] * py + box[i, 8] * pz
    dh = max(box[i, 9] - h, 0.0, h - box[i, 10])
    return max(dx * dx + dy * dy + dz * dz, dh * dh)


# ---------------------------------------------------------------------------------------------
# Queries
# ---------------------------------------------------------------------------------------------

_HEAP = 256  # best-first queue capacity; a full queue hands the extra subtree to a depth-first scan


@_jit
def _child_d2(box, c, px, py, pz, cx, cy, cz, r2):
    """Bound of node ``c`` for :func:`closest`: inf when it lies outside the ball (c, sqrt(r2))."""
    if r2 < np.inf and _box_d2(box, c, cx, cy, cz) > r2:
        return np.inf
    return _box_d2(box, c, px, py, pz)


@_jit
def _scan_leaf(tri, node, i, px, py, pz, hint, cx, cy, cz, r2, res):
    """Test the rows of leaf ``i`` (all but ``hint``) against the best so far in ``res``."""
    s = node[i, 0]
    for k in range(s, s - node[i, 1]):
        if k == hint:
            continue
        qx, qy, qz, u, v, w, reg = closest_on_triangle(tri, k, px, py, pz)  # count: tri
        d2 = (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2
        if d2 < res[0]:
            if r2 < np.inf:
                r = closest_on_triangle(tri, k, cx, cy, cz)
                if (r[0] - cx) ** 2 + (r[1] - cy) ** 2 + (r[2] - cz) ** 2 > r2:
                    continue
            res[0], res[1], res[2], res[3], res[4] = d2, k, qx, qy, qz
            res[5], res[6], res[7], res[8] = u, v, w, reg


@_jit
def _scan_depth_first(tri, box, node, root, droot, px, py, pz, hint, cx, cy, cz, r2, res):
    """Depth-first, near child first, over the subtree ``root`` (bound ``droot``)."""
    st = np.empty(_STACK, np.int64)
    sd = np.empty(_STACK)
    st[0], sd[0] = root, droot
    top = 1
    while top > 0:
        top -= 1
        i = st[top]  # count: node
        if sd[top] > res[0]:
            continue
        if node[i, 1] < 0:
            _scan_leaf(tri, node, i, px, py, pz, hint, cx, cy, cz, r2, res)
            continue
        left, right = node[i, 0], node[i, 1]
        dl = _child_d2(box, left, px, py, pz, cx, cy, cz, r2)
        dr = _child_d2(box, right, px, py, pz, cx, cy, cz, r2)
        if dl < dr:  # push the far child first so the near one is popped first
            left, right, dl, dr = right, left, dr, dl
        if dl <= res[0]:
            st[top], sd[top] = left, dl
            top += 1
        if dr <= res[0]:
            st[top], sd[top] = right, dr
            top += 1


@_jit
def _heap_pop(hd, hn, n):
    """Remove the root of the min-heap (hd keys, hn values, n entries); returns the new size."""
    n -= 1
    ld, ln = hd[n], hn[n]
    j = 0
    while True:
        c = 2 * j + 1
        if c >= n:
            break
        if c + 1 < n and hd[c + 1] < hd[c]:
            c += 1
        if hd[c] >= ld:
            break
        hd[j], hn[j] = hd[c], hn[c]
        j = c
    hd[j], hn[j] = ld, ln
    return n


@_jit
def _heap_push(hd, hn, n, d, v):
    """Insert (d, v) into the min-heap; returns the new size."""
    j = n
    while j > 0:
        up = (j - 1) // 2
        if hd[up] <= d:
            break
        hd[j], hn[j] = hd[up], hn[up]
        j = up
    hd[j], hn[j] = d, v
    return n + 1


@_jit
def closest(tri, box, node, px, py, pz, hint, cx, cy, cz, r2):
    """Exact closest surface point to p over all rows whose distance to c is <= sqrt(r2).

    ``r2 = inf`` searches the whole mesh. ``hint`` (a row, or -1) is tested first: a good guess
    (temporal coherence) tightens the bound so that most of the tree is pruned. Ties keep the first
    row found; the point is the same.

    Best-first: nodes come off a min-queue in order of their distance bound, so the search stops
    at the first node whose bound exceeds the best distance found, having opened only nodes that
    could hold something nearer than the answer (a depth-first scan opens every node nearer than
    the best found *so far*, which on a curved shell seen from inside is several times more).

    Returns ``(row, d2, qx, qy, qz, u, v, w, region)``; row = -1 if nothing lies within the ball.
    """
    res = np.empty(9)  # best d2, row, q (3), barycentrics (3), region
    res[0], res[1], res[2], res[3], res[4] = np.inf, -1.0, 0.0, 0.0, 0.0
    res[5], res[6], res[7], res[8] = 0.0, 0.0, 0.0, 0.0
    if hint >= 0:
        ok = True
        if r2 < np.inf:
            r = closest_on_triangle(tri, hint, cx, cy, cz)
            ok = (r[0] - cx) ** 2 + (r[1] - cy) ** 2 + (r[2] - cz) ** 2 <= r2
        if ok:
            qx, qy, qz, u, v, w, reg = closest_on_triangle(tri, hint, px, py, pz)
            res[0] = (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2
            res[1], res[2], res[3], res[4] = hint, qx, qy, qz
            res[5], res[6], res[7], res[8] = u, v, w, reg
    # Binary min-heap of (bound, node). The nearer child is opened straight away (no push/pop)
    # when nothing in the heap is nearer: the order stays best-first.
    hd = np.empty(_HEAP)
    hn = np.empty(_HEAP, np.int64)
    n = 0
    best = res[0]
    i = 0
    d = _child_d2(box, 0, px, py, pz, cx, cy, cz, r2)
    while d <= best:
        if node[i, 1] < 0:  # count: node
            _scan_leaf(tri, node, i, px, py, pz, hint, cx, cy, cz, r2, res)
            best = res[0]
        else:
            a, b = node[i, 0], node[i, 1]
            da = _child_d2(box, a, px, py, pz, cx, cy, cz, r2)
            db = _child_d2(box, b, px, py, pz, cx, cy, cz, r2)
            if db < da:
                a, b, da, db = b, a, db, da
            if db <= best:  # the farther child waits in the heap
                if n < _HEAP:
                    n = _heap_push(hd, hn, n, db, b)
                else:  # full (not seen on real meshes): finish that subtree depth-first
                    _scan_depth_first(tri, box, node, b, db, px, py, pz, hint, cx, cy, cz, r2,
                                      res)
                    best = res[0]
            if da <= best and (n == 0 or da <= hd[0]):
                i, d = a, da
                continue
            if da <= best:
                if n < _HEAP:
                    n = _heap_push(hd, hn, n, da, a)
                else:
                    _scan_depth_first(tri, box, node, a, da, px, py, pz, hint, cx, cy, cz, r2,
                                      res)
                    best = res[0]
        if n == 0:
            break
        d, i = hd[0], hn[0]  # every node left is at least d away: the loop test stops there
        n = _heap_pop(hd, hn, n)
    return (np.int64(res[1]), res[0], res[2], res[3], res[4], res[5], res[6], res[7],
            np.int64(res[8]))


@_jit
def pseudo_normal(tri, box, node, px, py, pz, row, qx, qy, qz, region, tol):
    """Angle-weighted pseudo-normal (Baerentzen & Aanaes 2005) at closest point q, unnormalised.

    In a face interior it is the face normal. On an edge or a vertex it sums, over every
    non-degenerate face whose own closest point to p is q (within ``tol`` [m]), the face normal
    weighted by the angle that face subtends at q (pi on an edge, the corner angle at a vertex).
    Finding those faces geometrically rather than through the connectivity keeps the sign right on
    unmerged duplicate vertices, T-junctions and zero-area slivers; on a closed 2-manifold it is
    exactly Baerentzen & Aanaes' pseudo-normal, for which sign((p - q) . n) is the inside test.
    """
    if region == FACE and tri[row, 12] == 0.0:
        return tri[row, 9], tri[row, 10], tri[row, 11]
    d = math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2) + 2.0 * tol
    r2 = d * d
    tol2 = tol * tol
    nx = ny = nz = 0.0
    st = np.empty(_STACK, np.int64)
    st[0] = 0
    top = 1
    while top > 0:
        top -= 1
        i = st[top]  # count: node
        if _box_d2(box, i, px, py, pz) > r2:
            continue
        if node[i, 1] >= 0:
            st[top] = node[i, 0]
            st[top + 1] = node[i, 1]
            top += 2
            continue
        s = node[i, 0]
        for k in range(s, s - node[i, 1]):
            if tri[k, 12] != 0.0:
                continue
            rx, ry, rz, u, v, w, reg = closest_on_triangle(tri, k, px, py, pz)  # count: tri
            if (rx - qx) ** 2 + (ry - qy) ** 2 + (rz - qz) ** 2 > tol2:
                continue
            if reg == FACE:  # q is interior to a face: its normal decides
                return tri[k, 9], tri[k, 10], tri[k, 11]
            if reg == VA:
                wt = tri[k, 13]
            elif reg == VB:
                wt = tri[k, 14]
            elif reg == VC:
                wt = tri[k, 15]
            else:
                wt = math.pi
            nx += wt * tri[k, 9]
            ny += wt * tri[k, 10]
            nz += wt * tri[k, 11]
    return nx, ny, nz


@_jit
def _slab_clip(lo, hi, o, inv, t0, t1):
    """Clip [t0, t1] to the parameters where o + t d lies in [lo, hi] (``inv`` = 1/d, inf when
    the ray is parallel: then the whole line is in or out)."""
    if inv == np.inf or inv == -np.inf:
        if o < lo or o > hi:
            return 1.0, 0.0
        return t0, t1
    ta = (lo - o) * inv
    tb = (hi - o) * inv
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@_jit
def _ray_enter(box, i, ox, oy, oz, dx, dy, dz, ix, iy, iz, tmin, tmax):
    """Entry parameter of the ray o + t d, t in [tmin, tmax], into the AABB of node ``i``; inf
    when it misses. ``i*`` = 1 / d*. Boxes are padded (build_tables), so grazing rays are not
    lost here."""
    t0, t1 = _slab_clip(box[i, 0], box[i, 3], ox, ix, tmin, tmax)
    t0, t1 = _slab_clip(box[i, 1], box[i, 4], oy, iy, t0, t1)
    t0, t1 = _slab_clip(box[i, 2], box[i, 5], oz, iz, t0, t1)
    # (Clipping by the node slab as well was measured: no faster for the axis-aligned rays the
    # detector and the tracker cast, so rays use the AABB only.)
    return t0 if t0 <= t1 else np.inf


@_jit
def raycast(tri, box, node, ox, oy, oz, dx, dy, dz, tmin, tmax, facing, eps):
    """Nearest crossing of the ray o + t d, tmin <= t <= tmax, with a non-degenerate face.

    ``facing``: 0 any face; +1 only faces the ray leaves through (n . d > 0); -1 only faces it
    enters through (n . d < 0). ``eps`` widens the barycentric bounds so a ray exactly through an
    edge or vertex still hits (Moller & Trumbore 1997 test). Front to back: the child the ray
    enters first is opened first, and a node entered beyond the nearest crossing so far is skipped.

    Returns ``(row, t, u, v, w)``; row = -1 when there is no crossing.
    """
    ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
    brow, bt, bu, bv, bw = -1, tmax, 0.0, 0.0, 0.0
    st = np.empty(_STACK, np.int64)
    sd = np.empty(_STACK)
    st[0] = 0
    sd[0] = _ray_enter(box, 0, ox, oy, oz, dx, dy, dz, ix, iy, iz, tmin, bt)
    top = 1 if sd[0] < np.inf else 0
    while top > 0:
        top -= 1
        i = st[top]  # count: node
        if sd[top] > bt:
            continue
        if node[i, 1] >= 0:
            a, b = node[i, 0], node[i, 1]
            ta = _ray_enter(box, a, ox, oy, oz, dx, dy, dz, ix, iy, iz, tmin, bt)
            tb = _ray_enter(box, b, ox, oy, oz, dx, dy, dz, ix, iy, iz, tmin, bt)
            if ta < tb:  # push the far child first so the near one is popped first
                a, b, ta, tb = b, a, tb, ta
            if ta < np.inf:
                st[top], sd[top] = a, ta
                top += 1
            if tb < np.inf:
                st[top], sd[top] = b, tb
                top += 1
            continue
        s = node[i, 0]
        for k in range(s, s - node[i, 1]):
            if tri[k, 12] != 0.0:
                continue
            ndot = tri[k, 9] * dx + tri[k, 10] * dy + tri[k, 11] * dz  # count: tri
            if (facing > 0 and ndot <= 0.0) or (facing < 0 and ndot >= 0.0):
                continue
            e1x, e1y, e1z = tri[k, 3] - tri[k, 0], tri[k, 4] - tri[k, 1], tri[k, 5] - tri[k, 2]
            e2x, e2y, e2z = tri[k, 6] - tri[k, 0], tri[k, 7] - tri[k, 1], tri[k, 8] - tri[k, 2]
            hx, hy, hz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
            det = e1x * hx + e1y * hy + e1z * hz
            if det == 0.0:
                continue
            f = 1.0 / det
            sx, sy, sz = ox - tri[k, 0], oy - tri[k, 1], oz - tri[k, 2]
            v = f * (sx * hx + sy * hy + sz * hz)
            if v < -eps or v > 1.0 + eps:
                continue
            qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
            w = f * (dx * qx + dy * qy + dz * qz)
            if w < -eps or v + w > 1.0 + eps:
                continue
            t = f * (e2x * qx + e2y * qy + e2z * qz)
            if t < tmin or t > bt or (t == bt and brow >= 0):
                continue
            brow, bt, bu, bv, bw = k, t, 1.0 - v - w, v, w
    return brow, bt, bu, bv, bw


# Output columns of the query kernels (one row per probe point). Faces are caller's face indices.
OUT_POINT, OUT_FACE, OUT_BARY, OUT_SD, OUT_NORMAL = 0, 3, 4, 7, 8
OUT_DEPTH, OUT_CPOINT, OUT_CFACE, OUT_DIR, OUT_ROW = 11, 12, 15, 16, 19
OUT_WIDTH = 20
# Parameter vector `par`: fixed-direction flag, direction (3), pseudo-normal tol [m], ray eps.
PAR_FIXED, PAR_DIR, PAR_TOL, PAR_EPS = 0, 1, 4, 5


@_jit
def _query_point(tri, box, node, ids, par, px, py, pz, hint, out):
    """Stateless contact query for one point; writes the row ``out`` (OUT_WIDTH,).

    ``ids`` (2, F): tree row -> face index, face index -> tree row. ``hint`` is a tree row or -1.
    See :meth:`haptic_anfis.contact.ContactDetector.query` for the definitions.
    """
    tol, eps = par[PAR_TOL], par[PAR_EPS]
    dx, dy, dz = par[1], par[2], par[3]
    row, d2, qx, qy, qz, u, v, w, reg = closest(tri, box, node, px, py, pz, hint,
                                                0.0, 0.0, 0.0, np.inf)
    nx, ny, nz = pseudo_normal(tri, box, node, px, py, pz, row, qx, qy, qz, reg, tol)
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    dist = math.sqrt(d2)
    if nn > 0.0:
        nx, ny, nz = nx / nn, ny / nn, nz / nn
        side = (px - qx) * nx + (py - qy) * ny + (pz - qz) * nz
    elif dist > 0.0:  # faces cancel (a two-sided sheet): call it outside, normal towards p
        nx, ny, nz = (px - qx) / dist, (py - qy) / dist, (pz - qz) / dist
        side = 1.0
    else:
        side = 1.0
    sdist = -dist if side < 0.0 else dist
    depth = 0.0
    cqx, cqy, cqz, crow = qx, qy, qz, row
    if par[PAR_FIXED] != 0.0:
        ux, uy, uz = dx, dy, dz
        if sdist < 0.0:
            # Walk back out along -direction to the first crossing: the surface point the probe
            # entered at. It must face the probe (n . direction < 0); a back face means the
            # probe is inside but came through the far side (e.g. the chest wall): no contact.
            hrow, t, hu, hv, hw = raycast(tri, box, node, px, py, pz, -dx, -dy, -dz,
                                          0.0, np.inf, 0, eps)
            if hrow >= 0 and t > 0.0 and (tri[hrow, 9] * dx + tri[hrow, 10] * dy
                                          + tri[hrow, 11] * dz) < 0.0:
                depth = t
                cqx, cqy, cqz, crow = px - t * dx, py - t * dy, pz - t * dz, hrow
    else:
        ux, uy, uz = -nx, -ny, -nz
        if sdist < 0.0:
            depth = -sdist
    out[0], out[1], out[2] = qx, qy, qz
    out[OUT_FACE] = ids[0, row]
    out[4], out[5], out[6] = u, v, w
    out[OUT_SD] = sdist
    out[8], out[9], out[10] = nx, ny, nz
    out[OUT_DEPTH] = depth
    out[12], out[13], out[14] = cqx, cqy, cqz
    out[OUT_CFACE] = ids[0, crow]
    out[16], out[17], out[18] = ux, uy, uz
    out[OUT_ROW] = row


@_jit
def query_one(tri, box, node, ids, par, px, py, pz, hint_face, out):
    """One point (scalars, so the Python call stays cheap); ``hint_face`` a face index or -1."""
    hint = ids[1, hint_face] if 0 <= hint_face < ids.shape[1] else -1
    _query_point(tri, box, node, ids, par, px, py, pz, hint, out)


# The packed form: every table in one float64 buffer, so that the per-call dispatch (numba types
# each argument, ~50 ns per array) sees 6 arguments instead of 10. Header: F, N, then tri (F, 16),
# box (N, 11), par (6,), and the int64 tables node (N, 2), ids (2, F) stored bit for bit.
_HDR = 2


def pack_tables(tri, box, node, ids, par):
    """One buffer holding the tables; returns ``(buf, (tri, box, node, ids, par))`` where the
    tables are views into ``buf`` (no second copy)."""
    F, N = tri.shape[0], box.shape[0]
    parts = [np.array([F, N], np.float64), tri.ravel(), box.ravel(), par.ravel(),
             np.ascontiguousarray(node, np.int64).ravel().view(np.float64),
             np.ascontiguousarray(ids, np.int64).ravel().view(np.float64)]
    buf = np.ascontiguousarray(np.concatenate(parts))
    return buf, unpack_tables(buf)


@_jit
def unpack_tables(buf):
    """Views ``(tri, box, node, ids, par)`` into a buffer made by :func:`pack_tables`."""
    F, N = np.int64(buf[0]), np.int64(buf[1])
    a = _HDR
    tri = buf[a:a + 16 * F].reshape((F, 16))
    a += 16 * F
    box = buf[a:a + 11 * N].reshape((N, 11))
    a += 11 * N
    par = buf[a:a + 6]
    a += 6
    node = buf[a:a + 2 * N].view(np.int64).reshape((N, 2))
    a += 2 * N
    ids = buf[a:a + 2 * F].view(np.int64).reshape((2, F))
    return tri, box, node, ids, par


@_jit
def query_packed(buf, px, py, pz, hint_face, out):
    """:func:`query_one` on a packed buffer; also returns the scalars the caller needs as Python
    numbers: ``(face, signed_distance, depth, contact_face)``."""
    tri, box, node, ids, par = unpack_tables(buf)
    hint = ids[1, hint_face] if 0 <= hint_face < ids.shape[1] else -1
    _query_point(tri, box, node, ids, par, px, py, pz, hint, out)
    return (np.int64(out[OUT_FACE]), out[OUT_SD], out[OUT_DEPTH], np.int64(out[OUT_CFACE]))


@_jit
def query_batch(tri, box, node, ids, par, P, out):
    """Each row of ``P`` (n, 3) [m] into ``out`` (n, OUT_WIDTH); each point is first tested
    against the previous point's face (ordered paths prune most of the tree that way)."""
    hint = -1
    for i in range(P.shape[0]):
        _query_point(tri, box, node, ids, par, P[i, 0], P[i, 1], P[i, 2], hint, out[i])
        hint = np.int64(out[i, OUT_ROW])


@_jit
def follow_packed(buf, px, py, pz, dx, dy, dz, max_step, out):
    """The tracker's proxy step in one call (see :class:`haptic_anfis.contact.ContactTracker`).

    From the probe p walk back along -d (from ``-max_step``) to the first face the ray leaves
    through (n . d < 0 seen along d): the proxy e = p - t d; then along +d from e to the next
    crossing (the tissue thickness under the proxy). Writes e (0:3) and that face's normal (3:6)
    into ``out`` and returns ``(face, t, thickness)``; face = -1 when there is no such crossing
    (then only t is meaningful); thickness = inf when nothing lies behind the proxy within t
    (a thickness beyond t would not change the tracker's depth).
    """
    tri, box, node, ids, par = unpack_tables(buf)
    tol, eps = par[PAR_TOL], par[PAR_EPS]
    row, t, u, v, w = raycast(tri, box, node, px, py, pz, -dx, -dy, -dz, -max_step, np.inf, 1,
                              eps)
    if row < 0:
        return np.int64(-1), t, np.inf
    ex, ey, ez = px - t * dx, py - t * dy, pz - t * dz
    out[0], out[1], out[2] = ex, ey, ez
    out[3], out[4], out[5] = tri[row, 9], tri[row, 10], tri[row, 11]
    if t <= 0.0:
        return ids[0, row], t, np.inf
    # Only a thickness below the depth t changes the answer (depth = min(t, thickness, cap)), so
    # the ray stops at the probe: the far side (the chest wall's long fan) is not searched while
    # the probe is above it. Returning inf for "no crossing up to t" gives the same depth.
    trow, tt, u, v, w = raycast(tri, box, node, ex, ey, ez, dx, dy, dz, tol, t, 0, eps)
    return ids[0, row], t, (tt if trow >= 0 else np.inf)
