"""Structured hexahedral meshes, built afresh for each loading point in milliseconds.

How a mesh is made (all in the (y, z) chest-wall plane first, then extruded along x):

1. Pre-image O-grid of the unit disc: an ``n x n`` square grid mapped onto the disc |w| <= s (its
   4n rim nodes evenly spaced in angle), surrounded by rings whose radii grow geometrically by
   exp(pi / 2n), so every ring cell is a square in log-polar terms.
2. A Moebius map of the unit disc onto itself, w -> (w + c) / (1 + conj(c) w), chosen so that the
   circle |w| = s lands exactly on the probe outline (centre p, radius a). It is conformal, so
   cells stay square; and it shrinks them near p, so the mesh is finest under the probe and
   coarse far from it: model only what the load case needs. The footprint outline is a mesh
   line by construction (docs/design.md: nodes ON r = a, not "nodes with r <= a").
3. Scale the unit disc to the base ellipse (radii Ry, Rz times ``rim``); for Ry != Rz a local radial
   correction puts the footprint nodes back onto the circle r = a.
4. Extrude each base node from the chest wall (x = 0, or the domain's ``floor``: the ribs) to
   the surface in the same number of layers, graded geometrically from about the probe-edge
   element size at the skin. A floor makes the clamped wall follow the ribs, so a rib is a
   boundary of the mesh, exact at every node, not a stiffness smeared over the cells it cuts.

Stiff inclusions are represented per cell by their volume fraction (27 samples per hexahedron),
so forces vary smoothly as the mesh moves with the loading point (no staircase noise in the data).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

HeightFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Domain:
    """A body on the chest wall x = 0: elliptic base of radii (ry, rz) [m] (the meshed extent) and
    surface ``height(y, z)`` [m] > 0 over it. ``fix_rim``: also clamp the lateral rim wall.
    ``floor(y, z)`` [m], 0 <= floor < height: where the clamped wall lies (rigid ribs rising from
    the chest wall); None: the flat chest wall x = 0."""

    ry: float
    rz: float
    height: HeightFn
    fix_rim: bool = True
    floor: HeightFn | None = None


@dataclass
class HexMesh:
    """A hexahedral mesh and the node sets the load case needs.

    Attributes:
        points: (N, 3) node coordinates (x, y, z) [m].
        cells: (M, 8) hexahedra, node order of felupe/VTK (positive Jacobian).
        footprint: (F,) ids of the surface nodes under the probe (rim nodes on r = a included).
        fixed: (B,) ids of clamped nodes (chest wall, and the lateral rim if fixed).
        surface_point: (3,) loading point: the footprint centre on the undeformed surface [m].
        probe_edge_size: element edge length along the probe outline [m].
        footprint_radius: radius of the meshed footprint outline [m]: the probe radius, less
            ``edge_offset`` times the first cell outside it (see ``build_mesh``).
        skin: (S,) ids of the skin (top-layer) nodes; empty if the builder did not say.
        skin_quads: (Q, 4) skin faces as node ids (the top faces of the top-layer cells).
    """

    points: np.ndarray
    cells: np.ndarray
    footprint: np.ndarray
    fixed: np.ndarray
    surface_point: np.ndarray
    probe_edge_size: float
    footprint_radius: float = 0.0
    skin: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    skin_quads: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=np.int64))

    @property
    def ndof(self) -> int:
        return 3 * len(self.points)


def outer_halvings(refine: int, outer_refine: int | None) -> int:
    """Halvings of the radial cell size just outside the probe circle (``outer_refine`` defaults
    to ``refine`` and cannot exceed it)."""
    return refine if outer_refine is None else min(outer_refine, refine)


def disc_ogrid(n: int, s: float, refine: int = 0, outer_refine: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, int]:
    """O-grid of the unit disc holding the circle |w| = s as a mesh line.

    The disc |w| <= s is an n x n square grid mapped to a disc, surrounded (when ``refine`` > 0)
    by rings graded towards |w| = s; outside, rings grow from s to 1. With ``refine`` = k the
    radial cell size at the circle is 2^-k of the circumferential one, on both sides: the probe's
    edge singularity needs radial (and depth) resolution, not circumferential.

    Returns:
        w: (N2,) complex node positions; the first (n+1)^2 are the mapped square's nodes.
        quads: (M2, 4) counter-clockwise quadrilaterals.
        n_core: number of mapped-square nodes, (n+1)^2.
    """
    if not 0.0 < s < 1.0:
        raise ValueError(f'inner radius must be in (0, 1), got {s!r}')
    dq = 0.5 * np.pi / n
    fine = dq * 2.0 ** -np.arange(refine, 0, -1)  # e.g. dq/4, dq/2 for refine = 2
    ko = outer_halvings(refine, outer_refine)
    fine_out = dq * 2.0 ** -np.arange(ko, 0, -1)  # the graded rings outside the circle
    # log-radius offsets of the graded rings inside the circle (from the mapped square outwards)
    inner_steps = np.concatenate([[dq], fine[::-1]]) if refine else np.zeros(0)
    s_out = s
    s = s * np.exp(-inner_steps.sum())  # the mapped square's radius
    # tan-spaced lines put the square's boundary nodes at even angles once mapped to the circle.
    g = np.tan(0.25 * np.pi * np.linspace(-1.0, 1.0, n + 1))
    u, v = np.meshgrid(g, g, indexing='ij')
    m = np.maximum(np.abs(u), np.abs(v))
    rho = np.hypot(u, v)
    k = 0.25 * np.pi  # central cells about as large as the rim cells
    with np.errstate(invalid='ignore', divide='ignore'):
        f = np.where(rho > 0, (1.0 - m) * k + m * m / np.where(rho > 0, rho, 1.0), k)
    core = (s * (u + 1j * v) * f).ravel()
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = [np.column_stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(),
                              idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()])]
    boundary = np.unique(np.concatenate([idx[0], idx[-1], idx[:, 0], idx[:, -1]]))
    boundary = boundary[np.argsort(np.angle(core[boundary]))]
    theta = np.angle(core[boundary])
    radii = np.concatenate([s * np.exp(np.cumsum(inner_steps)),
                            s_out * np.exp(np.cumsum(fine_out)) if ko else np.zeros(0)])
    radii = np.concatenate([radii, ring_radii(radii[-1] if refine else s, n)])
    nodes = [core]
    inner = boundary
    start = len(core)
    for r in radii:
        outer = start + np.arange(len(theta))
        nodes.append(r * np.exp(1j * theta))
        quads.append(np.column_stack([inner, outer, np.roll(outer, -1), np.roll(inner, -1)]))
        inner, start = outer, start + len(theta)
    w = np.concatenate(nodes)
    q = np.concatenate(quads)
    # Orient every quad counter-clockwise (shoelace area > 0).
    z = w[q]
    area = 0.5 * np.sum((z.real * np.roll(z.imag, -1, axis=1)
                         - np.roll(z.real, -1, axis=1) * z.imag), axis=1)
    q[area < 0] = q[area < 0][:, ::-1]
    return w, q, (n + 1) ** 2


def ring_radii(s: float, n: int, near: float = np.inf) -> np.ndarray:
    """Radii of the O-grid rings from s (exclusive) to 1 (inclusive).

    Up to ``near * s`` they grow by q = exp(pi / 2n), which keeps ring cells square; beyond, by
    q^2 (cells twice as long radially): the far field needs fewer rings than the probe's
    neighbourhood. The outer part is stretched slightly so the last ring lands on 1.
    """
    dq = 0.5 * np.pi / n
    logs = [np.log(s)]
    while logs[-1] + dq <= min(np.log(near * s), 0.0) + 1e-12:
        logs.append(logs[-1] + dq)
    start = logs[-1]
    nfar = max(1, int(np.ceil(-start / (2 * dq))))
    logs.extend(start + (-start) * np.arange(1, nfar + 1) / nfar)
    return np.exp(np.array(logs[1:]))


def moebius_for_circle(p: complex, a: float) -> tuple[complex, float]:
    """Moebius parameter c and pre-image radius s such that w -> (w + c)/(1 + conj(c) w) maps the
    circle |w| = s onto the circle of centre p, radius a (inside the unit disc)."""
    P = abs(p)
    if P + a >= 1.0:
        raise ValueError(f'circle (|centre| {P:.4g}, radius {a:.4g}) does not fit in the unit disc')
    A, B = P + a, P - a
    if P < 1e-12:
        return 0j, a
    # The pre-images of the circle's real-axis extremes are -s and +s: a quadratic in |c|.
    gamma = ((1 + A * B) - np.sqrt((1 + A * B) ** 2 - (A + B) ** 2)) / (A + B)
    s = (A - gamma) / (1 - gamma * A)
    return gamma * p / P, float(s)


def layer_fractions(thickness: float, first: float, growth: float, refine: int = 0) -> np.ndarray:
    """(L+1,) increasing fractions 0 .. 1 of the local thickness: layers from the chest wall up,
    the top one about ``first`` * 2^-refine [m] thick at ``thickness`` [m], doubling down to
    ``first`` and then growing by ``growth`` downwards."""
    t = [first * 2.0 ** -k for k in range(refine, 0, -1)] + [first]
    while sum(t) < thickness:
        t.append(t[-1] * growth)
    d = np.array(t[::-1])
    # Merge a thin last (deepest) layer into its neighbour rather than stretch all of them.
    if len(d) > 2 and sum(t[:-1]) > 0.8 * thickness:
        d = d[1:]
    f = np.concatenate([[0.0], np.cumsum(d)])
    return f / f[-1]


def cell_samples(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(M, 27, 3) sample points [m] of each hexahedron (a 3 x 3 x 3 rule at +-2/3 and 0 of the
    reference cube): what the volume fractions of inclusions are counted on."""
    xi = np.array([-2.0, 0.0, 2.0]) / 3.0
    r, s, t = (a.ravel() for a in np.meshgrid(xi, xi, xi, indexing='ij'))
    sign = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                     [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)
    N = 0.125 * ((1 + np.outer(r, sign[:, 0])) * (1 + np.outer(s, sign[:, 1]))
                 * (1 + np.outer(t, sign[:, 2])))  # (27, 8) trilinear shape functions
    return np.einsum('qn,mnd->mqd', N, points[cells])


