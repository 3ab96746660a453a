"""What the browser view draws, as plain arrays (no ROS, no viser): the skin coloured per pressure
level and darkened by the dent, the probe's pose, the lesion and mark colours, the camera framing.

Tissue frame, metres: chest wall at x = 0, +x out of the body along the nipple axis.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['DEEP_DARK', 'LESION_RGB', 'LEVEL_RGB', 'MARK_RGB', 'SKIN_RGB', 'Framing', 'SkinPaint',
           'frame_camera', 'probe_quaternion']

#: untouched skin (RGB 0..255)
SKIN_RGB = (236, 196, 178)
#: coverage colour per highest level reached: none (skin), light, medium, deep — a heat scale
#: yellow -> orange -> red, far from the skin tone and the white page
LEVEL_RGB = np.array([SKIN_RGB, (250, 222, 70), (245, 140, 30), (200, 25, 35)], np.uint8)
#: the dent darkens a corner towards this colour at ``colour_depth`` of displacement
DEEP_DARK = np.array([110, 40, 40], float)
#: lesion markers revealed in the debrief
LESION_RGB = {'hit': (20, 170, 60), 'missed': (150, 0, 200), 'below device': (120, 120, 120)}
#: marks: a hit, another mark on a found lesion, a false mark
MARK_RGB = {'hit': (20, 170, 60), 'repeat': (0, 170, 200), 'false': (20, 20, 20)}


class SkinPaint:
    """Vertex colours of the skin mesh from the coverage of its region faces and a dent.

    Args:
        vertices: (v, 3) [m]; faces: (f, 3) int.
        region_faces: (m,) indices into ``faces`` of the coverage grid's faces
            (:attr:`~haptic_anfis.exam.CoverageGrid.faces_index`), in the grid's order.
        colour_depth: displacement [m] drawn darkest.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, region_faces: np.ndarray,
                 colour_depth: float = 0.016) -> None:
        self.vertices = np.asarray(vertices, float)
        self.faces = np.asarray(faces, np.int64)
        self.region_faces = np.asarray(region_faces, np.int64)
        self.colour_depth = float(colour_depth)
        # the corners of each region face, for the per-vertex maximum of the face levels
        self._corner_v = self.faces[self.region_faces].reshape(-1)

    def vertex_levels(self, face_levels: np.ndarray) -> np.ndarray:
        """(v,) int: per vertex, the highest level (0..3) of the region faces around it."""
        out = np.zeros(len(self.vertices), np.int64)
        np.maximum.at(out, self._corner_v, np.repeat(np.asarray(face_levels, np.int64), 3))
        return out

    def colours(self, vertex_levels: np.ndarray | None = None,
                displacement: np.ndarray | None = None) -> np.ndarray:
        """(v, 4) uint8 RGBA: the level colour (skin where none), darkened by the displacement
        [m] (v, 3) under the probe."""
        lv = np.zeros(len(self.vertices), np.int64) if vertex_levels is None else vertex_levels
        rgb = LEVEL_RGB[np.clip(lv, 0, 3)].astype(float)
        if displacement is not None:
            t = np.clip(np.linalg.norm(displacement, axis=1) / self.colour_depth, 0.0, 1.0)
            rgb = (1 - t)[:, None] * rgb + t[:, None] * DEEP_DARK
        out = np.empty((len(rgb), 4), np.uint8)
        out[:, :3] = np.round(rgb)
        out[:, 3] = 255
        return out


@dataclass(frozen=True)
class Framing:
    """Camera pose that frames the breast: ``position``, ``look_at``, ``up`` [m], vertical
    ``fov`` [rad], clip planes ``near`` / ``far`` [m]."""
    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    fov: float
    near: float
    far: float


def frame_camera(vertices: np.ndarray, fov: float = np.radians(40.0),
                 direction=(1.0, -0.55, 0.45), margin: float = 1.15) -> Framing:
    """Camera looking at the middle of the mesh from ``direction`` (tissue frame: in front of the
    chest, a little to the side and above), far enough that the bounding sphere of ``vertices``
    [m] fills the view with ``margin``. viser's default camera sits 5 m away from a scene of
    14 cm, where the breast is a few pixels."""
    v = np.asarray(vertices, float)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = 0.5 * (lo + hi)
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    dist = margin * radius / np.sin(0.5 * fov)
    pos = centre + dist * d
    return Framing(tuple(map(float, pos)), tuple(map(float, centre)), (0.0, 0.0, 1.0), float(fov),
                   near=max(dist - 3 * radius, 1e-3) * 0.1, far=dist + 10 * radius)


def probe_quaternion(direction) -> tuple[float, float, float, float]:
    """(w, x, y, z) rotating the +z axis onto ``-direction`` (the probe cylinder, built along +z
    from its face, stands out of the tissue opposite the indentation direction)."""
    v = -np.asarray(direction, float)
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n < 1e-12:
        v = np.array([1.0, 0.0, 0.0])
    else:
        v = v / n
    z = np.array([0.0, 0.0, 1.0])
    c = float(z @ v)
    if c < -1 + 1e-12:
        return (0.0, 1.0, 0.0, 0.0)
    axis = np.cross(z, v)
    q = np.array([1.0 + c, *axis])
    q /= np.linalg.norm(q)
    return tuple(float(x) for x in q)
