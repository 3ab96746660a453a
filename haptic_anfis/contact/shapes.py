"""Analytic tissue-shaped meshes (tests, benchmarks, demos without a scanned surface)."""
from __future__ import annotations

import numpy as np
import trimesh


def ellipsoid_dome(radii: tuple[float, float, float] = (0.045, 0.070, 0.070), n_theta: int = 25,
                   n_phi: int = 100, closed: bool = True) -> trimesh.Trimesh:
    """The breast as the semi-ellipsoid (x/rx)^2 + (y/ry)^2 + (z/rz)^2 = 1, x >= 0 [m].

    The chest wall is the plane x = 0 and +x points out of the body (the tissue frame of
    :mod:`haptic_anfis.tissue.synthetic`). The dome is a (polar angle from +x) x (azimuth) grid with a
    triangle fan at the nipple pole; ``closed`` adds the chest-wall disc as a fan of long thin
    triangles from the centre. Faces: ``2 * n_theta * n_phi`` (closed) or
    ``n_phi * (2 * n_theta - 1)`` (open). Normals point outwards.
    """
    rx, ry, rz = radii
    theta = np.linspace(0.0, 0.5 * np.pi, n_theta + 1)[1:]
    phi = np.linspace(0.0, 2.0 * np.pi, n_phi, endpoint=False)
    th, ph = np.meshgrid(theta, phi, indexing='ij')  # (n_theta, n_phi)
    ring = np.stack([rx * np.cos(th), ry * np.sin(th) * np.cos(ph), rz * np.sin(th) * np.sin(ph)],
                    axis=-1).reshape(-1, 3)
    ring[-n_phi:, 0] = 0.0  # the last ring lies exactly on the chest wall
    pole = 0
    vid = 1 + np.arange(n_theta * n_phi).reshape(n_theta, n_phi)
    nxt = np.roll(vid, -1, axis=1)
    faces = [np.column_stack([np.full(n_phi, pole), vid[0], nxt[0]])]
    a, b, c, d = vid[:-1], vid[1:], nxt[1:], nxt[:-1]
    faces.append(np.column_stack([a.ravel(), b.ravel(), c.ravel()]))
    faces.append(np.column_stack([a.ravel(), c.ravel(), d.ravel()]))
    vertices = [np.array([[rx, 0.0, 0.0]]), ring]
    if closed:
        centre = 1 + n_theta * n_phi
        vertices.append(np.zeros((1, 3)))
        faces.append(np.column_stack([np.full(n_phi, centre), nxt[-1], vid[-1]]))
    return trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=False)
