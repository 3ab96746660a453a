"""``haptic-anfis dataset``: finite-element force data for a tissue scene.

    haptic-anfis dataset SCENE --out DATA.csv [--coarse] [--workers N] [--work-dir DIR]
        # also writes DATA.displacement.npz: the skin's dent for every point and depth
    haptic-anfis dataset [SCENE] --surface OUT.stl        # the contact detector's surface mesh
    haptic-anfis dataset [SCENE] --report DIR [--data DATA.csv] [--coarse]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..tissue.dataset import save_dataset
from ..tissue.displacement import displacement_path, save_displacements
from ..tissue.geometry import write_surface_mesh
from ..tissue.report import write_report
from ..tissue.scene import DEFAULT_SCENE, load_scene
from ..tissue.sweep import run_sweep

NAME = 'dataset'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('scene', nargs='?', default=None,
                        help='scene YAML (default: config/scenes/default.yaml)')
    parser.add_argument('--out', type=Path, help='dataset CSV to write (JSON sidecar beside it)')
    parser.add_argument('--coarse', action='store_true',
                        help="the scene's coarse mesh (minutes on 2 cores; for CI and quick looks)")
    parser.add_argument('--workers', type=int, default=2,
                        help='worker processes, one math thread each (default 2)')
    parser.add_argument('--work-dir', type=Path, default=None,
                        help='per-point results, for resuming (default: OUT without suffix + .work)')
    parser.add_argument('--points', type=str, default=None,
                        help='comma-separated loading-point ids to solve (default: all)')
    parser.add_argument('--surface', type=Path, default=None,
                        help='also write the tissue surface mesh (STL/PLY by suffix)')
    parser.add_argument('--surface-units', choices=('mm', 'm'), default='mm',
                        help='units of the written surface mesh (default mm)')
    parser.add_argument('--report', type=Path, default=None,
                        help='write the validation report (PNG plots + JSON numbers) into DIR')
    parser.add_argument('--data', type=Path, default=None,
                        help='dataset CSV for the report\'s surface map (default: the shipped one)')
    parser.add_argument('--quiet', action='store_true', help='no progress line')


def run(args: argparse.Namespace) -> int:

    scene = load_scene(args.scene or DEFAULT_SCENE)
    if not (args.out or args.surface or args.report):
        print('haptic-anfis dataset: nothing to do; give --out, --surface and/or --report',
              file=sys.stderr)
        return 2
    if args.workers < 1:
        raise ValueError(f'--workers must be >= 1, got {args.workers}')
    if args.surface:

        path = write_surface_mesh(scene, args.surface, units=args.surface_units)
        print(f'wrote {path} (tissue surface, {args.surface_units})')
    if args.out:

        work = args.work_dir or args.out.with_suffix('.work')
        indices = ([int(v) for v in args.points.split(',') if v.strip()]
                   if args.points else None)
        res = run_sweep(scene, work, coarse=args.coarse, workers=args.workers, indices=indices,
                        progress=not args.quiet)
        save_dataset(res.dataset, args.out)
        if res.displacements is not None:

            dpath = save_displacements(res.displacements, displacement_path(args.out))
            print(f'wrote {dpath} (skin displacement profiles, dataset sha256 '
                  f'{res.dataset.sha256()[:12]})')
        prov = res.dataset.provenance
        print(f'wrote {args.out}: {len(res.dataset)} samples from {prov["n_points"]} points '
              f'({len(res.failed)} failed: {res.failed}); mesh {prov["mesh"]["ndof_mean"]:.0f} '
              f'DOF per point; {prov["wall_time_s"]["sum_over_points"]:.0f} s of solver time, '
              f'{res.elapsed_s:.0f} s this run; work dir {work}')
        if res.failed:
            return 3
    if args.report:

        for line in write_report(scene, args.report, data=args.data, coarse=args.coarse):
            print(line)
    return 0
