"""The display dent: model error against held-out FE fields, evaluation time, drawn-mesh error.

1. Held-out error of each model form (5 folds grouped by loading point): RMS vector error over
   the polar grid, area-weighted, as a fraction of the depth, in the annulus a < rho <= 3 a (the
   visible dent outside the probe), the dent rho <= 3 a, and everything recorded; plus the
   interpolant with one depth left out of the fit (the depth interpolation).
2. Time of ``DeformationModel.displace`` for every vertex of the shipped surface mesh, and of one
   ``DentSurface.update`` (what the visualizer does per frame before building messages), over
   random contacts on the palpable disc, depths 1-16 mm: p50 / p99 / max.
3. Drawn-mesh error: the surface a triangle mesh of edge h draws (linear between vertices) against
   the model at face centroids and edge midpoints, for the shipped mesh and one subdivision.

    .venv/bin/python bench/bench_deformation.py [--data FILE.displacement.npz | --work-dir DIR]

Timings are printed with the machine's load average; never asserted.
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from haptic_anfis.tissue.deformation import DeformationModel, holdout_errors  # noqa: E402
from haptic_anfis.tissue.displacement import (displacement_path,  # noqa: E402
                                              displacements_from_records, load_displacements)
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])


def load_data(args):
    if args.work_dir:
        from haptic_anfis.tissue.scene import load_scene

        scene = load_scene(args.scene) if args.scene else load_scene()
        recs = [json.loads(Path(f).read_text())
                for f in sorted(glob.glob(os.path.join(args.work_dir, 'point_*.json')))]
        return displacements_from_records(recs, scene.depths, {
            'probe_radius_m': scene.probe_radius, 'dataset_sha256': 'work dir'})
    from haptic_anfis.tissue.dataset import DEFAULT_DATASET

    return load_displacements(args.data or displacement_path(DEFAULT_DATASET))


def surface():
    from haptic_anfis.contact import load_mesh
    from haptic_anfis.tissue.dataset import DATA_DIR

    m = load_mesh(DATA_DIR / 'default_surface.stl', unit='mm')
    m.merge_vertices()
    return m


def contacts(n, seed, radii=(0.045, 0.07, 0.07), r_max=0.042):
    rng = np.random.default_rng(seed)
    r = r_max * np.sqrt(rng.random(n))
    t = 2 * np.pi * rng.random(n)
    y, z = r * np.cos(t), r * np.sin(t)
    x = radii[0] * np.sqrt(1 - (y / radii[1]) ** 2 - (z / radii[2]) ** 2)
    return np.column_stack([x, y, z]), rng.uniform(0.001, 0.016, n)


def pct(v):
    v = np.asarray(v) * 1e3
    p50, p99 = np.percentile(v, [50, 99])
    return f'p50 {p50:6.2f}  p99 {p99:6.2f}  max {v.max():6.2f} ms'


def errors(data):
    print(f'== held-out error ({len(data.point)} loading points x {len(data.depths)} depths; '
          'RMS vector error / depth)')
    print(f'{"form":<24} {"annulus a..3a":>14} {"worst":>7} {"dent <=3a":>10} {"all":>7} '
          f'{"footprint dev":>14}')
    rows = [('interpolant', {}), ('nearest', {}), ('radial', {}),
            ('interpolant, reach 5a', {'taper': 4.0, 'reach': 5.0})]
    for name, kw in rows:
        form = name.split(',')[0]
        e = holdout_errors(data, form=form, folds=5, **kw)
        print(f'{name:<24} {100 * e["annulus_rms_over_depth"]:13.2f}% '
              f'{100 * e["annulus_worst_over_depth"]:6.1f}% {100 * e["dent_rms_over_depth"]:9.2f}% '
              f'{100 * e["all_rms_over_depth"]:6.2f}% {e["footprint_max_dev_m"]:12.1e} m')
    mid = len(data.depths) // 2
    e = holdout_errors(data, folds=5, hold_depth=mid)
    print(f'interpolant, {data.depths[mid] * 1e3:.0f} mm depth also held out: annulus '
          f'{100 * e["annulus_rms_over_depth"]:.2f}% '
          f'(worst {100 * e["annulus_worst_over_depth"]:.1f}%)')
    trunc = np.nanmax(data.truncation_rms / data.depths)
    print(f'harmonic truncation (in the data): max {trunc:.2%} of the depth within 3a')


def timing(data, n):
    from haptic_anfis.nodes.cdr import triangle_markers
    from haptic_anfis.tissue.dent_display import DentSurface

    mesh = surface()
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    model = DeformationModel().fit(data)
    P, D = contacts(n, 1)
    d = np.array([-1.0, 0.0, 0.0])
    for i in range(5):
        model.displace(V, P[i], d, D[i])
    t, cpu = [], []
    for p, dep in zip(P, D):
        t0, c0 = time.perf_counter(), time.process_time()
        model.displace(V, p, d, dep)
        t.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    print(f'== per frame ({len(V)} vertices, {len(F)} faces; load {os.getloadavg()[0]:.1f} '
          f'on {os.cpu_count()} cores)')
    print(f'displace, every vertex          {pct(t)} wall; CPU mean {np.mean(cpu) * 1e3:.2f} ms')
    for reach in (9.0, 5.0):
        surf = DentSurface(V, F, DeformationModel(taper=reach - 1, reach=reach).fit(data))
        t, cpu, corners, ser = [], [], [], []
        # a press that moves: consecutive contacts 0.5 mm apart, depth ramping
        path = P[0] + np.linspace(0, 0.01, n)[:, None] * np.array([0.0, 1.0, 0.5])
        depth = np.linspace(0.002, 0.016, n)
        for p, dep in zip(path, depth):
            t0, c0 = time.perf_counter(), time.process_time()
            ch = surf.update(p, d, dep)
            t.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            corners.append(sum(len(c.corners) for c in ch))
            t0 = time.perf_counter()  # the visualizer's messages: MarkerArray CDR, 1500 corners
            batch, k = [], 0
            for c in ch:
                if batch and k + len(c.corners) > 1500:
                    triangle_markers('tissue', 'tissue', batch)
                    batch, k = [], 0
                batch.append((c.index, c.corners, c.colours))
                k += len(c.corners)
            if batch:
                triangle_markers('tissue', 'tissue', batch)
            ser.append(time.perf_counter() - t0)
        print(f'DentSurface.update, reach {reach:.0f}a   {pct(t)} wall; CPU mean '
              f'{np.mean(cpu) * 1e3:.2f} ms; corners re-sent per frame '
              f'p50 {np.percentile(corners, 50):.0f}, max {max(corners)} '
              f'(of {3 * len(F)}); serialized as MarkerArray CDR {pct(ser)} wall')


def drawn_error(data):
    import trimesh

    mesh = surface()
    model = DeformationModel().fit(data)
    print('== drawn-mesh error (linear across a face vs the model), contact at the apex and '
          '(y, z) = (-25, 20) mm')
    for level in (0, 1):
        m = mesh if level == 0 else trimesh.Trimesh(*trimesh.remesh.subdivide(
            mesh.vertices, mesh.faces), process=False)
        V, F = np.asarray(m.vertices), np.asarray(m.faces)
        h = np.median(m.edges_unique_length) * 1e3
        for dep in (0.005, 0.012, 0.016):
            worst, sq, n = 0.0, 0.0, 0
            for y, z in ((0.0, 0.0), (-0.025, 0.02)):
                x = 0.045 * np.sqrt(1 - (y / 0.07) ** 2 - (z / 0.07) ** 2)
                c = np.array([x, y, z])
                u = model.displacement(V, c, [-1, 0, 0], dep)
                near = np.flatnonzero(np.hypot(V[F].mean(1)[:, 1] - y,
                                               V[F].mean(1)[:, 2] - z) < 3 * model.probe_radius_)
                bary = np.array([[1, 1, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1]], float)
                bary /= bary.sum(1, keepdims=True)
                for b in bary:
                    pts = np.einsum('k,fkc->fc', b, V[F[near]])
                    drawn = np.einsum('k,fkc->fc', b, u[F[near]])
                    true = model.displacement(pts, c, [-1, 0, 0], dep)
                    e = np.linalg.norm(drawn - true, axis=1)
                    worst = max(worst, e.max())
                    sq += np.sum(e ** 2)
                    n += len(e)
            print(f'edge {h:4.2f} mm, depth {dep * 1e3:4.1f} mm: max {worst * 1e3:5.2f} mm, '
                  f'RMS {np.sqrt(sq / n) * 1e3:5.2f} mm ({np.sqrt(sq / n) / dep:.1%} of depth) '
                  f'within 3a')


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('--data', help='displacement file (default: the shipped one)')
    p.add_argument('--work-dir', help='assemble from a sweep work dir instead')
    p.add_argument('--scene', help='scene of the work dir (default: the default scene)')
    p.add_argument('--frames', type=int, default=200)
    p.add_argument('--skip-errors', action='store_true')
    args = p.parse_args()
    data = load_data(args)
    if not args.skip_errors:
        errors(data)
    timing(data, args.frames)
    drawn_error(data)
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
