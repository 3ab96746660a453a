"""``haptic-anfis train DATASET.csv --out MODEL.json``: the paper's protocol on a force dataset."""
from __future__ import annotations

import argparse

from ..anfis import train_on_dataset
from ..dataset import OUTPUT_NAMES, load_dataset

NAME = 'train'
HELP = 'train the Fx/Fy/Fz ANFIS models on a force dataset (structure search, hybrid learning)'


def parse_structure(text: str) -> tuple[int, ...]:
    """'3-3-3-2' -> (3, 3, 3, 2)."""
    try:
        st = tuple(int(v) for v in text.replace(',', '-').split('-'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'structure {text!r}: expected MF counts like 3-3-3-2') from None
    if len(st) != 4 or min(st) < 1:
        raise argparse.ArgumentTypeError(f'structure {text!r}: expected 4 MF counts >= 1, like 3-3-3-2')
    return st


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('dataset', help='force dataset CSV (point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N)')
    p.add_argument('--out', required=True, help='model file to write (JSON)')
    p.add_argument('--structure', type=parse_structure, default=None,
                   help='fixed MF counts for all outputs, e.g. 3-3-3-2 (default: search per output)')
    p.add_argument('--epochs', type=int, default=60, help='maximum epochs (default 60)')
    p.add_argument('--test-fraction', type=float, default=0.2, help='held-out test part (default 0.2)')
    p.add_argument('--split', choices=('point', 'sample'), default='point',
                   help='hold out whole surface points (default) or single samples')
    p.add_argument('--seed', type=int, default=0, help='seed of the splits (default 0)')


def run(args: argparse.Namespace) -> int:
    ds = load_dataset(args.dataset)
    print(f'dataset {args.dataset}: {len(ds)} samples at {len(set(ds.point.tolist()))} surface points'
          + (f' [{ds.provenance["kind"]}]' if ds.provenance.get('kind') else ''))
    model, test = train_on_dataset(ds, test_fraction=args.test_fraction, seed=args.seed,
                                   verbose=True, dataset_path=str(args.dataset),
                                   structure=args.structure, epochs=args.epochs, split=args.split)
    r = model.metadata_['rmse']
    print(f'\n{"output":<6} {"structure":<10} {"train N":>9} {"val N":>9} {"test N":>9}')
    for o, name in enumerate(OUTPUT_NAMES):
        print(f'{name:<6} {"-".join(map(str, model.structures_[o])):<10} {r["train"][o]:>9.5f} '
              f'{r["validation"][o]:>9.5f} {r["test"][o]:>9.5f}')
    print(f'trained in {model.fit_seconds_:.1f} s; test set: {len(test)} samples')
    model.save(args.out)
    print(f'wrote {args.out}')
    return 0
