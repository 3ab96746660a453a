"""The stateless contact query: closest surface point, inside/outside, penetration depth."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import trimesh

from . import bvh
from .mesh_io import load_mesh, validate


@dataclass(frozen=True)
class ContactResult:
    """One contact query. Lengths in metres, vectors in the tissue frame.

    Attributes:
        point: (3,) closest point of the surface to the probe.
        triangle: face index (into ``mesh.faces``) holding ``point``.
        barycentric: (3,) coordinates of ``point`` in that face (sum 1, all >= 0).
        signed_distance: distance probe-surface, negative inside.
        normal: (3,) outward unit normal at ``point`` (angle-weighted pseudo-normal on an edge or
            vertex); ``signed_distance`` has the sign of (probe - point) . normal.
        depth: penetration depth >= 0 along ``direction`` (see :meth:`ContactDetector.query`).
        direction: (3,) unit indentation direction (into the tissue).
        contact_point: (3,) surface point that goes with ``depth`` (the force model's input).
        contact_triangle: face index holding ``contact_point``.
        in_contact: ``depth > 0``.
    """
    point: np.ndarray
    triangle: int
    barycentric: np.ndarray
    signed_distance: float
    normal: np.ndarray
    depth: float
    direction: np.ndarray
    contact_point: np.ndarray
    contact_triangle: int
    in_contact: bool


@dataclass(frozen=True)
class ContactBatch:
    """Many contact queries: the fields of :class:`ContactResult` stacked, n rows.

    Shapes: ``point`` (n, 3), ``triangle`` (n,) int64, ``barycentric`` (n, 3), ``signed_distance``
    (n,), ``normal`` (n, 3), ``depth`` (n,), ``direction`` (n, 3), ``contact_point`` (n, 3),
    ``contact_triangle`` (n,) int64, ``in_contact`` (n,) bool.
    """
    point: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    signed_distance: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    direction: np.ndarray
    contact_point: np.ndarray
    contact_triangle: np.ndarray
    in_contact: np.ndarray

    def __len__(self) -> int:
        return len(self.depth)


_object_new = object.__new__


def _unit_direction(direction) -> np.ndarray | None:
    if direction is None:
        return None
    d = np.asarray(direction, dtype=np.float64).reshape(-1)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0.0:
        raise ValueError('direction: expected None or a finite non-zero 3-vector, '
                         f'got {direction!r}')
    return d / np.linalg.norm(d)


class ContactDetector:
    """Exact contact queries against a triangle surface (the undeformed tissue).

    Build once (the AABB tree is built and the numba kernels compiled or loaded from cache at
    construction; the very first compile takes longest), then query at haptic rate (build time
    and per-call latency on 5k-80k faces: ``docs/measurements/contact.md``, written by
    ``bench/bench_contact.py``).

    Args:
        mesh: ``trimesh.Trimesh`` in metres, tissue frame; faces are used as given (no merging).
            Open meshes work; inside/outside then only means "behind the nearest face".
        direction: indentation direction into the tissue, a 3-vector (normalised here), e.g.
            ``(-1, 0, 0)`` for the paper's fixed axis perpendicular to the chest wall; ``None``
            measures depth along the surface normal.

    Raises:
        ValueError: a mesh :func:`~haptic_anfis.contact.mesh_io.validate` rejects, a bad direction.
    """

    def __init__(self, mesh: trimesh.Trimesh, direction=None, *, _validated: bool = False):
        vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        if not _validated:
            validate(vertices, faces, name='mesh')
        self.mesh = mesh
        self.direction = _unit_direction(direction)
        self._tri, self._box, self._node, self._order = bvh.build_tables(vertices, faces)
        scale = float(np.ptp(vertices[np.unique(faces)], axis=0).max())
        #: Size of the mesh's bounding box [m]; sets the tolerances below.
        self.scale = scale
        # Points within `_tol` of the closest point count as touching it (pseudo-normal), ~1e-10 m
        # on a breast-sized mesh: far below any real feature, far above float rounding.
        self._tol = 1e-9 * scale
        self._eps = 1e-9  # barycentric slack of ray casts, so rays through edges/vertices hit
        d = self.direction if self.direction is not None else np.zeros(3)
        self._par = np.array([float(self.direction is not None), *d, self._tol, self._eps])
        row_of = np.empty_like(self._order)
        row_of[self._order] = np.arange(len(self._order))
        # One buffer for the single-query kernel; the tables are views into it.
        self._buf, (self._tri, self._box, self._node, self._ids, self._par) = bvh.pack_tables(
            self._tri, self._box, self._node, np.stack([self._order, row_of]), self._par)
        self._order, self._row_of = self._ids[0], self._ids[1]
        self._compile()

    def _compile(self) -> None:
        """Compile (or load from numba's cache) every kernel of this surface's queries now, not
        in the 1 kHz loop: the closest point, the ray casts of a contact's entry and of the
        approach and the normal ahead (:mod:`.approach`), and the tracker's follow
        (:mod:`.proxy`), called as they are called there, at the first triangle (answers
        unused). With a cold cache the ray casts and the follow compiled at the trainee's first
        touch: the contact stream stopped for ~1.5 s and the servo loop rendered 0 N for 0.65 s
        as its model expired."""
        q = self._tri[0, 0:3].copy()
        p = q + self._tri[0, 9:12] * (1e-3 * self.scale)  # off the surface, outside
        self.query(q)
        self.query_many(self._tri[:2, 0:3])
        self._raycast(p, np.array([0.0, 0.0, 1.0]), 0.0, 1.0, -1)
        self._normal_at(p, int(self._order[0]), q)
        x, y, z = q.tolist()
        bvh.follow_packed(self._buf, x, y, z, 0.0, 0.0, 1.0, 0.01, np.empty(6))

    @classmethod
    def from_file(cls, path: str | os.PathLike, unit: str = 'mm', transform=None,
                  direction=None) -> 'ContactDetector':
        """Load a mesh file (see :func:`haptic_anfis.contact.mesh_io.load_mesh`) and build on it."""
        mesh = load_mesh(path, unit=unit, transform=transform)  # validates, warns naming the file
        return cls(mesh, direction=direction, _validated=True)

    @property
    def n_faces(self) -> int:
        return len(self._order)

    # -- queries ------------------------------------------------------------------------------

    def _check_points(self, P, name: str) -> np.ndarray:
        P = np.asarray(P, dtype=np.float64)
        if P.ndim == 1:
            P = P.reshape(1, -1)
        if P.ndim != 2 or P.shape[1] != 3:
            raise ValueError(f'{name}: expected shape (3,) or (n, 3), got {np.shape(P)}')
        if not np.isfinite(P).all():
            bad = np.flatnonzero(~np.isfinite(P).all(axis=1))
            raise ValueError(f'{name}: probe position must be finite, got NaN/Inf '
                             f'in {len(bad)} point(s), first row {bad[0]}: {P[bad[0]]}')
        return np.ascontiguousarray(P)

    def query(self, p, hint: int = -1) -> ContactResult:
        """Contact query for one probe point.

        Args:
            p: (3,) probe position [m], tissue frame.
            hint: a face index likely to be near the answer (e.g. last call's ``triangle``), or -1.
                Only a speed-up: the result is the exact closest point either way.

        Returns:
            :class:`ContactResult`. ``point`` is the exact closest surface point (the true closest
            face every time, AABB tree + Ericson's closest-point-on-triangle), ``signed_distance``
            its distance, negative inside, the sign taken from the angle-weighted pseudo-normal so
            that it is right on edges and vertices too. Depth:

            - ``direction=None``: ``depth = max(0, -signed_distance)`` and ``direction = -normal``;
              ``contact_point = point``.
            - fixed ``direction`` d: for a probe inside, walk from the probe back along -d to the
              first surface crossing e = p - t d; ``depth = t`` (the paper's penetration along the
              axis perpendicular to the body) and ``contact_point = e``, provided the crossed face
              faces the probe (n . d < 0). Outside, or when the crossing is a back face (the probe
              is inside but entered through the far side, e.g. through the chest wall), or when
              there is none (open mesh): ``depth = 0`` and ``contact_point = point``.

            ``in_contact = depth > 0``. A stateless query has no memory: a probe pushed through the
            whole tissue and out of its far side is "outside" here; :class:`ContactTracker`
            keeps such a contact and saturates its depth.

        Raises:
            ValueError: ``p`` is not a finite 3-vector.
        """
        try:  # fast path for the 1 kHz loop: plain floats, one finiteness test
            x, y, z = p.tolist() if type(p) is np.ndarray else p
            x, y, z = float(x), float(y), float(z)
            ok = math.isfinite(x + y + z)  # NaN or Inf in any coordinate makes the sum non-finite
        except (TypeError, ValueError):
            ok = False
        if not ok:
            P = self._check_points(p, 'p')  # raises the precise error
            if P.shape[0] != 1:
                raise ValueError(f'p: expected one point of shape (3,), got {np.shape(p)}')
            x, y, z = (float(c) for c in P[0])  # finite, but x + y + z overflowed
        o = np.empty(bvh.OUT_WIDTH)
        face, sd, depth, cface = bvh.query_packed(self._buf, x, y, z, hint, o)
        r = _object_new(ContactResult)  # no frozen-dataclass __init__ (~1 us of setattr calls)
        d = r.__dict__
        d['point'] = o[0:3]
        d['triangle'] = face
        d['barycentric'] = o[4:7]
        d['signed_distance'] = sd
        d['normal'] = o[8:11]
        d['depth'] = depth
        d['direction'] = o[16:19]
        d['contact_point'] = o[12:15]
        d['contact_triangle'] = cface
        d['in_contact'] = depth > 0.0
        return r

    def query_many(self, P) -> ContactBatch:
        """:meth:`query` for each row of ``P`` (n, 3) [m]; returns a :class:`ContactBatch`.

        Consecutive points reuse the previous answer as a hint, so ordered paths (a sweep, a
        recorded trajectory) run faster than shuffled ones.
        """
        P = self._check_points(P, 'P')
        o = np.empty((len(P), bvh.OUT_WIDTH))
        bvh.query_batch(self._tri, self._box, self._node, self._ids, self._par, P, o)
        return ContactBatch(
            point=o[:, 0:3], triangle=o[:, bvh.OUT_FACE].astype(np.int64),
            barycentric=o[:, 4:7], signed_distance=o[:, bvh.OUT_SD], normal=o[:, 8:11],
            depth=o[:, bvh.OUT_DEPTH], direction=o[:, 16:19], contact_point=o[:, 12:15],
            contact_triangle=o[:, bvh.OUT_CFACE].astype(np.int64),
            in_contact=o[:, bvh.OUT_DEPTH] > 0.0)

    # -- building blocks for ContactTracker (face indices in, face indices out) ---------------

    def _normal_at(self, p: np.ndarray, face: int, q: np.ndarray) -> np.ndarray:
        """Outward unit pseudo-normal at the surface point q of ``face`` seen from p."""
        row = self._row_of[face]
        reg = bvh.closest_on_triangle(self._tri, row, q[0], q[1], q[2])[6]
        n = np.array(bvh.pseudo_normal(self._tri, self._box, self._node, p[0], p[1], p[2], row,
                                       q[0], q[1], q[2], reg, self._tol))
        nn = np.linalg.norm(n)
        return n / nn if nn > 0 else self._tri[row, 9:12].copy()

    def _raycast(self, origin: np.ndarray, d: np.ndarray, tmin: float, tmax: float, facing: int):
        """First crossing of origin + t d: (face, t) or None; see :func:`bvh.raycast`."""
        r = bvh.raycast(self._tri, self._box, self._node, origin[0], origin[1], origin[2],
                        d[0], d[1], d[2], tmin, tmax, facing, self._eps)
        if r[0] < 0:
            return None
        return int(self._order[r[0]]), float(r[1])
