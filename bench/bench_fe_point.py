"""FE point solve at the validated density, before / after: CPU seconds per point.

"before" is the previous default: :class:`haptic_anfis.tissue.linsolve.ReusedFactorSolver` on
SciPy's SuperLU (symmetric mode; the kept factor preconditions GMRES for the next Newton systems)
and load increments back at the scene's step after each cut-back. "after" is the default now
(:func:`haptic_anfis.tissue.fe.default_linear_solver`: PARDISO LDL^T per Newton iteration with
the analysis kept, when pypardiso is installed) with increments held halved after a cut-back.
Same points, each solved ``--repeat`` times with the variants interleaved (the machine is shared:
the median is reported), forces compared with each other and with the committed store.

Timings are CPU seconds of this process (``time.process_time``) and wall seconds; the wall
figures carry the load printed with them. Also the per-point CPU time of every point already in
the committed store (``fe_store/``, solved by earlier sweeps with the solver their records name)
and the projected wall time of one case on 2 cores. Asserts nothing.

    .venv/bin/python bench/bench_fe_point.py [--points 3] [--repeat 3]
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
from haptic_anfis.tissue.fe import default_linear_solver, solve_scene_point  # noqa: E402
from haptic_anfis.tissue.geometry import loading_points  # noqa: E402
from haptic_anfis.tissue.linsolve import ReusedFactorSolver  # noqa: E402
from haptic_anfis.tissue.store import point_key  # noqa: E402

CASE = 'lib_m_dense_idc25_d15'
#: the nodular series' point timed beside CASE's (over its lesion)
NODULAR = 'nod_s_fatty_idc10_d10'
ROOT = Path(__file__).resolve().parents[1]


def _run(scene, p, variant: str):
    if variant == 'before':
        solver, hold = ReusedFactorSolver(backend='scipy-superlu-sym'), False
    else:
        solver, hold = default_linear_solver()[1], True
    c0, t0 = time.process_time(), time.perf_counter()
    res = solve_scene_point(scene, p, solver=solver, hold_cutback=hold)
    return res, time.process_time() - c0, time.perf_counter() - t0


def _over_lesion(scene, pts: np.ndarray) -> int:
    t = scene.tumours[0]
    return int(np.argmin(np.hypot(pts[:, 1] - t.centre[1], pts[:, 2] - t.centre[2])))


def _stored_forces(case: str, p: np.ndarray) -> np.ndarray | None:
    f = ROOT / 'fe_store' / case / f'{point_key(p[1], p[2])}.npz'
    if not f.is_file():
        return None
    with np.load(f) as z:
        return np.asarray(z['forces'], dtype=float)


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    """Largest force difference relative to the force's magnitude at its depth."""
    scale = np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-3)
    return float(np.max(np.abs(a - b) / scale))


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
    ap.add_argument('--points', type=int, default=3,
                    help='points to time (default 3: over the lesion and at the apex of CASE, '
                         'over the lesion of NODULAR; 0: only the committed store\'s figures, '
                         'written into the README, the page left as it is)')
    ap.add_argument('--repeat', type=int, default=3, help='solves per point and variant')
    args = ap.parse_args()
    scene = library().get(CASE).scene
    pts = loading_points(scene)
    nod = library().get(NODULAR).scene
    npts = loading_points(nod)
    apex = int(np.argmin(np.hypot(pts[:, 1], pts[:, 2])))
    chosen = [(CASE, scene, pts[_over_lesion(scene, pts)]), (CASE, scene, pts[apex]),
              (NODULAR, nod, npts[_over_lesion(nod, npts)])][:args.points]
    load0 = os.getloadavg()[0]
    after_name = default_linear_solver()[0]
    names = {'before': 'before: reused SuperLU factor (GMRES), step back to max after a cut-back',
             'after': f'after: {after_name}, increments held halved after a cut-back'}
    print(f'{scene.mesh.probe_cells} cells across the probe, load {load0:.1f}')
    head = ('| case, point (y, z) mm | solver | CPU s median (min) | wall s median | Newton it. | '
            'cut-backs | factorisations | Fx @16 mm N | max rel. dF vs before | '
            'max rel. dF vs fe_store |')
    print(head)
    rows, ratios = [], []
    for case, sc, p in chosen:
        runs = {'before': [], 'after': []}
        for _ in range(args.repeat):
            for v in ('before', 'after'):
                runs[v].append(_run(sc, p, v))
        ref = runs['before'][0][0].forces
        stored = _stored_forces(case, p)
        med = {}
        for v in ('before', 'after'):
            res = runs[v][0][0]
            cpu = [r[1] for r in runs[v]]
            med[v] = float(np.median(cpu))
            row = (f'| {case}, ({p[1] * 1e3:.0f}, {p[2] * 1e3:.0f}) | {names[v]} | '
                   f'{med[v]:.2f} ({min(cpu):.2f}) | {np.median([r[2] for r in runs[v]]):.1f} | '
                   f'{res.newton_iterations} | {res.cutbacks} | '
                   f'{res.info.get("factorisations", "-")} | {res.forces[-1, 0]:.3f} | '
                   f'{"-" if v == "before" else f"{_rel(res.forces, ref):.1e}"} | '
                   f'{"-" if stored is None else f"{_rel(res.forces, stored):.1e}"} |')
            print(row, flush=True)
            rows.append(row)
        ratios.append(med['before'] / med['after'])
    summary = (f'\n\nSpeed-up per point (median CPU before / after): '
               f'{", ".join(f"{r:.2f}" for r in ratios)}; median {np.median(ratios):.2f}.'
               if ratios else '')
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
    table = (f'Load average at the start: {load0:.1f}, at the end {os.getloadavg()[0]:.1f} (2 cores, '
             f'shared with other developers); {args.repeat} solves per point and solver, '
             f'interleaved.\n\n'
             + '\n'.join([head, '|---|---|---|---|---|---|---|---|---|---|', *rows])
             + summary + sweep)
    write_page('fe_point', 'FE point solve: before / after', table,
               command='.venv/bin/python bench/bench_fe_point.py')


if __name__ == '__main__':
    main()
