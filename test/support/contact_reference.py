"""Brute-force references and test meshes for the contact tests (numpy, deliberately simple)."""
from __future__ import annotations

import numpy as np
import trimesh

from haptic_anfis.contact import ellipsoid_dome

DEG_RTOL = 1e-12  # the detector's definition of a zero-area face


def brute_closest(V: np.ndarray, F: np.ndarray, P: np.ndarray, return_unique: bool = False,
                  tie: float = 1e-13):
    """Closest surface point to each row of P (n, 3) over ALL faces: (points (n, 3), dist (n,)).

    With ``return_unique`` also (n,) bool: False where two different points are equally close
    (within ``tie`` [m]), e.g. inside a convex mesh on the bisector of two faces.

    Per face: the projection onto its plane when it falls inside the triangle, else the nearest of
    the three edges (each a clamped segment projection). Zero-area faces are just their edges.
    """
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(B - A, C - A)
    nn = np.einsum('ij,ij->i', n, n)
    longest2 = np.max([np.einsum('ij,ij->i', e, e) for e in (B - A, C - B, A - C)], axis=0)
    good = np.sqrt(nn) > DEG_RTOL * longest2
    out = np.empty_like(P)
    dist = np.empty(len(P))
    unique = np.ones(len(P), bool)
    for i, p in enumerate(P):
        cands = []
        for s, e in ((A, B), (B, C), (C, A)):
            d = e - s
            dd = np.einsum('ij,ij->i', d, d)
            t = np.where(dd > 0, np.einsum('ij,ij->i', p - s, d) / np.where(dd > 0, dd, 1), 0.0)
            cands.append(s + np.clip(t, 0, 1)[:, None] * d)
        q = p - (np.einsum('ij,ij->i', p - A, n) / np.where(good, nn, 1))[:, None] * n
        inside = good.copy()
        for s, e in ((A, B), (B, C), (C, A)):
            inside &= np.einsum('ij,ij->i', np.cross(e - s, q - s), n) >= 0
        d2 = np.stack([np.sum((c - p) ** 2, axis=1) for c in cands])  # (3, F)
        k = np.argmin(d2, axis=0)
        best = np.stack(cands)[k, np.arange(len(F))]
        best = np.where(inside[:, None], q, best)
        bd2 = np.sum((best - p) ** 2, axis=1)
        j = np.argmin(bd2)
        out[i] = best[j]
        dist[i] = np.sqrt(bd2[j])
        # Tie: another face reaches (almost) the same distance at a different point.
        near = np.abs(np.sqrt(bd2) - dist[i]) <= tie
        unique[i] = not np.any(np.linalg.norm(best[near] - best[j], axis=1) > 1e-12)
    return (out, dist, unique) if return_unique else (out, dist)


