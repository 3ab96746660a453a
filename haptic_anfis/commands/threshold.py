"""``haptic-anfis threshold``: measure a trainee's own stiffness-discrimination threshold.

    haptic-anfis threshold --trainee-id ID [--backend sim|falcon] [--observer PCT] [--seed N]
                           [--db PATH] [--json]

A two-alternative forced-choice staircase, 3-down-1-up (Levitt 1971), between two presses on the
device that differ in stiffness (haptic_anfis.exam.staircase, haptic_anfis.exam.threshold_run).
``--backend sim`` renders every press on the simulated Falcon and answers with a simulated
observer whose threshold is ``--observer`` (a check of the procedure, or a demonstration);
``--backend falcon`` renders them on a Novint Falcon while the trainee presses (``--press-time``
seconds each, announced on the terminal) and asks which was stiffer. The result is stored in the
trainee record; ``cases list --threshold`` and ``exam run --next`` then grade the library against
it.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

from ..device.falcon import WorkspaceMapping
from ..device.falcon_usb import FalconUSB, import_ftdi
from ..device.stiffness_press import DevicePresses, SimulatedPresses
from ..exam.staircase import SimulatedObserver
from ..exam.threshold_run import run_threshold
from ..record.store import check_trainee_id
from ..record.thresholds import store_threshold

NAME = 'threshold'


def percentage(text: str) -> float:
    """A percentage > 0 from the command line (argparse ``type``; 22 = 22 %)."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and 0 < v < 1000):
        raise argparse.ArgumentTypeError(f'expected a percentage > 0 (e.g. 22), got {text!r}')
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('--trainee-id', required=True, metavar='ID',
                   help='the trainee whose threshold this is (stored in the record)')
    p.add_argument('--backend', choices=('sim', 'falcon'), default='sim',
                   help="'sim': the simulated Falcon and a simulated observer; 'falcon': a "
                        'Novint Falcon and the trainee answering (default sim)')
    p.add_argument('--observer', type=percentage, default=22.0, metavar='PCT',
                   help="sim: the simulated observer's threshold [%%] (default 22)")
    p.add_argument('--seed', type=int, default=0, help='seed of the press order (and of the '
                                                       'simulated observer)')
    p.add_argument('--press-time', type=float, default=2.0, metavar='S',
                   help='falcon: seconds the spring is rendered for each press (default 2)')
    p.add_argument('--db', default=None, metavar='PATH',
                   help='the record file (default $HAPTIC_ANFIS_DB, else '
                        '$XDG_DATA_HOME/haptic_anfis/trainees.sqlite)')
    p.add_argument('--no-store', action='store_true', help='measure only, store nothing')
    p.add_argument('--json', action='store_true', help='print the result as one JSON object')


def run(args: argparse.Namespace) -> int:

    check_trainee_id(args.trainee_id)
    if args.backend == 'sim':
        press, choose, device = _simulated(args)
    else:
        press, choose, device = _falcon(args)
    verbose = not args.json

    def said(n: int, delta: float, correct: bool) -> None:
        if verbose:
            print(f'trial {n:3d}: {100 * delta:6.1f} % stiffer: '
                  f'{"correct" if correct else "wrong"}', flush=True)
    # the real device's servo process holds it for the whole series (zero force on exit)
    with press:
        res = run_threshold(press, choose, seed=args.seed, on_trial=said)
    res.update(device=device, trainee_id=args.trainee_id)
    if args.backend == 'sim':
        res['observer_threshold_pct'] = args.observer
    if not args.no_store:
        res['record_id'] = store_threshold(args.db, args.trainee_id, res['threshold_pct'],
                                           res['trials'], device, res)
    if args.json:
        print(json.dumps(res))
    else:
        print(f"threshold of {args.trainee_id}: {res['threshold_pct']:.1f} % stiffer "
              f"({res['trials']} trials, {res['reversals']} reversals, "
              f"{res['correct_pct']:.0f} % correct; the library's default is the stylus "
              f"threshold 22 %)" + ('' if args.no_store else '; stored in the trainee record'))
    return 0


def _simulated(args):
    """Presses on the simulated Falcon, answered by a simulated observer of known threshold."""
    obs = SimulatedObserver(args.observer / 100.0, seed=args.seed)
    return SimulatedPresses(), lambda a, b: obs.choose(a.stiffness, b.stiffness), 'sim'


def _falcon(args):
    """Presses on a Novint Falcon; the trainee answers 1 or 2 on the terminal."""
    if not (math.isfinite(args.press_time) and args.press_time > 0):
        raise ValueError(f'--press-time: expected > 0 s, got {args.press_time}')
    import_ftdi()
    mapping = WorkspaceMapping()
    # the plane through the workspace's centre
    presses = DevicePresses(FalconUSB, mapping.offset[0], args.press_time, mapping,
                            before=lambda: input('press ENTER, then press the grip down into '
                                                 'the spring and let it back up... '))

    def choose(a, b) -> int:
        while True:
            got = input('which press was stiffer, 1 or 2? ').strip()
            if got in ('1', '2'):
                return int(got) - 1
            print(f'expected 1 or 2, got {got!r}', file=sys.stderr)
    return presses, choose, 'falcon'
