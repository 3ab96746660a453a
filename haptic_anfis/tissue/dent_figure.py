"""A strip of what the trainee sees: the drawn tissue around the probe, undeformed and pressed.

The triangles are the visualizer's own: :class:`~haptic_anfis.tissue.dent_display.DentSurface`
patches (the corners and per-corner colours the visualizer turns into its TRIANGLE_LIST markers),
dented by the shipped (or a given) displacement data.

    python -m haptic_anfis.tissue.dent_figure OUT.png [--data FILE.displacement.npz]
        [--depths 0,5,12] [--yz 0,0]
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from ..contact import load_mesh
from .dataset import DATA_DIR
from .deformation import DeformationModel
from .dent_display import DentSurface

try:  # matplotlib: an optional dependency (the 'report' and 'fe' extras); PNG files, no display
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
except ImportError:
    plt = None


def render_strip(surface: DentSurface, contact_point: Sequence[float], direction: Sequence[float],
                 depths_m: Sequence[float], path: str | os.PathLike, half_width: float = 0.03
                 ) -> Path:
    """Write a PNG with one 3-D view per depth [m] of the drawn surface within ``half_width`` [m]
    (in y and z) of the contact, plus a cross-section through the probe axis."""
    if plt is None:
        raise ImportError('the strip figure needs matplotlib (pip install matplotlib)')
    c = np.asarray(contact_point, dtype=float)
    d = np.asarray(direction, dtype=float)
    a = surface.model.probe_radius_
    n = len(depths_m)
    fig = plt.figure(figsize=(4.2 * n, 5.6))
    light = np.array([0.6, -0.4, 0.7])
    light /= np.linalg.norm(light)
    for i, depth in enumerate(depths_m):
        surface.update(c if depth > 0 else None, d, depth)
        ax = fig.add_subplot(2, n, i + 1, projection='3d')
        tris, cols = [], []
        for p in surface.all_patches():
            T = p.corners.reshape(-1, 3, 3)
            keep = (np.abs(T[:, :, 1] - c[1]).max(1) < half_width) \
                & (np.abs(T[:, :, 2] - c[2]).max(1) < half_width) & (T[:, :, 0].min(1) > 0)
            if not keep.any():
                continue
            T = T[keep]
            nrm = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True) + 1e-30
            shade = 0.55 + 0.45 * np.abs(nrm @ light)
            rgb = p.colours.reshape(-1, 3, 4)[keep][:, :, :3].mean(1) * shade[:, None]
            tris.append(T * 1e3)
            cols.append(np.clip(rgb, 0, 1))
        T = np.concatenate(tris)
        ax.add_collection3d(Poly3DCollection(T[:, :, [1, 2, 0]], facecolors=np.concatenate(cols),
                                             edgecolors=(0, 0, 0, 0.15), linewidths=0.2))
        if depth > 0:  # the probe face (flat disc) at the probe position
            t = np.linspace(0, 2 * np.pi, 60)
            face = c + depth * d
            ax.plot(face[1] * 1e3 + a * 1e3 * np.cos(t), face[2] * 1e3 + a * 1e3 * np.sin(t),
                    np.full_like(t, face[0] * 1e3), color=(0.2, 0.4, 1.0), lw=1.5)
        lo, hi = (c[1] - half_width) * 1e3, (c[1] + half_width) * 1e3
        ax.set_xlim(lo, hi)
        ax.set_ylim((c[2] - half_width) * 1e3, (c[2] + half_width) * 1e3)
        ax.set_zlim(c[0] * 1e3 - 30, c[0] * 1e3 + 5)
        ax.set_box_aspect((1, 1, 35 / (2 * half_width * 1e3)))
        ax.view_init(elev=28, azim=-60)
        ax.set_xlabel('y [mm]')
        ax.set_ylabel('z [mm]')
        ax.set_zlabel('x [mm]')
        ax.set_title('undeformed' if depth <= 0 else f'probe at {depth * 1e3:.0f} mm')
        # cross-section: the drawn triangles cut by the plane z = contact z
        ax2 = fig.add_subplot(2, n, n + i + 1)
        for corners, colour, label in ((surface.vertices[surface.faces], '0.6', 'undeformed'),
                                       (None, (0.75, 0.25, 0.25), 'drawn')):
            seg = _plane_cut(surface, c[2], drawn=corners is None)
            seg = seg[(np.abs(seg[:, :, 1] - c[1]) < half_width).all(1)]
            for k, sg in enumerate(seg * 1e3):
                ax2.plot(sg[:, 1], sg[:, 0], color=colour, lw=1.2,
                         label=label if k == 0 else None)
        if depth > 0:
            face = c + depth * d
            ax2.plot([face[1] * 1e3 - a * 1e3, face[1] * 1e3 + a * 1e3], [face[0] * 1e3] * 2,
                     color=(0.2, 0.4, 1.0), lw=3, label='probe face')
        ax2.set_xlim(lo, hi)
        ax2.set_ylim(c[0] * 1e3 - 20, c[0] * 1e3 + 3)
        ax2.set_aspect('equal')
        ax2.set_xlabel('y [mm]')
        ax2.set_ylabel('x [mm]')
        if i == 0:
            ax2.legend(fontsize=7, loc='lower left')
    surface.update(None, None, 0.0)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plane_cut(surface: DentSurface, z0: float, drawn: bool) -> np.ndarray:
    """(s, 2, 3) segments where the surface's triangles (drawn: dented as now; else undeformed)
    cross the plane z = z0 of the undeformed surface (the skin's faces only, x > 0)."""
    F = surface.faces
    V0 = surface.vertices
    V = V0 + surface.displacement if drawn else V0
    zf = V0[F][:, :, 2] - z0
    keep = (zf.min(1) < 0) & (zf.max(1) >= 0) & (V0[F][:, :, 0].min(1) > 0)
    out = []
    for f, zz in zip(F[keep], zf[keep]):
        pts = []
        for i, j in ((0, 1), (1, 2), (2, 0)):
            if (zz[i] < 0) != (zz[j] < 0):
                t = zz[i] / (zz[i] - zz[j])
                pts.append(V[f[i]] + t * (V[f[j]] - V[f[i]]))
        if len(pts) == 2:
            out.append(pts)
    return np.array(out).reshape(-1, 2, 3)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('out', type=Path)
    p.add_argument('--data', help='displacement file (default: the shipped default scene)')
    p.add_argument('--depths', default='0,5,12', help='depths in mm (default 0,5,12)')
    p.add_argument('--yz', default='0,0', help='contact (y, z) in mm on the default dome')
    args = p.parse_args(argv)

    model = DeformationModel.load(args.data) if args.data else DeformationModel.load_default()
    mesh = load_mesh(DATA_DIR / 'default_surface.stl', unit='mm')
    mesh.merge_vertices()
    surface = DentSurface(np.asarray(mesh.vertices), np.asarray(mesh.faces), model)
    y, z = (float(v) * 1e-3 for v in args.yz.split(','))
    rx, ry, rz = 0.045, 0.07, 0.07
    c = np.array([rx * np.sqrt(1 - (y / ry) ** 2 - (z / rz) ** 2), y, z])
    depths = [float(v) * 1e-3 for v in args.depths.split(',')]
    print(render_strip(surface, c, [-1.0, 0.0, 0.0], depths, args.out))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
