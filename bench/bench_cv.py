"""Grouped cross-validation of force-model variants (issue 18): the repo's own
:func:`haptic_anfis.report.cv.group_cv` (k folds over surface points, every depth of a point in one
fold), one line per variant with the out-of-fold RMSE mean ± std over the seeds.

Run (slow: 15 fits per variant with the defaults; prefix with ``nice``)::

    .venv/bin/python bench/bench_cv.py                      # the shipped config and the RBF peer
    .venv/bin/python bench/bench_cv.py --variant 'fx7=structure=[[7,7,2],[5,5,2],[5,5,2]]' \
        --variant 'ridge1e-4=ridge=1e-4' --seeds 0 1 2 --jsonl out/cv.jsonl

A variant is ``NAME=KEY=JSON[;KEY=JSON...]``: ForceModel keyword arguments on top of
config/force_model.yaml's (so ``NAME=`` alone is the shipped configuration). ``--peers rbf mlp
plain`` adds the report's peers (RBF thin-plate, MLP 32-32 tanh, the paper's plain 3-3-3-2).
Results are printed and, with ``--jsonl``, appended one JSON object per variant. ``--before
FILE.jsonl`` first prints the records of an earlier run (this script's ``--jsonl`` at another
commit) as they were measured, labelled with FILE's name: a before/after page.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from haptic_anfis.anfis import ForceModel
from haptic_anfis.anfis.defaults import AUTO, SHIPPED_STRUCTURE
from haptic_anfis.commands.train import load_config
from haptic_anfis.report.cv import group_cv
from haptic_anfis.tissue.dataset import DEFAULT_DATASET, load_dataset
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'force_model.yaml'


def parse_variant(text: str) -> tuple[str, dict]:
    """'name=key=json;key=json' -> (name, {key: value})."""
    name, _, rest = text.partition('=')
    params = {}
    for item in filter(None, rest.split(';')):
        key, _, value = item.partition('=')
        params[key.strip()] = json.loads(value)
    return name, params


def ours(params: dict, outputs: str = 'xyz'):
    """seed -> ForceModel with config/force_model.yaml's hyper-parameters updated by ``params``;
    outputs not in ``outputs`` (letters of x, y, z) get a one-rule model (cheap: a screening run
    for one axis; their RMSE is then meaningless)."""
    base = load_config(str(CONFIG))
    base.pop('test_fraction', None)
    base.pop('seed', None)
    base.update(params)
    for key in ('extrapolation', 'inputs', 'max_mfs', 'search_start'):
        if isinstance(base.get(key), list):   # YAML lists; 'auto' stays a string
            base[key] = tuple(base[key])
    if isinstance(base.get('structure'), list):
        st = base['structure']
        base['structure'] = tuple(st) if st and isinstance(st[0], int) else [tuple(s) for s in st]
    if outputs != 'xyz':
        st = base['structure']
        if st == AUTO:   # the shipped structures (the default inputs of the shipped data)
            st = [tuple(s) for s in SHIPPED_STRUCTURE]
        per = [tuple(st)] * 3 if isinstance(st[0], (int, np.integer)) else list(st)
        d = len(per[0])
        base['structure'] = [s if 'xyz'[o] in outputs else (1,) * d for o, s in enumerate(per)]
    return lambda seed: ForceModel(seed=seed, **base)


def disc_to_square(y: np.ndarray, z: np.ndarray, R: float) -> tuple[np.ndarray, np.ndarray]:
    """Elliptical-grid map of the disc of radius R onto the square [-R, R]² (Fong 2015's inverse
    of the square-to-disc map): a grid partition in (u, v) then has data under every rule, where a
    grid over (y, z) leaves its corners (|y| = |z| = R) empty. Radii past R are clamped to R."""
    a, b = y / R, z / R
    r = np.hypot(a, b)
    k = np.where(r > 1.0, 1.0 / np.maximum(r, 1e-300), 1.0)
    a, b = a * k, b * k
    s2 = 2.0 * np.sqrt(2.0)
    d = a * a - b * b
    u = 0.5 * np.sqrt(np.maximum(2 + d + s2 * a, 0)) - 0.5 * np.sqrt(np.maximum(2 + d - s2 * a, 0))
    v = 0.5 * np.sqrt(np.maximum(2 - d + s2 * b, 0)) - 0.5 * np.sqrt(np.maximum(2 - d - s2 * b, 0))
    return u * R, v * R


def transformed(ds, how: str, factor: float = 1.0):
    """The dataset with its (y, z) columns remapped (a prototype of an input transform)."""
    from haptic_anfis.tissue.dataset import ForceDataset
    if how == 'none':
        return ds
    X = ds.X.copy()
    R = factor * float(ds.provenance['scene_si']['palpable_radius'])
    if how == 'square':
        X[:, 1], X[:, 2] = disc_to_square(X[:, 1], X[:, 2], R)
    else:
        raise ValueError(f'unknown transform {how!r}')
    return ForceDataset(X, ds.Y, ds.point, ds.provenance)


def peer(name: str):
    from haptic_anfis.report.peers import MlpPeer, OursPeer, RbfPeer
    return {'rbf': lambda s: RbfPeer(),
            'mlp': lambda s: MlpPeer((32, 32), seed=s),
            'plain': lambda s: OursPeer((3, 3, 3, 2), form='plain', seed=s)}[name]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--variant', action='append', default=[], help='NAME=KEY=JSON[;KEY=JSON]')
    p.add_argument('--peers', nargs='*', default=None, help='rbf mlp plain')
    p.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
    p.add_argument('--folds', type=int, default=5)
    p.add_argument('--dataset', default=str(DEFAULT_DATASET))
    p.add_argument('--transform', default='none', choices=('none', 'square'),
                   help='remap (y, z) before the CV (prototype of an input transform)')
    p.add_argument('--radius-factor', type=float, default=1.0,
                   help='map radius = this x the scene\'s palpable radius')
    p.add_argument('--outputs', default='xyz',
                   help='axes to train (x, y, z letters); the others get a one-rule model')
    p.add_argument('--jsonl', default=None, help='append results here')
    p.add_argument('--before', default=None,
                   help="an earlier run's --jsonl records, printed first (a before/after page)")
    args = p.parse_args(argv)
    ds = transformed(load_dataset(args.dataset), args.transform, args.radius_factor)
    jobs = [(n, ours(kw, args.outputs), kw) for n, kw in map(parse_variant, args.variant)]
    if not args.variant and args.peers is None:
        jobs = [('shipped config', ours({}), {})]
        args.peers = ['rbf']  # the MLP peer takes ~20 min here: ask for it (--peers rbf mlp)
    jobs += [(n, peer(n), {'peer': n}) for n in (args.peers or [])]
    print(f'grouped {args.folds}-fold CV over surface points, seeds {args.seeds}, '
          f'{len(ds)} samples; out-of-fold RMSE [N] mean ± std over seeds')
    if args.before:
        for line in Path(args.before).read_text().splitlines():
            rec = json.loads(line)
            cells = ' | '.join(f'{m:.4f} ± {s:.4f}' for m, s in zip(rec['mean'], rec['std']))
            label = f'{rec["name"]} ({Path(args.before).stem})'
            print(f'{label:<28} | {cells} | fit {rec["fit_s"]:.2f} s | seeds {rec["seeds"]}')
    for name, make, kw in jobs:
        t0 = time.perf_counter()
        r = group_cv(ds, make, folds=args.folds, seeds=args.seeds)
        cells = ' | '.join(f'{m:.4f} ± {s:.4f}' for m, s in zip(r['mean'], r['std']))
        print(f'{name:<28} | {cells} | fit {r["fit_s"]:.2f} s | {time.perf_counter() - t0:.0f} s',
              flush=True)
        if args.jsonl:
            rec = {'name': name, 'params': kw, 'transform': args.transform,
                   'radius_factor': args.radius_factor, 'outputs': args.outputs, 'seeds': args.seeds, 'folds': args.folds,
                   'rmse': np.asarray(r['rmse']).tolist(), 'mean': r['mean'].tolist(),
                   'std': r['std'].tolist(), 'fit_s': r['fit_s']}
            Path(args.jsonl).parent.mkdir(parents=True, exist_ok=True)
            with open(args.jsonl, 'a') as fh:
                fh.write(json.dumps(rec) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(run_with_page(main, __file__, __doc__))
