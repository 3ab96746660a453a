"""What every part of a scene file's parser shares: the error type, the edge units and the checks
of a number or a vector, and the height of the breast's surface. (``scene`` and ``background``
both read them; neither imports the other's internals.)"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import HapticAnfisError

MM = 1e-3
KPA = 1e3


class SceneError(HapticAnfisError, ValueError):
    """A scene file is missing, malformed or physically inconsistent."""


def check_keys(d: Any, allowed: set[str], where: str) -> dict[str, Any]:
    """``d`` itself when it is a mapping whose keys are all in ``allowed``; else SceneError naming
    ``where`` and the unknown keys."""
    if not isinstance(d, dict):
        raise SceneError(f'{where}: expected a mapping, got {type(d).__name__}')
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise SceneError(f'{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}')
    return d


def check_number(d: dict[str, Any], key: str, where: str, *, positive: bool = True,
                 default: float | None = None) -> float:
    """``d[key]`` as a finite float (> 0 when ``positive``); ``default`` when absent (None:
    required). Raises SceneError naming ``where.key``."""
    if key not in d:
        if default is None:
            raise SceneError(f'{where}: missing required key {key!r}')
        return default
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise SceneError(f'{where}.{key}: expected a finite number, got {v!r}')
    if positive and v <= 0:
        raise SceneError(f'{where}.{key}: must be > 0, got {v!r}')
    return float(v)


def check_vec(d: dict[str, Any], key: str, where: str, n: int) -> tuple[float, ...]:
    """``d[key]`` as a tuple of ``n`` finite floats; SceneError naming ``where.key`` otherwise."""
    v = d.get(key)
    if (not isinstance(v, (list, tuple)) or len(v) != n
            or not all(isinstance(c, (int, float)) and not isinstance(c, bool) and np.isfinite(c)
                       for c in v)):
        raise SceneError(f'{where}.{key}: expected a list of {n} finite numbers, got {v!r}')
    return tuple(float(c) for c in v)


def region_centre(t: dict[str, Any], where: str, radii: tuple[float, float, float]
                  ) -> tuple[tuple[float, float, float], str]:
    """A region's centre [m] from ``centre_mm`` (x, y, z), or from ``position_mm`` (y, z) over the
    chest wall plus ``depth_mm`` of the centre under the skin (along -x); and the given values as
    text for messages."""
    if ('centre_mm' in t) == ('position_mm' in t or 'depth_mm' in t):
        raise SceneError(f'{where}: give either centre_mm [x, y, z] or position_mm [y, z] with '
                         'depth_mm (centre depth under the skin)')
    if 'centre_mm' in t:
        c = tuple(v * MM for v in check_vec(t, 'centre_mm', where, 3))
        return (c[0], c[1], c[2]), f'centre {t["centre_mm"]} mm'
    y, z = (v * MM for v in check_vec(t, 'position_mm', where, 2))
    depth = check_number(t, 'depth_mm', where) * MM
    c = (float(surface_height(np.array(y), np.array(z), radii)) - depth, y, z)
    return c, f'position {t["position_mm"]} mm, depth {t["depth_mm"]} mm'


def surface_height(y: np.ndarray, z: np.ndarray, radii: tuple[float, float, float]) -> np.ndarray:
    """Height x [m] of the semi-ellipsoid above the chest wall at (y, z) [m]; 0 outside."""
    rx, ry, rz = radii
    return rx * np.sqrt(np.clip(1.0 - (np.asarray(y) / ry) ** 2 - (np.asarray(z) / rz) ** 2,
                                0.0, None))


def sphere_inside(centre: tuple[float, float, float], r: float,
                  radii: tuple[float, float, float]) -> bool:
    """True when the sphere (centre [m], radius r [m]) lies inside the semi-ellipsoid. Sufficient
    test: the centre lies in the ellipsoid shrunk by r (which the inner parallel body contains)
    and the sphere stays above the chest wall x = 0."""
    shrunk = np.array(radii) - r
    return bool(np.all(shrunk > 0) and centre[0] - r >= 0
                and sum((ci / si) ** 2 for ci, si in zip(centre, shrunk)) <= 1.0)
