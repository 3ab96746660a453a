"""Far-field reuse, measured (issue 29): may a lesion case take the lesion-free twin's forces at
points far from its lesions?

For the lesion case ``--case`` (default the largest lesion, lib_m_dense_idc25_d15), take
``--points`` of its loading points farther than ``--margin`` from the lesion's edge (spread over
the distance; solved into the case's store if not there yet), solve the lesion-free twin (same breast, tissue, mesh; no lesion) at up to ``--points`` of them
(spread over the distance; stored in the case's ``twin`` store, so never solved twice) and compare:
the largest |F_case - F_twin| / |F_twin| over the depths, per point. The issue's rule: above 1 %
of the local force, every point is solved (no reuse). Prints and writes
docs/measurements/far_field.md. Asserts nothing.

    .venv/bin/python bench/bench_far_field.py [--case NAME] [--points 8] [--margin-mm 14]
"""
from __future__ import annotations

import argparse
import os

for _v in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
    os.environ.setdefault(_v, '1')

import numpy as np  # noqa: E402

from _page import write_page  # noqa: E402
from haptic_anfis.cases import library  # noqa: E402
from haptic_anfis.cases.sweeps import case_stores, twin_scene  # noqa: E402
from haptic_anfis.tissue.geometry import loading_points  # noqa: E402
from haptic_anfis.tissue.pointsweep import run_point_sweep  # noqa: E402
from haptic_anfis.tissue.store import point_key  # noqa: E402

RULE_PCT = 1.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--case', default='lib_m_dense_idc25_d15')
    ap.add_argument('--points', type=int, default=8)
    ap.add_argument('--margin-mm', type=float, default=14.0,
                    help="distance from the lesion's edge beyond which reuse would apply "
                         '(the old REUSE_MARGIN)')
    ap.add_argument('--workers', type=int, default=1)
    args = ap.parse_args()
    case = library().get(args.case)
    scene = case.scene
    stores = case_stores(case)
    pts = loading_points(scene)
    gap = np.min([np.hypot(pts[:, 1] - t.centre[1], pts[:, 2] - t.centre[2]) - t.radius
                  for t in scene.tumours], axis=0)
    far = [i for i in np.argsort(gap) if gap[i] > args.margin_mm * 1e-3]
    pick = [far[int(k)] for k in np.unique(np.linspace(0, len(far) - 1, args.points).round())]
    # the case's own points go to its store (the sweep needs them anyway: never solved twice)
    run_point_sweep(scene, stores.main, pts[pick], stores.probe_cells, workers=args.workers,
                    progress=True, desc='case (far field)')
    run_point_sweep(twin_scene(scene), stores.twin, pts[pick], stores.probe_cells,
                    workers=args.workers, progress=True, desc='twin (far field)')
    rows, worst = [], 0.0
    for i in pick:
        k = point_key(pts[i, 1], pts[i, 2])
        a, b = stores.main.load(k), stores.twin.load(k)
        fa, fb = np.asarray(a['forces_N']), np.asarray(b['forces_N'])
        rel = np.linalg.norm(fa - fb, axis=1) / np.linalg.norm(fb, axis=1)
        worst = max(worst, float(rel.max()))
        rows.append(f'| ({pts[i, 1] * 1e3:.0f}, {pts[i, 2] * 1e3:.0f}) | {gap[i] * 1e3:.1f} | '
                    + ' | '.join(f'{100 * v:.2f}' for v in rel) + ' |')
    depths = ' | '.join(f'{d * 1e3:g} mm' for d in scene.depths)
    decision = ('above' if 100 * worst > RULE_PCT else 'within')
    text = (f'Case `{args.case}` ({", ".join(f"{t.name}: {2e3 * t.radius:g} mm, E {t.youngs / 1e3:g} kPa" for t in scene.tumours)}), '
            f'{len(pick)} of its solved points farther than {args.margin_mm:g} mm from the '
            f"lesion's edge, against the lesion-free twin at the same points (same mesh).\n\n"
            f'| point (y, z) mm | from lesion edge mm | {depths} |\n'
            f'|---|---|{"---|" * len(scene.depths)}\n' + '\n'.join(rows)
            + f'\n\n|F_case - F_twin| / |F_twin| in %. Largest: **{100 * worst:.2f} %**, '
            f'{decision} the issue\'s {RULE_PCT:g} % of the local force: '
            + ('every point of every case is solved (the graded library reuses nothing).'
               if decision == 'above' else
               'reuse would be allowed at this margin; the graded library still solves every '
               'point (it costs CPU, not correctness).'))
    print(text)
    write_page('far_field', 'Far-field reuse from the lesion-free twin, measured', text,
               command=f'.venv/bin/python bench/bench_far_field.py --case {args.case} '
                       f'--points {args.points} --margin-mm {args.margin_mm:g}')


if __name__ == '__main__':
    main()
