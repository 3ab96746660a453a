"""Load a tissue surface mesh into the tissue frame (metres) and check it is usable for contact.

Errors (``ValueError``, naming the input) for what no query could survive: not a mesh file, no
faces, non-finite vertices, face indices out of range, every face of zero area, and an extent no
breast has in the stated unit (a millimetre file read as metres is a 45 m breast; the error names
``mesh_unit``, the contact detector's parameter, and the unit the numbers look like). Warnings (``warnings.warn``) for what
the detector handles but the user should know: an open (not watertight) surface, duplicate
vertices, some zero-area faces.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import trimesh

#: Metres per unit.
UNITS = {'m': 1.0, 'mm': 1e-3}
#: Plausible size of a tissue surface [m] (largest bounding-box side): a breast, or a phantom
#: patch the 10 cm Falcon workspace can reach, is between 1 cm and 1 m across.
PLAUSIBLE_EXTENT = (0.01, 1.0)
_FORMATS = 'STL, OBJ, PLY, OFF or GLB'


class MeshWarning(UserWarning):
    """A mesh the detector can use but that is not what a tissue surface should be."""


def load_mesh(path: str | os.PathLike, unit: str = 'mm',
              transform: np.ndarray | None = None,
              plausible_extent: tuple[float, float] | None = PLAUSIBLE_EXTENT) -> trimesh.Trimesh:
    """Read any mesh trimesh reads (STL, OBJ, PLY, OFF, GLB...) into the tissue frame.

    Args:
        path: mesh file.
        unit: length unit of the file's coordinates, ``'mm'`` or ``'m'``.
        transform: optional (4, 4) homogeneous transform applied after the unit scaling, from the
            file's frame (in metres) into the tissue frame (chest wall x = 0, +x out of the body).
        plausible_extent: (min, max) [m] of the surface's largest bounding-box side; outside it
            the unit is wrong (error naming ``mesh_unit``). None: no check.

    Returns:
        ``trimesh.Trimesh`` in metres, faces and vertex order as in the file (``process=False``: no
        merging or reordering, so face indices match the file).

    Raises:
        FileNotFoundError: no such file.
        ValueError: unknown unit, bad transform, unreadable file, or a mesh :func:`validate`
            rejects.
    """
    path = Path(path)
    if unit not in UNITS:
        raise ValueError(f'{path}: unit must be one of {sorted(UNITS)}, got {unit!r}')
    if not path.is_file():
        raise FileNotFoundError(f'{path}: no such mesh file')
    try:
        # force='mesh' concatenates a multi-body scene into one mesh.
        mesh = trimesh.load(str(path), force='mesh', process=False)
    except Exception as exc:  # trimesh raises many kinds; all mean "not a mesh we can read"
        raise ValueError(f'{path}: not a mesh file: could not read a triangle mesh '
                         f'({type(exc).__name__}: {exc}); expected {_FORMATS}') from exc
    if not isinstance(mesh, trimesh.Trimesh):
        raise ValueError(f'{path}: expected a triangle mesh, trimesh read {type(mesh).__name__}')
    if len(mesh.faces) == 0 and path.stat().st_size > 0:
        raise ValueError(f'{path}: not a mesh file: no triangle could be read from its '
                         f'{path.stat().st_size} bytes (expected {_FORMATS})')
    vertices = np.asarray(mesh.vertices, dtype=np.float64) * UNITS[unit]
    if transform is not None:
        T = np.asarray(transform, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f'{path}: transform must be a finite (4, 4) matrix, '
                             f'got shape {T.shape}')
        if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0]):
            raise ValueError(f'{path}: transform must be affine (last row 0 0 0 1), got {T[3]}')
        if np.linalg.det(T[:3, :3]) <= 0.0:
            raise ValueError(f'{path}: transform must keep orientation (det > 0); a mirror would '
                             'turn the surface inside out')
        vertices = vertices @ T[:3, :3].T + T[:3, 3]
    faces = np.asarray(mesh.faces)
    # STL stores each triangle's corners separately: duplicates there are the format, not a defect.
    validate(vertices, faces, name=str(path), warn_duplicates=path.suffix.lower() != '.stl')
    if plausible_extent is not None:
        check_extent(vertices[np.unique(faces)], unit, str(path), plausible_extent)
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False)


def _length(m: float) -> str:
    return (f'{m:.3g} m' if m >= 1.0 else f'{m * 1e3:.3g} mm' if m >= 1e-3
            else f'{m * 1e6:.3g} µm')


def check_extent(vertices: np.ndarray, unit: str, name: str = 'mesh',
                 plausible: tuple[float, float] = PLAUSIBLE_EXTENT) -> float:
    """The largest bounding-box side [m] of ``vertices`` (V, 3) [m]; ValueError naming
    ``mesh_unit`` (and the unit the numbers look like) when it lies outside ``plausible``."""
    extent = float(np.max(np.ptp(vertices, axis=0)))
    lo, hi = plausible
    if lo <= extent <= hi:
        return extent
    scale = 1.0 / UNITS[unit]  # the file's numbers
    fits = [u for u, k in UNITS.items() if u != unit and lo <= extent * scale * k <= hi]
    hint = (f"the numbers look like {fits[0]}: set mesh_unit: {fits[0]}" if fits
            else "check the file's scale and mesh_unit")
    raise ValueError(f"{name}: the surface is {_length(extent)} across read with mesh_unit "
                     f"'{unit}', implausible for a breast (expected {_length(lo)} to "
                     f"{_length(hi)} across); {hint}")


def validate(vertices: np.ndarray, faces: np.ndarray, name: str = 'mesh',
             warn_duplicates: bool = True, degenerate_rtol: float = 1e-12) -> None:
    """Check a triangle mesh for contact queries; raise or warn (see the module docstring).

    Args:
        vertices: (V, 3) float [m].
        faces: (F, 3) int.
        name: what to call the input in messages (a path, 'mesh').
        warn_duplicates: warn when distinct vertices share coordinates.
        degenerate_rtol: zero-area threshold, as in :func:`haptic_anfis.contact.bvh.build_tables`.
    """
    vertices = np.asarray(vertices)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f'{name}: expected vertices of shape (V, 3), got {vertices.shape}')
    if faces.size == 0:
        raise ValueError(f'{name}: expected a triangle mesh with at least one face, got none')
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f'{name}: expected triangular faces of shape (F, 3), got {faces.shape}')
    if not np.issubdtype(faces.dtype, np.integer):
        raise ValueError(f'{name}: expected integer face indices, got {faces.dtype}')
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f'{name}: face indices must lie in [0, {len(vertices)}), '
                         f'got [{faces.min()}, {faces.max()}]')
    used = np.unique(faces)
    bad = ~np.all(np.isfinite(vertices[used]), axis=1)
    if bad.any():
        raise ValueError(f'{name}: expected finite vertex coordinates, {int(bad.sum())} vertices '
                         f'used by faces are NaN/Inf (first: index {int(used[bad][0])})')
    a, b, c = (vertices[faces[:, k]].astype(np.float64) for k in range(3))
    dbl_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.max(np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                               np.linalg.norm(a - c, axis=1)]), axis=0)
    deg = dbl_area <= degenerate_rtol * longest * longest
    if deg.all():
        raise ValueError(f'{name}: expected faces with non-zero area, all {len(faces)} faces are '
                         'degenerate (collinear or repeated corners)')
    if deg.any():
        warnings.warn(f'{name}: {int(deg.sum())} of {len(faces)} faces have zero area; they are '
                      'kept as segments and ignored for normals', MeshWarning, stacklevel=3)
    if warn_duplicates:
        n_unique = len(np.unique(vertices[used], axis=0))
        if n_unique < len(used):
            warnings.warn(f'{name}: {len(used) - n_unique} duplicate vertices (same coordinates, '
                          'different indices); contact queries handle them, but the mesh is not '
                          'connected through them', MeshWarning, stacklevel=3)
    # Watertight: every edge shared by exactly two faces. Vertices are identified by coordinates,
    # so an STL (corners stored per triangle) of a closed surface counts as closed.
    vid = np.unique(vertices, axis=0, return_inverse=True)[1].reshape(-1)
    g = vid[faces]
    edges = np.sort(np.concatenate([g[:, [0, 1]], g[:, [1, 2]], g[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    if np.any(counts != 2):
        warnings.warn(f'{name}: mesh is not watertight ({int(np.sum(counts == 1))} boundary edges, '
                      f'{int(np.sum(counts > 2))} non-manifold); inside/outside is only meaningful '
                      'near the surface', MeshWarning, stacklevel=3)
