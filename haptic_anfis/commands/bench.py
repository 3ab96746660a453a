"""``haptic-anfis bench model``: speed against error of the force model."""
from __future__ import annotations

import argparse

from ..tissue.dataset import DEFAULT_DATASET, load_dataset
from .train import parse_structure

NAME = 'bench'
HELP = 'benchmarks (printed, never asserted): "model" = speed against error of the ANFIS models'

DEFAULT_STRUCTURES = ('2-2-2-2', '3-2-2-2', '3-3-3-2', '4-4-4-2', '5-5-5-3')


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('what', choices=('model',), help='what to benchmark')
    p.add_argument('--dataset', default=str(DEFAULT_DATASET), help='force dataset CSV')
    p.add_argument('--structures', nargs='*', default=list(DEFAULT_STRUCTURES),
                   help='structures to compare, plus the searched one (default: %(default)s)')
    p.add_argument('--repeats', type=int, default=20000, help='single-query timings per model')


def run(args: argparse.Namespace) -> int:
    from ..report.model_bench import bench_structures, format_table

    ds = load_dataset(args.dataset)
    structures = [None] + [parse_structure(s) for s in args.structures]
    print(f'dataset {args.dataset}: {len(ds)} samples; test = 20 % of surface points held out')
    print(format_table(bench_structures(ds, structures, repeats=args.repeats)))
    return 0
