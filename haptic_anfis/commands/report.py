"""``haptic-anfis report``: speed against error of our force models and their peers."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..report.run import build_report, headline_table
from ..tissue.dataset import DEFAULT_DATASET, load_dataset

try:  # the report's figures and peers: the 'report' extra
    import matplotlib  # noqa: F401
    import sklearn  # noqa: F401
except ImportError as exc:
    _NO_REPORT_EXTRA: ImportError | None = exc
else:
    _NO_REPORT_EXTRA = None

NAME = 'report'


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('--out', default='out/report', help='output directory (default: %(default)s)')
    p.add_argument('--dataset', default=str(DEFAULT_DATASET), help='force dataset CSV')
    p.add_argument('--quick', action='store_true',
                   help='few structures, tiny peers, short timings (for CI; numbers are not the report)')
    p.add_argument('--seed', type=int, default=0, help='train/test split seed (default: %(default)s)')
    p.add_argument('--cv-seeds', type=int, nargs='*', default=None,
                   help='seeds of the grouped cross-validation table (default: 0 1 2; 0 with '
                        '--quick; none given: skip it)')
    p.add_argument('--cv-folds', type=int, default=None,
                   help='folds over surface points (default: 5; 3 with --quick)')


def run(args: argparse.Namespace) -> int:
    if _NO_REPORT_EXTRA is not None:
        raise OSError('the report needs the "report" extra: pip install -e ".[report]" '
                      f'({_NO_REPORT_EXTRA})')
    ds = load_dataset(args.dataset)
    label = Path(args.dataset).name
    print(f'report: {label}, {len(ds)} samples; training and measuring every model on one split')
    seeds = args.cv_seeds if args.cv_seeds is not None else ([0] if args.quick else [0, 1, 2])
    folds = args.cv_folds if args.cv_folds is not None else (3 if args.quick else 5)
    res = build_report(ds, args.out, quick=args.quick, seed=args.seed, dataset_label=label,
                       cv_seeds=seeds, cv_folds=folds)
    print()
    print(headline_table(res))
    failed = [r['name'] for r in res['rows'] if r['status'] != 'ok']
    if failed:
        print(f'failed (listed in the report): {", ".join(failed)}')
    print(f'\nwrote {Path(args.out) / "report.md"} and {len(res["figures"])} figures '
          f'({res["seconds"]:.0f} s)')
    return 0
