"""What the browser view draws, as plain arrays (no ROS, no viser): the skin coloured per pressure
level (:mod:`haptic_anfis.palette`, the meanings of report.png), the region to examine outlined
and apart from the skin outside it, the dent under the probe in the continuous pressure colours;
the probe's pose, the lesion and mark colours, the camera framing.

Tissue frame, metres: chest wall at x = 0, +x out of the body along the nipple axis.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..palette import FINDING, LEVEL, MARK, NORMAL, NOT_PRESSED, SKIN, rgb255

__all__ = ['FRONTAL', 'LESION_RGB', 'LEVEL_RGB', 'MARK_RGB', 'NORMAL_RGB', 'OUTSIDE_RGB',
           'PROBE_LENGTH', 'Framing', 'SkinPaint', 'frame_camera', 'pressure_rgb', 'probe_centred',
           'probe_quaternion', 'region_outline']

#: [m] drawn length of the probe cylinder (its face at the probe tip, its body out of the tissue)
PROBE_LENGTH = 0.03

#: coverage colour per highest level reached (the palette's, as report.png): none (the region
#: not yet palpated: a neutral, lighter than light), light, medium, deep
LEVEL_RGB = np.array([rgb255(NOT_PRESSED)] + [rgb255(LEVEL[k]) for k in LEVEL], np.uint8)
#: skin outside the region to examine: the skin tone dimmed, so what is left to palpate (the
#: neutral inside the outline) stands apart from what need not be
OUTSIDE_RGB = tuple(int(round(0.62 * c)) for c in rgb255(SKIN))
#: lesion markers revealed in the debrief (the palette's findings)
LESION_RGB = {'hit': rgb255(FINDING['found']), 'missed': rgb255(FINDING['missed']),
              'below device': rgb255(FINDING['not palpable'])}
#: the normal background revealed in the debrief: a lobule or rib, one that stands out as much
#: as a lesion would (:class:`~haptic_anfis.view.debrief.NormalMarker` ``status``)
NORMAL_RGB = {k: rgb255(v) for k, v in NORMAL.items()}
#: marks: a hit, another mark on a found lesion, a false mark; live (not yet scored): 'live'
MARK_RGB = {'hit': rgb255(MARK['hit']), 'repeat': rgb255(MARK['repeat']),
            'false': rgb255(MARK['false']), 'not_palpable': rgb255(MARK['not_palpable']),
            'live': rgb255(MARK['repeat'])}


def pressure_rgb(depth: np.ndarray, thresholds) -> np.ndarray:
    """(n, 3) float 0..255: the continuous pressure map for depths ``depth`` (n,) [m]: the
    not-pressed neutral at 0, then linear through the palette's light, medium and deep colours
    at the ``thresholds`` (light, medium, deep) [m], deep beyond (the legend's scale)."""
    xs = np.concatenate([[0.0], np.asarray(thresholds, float)])
    d = np.clip(np.asarray(depth, float), 0.0, xs[-1])
    return np.stack([np.interp(d, xs, LEVEL_RGB[:, k].astype(float)) for k in range(3)], axis=1)


def region_outline(faces: np.ndarray, region_faces: np.ndarray) -> np.ndarray:
    """(e, 2) int: the vertex pairs of the region's border (edges of exactly one region face)."""
    f = np.asarray(faces, np.int64)[np.asarray(region_faces, np.int64)]
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, count = np.unique(e, axis=0, return_counts=True)
    return uniq[count == 1]


class SkinPaint:
    """Vertex colours of the skin mesh from the coverage of its region faces and a dent.

    Args:
        vertices: (v, 3) [m]; faces: (f, 3) int.
        region_faces: (m,) indices into ``faces`` of the coverage grid's faces
            (:attr:`~haptic_anfis.exam.coverage.CoverageGrid.faces_index`), in the grid's order.
        thresholds: (light, medium, deep) [m]: the dent's continuous pressure scale.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, region_faces: np.ndarray,
                 thresholds=(0.002, 0.005, 0.008)) -> None:
        self.vertices = np.asarray(vertices, float)
        self.faces = np.asarray(faces, np.int64)
        self.region_faces = np.asarray(region_faces, np.int64)
        self.thresholds = tuple(float(t) for t in thresholds)
        # the corners of each region face, for the per-vertex maximum of the face levels
        self._corner_v = self.faces[self.region_faces].reshape(-1)
        self.in_region = np.zeros(len(self.vertices), bool)
        self.in_region[self._corner_v] = True

    def vertex_levels(self, face_levels: np.ndarray) -> np.ndarray:
        """(v,) int: per vertex, the highest level (0..3) of the region faces around it."""
        out = np.zeros(len(self.vertices), np.int64)
        np.maximum.at(out, self._corner_v, np.repeat(np.asarray(face_levels, np.int64), 3))
        return out

    def colours(self, vertex_levels: np.ndarray | None = None,
                displacement: np.ndarray | None = None) -> np.ndarray:
        """(v, 4) uint8 RGBA: the level colour (the not-pressed neutral in the region, the
        dimmed skin outside), and under the probe the continuous pressure colour of the
        displacement [m] (v, 3), faded in over the first light threshold of it."""
        lv = np.zeros(len(self.vertices), np.int64) if vertex_levels is None else vertex_levels
        rgb = LEVEL_RGB[np.clip(lv, 0, 3)].astype(float)
        rgb[~self.in_region] = OUTSIDE_RGB
        if displacement is not None:
            d = np.linalg.norm(displacement, axis=1)
            w = np.clip(d / self.thresholds[0], 0.0, 1.0)[:, None]
            rgb = (1 - w) * rgb + w * pressure_rgb(d, self.thresholds)
        out = np.empty((len(rgb), 4), np.uint8)
        out[:, :3] = np.round(rgb)
        out[:, 3] = 255
        return out


#: the camera's direction from the breast: in front of the chest, a little above so the dome
#: reads as one (tilted 10 degrees). Frontal, so the whole region to examine is in view: from
#: the side its far edge hides behind the dome's silhouette
FRONTAL = (1.0, 0.0, 0.18)


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
                 direction=FRONTAL, margin: float = 1.15) -> Framing:
    """Camera looking at the middle of the mesh from ``direction`` (tissue frame; the default
    :data:`FRONTAL`), far enough that the bounding sphere of ``vertices`` [m] fills the view
    with ``margin``. viser's default camera sits 5 m away from a scene of 14 cm, where the
    breast is a few pixels."""
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


def probe_centred(tip, direction) -> tuple[tuple[float, float, float],
                                           tuple[float, float, float, float]]:
    """(centre (3,) [m], (w, x, y, z)) of the probe cylinder drawn about its centre (RViz's
    cylinder): its face at the probe ``tip`` (3,) [m], its body out of the tissue against the
    indentation ``direction`` (None, zero or not finite: -x, the nipple axis inwards)."""
    d = np.asarray((-1.0, 0.0, 0.0) if direction is None else direction, float)
    n = float(np.linalg.norm(d))
    d = d / n if n > 1e-9 else np.array([-1.0, 0.0, 0.0])
    c = np.asarray(tip, float) - 0.5 * PROBE_LENGTH * d
    return (float(c[0]), float(c[1]), float(c[2])), probe_quaternion(d)
