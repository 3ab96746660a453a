"""The drawn tissue surface, split into patches so only the dent is re-sent each frame (no ROS).

A marker message pays per triangle corner (rclpy converts every ``geometry_msgs/Point`` one by
one), so the visualizer cannot re-send the whole skin at 30 Hz. The surface's faces are grouped
into square (y, z) patches; each frame :meth:`DentSurface.update` moves the vertices by the
:class:`~haptic_anfis.tissue.deformation.DeformationModel` and reports only the patches whose
drawing changed (dented now, or dented last frame and restored now). Every triangle corner carries
a colour: skin tone, darkening with the local displacement.

SI units (m); tissue frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .deformation import DeformationModel

SKIN = np.array([1.0, 0.8, 0.7])
DEEP = np.array([0.75, 0.25, 0.25])


@dataclass
class Patch:
    """One drawn piece: ``corners`` (3 m, 3) triangle corners [m] and ``colours`` (3 m, 4)."""

    index: int
    corners: np.ndarray
    colours: np.ndarray


class DentSurface:
    """The tissue surface as patches, dented by a deformation model.

    Each patch remembers the displacement it was last drawn with; :meth:`update` re-sends a patch
    when a corner under the probe moved at all, or another corner would move by more than
    ``tolerance`` (so a steady press, or the slowly changing far field, costs nothing), and
    restores every dented patch exactly when the probe lifts. Adjacent patches therefore agree within 2 ``tolerance`` at shared vertices.

    Args:
        vertices: (n, 3) skin vertices [m]; faces: (f, 3) vertex ids.
        model: the dent model (its reach bounds the re-sent region).
        patch_size: edge of the square (y, z) patches [m]; faces on the chest wall (x = 0) form
            patches of their own (they never move).
        tolerance: largest drawn error of a corner [m] before its patch is re-sent.
        alpha: opacity of every corner colour; colour_depth: displacement [m] drawn darkest.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, model: DeformationModel,
                 patch_size: float = 0.008, tolerance: float = 1e-4, alpha: float = 1.0,
                 colour_depth: float = 0.016) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=float)
        self.faces = np.asarray(faces, dtype=np.int64)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or self.faces.ndim != 2 \
                or self.faces.shape[1] != 3:
            raise ValueError('vertices must be (n, 3) and faces (f, 3)')
        if not patch_size > 0:
            raise ValueError(f'patch_size must be > 0 m, got {patch_size!r}')
        if not tolerance >= 0:
            raise ValueError(f'tolerance must be >= 0 m, got {tolerance!r}')
        self.model, self.alpha, self.colour_depth = model, float(alpha), float(colour_depth)
        self.tolerance = float(tolerance)
        cen = self.vertices[self.faces].mean(axis=1)
        key = np.column_stack([np.floor(cen[:, 1:] / patch_size).astype(np.int64),
                               (self.vertices[self.faces][:, :, 0] > 0).any(axis=1)])
        _, label = np.unique(key, axis=0, return_inverse=True)
        label = label.ravel()
        order = np.argsort(label, kind='stable')
        self.face_patch = label
        self.patch_faces = np.split(order, np.flatnonzero(np.diff(label[order])) + 1)
        counts = np.array([len(f) for f in self.patch_faces])
        self._corners = 3 * counts  # corners per patch
        self._start = np.concatenate([[0], np.cumsum(self._corners)[:-1]])  # corner offsets
        self._corner_vid = self.faces[order].reshape(-1)  # corners in patch order
        self._corner_xyz = self.vertices[self._corner_vid]
        self._sent = np.zeros_like(self._corner_xyz)  # displacement each corner is drawn with
        self._sent_moved = np.zeros(len(self._sent), bool)  # corners drawn displaced
        self._corner_patch = np.repeat(np.arange(len(counts)), self._corners)
        self.displacement = np.zeros_like(self.vertices)

    @property
    def n_patches(self) -> int:
        return len(self.patch_faces)

    def patch(self, k: int) -> Patch:
        """Patch ``k`` as drawn now."""
        sl = slice(self._start[k], self._start[k] + self._corners[k])
        u = self._sent[sl]
        return Patch(k, self._corner_xyz[sl] + u, self._colours(u))

    def all_patches(self) -> list[Patch]:
        return [self.patch(k) for k in range(self.n_patches)]

    def update(self, contact_point: Sequence[float] | None, direction: Sequence[float] | None,
               depth: float) -> list[Patch]:
        """Dent the surface for a contact (``contact_point`` None or depth <= 0: no contact) and
        return the patches whose drawing changed."""
        # Only corners that move now or are drawn displaced can change: the rest of the 60 000
        # corners are skipped (the full-mesh comparison was most of a frame's ~9 ms).
        if contact_point is None or direction is None or not depth > 0:
            self.displacement = np.zeros_like(self.vertices)
            idx = np.flatnonzero(self._sent_moved)
            err = np.abs(self._sent[idx]).max(axis=1)  # restore exactly
            limit = 0.0
        else:
            self.displacement = self.model.displacement(self.vertices, contact_point, direction,
                                                        depth)
            moving = np.any(self.displacement != 0.0, axis=1)
            idx = np.flatnonzero(moving[self._corner_vid] | self._sent_moved)
            vid = self._corner_vid[idx]
            err = np.abs(self.displacement[vid] - self._sent[idx]).max(axis=1)
            limit = self.tolerance
            # under the probe the drawing is exact: any change re-sends (the footprint's
            # vertices are the ones moved by exactly depth x direction)
            d = np.asarray(direction, dtype=float)
            face = np.all(self.displacement == depth * d / np.linalg.norm(d), axis=1)
            err[face[vid] & (err > 0)] = np.inf
        worst = np.zeros(self.n_patches)
        np.maximum.at(worst, self._corner_patch[idx], err)
        is_dirty = worst > limit
        dirty = np.flatnonzero(is_dirty)
        if len(dirty) == 0:
            return []
        # every corner of the dirty patches at once (patches are contiguous runs of corners)
        ci = np.flatnonzero(is_dirty[self._corner_patch])
        u = self.displacement[self._corner_vid[ci]]
        self._sent[ci] = u
        self._sent_moved[ci] = np.any(u != 0.0, axis=1)
        xyz, rgba = self._corner_xyz[ci] + u, self._colours(u)
        ends = np.cumsum(self._corners[dirty])
        starts = np.concatenate([[0], ends[:-1]])
        return [Patch(int(k), xyz[a:b], rgba[a:b]) for k, a, b in zip(dirty, starts, ends)]

    def _colours(self, u: np.ndarray) -> np.ndarray:
        """(n, 4) RGBA of corners displaced by ``u`` (n, 3) [m]: skin darkening with depth."""
        t = np.clip(np.sqrt(np.einsum('ij,ij->i', u, u)) / self.colour_depth, 0.0, 1.0)[:, None]
        out = np.empty((len(u), 4))
        out[:, :3] = (1 - t) * SKIN + t * DEEP
        out[:, 3] = self.alpha
        return out