def _tumour_fraction(points: np.ndarray, cells: np.ndarray,
                     spheres: Sequence[tuple[np.ndarray, float]],
                     samples: np.ndarray | None = None) -> np.ndarray:
    """(M, len(spheres)) volume fraction of each hexahedron inside each sphere (27-point rule;
    ``samples`` from :func:`cell_samples` when the caller has them already)."""
    out = np.zeros((len(cells), len(spheres)))
    if not spheres:
        return out
    X = points[cells]  # (M, 8, 3)
    if samples is None:
        samples = cell_samples(points, cells)
    mid, size = X.mean(1), np.ptp(X, axis=1).max(1)
    for k, (c, rad) in enumerate(spheres):
        near = np.linalg.norm(mid - c, axis=1) < rad + size
        if near.any():
            out[near, k] = (np.linalg.norm(samples[near] - c, axis=2) <= rad).mean(1)
    return out


def build_mesh(domain: Domain, centre_yz: tuple[float, float], a: float, n: int,
               growth_vertical: float | None = None, refine: int = 2,
               depth_refine: int | None = None, outer_refine: int | None = None,
               edge_offset: float = 0.0) -> HexMesh:
    """Hexahedral mesh of ``domain`` whose surface holds the probe outline (radius a [m], centred
    above ``centre_yz`` [m]) as a mesh line, with ``n`` cells across the probe.

    The element edge along the outline is about pi a / (2 n); layers under the skin start at that
    size and grow by ``growth_vertical`` (default: the larger of 1.25 and the in-plane growth).
    ``refine`` halvings of the radial and depth cell size grade the mesh towards the probe edge;
    ``depth_refine`` (default: ``refine``) sets the depth halvings separately.

    ``edge_offset`` (alpha) places the footprint outline alpha times the radial size of the first
    cell outside it inside the probe radius: a bonded footprint on linear elements behaves like a
    punch about that much wider than its last pinned node ring, because the cell outside that
    ring carries part of the edge load (the force error is O(h)). alpha = 0.2 makes the forces of
    6 and 8 cells across the probe agree (measured; ``config/scenes/default.yaml``).
    """
    if not 0.0 <= edge_offset < 1.0:
        raise ValueError(f'edge_offset: fraction of the edge cell in [0, 1), got {edge_offset!r}')
    # first outer cell ~ a * dq: its log-radius step times the radius
    a = a / (1.0 + edge_offset * 0.5 * np.pi / n * 2.0 ** -outer_halvings(refine, outer_refine))
    rm = np.sqrt(domain.ry * domain.rz)
    p_hat = complex(centre_yz[0] / domain.ry, centre_yz[1] / domain.rz)
    c, s = moebius_for_circle(p_hat, a / rm)
    w, quads, _ = disc_ogrid(n, s, refine, outer_refine)
    zeta = (w + c) / (1.0 + np.conj(c) * w)
    y, z = domain.ry * zeta.real, domain.rz * zeta.imag
    if not np.isclose(domain.ry, domain.rz):
        y, z = _round_footprint(y, z, centre_yz, a, a / rm * domain.ry, a / rm * domain.rz)
    top = np.asarray(domain.height(y, z), dtype=float)
    base = (np.zeros_like(top) if domain.floor is None
            else np.asarray(domain.floor(y, z), dtype=float))
    thick = top - base
    if np.any(thick <= 0) or np.any(base < 0):
        raise ValueError('domain height must be > 0 over the whole base, above a floor >= 0')
    edge = 0.5 * np.pi * a / n
    cy, cz = np.array(centre_yz[0]), np.array(centre_yz[1])
    t0 = float(domain.height(cy, cz)) - (0.0 if domain.floor is None
                                         else float(domain.floor(cy, cz)))
    frac = layer_fractions(t0, edge, growth_vertical or max(np.exp(0.5 * np.pi / n), 1.25),
                           refine if depth_refine is None else depth_refine)
    L, N2 = len(frac) - 1, len(w)
    pts = np.empty((L + 1, N2, 3))
    pts[:, :, 0] = base[None, :] + frac[:, None] * thick[None, :]
    pts[:, :, 1], pts[:, :, 2] = y[None, :], z[None, :]
    pts = pts.reshape(-1, 3)
    lay = np.arange(L)[:, None, None] * N2
    # Local (r, s, t) -> (y, z, x): quad counter-clockwise in (y, z), t along +x, so det J > 0.
    cells = np.concatenate([quads[None] + lay, quads[None] + lay + N2], axis=2).reshape(-1, 8)
    footprint = L * N2 + np.flatnonzero(np.abs(w) <= s * (1.0 + 1e-9))
    fixed = [np.arange(N2)]
    if domain.fix_rim:
        ring = np.flatnonzero(np.abs(w) > 1.0 - 1e-9)
        fixed.append((np.arange(1, L + 1)[:, None] * N2 + ring[None, :]).ravel())
    centre_x = float(domain.height(np.array(centre_yz[0]), np.array(centre_yz[1])))
    return HexMesh(points=pts, cells=cells.astype(np.int64), footprint=footprint,
                   fixed=np.unique(np.concatenate(fixed)),
                   surface_point=np.array([centre_x, *centre_yz]), probe_edge_size=edge,
                   footprint_radius=a, skin=L * N2 + np.arange(N2, dtype=np.int64),
                   skin_quads=(quads + L * N2).astype(np.int64))


def _round_footprint(y: np.ndarray, z: np.ndarray, centre: tuple[float, float], a: float,
                     ay: float, az: float) -> tuple[np.ndarray, np.ndarray]:
    """Radially rescale about the probe centre so the elliptic footprint image (semi-axes ay, az)
    becomes the circle r = a; the correction fades out linearly by three footprint radii."""
    dy, dz = y - centre[0], z - centre[1]
    r = np.hypot(dy, dz)
    th = np.arctan2(dz, dy)
    rho = 1.0 / np.sqrt((np.cos(th) / ay) ** 2 + (np.sin(th) / az) ** 2)
    beta = np.clip(1.0 - (r / rho - 1.0) / 2.0, 0.0, 1.0)
    scale = 1.0 + (a / rho - 1.0) * beta
    return centre[0] + dy * scale, centre[1] + dz * scale


def tumour_fractions(mesh: HexMesh, spheres: Sequence[tuple[Sequence[float], float]],
                     samples: np.ndarray | None = None) -> np.ndarray:
    """(M, T) volume fraction of each cell inside each sphere (centre (3,) [m], radius [m])."""
    return _tumour_fraction(mesh.points, mesh.cells,
                            [(np.asarray(c, dtype=float), float(r)) for c, r in spheres], samples)
