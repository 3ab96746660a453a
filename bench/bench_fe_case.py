"""Time of one graded case's FE sweep (every loading point and the lesion-free twin points) with
1 and 2 workers, solved afresh into a temporary store (the committed ``fe_store/`` is not touched).

Each worker is one single-threaded process (``cases sweep --workers N``). Reported per run: wall
time, the sum of the workers' CPU seconds (what the case costs on idle cores with one worker),
CPU per point, Newton iterations and cut-backs, the linear solver the records name, and the
largest force difference from the committed store's points of the same case (the FE's
tolerance, not the solver's, decides: forces there are stored in float32). The machine is shared,
so the wall figures carry the load averages printed with them. Asserts nothing.

    .venv/bin/python bench/bench_fe_case.py [--case nod_s_fatty_idc10_d10] [--workers 1 2]
        [--points N]   (N evenly spaced loading points instead of all)
        [--stores CASE ...]   (also: whole committed sweeps, from each point's CPU record)
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time

for _v in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
    os.environ.setdefault(_v, '1')

import numpy as np  # noqa: E402

from harness import write_page  # noqa: E402
from haptic_anfis.cases import library  # noqa: E402
from haptic_anfis.cases.sweeps import (case_stores, stored_records, twin_points,  # noqa: E402
                                       twin_scene)
from haptic_anfis.tissue.geometry import loading_points  # noqa: E402
from haptic_anfis.tissue.pointsweep import run_point_sweep  # noqa: E402
from haptic_anfis.tissue.store import point_key  # noqa: E402


def _sweep(case, points: np.ndarray, workers: int, root: str) -> dict:
    """Sweep ``points`` of ``case`` (and its twin points) into a fresh store under ``root``."""
    stores, fresh = case_stores(case), case_stores(case, root)
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    run_point_sweep(case.scene, fresh.main, points, fresh.probe_cells, workers=workers,
                    progress=False, desc=case.name)
    twins = twin_points(case.scene) if fresh.twin is not None else np.zeros((0, 3))
    if len(twins):
        run_point_sweep(twin_scene(case.scene), fresh.twin, twins, fresh.probe_cells,
                        workers=workers, progress=False)
    wall = time.perf_counter() - t0
    recs, diffs = [], []
    for store, pts in ((fresh.main, points), (fresh.twin, twins)):
        for p in pts:
            k = point_key(p[1], p[2])
            rec = store.load(k)
            recs.append(rec)
            ref_store = stores.main if store is fresh.main else stores.twin
            if ref_store is not None and ref_store.has(k):
                ref = np.asarray(ref_store.load(k)['forces_N'], dtype=float)
                f = np.asarray(rec['forces_N'], dtype=float)
                scale = np.maximum(np.linalg.norm(ref, axis=1, keepdims=True), 1e-3)
                diffs.append(float(np.max(np.abs(f - ref) / scale)))
    cpu = np.array([r['cpu_time_s'] for r in recs])
    return {'workers': workers, 'points': len(recs), 'wall_s': wall, 'cpu_s': float(cpu.sum()),
            'cpu_med': float(np.median(cpu)), 'cpu_p90': float(np.percentile(cpu, 90)),
            'newton': float(np.median([r['newton_iterations'] for r in recs])),
            'cutbacks': float(np.median([r['cutbacks'] for r in recs])),
            'solver': sorted({r['linear_solver'] for r in recs}),
            'compared': len(diffs), 'max_rel_diff': max(diffs) if diffs else float('nan'),
            'load': (load0, os.getloadavg()[0])}


def store_rows(names: list[str]) -> str:
    """A table of whole committed sweeps: per case its points (and twin points), depths, linear
    solvers, CPU per point from each point's own record, and the case's CPU total, which is its
    time with one worker on an idle core (two workers: half)."""
    out = ['| case | points | depths | linear solver | CPU s per point median (p90) | '
           'CPU min total = 1 worker | 2 workers min |', '|---|---|---|---|---|---|---|']
    for n in names:
        recs, twins = stored_records(case_stores(library().get(n)))
        allr = list(recs) + list(twins.values())
        cpu = np.array([r['cpu_time_s'] for r in allr])
        nd = sorted({len(r['depths_m']) for r in recs})
        solver = sorted({str(r.get('linear_solver', '?')) for r in allr})
        out.append(f'| {n} | {len(allr)} | {"/".join(map(str, nd))} | {", ".join(solver)} | '
                   f'{np.median(cpu):.2f} ({np.percentile(cpu, 90):.2f}) | {cpu.sum() / 60:.1f} | '
                   f'{cpu.sum() / 120:.1f} |')
    return '\n'.join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--case', default='nod_s_fatty_idc10_d10')
    ap.add_argument('--workers', type=int, nargs='+', default=[1, 2])
    ap.add_argument('--points', type=int, default=0,
                    help='N evenly spaced loading points (default 0: all of them)')
    ap.add_argument('--stores', nargs='*', default=[],
                    help='cases whose committed sweeps to summarise (no solve)')
    args = ap.parse_args()
    stores = store_rows(args.stores) if args.stores else ''
    if stores:
        print(stores, flush=True)
    case = library().get(args.case)
    pts = loading_points(case.scene)
    n_case = len(pts) + len(twin_points(case.scene))
    if args.points:
        pts = pts[np.unique(np.linspace(0, len(pts) - 1, args.points).round().astype(int))]
    head = ('| workers | points solved | wall min (load avg start / end) | CPU min (sum) | '
            'CPU s per point median (p90) | Newton it. median | cut-backs median | '
            'max rel. force diff vs fe_store | linear solver |')
    rows = []
    for w in args.workers:
        with tempfile.TemporaryDirectory(prefix='bench_fe_case_') as root:
            r = _sweep(case, pts, w, root)
        row = (f'| {w} | {r["points"]} | {r["wall_s"] / 60:.1f} ({r["load"][0]:.1f} / '
               f'{r["load"][1]:.1f}) | {r["cpu_s"] / 60:.1f} | {r["cpu_med"]:.2f} '
               f'({r["cpu_p90"]:.2f}) | {r["newton"]:.0f} | {r["cutbacks"]:.0f} | '
               f'{r["max_rel_diff"]:.1e} ({r["compared"]} points) | {", ".join(r["solver"])} |')
        print(row, flush=True)
        rows.append((w, r, row))
        one = [x for x in rows if x[0] == 1]
        per_pt = (one or rows)[0][1]['cpu_s'] / (one or rows)[0][1]['points']
        text = (f'Case `{args.case}`: {n_case} points (loading points and lesion-free twin '
                f'points), {len(case.scene.depths)} depths each, the validated mesh; each run '
                f'solved afresh into a '
                f'temporary store, one single-threaded process per worker, on a machine shared '
                f'with other developers (load averages in the table; 2 cores).\n\n'
                + '\n'.join([head, '|---|---|---|---|---|---|---|---|---|',
                             *(x[2] for x in rows)])
                + f'\n\nThe case on idle cores, from the measured CPU per point '
                  f'({per_pt:.2f} s, mean): 1 worker {n_case * per_pt / 60:.1f} min, 2 workers '
                  f'{n_case * per_pt / 120:.1f} min (two single-threaded workers on two idle '
                  f'cores each run at full speed). The wall times above are what the shared '
                  f'machine gave.')
        if stores:
            text += ('\n\nWhole sweeps of the nodular series, from the committed stores (each '
                     "point's CPU as its record gives it; the older cases were solved before the "
                     'PARDISO solver, "reused-factor/scipy-superlu-sym"; the rib scenes solve '
                     'four depths):\n\n' + stores)
        cmd = (f'.venv/bin/python bench/bench_fe_case.py --case {args.case} --workers '
               f'{" ".join(map(str, args.workers))}' + (f' --points {args.points}' if args.points else '')
               + (f' --stores {" ".join(args.stores)}' if args.stores else ''))
        write_page('fe_case', 'FE sweep of one case: time with 1 and 2 workers', text, command=cmd)


if __name__ == '__main__':
    main()
