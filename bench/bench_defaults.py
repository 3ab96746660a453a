"""ForceModel's defaults against the shipped configuration and the earlier API defaults (issue 26.2):
test RMSE on a grouped split (20 % of the loading points held out, whole points), printed and
written to docs/measurements/defaults.md. Never asserted.

1. The shipped FE dataset: ``ForceModel().fit`` (the defaults = anfis.defaults.SHIPPED),
   ``train --config config/force_model.yaml`` (the same by construction: the row shows it), and
   the earlier API defaults (structure search up to 5-5-3 on 3 folds, a 20 % epoch hold-out, 60
   epochs, x dropped without a check).
2. Data where x varies independently of (y, z) (the synthetic closed form with each point's
   layer thickness x drawn from 20-45 mm: an indenter over slabs, not one skin surface): Fx test
   RMSE as % of Fx's range for the new default (the check keeps x; structure search), the earlier
   default (x silently dropped) and the inputs named (x, y, z, depth) under the earlier defaults.

Run (slow, minutes of CPU; prefix with ``nice``)::

    .venv/bin/python bench/bench_defaults.py [--seeds 0 1 2]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _v in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS', 'OPENBLAS_NUM_THREADS'):
    os.environ.setdefault(_v, '1')
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from _page import write_page  # noqa: E402
from haptic_anfis.anfis import ForceModel  # noqa: E402
from haptic_anfis.commands.train import load_config  # noqa: E402
from haptic_anfis.tissue.dataset import DEFAULT_DATASET, load_dataset, split_indices  # noqa: E402
from haptic_anfis.tissue.synthetic import make_synthetic_dataset  # noqa: E402

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'force_model.yaml'
#: ForceModel's keyword defaults before issue 26 (git show b517df5:haptic_anfis/anfis/force_model.py)
EARLIER = dict(structure=None, epochs=60, search_folds=3, val_fraction=0.2, max_mfs=None,
               inputs=('y', 'z', 'depth'))
EARLIER_NAMED = dict(EARLIER, inputs=('x', 'y', 'z', 'depth'))


def grouped(ds, params: dict, seed: int) -> tuple[np.ndarray, float, dict]:
    """Test RMSE (3,) [N] of ForceModel(**params) on a 20 % held-out split of whole points,
    fit seconds, training metadata."""
    tr, te = split_indices(ds, 0.2, seed, by='point')
    t0 = time.perf_counter()
    m = ForceModel(**{**params, 'seed': seed}).fit(ds.X[tr], ds.Y[tr], groups=ds.point[tr])
    s = time.perf_counter() - t0
    r = np.sqrt(np.mean((m.predict(ds.X[te]) - ds.Y[te]) ** 2, axis=0))
    return r, s, m.metadata_['training'] | {'structures': [list(x) for x in m.structures_]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seeds', type=int, nargs='*', default=[0, 1, 2])
    a = ap.parse_args()
    cfg = load_config(str(CONFIG))
    cfg.pop('test_fraction')
    cfg.pop('seed')
    fe = load_dataset(DEFAULT_DATASET)
    slabs = make_synthetic_dataset(seed=0, x_range=(0.020, 0.045))
    rows = []
    print(f'load {os.getloadavg()[0]:.2f}; seeds {a.seeds}', flush=True)

    def run(data_name, ds, name, params):
        res = [grouped(ds, params, s) for s in a.seeds]
        r = np.array([x[0] for x in res])
        rng = np.ptp(ds.Y, axis=0)
        meta = res[0][2]
        row = dict(data=data_name, variant=name, rmse=r.mean(0), sd=r.std(0), pct=100 * r.mean(0) / rng,
                   fit_s=float(np.mean([x[1] for x in res])), inputs='-'.join(meta['inputs']),
                   structures=' / '.join('-'.join(map(str, s)) for s in meta['structures']),
                   check=meta.get('input_check', {}).get('rel_rmse'))
        rows.append(row)
        print(f"{data_name:8s} {name:34s} Fx {row['rmse'][0]:.4f} Fy {row['rmse'][1]:.4f} "
              f"Fz {row['rmse'][2]:.4f} N  Fx {row['pct'][0]:.2f} % of range  inputs "
              f"{row['inputs']}  {row['structures']}  fit {row['fit_s']:.1f} s  load "
              f"{os.getloadavg()[0]:.2f}", flush=True)

    run('FE', fe, 'ForceModel() (new defaults)', {})
    run('FE', fe, 'config/force_model.yaml', cfg)
    run('FE', fe, 'earlier API defaults', EARLIER)
    run('slabs', slabs, 'ForceModel() (new defaults)', {})
    run('slabs', slabs, 'earlier API defaults (x dropped)', EARLIER)
    run('slabs', slabs, "earlier defaults, inputs named x,y,z,depth", EARLIER_NAMED)
    lines = ['Grouped split: 20 % of the loading points held out (whole points), mean ± sd over '
             f'seeds {a.seeds}; "FE" = the shipped dataset (haptic_anfis/data/default_forces.csv), '
             '"slabs" = `make_synthetic_dataset(seed=0, x_range=(0.020, 0.045))` (each point\'s '
             'layer thickness x independent of (y, z)). "x check" = leave-one-out polynomial '
             'regression of x on (y, z), RMS as a fraction of x\'s spread (x dropped below 0.2).',
             '',
             '| data | variant | Fx RMSE [N] | Fy RMSE [N] | Fz RMSE [N] | Fx % of range | inputs '
             '| structures (seed 0) | x check | fit [s] |',
             '|---|---|---|---|---|---|---|---|---|---|']
    for r in rows:
        e = ' | '.join(f'{m:.4f} ± {s:.4f}' for m, s in zip(r['rmse'], r['sd']))
        chk = '' if r['check'] is None else f"{r['check']:.3f}"
        lines.append(f"| {r['data']} | {r['variant']} | {e} | {r['pct'][0]:.2f} | {r['inputs']} | "
                     f"{r['structures']} | {chk} | {r['fit_s']:.1f} |")
    table = '\n'.join(lines)
    print(table)
    write_page('defaults', 'Force-model defaults against the shipped configuration', table,
               command='.venv/bin/python bench/bench_defaults.py --seeds '
                       + ' '.join(map(str, a.seeds)))


if __name__ == '__main__':
    main()
