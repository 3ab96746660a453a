"""Coverage of the palpable skin per pressure level, on the surface mesh's triangles (no ROS).

After Saunders, Pilgrim & Pennypacker (Cancer 1986), who marked the squares of a grid on the breast
when touched: here the "squares" are the mesh triangles of the palpable region, area-weighted.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .config import LEVELS


class CoverageGrid:
    """Which region triangles the probe footprint pressed, at which level.

    Args:
        vertices: (v, 3) mesh vertices [m]; faces: (f, 3) int.
        region_radius: the palpable region = faces whose centroid has sqrt(y^2 + z^2) <= this [m]
            (the nipple axis is x).
        footprint_radius: probe footprint radius [m].
        thresholds: depth thresholds (light, medium, deep) [m], cumulative.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, region_radius: float,
                 footprint_radius: float, thresholds):
        v = np.asarray(vertices, float)
        f = np.asarray(faces, np.int64)
        c = v[f].mean(axis=1)
        keep = np.hypot(c[:, 1], c[:, 2]) <= region_radius
        # the chest-wall base (if the mesh has one) is not skin
        n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        keep &= ~((np.abs(n[:, 0]) > 0.99 * np.linalg.norm(n, axis=1)) & (c[:, 0] <= 1e-6))
        if not keep.any():
            raise ValueError(f'coverage: no mesh triangle within the palpable radius '
                             f'{region_radius * 1e3:.1f} mm of the nipple axis')
        self.faces_index = np.flatnonzero(keep)        # region faces into the mesh's faces
        self.vertices, self.faces = v, f
        self.centroids = c[keep]                       # (m, 3)
        self.areas = 0.5 * np.linalg.norm(n[keep], axis=1)
        self.footprint_radius = float(footprint_radius)
        self.thresholds = np.asarray(thresholds, float)
        self.covered = np.zeros((len(self.centroids), len(LEVELS)), bool)   # (m, 3)
        self._tree = cKDTree(self.centroids)

    def add(self, points: np.ndarray, depths: np.ndarray) -> None:
        """Press contact ``points`` (n, 3) [m] at ``depths`` (n,) [m] (0 = no contact)."""
        points = np.asarray(points, float).reshape(-1, 3)
        depths = np.asarray(depths, float).reshape(-1)
        ok = np.isfinite(points).all(axis=1) & np.isfinite(depths) & (depths >= self.thresholds[0])
        if not ok.any():
            return
        points, depths = points[ok], depths[ok]
        level = np.searchsorted(self.thresholds, depths, side='right')  # 1..3
        # Thin the 1 kHz stream: one sample per 1 mm cell per level is enough for an 8 mm footprint.
        key = np.c_[np.round(points * 1e3).astype(np.int64), level]
        _, first = np.unique(key, axis=0, return_index=True)
        lists = self._tree.query_ball_point(points[first], self.footprint_radius)
        lv = level[first]
        for k in range(len(self.thresholds)):   # cumulative: level k+1 or deeper covers level k
            hit = [ix for ix, ok in zip(lists, lv > k) if ok and ix]
            if hit:
                self.covered[np.concatenate(hit).astype(np.int64), k] = True

    def fraction(self) -> dict[str, float]:
        """Area share of the region covered per level, {light, medium, deep} in [0, 1]."""
        a = self.areas / self.areas.sum()
        return {name: float(a[self.covered[:, k]].sum()) for k, name in enumerate(LEVELS)}

    def level_per_face(self) -> np.ndarray:
        """(m,) int: highest level reached per region face (0 none, 1 light, 2 medium, 3 deep)."""
        return self.covered.sum(axis=1)

    def pressed_near(self, point, radius: float, level: int) -> bool:
        """Whether any face within ``radius`` [m] of ``point`` was pressed at ``level`` (0-based)."""
        idx = self._tree.query_ball_point(np.asarray(point, float), radius)
        return bool(idx) and bool(self.covered[idx, level].any())
