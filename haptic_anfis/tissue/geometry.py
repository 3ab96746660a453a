"""Breast surface geometry: loading points, surface normals and the triangulated surface mesh.

Pure numpy/trimesh, SI units (m) unless a function says otherwise. Frame: chest wall x = 0, +x out
of the body; the surface is the semi-ellipsoid with radii (Rx, Ry, Rz).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from .scene import Scene, surface_height


def _disc_grid(spacing: float, radius: float) -> np.ndarray:
    """(K, 2) (y, z) points of a square grid of ``spacing`` through the origin inside the disc of
    ``radius`` [m], ordered by y then z."""
    half = int(np.floor(radius / spacing + 1e-9))
    g = np.arange(-half, half + 1) * spacing
    yy, zz = np.meshgrid(g, g, indexing='ij')
    keep = yy ** 2 + zz ** 2 <= radius ** 2 * (1 + 1e-9)
    return np.column_stack([yy[keep], zz[keep]])


def loading_points(scene: Scene) -> np.ndarray:
    """Loading points on the undeformed surface: a square (y, z) grid of ``scene.spacing`` inside the
    palpable disc, lifted onto the surface; then, if the scene asks for it
    (``refine_spacing`` > 0), the points of a finer grid that lie within lesion radius +
    ``refine_margin`` of a lesion's (y, z), each lesion's centre (y, z) and its mirror point
    (-y, -z) (where the lesion contrast is measured), all that are not already base points;
    then, with ``ring_diameters``, each lesion's centre, mirror point and rings
    (:func:`_ring_points`).

    Returns:
        (P, 3) array of surface points (x, y, z) [m]: the base grid first, ordered by y then z (so a
        scene without refinement keeps its point ids), then the added points in the same order.
    """
    yz = _disc_grid(scene.spacing, scene.palpable_radius)
    if scene.refine_spacing > 0 and scene.tumours:
        fine = _disc_grid(scene.refine_spacing, scene.palpable_radius)
        near = np.zeros(len(fine), dtype=bool)
        for t in scene.tumours:
            near |= np.hypot(fine[:, 0] - t.centre[1], fine[:, 1] - t.centre[2]) \
                <= t.radius + scene.refine_margin + 1e-12
        # every lesion's centre and its mirror point (-y, -z): the FE contrast the models must keep
        marks = [(s * t.centre[1], s * t.centre[2]) for t in scene.tumours for s in (1.0, -1.0)]
        marks = np.array([m for m in marks if np.hypot(*m) <= scene.palpable_radius + 1e-12])
        fine = np.concatenate([fine[near], marks.reshape(-1, 2)])
        fine = fine[np.unique(np.round(fine / 1e-9), axis=0, return_index=True)[1]]
        fine = fine[np.lexsort((fine[:, 1], fine[:, 0]))]
        dist = np.min(np.hypot(fine[:, None, 0] - yz[None, :, 0], fine[:, None, 1] - yz[None, :, 1]),
                      axis=1) if len(fine) else np.zeros(0)
        yz = np.concatenate([yz, fine[dist > 1e-9]])
    if scene.ring_diameters and scene.tumours:
        yz = np.concatenate([yz, _ring_points(scene, yz)])
    y, z = yz[:, 0], yz[:, 1]
    return np.column_stack([surface_height(y, z, scene.radii), y, z])


#: ring points closer than this to an earlier point are dropped [m]
RING_MIN_GAP = 1e-3


def _ring_points(scene: Scene, existing: np.ndarray) -> np.ndarray:
    """(K, 2) (y, z) lesion points in order: per lesion its centre, its mirror point (-y, -z),
    then ``ring_points`` points on each ring of radius ``ring_diameters`` x the lesion diameter
    (angles 2 pi j / n, offset by half a step on every other ring); points outside the palpable
    disc or within :data:`RING_MIN_GAP` of an earlier point are left out."""
    out = [p for p in existing]
    for t in scene.tumours:
        c = np.array([t.centre[1], t.centre[2]])
        cand = [c, -c]
        for k, rd in enumerate(scene.ring_diameters):
            n = scene.ring_points
            th = 2.0 * np.pi * (np.arange(n) + 0.5 * (k % 2)) / n
            cand.extend(c + rd * 2.0 * t.radius * np.column_stack([np.cos(th), np.sin(th)]))
        for q in cand:
            if np.hypot(*q) > scene.palpable_radius + 1e-12:
                continue
            if out and np.min(np.hypot(*(np.asarray(out) - q).T)) < RING_MIN_GAP:
                continue
            out.append(np.asarray(q, dtype=float))
    return np.asarray(out[len(existing):]).reshape(-1, 2)


def surface_normals(points: np.ndarray, radii: tuple[float, float, float]) -> np.ndarray:
    """Outward unit normals (P, 3) of the ellipsoid at surface points (P, 3) [m]."""
    n = np.asarray(points, dtype=float) / np.asarray(radii, dtype=float) ** 2
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def indentation_direction(scene: Scene, points: np.ndarray) -> np.ndarray:
    """Unit vectors (P, 3) along which the probe moves INTO the tissue at each point.

    'axis' is -x (perpendicular to the body, the paper's protocol); 'normal' is the inward local
    surface normal.
    """
    points = np.atleast_2d(points)
    if scene.direction == 'axis':
        return np.tile([-1.0, 0.0, 0.0], (len(points), 1))
    return -surface_normals(points, scene.radii)


def surface_mesh(radii: tuple[float, float, float], subdivisions: int = 5):
    """Closed triangulated semi-ellipsoid (dome plus the chest-wall disc at x = 0), in metres.

    An icosphere's x >= 0 half becomes the dome; its x < 0 half is folded flat onto the chest-wall
    disc (azimuthal equidistant, so base triangles stay well shaped). Triangles are near-uniform,
    about 2 mm edges for 70 mm radii at 5 subdivisions; the rim is resolved to one triangle.
    Returns a watertight ``trimesh.Trimesh``.
    """
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    v = np.array(sphere.vertices)
    back = v[:, 0] < 0
    lateral = np.linalg.norm(v[back, 1:], axis=1, keepdims=True)
    rho = np.arccos(np.clip(-v[back, 0], -1.0, 1.0))[:, None] / (0.5 * np.pi)
    v[back, 1:] = np.where(lateral > 0, v[back, 1:] / np.where(lateral > 0, lateral, 1.0), 0.0) * rho
    v[back, 0] = 0.0
    dome = trimesh.Trimesh(v * np.asarray(radii, dtype=float), sphere.faces, process=True)
    dome.fix_normals()
    return dome


def write_surface_mesh(scene: Scene, path: str | os.PathLike, units: str = 'mm') -> Path:
    """Write the scene's tissue surface as STL/PLY (by suffix); ``units`` 'mm' (default) or 'm'."""
    if units not in ('mm', 'm'):
        raise ValueError(f"surface mesh units must be 'mm' or 'm', got {units!r}")
    mesh = surface_mesh(scene.radii)
    if units == 'mm':
        mesh.apply_scale(1e3)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + '.tmp' + path.suffix)
    mesh.export(tmp)
    os.replace(tmp, path)
    return path
