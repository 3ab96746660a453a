"""FE point solve at the validated density, before / after the solver work of issue 29.

"before" is felupe's Newton loop with SciPy's default ``spsolve`` (SuperLU, COLAMD: a fresh
factorisation every iteration, the solver the library used to ship with); "after" is the
default now, :class:`haptic_anfis.tissue.linsolve.ReusedFactorSolver` (symmetric-mode SuperLU
kept and used to precondition GMRES for the next Newton systems; pypardiso factorises when
importable). Same points, same forces (the largest difference is printed). Also the per-point
CPU time of every point already in the committed store (``fe_store/``), i.e. measured inside the
real sweeps, and the projected wall time of one case on 2 cores.

Timings are CPU seconds of this process (``time.process_time``) and wall seconds; the machine
is shared, so the wall figures carry the load printed with them. Asserts nothing.

    .venv/bin/python bench/bench_fe_point.py [--points 2] [--no-before]
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import time
from pathlib import Path

for _v in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
    os.environ.setdefault(_v, '1')

import numpy as np  # noqa: E402

from harness import write_page, write_readme_block  # noqa: E402
from haptic_anfis.cases import library  # noqa: E402
from haptic_anfis.tissue.fe import solve_scene_point  # noqa: E402
from haptic_anfis.tissue.geometry import loading_points  # noqa: E402
from haptic_anfis.tissue.linsolve import ReusedFactorSolver, backend_name  # noqa: E402

CASE = 'lib_m_dense_idc25_d15'
ROOT = Path(__file__).resolve().parents[1]


def _run(scene, p, solver):
    c0, t0 = time.process_time(), time.perf_counter()
    res = solve_scene_point(scene, p, solver=solver)
    return res, time.process_time() - c0, time.perf_counter() - t0


def _scipy_default(A, b):
    from scipy.sparse.linalg import spsolve

    return spsolve(A, b)


def _store_times(pattern: str) -> tuple[list[float], list[float]]:
    """(CPU s, wall s) of every point in the committed store directories matching ``pattern``."""
    cpu, wall = [], []
    for f in glob.glob(str(ROOT / 'fe_store' / pattern / '*.npz')):
        with np.load(f) as z:
            m = json.loads(str(z['meta']))
        cpu.append(m.get('cpu_time_s', np.nan))
        wall.append(m.get('wall_time_s', np.nan))
    return cpu, wall


def _nodular_line() -> str:
    """The nodular series (``nod_*``): points per case and the time per case projected from the
    CPU per point measured in its sweeps so far, with 1 and 2 workers."""
    cpu, wall = _store_times('nod_*')
    cases = [c for c in library().cases() if c.name.startswith('nod_')]
    if not cpu or not cases:
        return ''
    from haptic_anfis.cases.sweeps import twin_points

    n = [len(loading_points(c.scene)) + len(twin_points(c.scene)) for c in cases]
    med = float(np.nanmedian(cpu))
    return (f'\n\nNodular series (`fe_store/nod_*`, {len(cases)} cases, {min(n)}-{max(n)} points '
            f'each with the lesion-free twin points, {sum(n)} in all): {len(cpu)} points solved so '
            f'far by one niced worker, CPU per point median {med:.1f} s (p90 '
            f'{np.nanpercentile(cpu, 90):.1f} s), wall median {np.nanmedian(wall):.0f} s under the '
            f'shared load. Projected per case ({int(np.median(n))} points) on idle cores: 1 worker '
            f'{np.median(n) * med / 60:.0f} min, 2 workers {np.median(n) * med / 120:.0f} min; the '
            f'series: {sum(n) * med / 3600:.1f} CPU-hours. These points were solved with the '
            f'solver of their sweep\'s start (the records name it).')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--points', type=int, default=2,
                    help='loading points to time (default 2; 0: only the committed store\'s '
                         'figures, written into the README, the page left as it is)')
    ap.add_argument('--no-before', action='store_true', help='skip the slow "before" solver')
    args = ap.parse_args()
    case = library().get(CASE)
    scene = case.scene
    pts = loading_points(scene)
    t = scene.tumours[0]
    over = int(np.argmin(np.hypot(pts[:, 1] - t.centre[1], pts[:, 2] - t.centre[2])))
    apex = int(np.argmin(np.hypot(pts[:, 1], pts[:, 2])))
    chosen = [over, apex, 0][:args.points]
    load0 = os.getloadavg()[0]
    rows = []
    print(f'case {CASE}, {scene.mesh.probe_cells} cells across the probe, linear backend '
          f'{backend_name()}, load {load0:.1f}')
    head = (f'| point (y, z) mm | solver | CPU s | wall s | Newton it. | factorisations | '
            f'Fx @16 mm N | max |dF| vs before N |')
    print(head)
    for i in chosen:
        p = pts[i]
        before = None
        variants = ([] if args.no_before else [('before: spsolve (COLAMD) each iteration',
                                                _scipy_default)])
        variants.append((f'after: reused factor ({backend_name()})', None))
        for name, solver in variants:
            s = ReusedFactorSolver() if solver is None else solver
            res, cpu, wall = _run(scene, p, s)
            if before is None and solver is not None:
                before = res.forces
            diff = ('-' if before is None or solver is not None
                    else f'{np.abs(res.forces - before).max():.2e}')
            row = (f'| ({p[1] * 1e3:.0f}, {p[2] * 1e3:.0f}) | {name} | {cpu:.1f} | {wall:.1f} | '
                   f'{res.newton_iterations} | {res.info.get("factorisations", res.newton_iterations)} | '
                   f'{res.forces[-1, 0]:.3f} | {diff} |')
            print(row, flush=True)
            rows.append(row)
    # the real sweeps: every point in the committed store
    cpu, wall = _store_times('lib_*')
    n_pts = len(cpu)
    sweep = _nodular_line()
    if n_pts:
        graded = [c for c in library().cases() if c.name.startswith('lib_')]
        n_graded = sum(len(loading_points(c.scene)) for c in graded)
        med = float(np.nanmedian(cpu))
        per_case = len(pts) * med / 2 / 60
        sweep = (f'\n\nIn the committed store (`fe_store/`, the real background sweeps, '
                 f'niced, 2 workers): {n_pts} points, CPU per point median {med:.1f} s '
                 f'(p90 {np.nanpercentile(cpu, 90):.1f} s), wall per point median '
                 f'{np.nanmedian(wall):.0f} s under the shared load. Projected wall time of '
                 f'one case ({len(pts)} points of {CASE}) on idle cores: 1 worker '
                 f'{2 * per_case:.1f} min, 2 single-threaded workers on 2 cores {per_case:.1f} min '
                 f'(two such workers doubled throughput: tissue/sweep.py, limit_threads); '
                 f'the whole graded library ({len(graded)} cases, {n_graded} points): '
                 f'{n_graded * med / 3600:.1f} CPU-hours.') + sweep
        print(sweep.strip())
        write_readme_block('fe-case-time', (
            f'One graded case at full density ({len(pts)} loading points of {CASE}, five '
            f'depths), projected from the {n_pts} points solved in `fe_store/` (CPU per point '
            f'median {med:.1f} s): **{2 * per_case:.0f} min with 1 worker, {per_case:.0f} min with '
            f'2 workers** on idle cores.'), 'python bench/bench_fe_point.py --points 0')
        if not chosen:
            return
    table = (f'Load average at the start: {load0:.1f} (2 cores, shared with 7 other developers).\n\n'
             + '\n'.join([head, '|---|---|---|---|---|---|---|---|', *rows]) + sweep)
    write_page('fe_point', 'FE point solve: before / after (issue 29)', table,
               command='.venv/bin/python bench/bench_fe_point.py')


if __name__ == '__main__':
    main()
