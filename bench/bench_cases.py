"""Case library figures per case: FE time (recorded in each dataset's sidecar when the case was
generated, and optionally re-measured for one loading point), training time (measured here:
retraining with config/case_model.yaml), model size (rules, parameters, file bytes) and the
compiled evaluation time. Prints a table; asserts nothing. Timings on a shared machine are noisy:
the load is printed with them.

    .venv/bin/python bench/bench_cases.py [--no-train] [--fe-point] [NAMES...]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

for _v in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
    os.environ.setdefault(_v, '1')

from haptic_anfis.anfis import ForceModel  # noqa: E402
from haptic_anfis.cases import library  # noqa: E402
from haptic_anfis.cases.summary import eval_p50_us  # noqa: E402
from haptic_anfis.commands.train import load_config  # noqa: E402
from haptic_anfis.tissue.dataset import load_dataset  # noqa: E402
from haptic_anfis.tissue.scene import SCENE_DIR  # noqa: E402
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('names', nargs='*')
    ap.add_argument('--no-train', action='store_true', help='skip the training-time measurement')
    ap.add_argument('--fe-point', action='store_true',
                    help='also time one FE loading point (the apex) per case at its density')
    args = ap.parse_args()
    lib = library()
    params = load_config(str(SCENE_DIR.parent / 'case_model.yaml'))
    print(f'load average at start: {os.getloadavg()[0]:.1f} (2 cores)')
    print(f'{"case":<24} {"points":>6} {"cells":>5} {"FE sum s":>9} {"FE wall s":>9} '
          f'{"s/point":>7} {"apex s":>6} {"train s":>7} {"rules":>5} {"params":>6} '
          f'{"model kB":>8} {"p50 us":>6}')
    for case in (lib.get(n) for n in (args.names or lib.names())):
        if case.missing(('dataset_path', 'model_path')):
            print(f'{case.name:<24} (not generated: {", ".join(case.missing())})')
            continue
        ds = load_dataset(case.dataset_path)
        prov = ds.provenance
        wall = prov.get('wall_time_s', {})
        n_pts = prov.get('n_points', 0)
        fe_sum = wall.get('sum_over_points', float('nan'))
        solved = n_pts - len((prov.get('reused') or {}).get('points', []))  # not reused
        apex_s = float('nan')
        if args.fe_point:
            from haptic_anfis.tissue.fe import solve_scene_point
            from haptic_anfis.tissue.scene import surface_height

            s = case.scene
            apex = (float(surface_height(0.0, 0.0, s.radii)), 0.0, 0.0)
            apex_s = solve_scene_point(s, apex, probe_cells=prov['mesh']['probe_cells']).wall_time
        train_s = float('nan')
        if not args.no_train:
            from haptic_anfis.anfis import train_on_dataset

            p = dict(params)
            tf, seed = p.pop('test_fraction', 0.2), p.pop('seed', 0)
            t0 = time.perf_counter()
            train_on_dataset(ds, test_fraction=tf, seed=seed, **p)
            train_s = time.perf_counter() - t0
        model = ForceModel.load(case.model_path)
        rules = sum(e.n_rules_ for e in model.estimators_)
        n_par = sum(e.n_params_ for e in model.estimators_)
        print(f'{case.name:<24} {n_pts:>6} {prov["mesh"]["probe_cells"]:>5} {fe_sum:>9.0f} '
              f'{wall.get("this_run_elapsed", float("nan")):>9.0f} {fe_sum / max(solved, 1):>7.1f} '
              f'{apex_s:>6.1f} {train_s:>7.1f} {rules:>5} {n_par:>6} '
              f'{case.model_path.stat().st_size / 1e3:>8.1f} {eval_p50_us(model, ds):>6.2f}',
              flush=True)
    print(f'load average at end: {os.getloadavg()[0]:.1f}. FE sum = solver seconds summed over '
          'the solved points (one core each; s/point over those, reused points cost none); '
          'FE wall = elapsed of the generating run (resumed runs: the last part only).')


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
