"""``haptic-anfis bench model``: speed against error of the force model."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..report.model_bench import bench_structures, format_table
from ..resources import config_file
from ..tissue.dataset import DEFAULT_DATASET, load_dataset
from .train import load_config, parse_structure

NAME = 'bench'

#: Structures of the default form (depth-scaled over y, z, depth); 'A/B/C' = one per output (Fx,
#: Fy, Fz); 'search' = the structure search; 'config' = config/force_model.yaml's structure.
DEFAULT_STRUCTURES = ('config', '3-3-2', '7-7-2')
CONFIG = config_file('force_model.yaml')


def parse_structures(text: str) -> Any:
    """'5-5-2' (all outputs), '7-7-2/5-5-2/5-5-2' (Fx/Fy/Fz), 'search' -> None, 'config' kept."""
    if text in ('search', 'config'):
        return None if text == 'search' else text
    parts = [parse_structure(t) for t in text.split('/')]
    if len(parts) not in (1, 3):
        raise argparse.ArgumentTypeError(f'structures {text!r}: one structure or three (Fx/Fy/Fz)')
    return parts[0] if len(parts) == 1 else parts


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('what', choices=('model',), help='what to benchmark')
    p.add_argument('--dataset', default=str(DEFAULT_DATASET), help='force dataset CSV')
    p.add_argument('--structures', nargs='*', type=parse_structures, default=list(DEFAULT_STRUCTURES),
                   help='structures of the default form to compare: 5-5-2 (all outputs), '
                        '7-7-2/5-5-2/5-5-2 (Fx/Fy/Fz), search, config (default: %(default)s)')
    p.add_argument('--config', default=str(CONFIG),
                   help='hyper-parameters besides the structure (default: %(default)s)')
    p.add_argument('--repeats', type=int, default=20000, help='single-query timings per model')


def run(args: argparse.Namespace) -> int:

    ds = load_dataset(args.dataset)
    params = load_config(args.config) if args.config and Path(args.config).is_file() else {}
    for key in ('test_fraction', 'seed'):
        params.pop(key, None)
    configured = params.pop('structure', None)
    parsed = [parse_structures(s) if isinstance(s, str) else s for s in args.structures]  # defaults
    structures = [configured if isinstance(s, str) else s for s in parsed]
    print(f'dataset {args.dataset}: {len(ds)} samples; test = 20 % of surface points held out; '
          f'other hyper-parameters from {args.config}')
    print(format_table(bench_structures(ds, structures, repeats=args.repeats, params=params)))
    return 0
