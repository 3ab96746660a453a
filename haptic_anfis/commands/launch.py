"""``haptic-anfis launch``: the haptic graph as separate node processes (``ros2 launch`` stand-in).

Starts each node's console script in its own process (the recorder first, the falcon driver last),
passes every ``--params-file`` to each of them (ROS parameter files are keyed by node name, so the
per-node YAMLs in config/ can all be given), waits for ``--duration`` seconds or Ctrl-C, then stops
them in reverse order with SIGINT (the driver zeroes the force first, the recorder closes its bag
last). A node that exits on its own ends the launch with exit code 1.
"""
from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

NAME = 'launch'
HELP = 'run the haptic nodes as separate processes (falcon_driver, contact_detector, ...)'

#: nodes that take the case parameters (--case / --random-case)
CASE_NODES = ('contact_detector', 'force_server', 'visualizer')
DEFAULT_NODES = 'falcon_driver,contact_detector,force_server,visualizer'
#: start order: consumers before producers, the device last (it starts publishing poses at once)
ORDER = ('recorder', 'trainer', 'force_server', 'contact_detector', 'visualizer', 'player',
         'falcon_driver')


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('--nodes', default=DEFAULT_NODES,
                   help=f'comma-separated nodes to start (default {DEFAULT_NODES})')
    p.add_argument('--params-file', action='append', default=[], metavar='YAML',
                   help='ROS 2 parameter file given to every node (repeatable), e.g. '
                        'config/falcon_driver.yaml')
    p.add_argument('--duration', type=float, default=0.0,
                   help='stop the nodes after this many seconds (default 0 = at Ctrl-C)')
    p.add_argument('--record', metavar='BAG', default=None,
                   help='also start the recorder, writing this new bag directory')
    p.add_argument('--domain-id', type=int, default=None,
                   help='ROS_DOMAIN_ID for the nodes (default: inherited)')
    p.add_argument('--localhost', action='store_true',
                   help='discovery on this machine only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)')
    from ..cases.library import add_case_arguments
    add_case_arguments(p)
    p.add_argument('--log-dir', default=None,
                   help="write each node's output to DIR/<node>.log (default: this terminal)")


def run(args: argparse.Namespace) -> int:
    from ..launch import node_env, node_names, start_node, stop_node

    known = node_names()
    names = [n.strip() for n in args.nodes.split(',') if n.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(f'--nodes: unknown node(s) {unknown or args.nodes!r}; known: '
                         f'{", ".join(known)}')
    if not (args.duration >= 0 and math.isfinite(args.duration)):
        raise ValueError(f'--duration: expected >= 0 s, got {args.duration}')
    for f in args.params_file:
        if not Path(f).is_file():
            raise ValueError(f'--params-file {f}: no such file')
    ros_args = [a for f in args.params_file for a in ('--params-file', str(Path(f).resolve()))]
    from ..cases.library import case_node_arguments
    case_args = case_node_arguments(args)
    extra: dict[str, list[str]] = {n: (list(case_args) if n in CASE_NODES else [])
                                   for n in names}
    if args.record:
        if Path(args.record).exists():
            raise ValueError(f'--record {args.record}: exists already; a recording needs a new '
                             'directory')
        extra.setdefault('recorder', []).extend(['-p', f'output:={Path(args.record).resolve()}'])
    env = node_env(args.domain_id, localhost=args.localhost)
    log_dir = Path(args.log_dir) if args.log_dir else None
    if log_dir:
        log_dir.mkdir(parents=True, exist_ok=True)

    procs = []
    t0 = time.monotonic()
    failed = None
    try:
        for name in sorted(extra, key=lambda n: ORDER.index(n) if n in ORDER else len(ORDER)):
            log = (log_dir / f'{name}.log').open('w') if log_dir else None
            p = start_node(name, [*ros_args, *extra[name]], env=env, log=log)
            procs.append((name, p))
            print(f'started {name:<17} pid {p.pid}' + (f', log {log.name}' if log else ''),
                  flush=True)
        print(f'{len(procs)} nodes running' + (f' for {args.duration:g} s' if args.duration
                                               else '; Ctrl-C stops them'), flush=True)
        while not (args.duration and time.monotonic() - t0 >= args.duration):
            dead = [(n, p.returncode) for n, p in procs if p.poll() is not None]
            if dead:
                failed = dead
                break
            time.sleep(0.1)
    except KeyboardInterrupt:
        print('interrupted: stopping the nodes', flush=True)
    finally:
        codes = {n: stop_node(p) for n, p in reversed(procs)}
    for n, _ in procs:
        print(f'stopped {n:<17} exit code {codes[n]}', flush=True)
    if failed:
        print(f'node(s) exited on their own: '
              + ', '.join(f'{n} (code {c})' for n, c in failed), flush=True)
        return 1
    return 0 if all(c == 0 for c in codes.values()) else 1
