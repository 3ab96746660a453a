"""Which ANFIS inputs suit the case library's depth-scaled models: test RMSE per case and input set.

Trains each case with config/case_model.yaml (the paper's protocol: 20 % of the loading points held
out for the test, the structure chosen per output by 3-fold validation within 5 % of the best) with
the inputs (y, z, depth) — the default's — and (x, y, z, depth) (2 MFs on x), on the same split,
and prints rules and test RMSE per output. Printed, never asserted.

    .venv/bin/python bench/bench_case_inputs.py [NAMES...]   # default: four contrasting cases
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

from haptic_anfis.anfis import train_on_dataset  # noqa: E402
from haptic_anfis.cases import resolve_case  # noqa: E402
from haptic_anfis.commands.train import load_config  # noqa: E402
from haptic_anfis.tissue.dataset import load_dataset  # noqa: E402
from haptic_anfis.tissue.scene import SCENE_DIR  # noqa: E402
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('names', nargs='*',
                    default=['normal', 'normal_fatty_small', 'small_breast_carcinoma', 'two_lesions'])
    a = ap.parse_args()
    base = load_config(str(SCENE_DIR.parent / 'case_model.yaml'))
    ladder = list(base['candidates'])
    variants = {
        'y, z, depth': dict(inputs=('y', 'z', 'depth'), candidates=ladder),
        'x, y, z, depth': dict(inputs=('x', 'y', 'z', 'depth'),
                               candidates=[(2,) + tuple(c) for c in ladder]),
    }
    print(f'load {os.getloadavg()[0]:.2f}')
    print(f'{"case":24s} {"inputs":15s} {"rules":>5s}  test RMSE Fx / Fy / Fz [N]   fit s')
    for name in a.names:
        ds = load_dataset(resolve_case(name, -1).dataset_path)
        for label, v in variants.items():
            p = dict(base)
            p.update(v)
            tf, seed = p.pop('test_fraction'), p.pop('seed')
            t0 = time.perf_counter()
            m, _ = train_on_dataset(ds, test_fraction=tf, seed=seed, **p)
            r = m.metadata_['rmse']['test']
            rules = sum(int(np.prod(s)) for s in m.structures_)
            print(f'{name:24s} {label:15s} {rules:5d}  {r[0]:.3f} / {r[1]:.3f} / {r[2]:.3f}'
                  f'              {time.perf_counter() - t0:5.1f}', flush=True)


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
