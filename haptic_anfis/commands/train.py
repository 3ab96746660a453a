"""``haptic-anfis train DATASET.csv --out MODEL.json``: the paper's protocol on a force dataset."""
from __future__ import annotations

import argparse

from ..anfis import train_on_dataset
from ..anfis.defaults import SHIPPED
from ..bag.training_data import load_training_data
from ..tissue.dataset import OUTPUT_NAMES
from ..yamlfile import read_yaml

NAME = 'train'


def parse_structure(text: str) -> tuple[int, ...]:
    """'5-5-2' -> (5, 5, 2): one MF count per ANFIS input (the model checks the count against its
    inputs: 3 for the default depth-scaled form over (y, z, depth), 4 over (x, y, z, depth))."""
    try:
        st = tuple(int(v) for v in text.replace(',', '-').split('-'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'structure {text!r}: expected MF counts like 5-5-2') from None
    if not 1 <= len(st) <= 4 or min(st) < 1:
        raise argparse.ArgumentTypeError(f'structure {text!r}: expected one MF count >= 1 per ANFIS '
                                         'input (3 for the default (y, z, depth) inputs, 4 for '
                                         'x, y, z, depth), like 5-5-2')
    return st


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = 0
    if v < 1:
        raise argparse.ArgumentTypeError(f'{text!r}: expected an integer >= 1')
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('dataset', help='force dataset CSV (point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N), '
                   'or a recorded session bag (its contact and force-command topics)')
    p.add_argument('--out', required=True, help='model file to write (JSON)')
    p.add_argument('--config', default=None,
                   help='YAML with a "force_model" section of hyper-parameters '
                        '(see config/force_model.yaml); command-line flags override it')
    p.add_argument('--structure', type=parse_structure, default=None,
                   help='fixed MF counts for all outputs, one per ANFIS input, e.g. 5-5-2 for the default '
                        '(y, z, depth) inputs (default: the shipped 6-6-2/6-6-2/5-5-2 over (y, z, '
                        'depth), a search per output when x is kept)')
    p.add_argument('--epochs', type=_positive_int, default=None,
                   help=f"epochs of the final models (default {SHIPPED['epochs']})")
    p.add_argument('--test-fraction', type=float, default=None,
                   help='held-out test part (default 0.2)')
    p.add_argument('--split', choices=('point', 'sample'), default=None,
                   help='hold out whole surface points (default) or single samples')
    p.add_argument('--seed', type=int, default=None, help='seed of the splits (default 0)')


#: Keys of the config's "force_model" section: ForceModel arguments plus the test split.
CONFIG_KEYS = {'structure', 'candidates', 'epochs', 'search_epochs', 'search_start', 'max_mfs', 'tol', 'ridge',
               'step', 'val_fraction', 'split', 'search_folds', 'extrapolation', 'seed',
               'test_fraction', 'form', 'inputs', 'ridge_candidates'}


def load_config(path: str | None) -> dict:
    """The "force_model" section of a YAML file, checked for unknown keys."""
    if path is None:
        return {}
    doc = read_yaml(path, 'config file') or {}
    if isinstance(doc, dict) and 'force_model' not in doc:   # a typo, or another config file
        raise ValueError(f'{path}: no "force_model" section (its top-level keys: '
                         f'{", ".join(map(str, doc)) or "none"}); see config/force_model.yaml')
    section = doc.get('force_model') if isinstance(doc, dict) else None
    if not isinstance(section, dict):
        raise ValueError(f'{path}: expected a mapping under "force_model"')
    unknown = sorted(set(section) - CONFIG_KEYS)
    if unknown:
        raise ValueError(f'{path}: unknown force_model key(s) {unknown}; known: {sorted(CONFIG_KEYS)}')
    # null means "the default" except for the structure, where it means "search"
    params = {k: v for k, v in section.items() if v is not None or k == 'structure'}
    for key in ('structure', 'search_start', 'max_mfs', 'extrapolation', 'inputs'):
        if isinstance(params.get(key), list):   # a string ('auto') stays as it is
            params[key] = tuple(params[key])
    if 'candidates' in params:  # an explicit list of structures instead of the greedy search
        params['candidates'] = [tuple(c) for c in params['candidates']]
    return params


def run(args: argparse.Namespace) -> int:
    ds = load_training_data(args.dataset)
    print(f'dataset {args.dataset}: {len(ds)} samples at {len(set(ds.point.tolist()))} surface points'
          + (f' [{ds.provenance["kind"]}]' if ds.provenance.get('kind') else ''))
    params = load_config(args.config)
    for key in ('structure', 'epochs', 'split', 'seed', 'test_fraction'):
        if getattr(args, key) is not None:
            params[key] = getattr(args, key)
    test_fraction = params.pop('test_fraction', SHIPPED['test_fraction'])
    seed = params.pop('seed', SHIPPED['seed'])
    model, test = train_on_dataset(ds, test_fraction=test_fraction, seed=seed, verbose=True,
                                   dataset_path=str(args.dataset), **params)
    r = model.metadata_['rmse']
    print(f'\n{"output":<6} {"structure":<10} {"train N":>9} {"val N":>9} {"test N":>9}')
    for o, name in enumerate(OUTPUT_NAMES):
        val = r['validation'][o]
        val = f'{val:>9.5f}' if val is not None else f'{"n/a":>9}'  # val_fraction 0: no hold-out
        print(f'{name:<6} {"-".join(map(str, model.structures_[o])):<10} {r["train"][o]:>9.5f} '
              f'{val} {r["test"][o]:>9.5f}')
    print(f'trained in {model.fit_seconds_:.1f} s; test set: {len(test)} samples')
    model.save(args.out)
    print(f'wrote {args.out}')
    return 0
