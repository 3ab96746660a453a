"""``haptic-anfis demo``: the ``make demo`` main job.

Trains the three force models on the shipped default dataset and prints their test RMSE and
evaluation speed (the simulated palpation session: ``haptic-anfis sim``).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ..anfis import ForceModel, train_on_dataset
from ..report.model_bench import throughput, time_single
from ..tissue.dataset import DATA_DIR, DEFAULT_DATASET, OUTPUT_NAMES, load_dataset

NAME = 'demo'


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('--dataset', default=str(DEFAULT_DATASET), help='force dataset CSV')
    p.add_argument('--out', default='out/demo_model.json', help='where to write the trained model')


def run(args: argparse.Namespace) -> int:
    ds = load_dataset(args.dataset)
    kind = ds.provenance.get('kind', 'unknown provenance')
    print(f'== dataset {args.dataset}\n   {len(ds)} samples, {len(np.unique(ds.point))} surface '
          f'points [{kind}]')
    print('== training (structure search per output, hybrid learning)')
    t0 = time.perf_counter()
    model, test = train_on_dataset(ds, verbose=True, dataset_path=str(args.dataset))
    print(f'   trained in {time.perf_counter() - t0:.1f} s (numba compile/cache load included)')
    path = model.save(args.out)
    model = ForceModel.load(path)  # what the force server would run: the file, not the object
    r = model.metadata_['rmse']['test']
    print(f'== test RMSE on {len(test)} held-out samples (whole surface points never seen in training)')
    for o, name in enumerate(OUTPUT_NAMES):
        print(f'   {name}: {r[o]:.4f} N   (structure {"-".join(map(str, model.structures_[o]))}, '
              f'force range {np.ptp(ds.Y[:, o]):.2f} N)')
    print('   paper (its own FE data): 0.0791 / 0.0063 / 0.0181 N')
    single = time_single(model.predict_one, test.X, 20000)
    rng = np.random.default_rng(0)
    lo, hi = model.input_range_
    rate = throughput(model.predict, lo + (hi - lo) * rng.random((100_000, 4)))
    print('== evaluation speed (compiled path)')
    print(f'   single query: p50 {np.percentile(single, 50) * 1e6:.2f} µs, '
          f'p99 {np.percentile(single, 99) * 1e6:.2f} µs')
    print(f'   batch: {rate:.3g} evaluations/s (paper: ~1e5/s)')
    print(f'== model written to {Path(path)}')
    print(f'   (a session runs the shipped model, {DATA_DIR / "default_model.json"}, unless '
          f"given this one: haptic-anfis sim --ros-args -p model_path:={Path(path)})")
    print('== next: haptic-anfis sim --duration 10 --record out/demo_session  (the haptic graph '
          'with the simulated Falcon),\n   haptic-anfis exam run --trainee systematic  (a scored '
          'examination), haptic-anfis cases list  (the case library)')
    return 0