def dent_model(path='', reach: float = 5.0) -> DeformationModel:
    """The dent model the views draw: the FE skin displacements of ``path`` (a case's dataset or
    its displacement file; '' = the shipped default scene's), fading to exactly 0 over the last
    probe radius before ``reach`` probe radii from the probe axis.

    Raises:
        DisplacementDataError, OSError, ValueError: no usable displacement data.
    """
    if path:
        return DeformationModel.load(path, taper=reach - 1.0, reach=reach)
    return DeformationModel.load_default(taper=reach - 1.0, reach=reach)


class DentFeed:
    """What one dent frame sends, for a drawing that subscribers receive as they join.

    :meth:`frame` is called at the frame rate with the surface shown now (a case switch swaps it),
    the probe's contact and the subscriber count; it returns the patches to send: every patch
    when a subscriber joined (a late one needs the whole surface as drawn), the changed ones
    when the contact moved, nothing while nobody draws it or the contact is the one drawn.
    ``frames`` counts the frames that changed the drawing; ``last`` is the contact drawn."""

    def __init__(self, subscribers: int = 0) -> None:
        self.subscribers = subscribers
        self.shown: DentSurface | None = None
        self.last: tuple | None = None
        self.frames = 0
        self._key: np.ndarray | None = None

    def frame(self, surface: DentSurface | None, contact: tuple | None,
              subscribers: int) -> list[Patch]:
        """The patches to send; ``contact``: (point (3,), direction (3,), depth [m]) or None
        (lifted)."""
        if surface is None:
            return []
        if surface is not self.shown:   # a new surface: its first dent drawn afresh
            self.shown, self._key = surface, None
        out: list[Patch] = []
        if subscribers > self.subscribers:
            out = surface.all_patches()
        self.subscribers = subscribers
        key = None if contact is None else np.concatenate([contact[0], contact[1], [contact[2]]])
        if subscribers == 0 or (key is None and self._key is None) or (
                key is not None and self._key is not None and np.array_equal(key, self._key)):
            return out   # nobody draws it, or the contact drawn: the surface keeps it
        out += surface.update(*(contact or (None, None, 0.0)))
        self.frames += 1
        self.last, self._key = contact, key
        return out