def winding_number(V: np.ndarray, F: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Generalised winding number (van Oosterom & Strackee solid angles) of a closed mesh, (n,)."""
    w = np.empty(len(P))
    for i, p in enumerate(P):
        a, b, c = V[F[:, 0]] - p, V[F[:, 1]] - p, V[F[:, 2]] - p
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        num = np.einsum('ij,ij->i', a, np.cross(b, c))
        den = (la * lb * lc + np.einsum('ij,ij->i', a, b) * lc + np.einsum('ij,ij->i', b, c) * la
               + np.einsum('ij,ij->i', c, a) * lb)
        w[i] = np.sum(2.0 * np.arctan2(num, den)) / (4 * np.pi)
    return w


def star_mesh(seed: int = 0, subdivisions: int = 2, radius: float = 0.05) -> trimesh.Trimesh:
    """Non-convex closed mesh with sharp ridges and pits: an icosphere with random vertex radii."""
    rng = np.random.default_rng(seed)
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    r = radius * rng.uniform(0.55, 1.45, len(s.vertices))
    return trimesh.Trimesh(s.vertices * r[:, None], s.faces, process=False)


def with_slivers(mesh: trimesh.Trimesh, n_split: int, seed: int = 0) -> trimesh.Trimesh:
    """Insert zero-area faces into a closed mesh, keeping it watertight.

    For ``n_split`` edges (a, b): add m = (a + b) / 2, split the face (a, b, c) into (a, m, c) and
    (m, b, c) and close the gap with the collinear sliver (a, b, m) (a T-junction repair, as CAD
    exporters make). Also append a few faces with a repeated corner (a, a, b).
    """
    rng = np.random.default_rng(seed)
    V = [v for v in np.asarray(mesh.vertices)]
    F = [list(f) for f in np.asarray(mesh.faces)]
    done = set()
    for fi in rng.permutation(len(F))[: 4 * n_split]:
        if len(done) >= n_split:
            break
        a, b, c = F[fi]
        if fi in done or (a, b) in done or (b, a) in done:
            continue
        m = len(V)
        V.append(0.5 * (V[a] + V[b]))
        F[fi] = [a, m, c]
        F.append([m, b, c])
        F.append([a, b, m])
        done.update({fi, (a, b)})
    for f in rng.choice(len(mesh.faces), 3, replace=False):
        a, b, _ = mesh.faces[f]
        F.append([a, a, b])
    return trimesh.Trimesh(np.array(V), np.array(F), process=False)


def probe_points(mesh: trimesh.Trimesh, n: int, seed: int, near: float) -> np.ndarray:
    """Random points: in and around the bounding box, and close to the surface (both sides)."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    pad = 0.3 * (hi - lo)
    box = rng.uniform(lo - pad, hi + pad, (n // 2, 3))
    m = n - len(box)
    fi = rng.integers(0, len(mesh.faces), m)
    bary = rng.dirichlet([1, 1, 1], m)
    tri = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[fi]]
    on = np.einsum('ij,ijk->ik', bary, tri)
    off = rng.normal(size=(m, 3)) * near * rng.uniform(0.001, 1.0, (m, 1))
    return np.vstack([box, on + off])


def feature_points(mesh: trimesh.Trimesh, n: int, seed: int, offset: float) -> np.ndarray:
    """Points exactly on vertices and edges, and offset from them along +-(averaged) normals."""
    rng = np.random.default_rng(seed)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    vi = rng.integers(0, len(V), n)
    vn = np.asarray(mesh.vertex_normals)[vi]
    f = rng.integers(0, len(F), n)
    k = rng.integers(0, 3, n)
    ea, eb = V[F[f, k]], V[F[f, (k + 1) % 3]]
    emid = 0.5 * (ea + eb)
    en = np.asarray(mesh.face_normals)[f]
    s = rng.choice([-1.0, 1.0], (n, 1)) * offset * rng.uniform(0.01, 1, (n, 1))
    jitter = rng.normal(size=(n, 3)) * 0.2 * offset
    return np.vstack([V[vi], emid, V[vi] + s * vn, emid + s * en, V[vi] + s * vn + jitter])


def dome(n_theta=25, n_phi=100, closed=True):
    return ellipsoid_dome((0.045, 0.070, 0.070), n_theta=n_theta, n_phi=n_phi, closed=closed)


def brute_raycast(V: np.ndarray, F: np.ndarray, o: np.ndarray, d: np.ndarray, tmin: float,
                  tmax: float, facing: int = 0, eps: float = 1e-9):
    """Nearest crossing t of o + t d (tmin <= t <= tmax) over ALL non-degenerate faces, or None.

    Moller & Trumbore with barycentrics widened by ``eps``; ``facing`` as in ``bvh.raycast``.
    """
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1, e2 = B - A, C - A
    n = np.cross(e1, e2)
    nn = np.linalg.norm(n, axis=1)
    longest2 = np.max([np.einsum('ij,ij->i', e, e) for e in (e1, C - B, A - C)], axis=0)
    good = nn > DEG_RTOL * longest2
    ndot = n @ d
    if facing > 0:
        good &= ndot > 0
    elif facing < 0:
        good &= ndot < 0
    h = np.cross(d, e2)
    det = np.einsum('ij,ij->i', e1, h)
    good &= det != 0
    f = 1.0 / np.where(det != 0, det, 1.0)
    s = o - A
    v = f * np.einsum('ij,ij->i', s, h)
    q = np.cross(s, e1)
    w = f * (q @ d)
    t = f * np.einsum('ij,ij->i', e2, q)
    hit = good & (v >= -eps) & (v <= 1 + eps) & (w >= -eps) & (v + w <= 1 + eps)
    hit &= (t >= tmin) & (t <= tmax)
    return float(np.min(t[hit])) if hit.any() else None
