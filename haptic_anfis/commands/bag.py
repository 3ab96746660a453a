"""``haptic-anfis bag info|export|recover|resim|play|record``: what ``ros2 bag`` would do for this
package's sessions (rosbag2 bags, MCAP storage; see :mod:`haptic_anfis.bag`)."""
from __future__ import annotations

import argparse
import importlib

from ..bag import bag_info, format_info, recover_bag
from ..bag.export import export_csv
from ..bag.topics import absolute

NAME = 'bag'

#: the actions that run the re-simulation pipeline (numba kernels) or a ROS node (rclpy: ROS 2 or
#: the 'ros' extra), each in a module of its own (``haptic_anfis.commands.<module>``) imported only
#: when chosen: info, export and recover load the bag room alone
ACTION_MODULES = {'resim': '_bag_resim', 'play': '_bag_nodes', 'record': '_bag_nodes'}


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest='bag_command', metavar='ACTION', required=True)
    a = sub.add_parser('info', help='topics, types, counts, duration and rates of a bag')
    a.add_argument('path', help='bag directory')
    a = sub.add_parser('export', help='one CSV per topic with readable fields')
    a.add_argument('path', help='bag directory')
    a.add_argument('--csv', required=True, metavar='OUT_DIR', help='directory for the CSV files')
    a.add_argument('--topics', nargs='*', default=None, help='topics to export (default: all)')
    a = sub.add_parser('recover', help='rebuild metadata.yaml and a complete MCAP after a crash')
    a.add_argument('path', help='bag directory left by an interrupted recording')
    a = sub.add_parser('resim', help='recorded poses through the current contact tracker and '
                       'force model; compare with the recorded force commands')
    a.add_argument('path', help='bag directory')
    a.add_argument('--params-file', action='append', default=[], metavar='YAML',
                   help='parameter file for contact_detector / force_server (repeatable)')
    a.add_argument('--model', default=None, help='force model file (overrides model_path)')
    a.add_argument('--tolerance', type=float, default=None, metavar='N',
                   help='exit 1 if the max force difference exceeds this many newtons')
    a = sub.add_parser('play', help='publish a bag with its original timing')
    a.add_argument('path', help='bag directory')
    a.add_argument('--rate', type=float, default=1.0, help='speed factor (default 1.0)')
    a.add_argument('--start-offset', type=float, default=0.0, metavar='S',
                   help='start S seconds into the bag')
    a.add_argument('--loop', action='store_true', help='play again and again')
    a.add_argument('--topics', nargs='*', default=None, help='topics to play (default: all)')
    a.add_argument('--clock', action='store_true', help='publish /clock with the recorded time')
    a.add_argument('--resimulate', action='store_true',
                   help='play the force commands recomputed by the current models; log the '
                        'comparison')
    a.add_argument('--params-file', action='append', default=[], metavar='YAML',
                   help='parameter file for the re-simulated nodes (repeatable)')
    a.add_argument('--live', action='store_true',
                   help='publish on the RECORDED topic names (default: under /playback): a running '
                        'falcon_driver then applies the recorded force commands to the device')
    a = sub.add_parser('record', help='record topics to a new bag (Ctrl-C stops and closes it)')
    a.add_argument('-o', '--output', default='', help='bag directory to create '
                   '(default: session_YYYYmmdd-HHMMSS)')
    a.add_argument('topics', nargs='*', help='topics (default: pose, contact, force command, '
                   'buttons)')
    a.add_argument('-a', '--all', action='store_true', help='also every other topic in the graph')
    a.add_argument('--duration', type=float, default=0.0, metavar='S',
                   help='stop after S seconds (default: until Ctrl-C)')
    a.add_argument('--flush-period', type=float, default=None, metavar='S',
                   help='flush to disk at least this often (default 0.5 s)')
    a.add_argument('--fallback-dir', default='', metavar='DIR',
                   help='if writing fails (disk full), continue in a bag of the same name here')
    a.add_argument('--compression', default=None, choices=('none', 'zstd', 'lz4'),
                   help='MCAP chunk compression (default: zstd)')


def run(args: argparse.Namespace) -> int:
    action = args.bag_command
    if action not in ACTION_MODULES:
        return globals()[f'_{action}'](args)
    try:
        mod = importlib.import_module(f'{__package__}.{ACTION_MODULES[action]}')
    except ModuleNotFoundError as exc:
        if (exc.name or '').startswith('haptic_anfis'):
            raise
        raise OSError(f"needs {exc.name} (ROS 2, or the package's ros extra): {exc}") from None
    return getattr(mod, action)(args)


def _info(args) -> int:
    print(format_info(bag_info(args.path)))
    return 0


def _export(args) -> int:
    topics = [absolute(t) for t in args.topics] if args.topics else None
    for topic, (f, n) in sorted(export_csv(args.path, args.csv, topics).items()):
        print(f'{topic}: {n} rows -> {f}' if f is not None else f'{topic}: no messages (no file)')
    return 0


def _recover(args) -> int:
    print(recover_bag(args.path).format())
    return 0
