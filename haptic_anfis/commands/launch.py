"""``haptic-anfis launch``: the haptic graph as separate node processes (``ros2 launch`` stand-in).

Starts each node's console script in its own process, passes every ``--params-file`` to each of
them (ROS parameter files are keyed by node name, so the per-node YAMLs in config/ can all be
given), and runs the session:

1. Readiness: the recorder and the other nodes start first; the falcon driver starts once each of
   them has said ``started`` on ``session/status`` (kernels compiled, mesh / model loaded). The
   simulated hand then waits at the script's start, force zero, until the first force command
   arrives; the driver says ``ready`` and the launch prints ``ready after N s``. ``--duration``
   counts from then.
2. Respawn: a node that dies (a crash, ``kill -9``) is started again, at most ``--max-restarts``
   times per node, while the others keep running: the recorder keeps recording and the driver's
   watchdog holds zero force until commands return. Each death and restart is printed and
   published on ``session/events`` (recorded in the bag). The recorder itself restarts into
   ``BAG.restartN``. The falcon driver is never restarted: its death stops the launch (exit 1),
   as does a node past its restart limit, or any death with ``--no-respawn``.
3. Stop: at the end of ``--duration`` or Ctrl-C the nodes are stopped in reverse start order with
   SIGINT (the driver zeroes the force first, the recorder closes its bag last).
"""
from __future__ import annotations

import argparse
import math
import os
import signal
import time
from pathlib import Path

NAME = 'launch'
HELP = 'run the haptic nodes as separate processes (falcon_driver, contact_detector, ...)'

#: nodes that take the case parameters (--case / --random-case)
CASE_NODES = ('contact_detector', 'force_server', 'visualizer', 'web_view')
DEFAULT_NODES = 'falcon_driver,contact_detector,force_server,visualizer'
#: start order: consumers before producers, the device last (it starts publishing poses at once)
ORDER = ('recorder', 'trainer', 'force_server', 'contact_detector', 'visualizer', 'web_view',
         'player', 'falcon_driver')
#: never restarted: the device owner (a restart would re-home a real Falcon mid-session)
NO_RESPAWN = ('falcon_driver',)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('--nodes', default=DEFAULT_NODES,
                   help=f'comma-separated nodes to start (default {DEFAULT_NODES})')
    p.add_argument('--params-file', action='append', default=[], metavar='YAML',
                   help='ROS 2 parameter file given to every node (repeatable), e.g. '
                        'config/falcon_driver.yaml')
    p.add_argument('--duration', type=float, default=0.0,
                   help='stop the nodes this many seconds after the session is ready (default 0 '
                        '= at Ctrl-C)')
    p.add_argument('--record', metavar='BAG', default=None,
                   help='also start the recorder, writing this new bag directory (with the '
                        'session/status and session/events topics)')
    p.add_argument('--domain-id', type=int, default=None,
                   help='ROS_DOMAIN_ID for the nodes (default: inherited)')
    p.add_argument('--localhost', action='store_true',
                   help='discovery on this machine only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)')
    from ..cases.library import add_case_arguments
    add_case_arguments(p)
    p.add_argument('--log-dir', default=None,
                   help="write each node's output to DIR/<node>.log (default: this terminal)")
    p.add_argument('--no-respawn', action='store_true',
                   help='a node that exits on its own stops the launch (exit code 1) instead of '
                        'being restarted')
    p.add_argument('--max-restarts', type=int, default=3,
                   help='restarts allowed per node before the launch gives up (default 3)')
    p.add_argument('--enclave-root', default=None, metavar='ENCLAVE',
                   help='SROS2: start each node with --enclave ENCLAVE/<node> (the launcher\'s own '
                        'monitor with ENCLAVE/launch_monitor); security itself is switched on by '
                        'ROS_SECURITY_KEYSTORE / ROS_SECURITY_ENABLE / ROS_SECURITY_STRATEGY')
    p.add_argument('--ready-timeout', type=float, default=300.0,
                   help='seconds to wait for the nodes to start and the first force command to '
                        'reach the driver (default 300: a cold numba compile on a busy machine)')
    p.add_argument('--json', action='store_true',
                   help='end with the loop report (haptic-anfis loop) as one JSON object on the '
                        'last line')


def _check(args: argparse.Namespace, known: tuple[str, ...]) -> list[str]:
    names = [n.strip() for n in args.nodes.split(',') if n.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(f'--nodes: unknown node(s) {unknown or args.nodes!r}; known: '
                         f'{", ".join(known)}')
    for opt in ('duration', 'ready_timeout'):
        v = getattr(args, opt)
        if not (v >= 0 and math.isfinite(v)):
            raise ValueError(f'--{opt.replace("_", "-")}: expected >= 0 s, got {v}')
    if args.max_restarts < 0:
        raise ValueError(f'--max-restarts: expected >= 0, got {args.max_restarts}')
    for f in args.params_file:
        if not Path(f).is_file():
            raise ValueError(f'--params-file {f}: no such file')
    if args.record and Path(args.record).exists():
        raise ValueError(f'--record {args.record}: exists already; a recording needs a new '
                         'directory')
    return names


def run(args: argparse.Namespace) -> int:
    from ..nodes.processes import (Supervisor, node_env, node_names, recorder_arguments,
                                   renamed_output)
    from .loop import launch_trace_path, print_launch_report

    names = _check(args, node_names())
    ros_args = [a for f in args.params_file for a in ('--params-file', str(Path(f).resolve()))]
    from ..cases.library import case_node_arguments
    case_args = case_node_arguments(args)
    extra: dict[str, list[str]] = {n: (list(case_args) if n in CASE_NODES else [])
                                   for n in names}
    if args.record:
        from ..bag.topics import DEFAULT_TOPICS
        from ..nodes.session import EVENTS_TOPIC, STATUS_TOPIC
        extra.setdefault('recorder', []).extend(
            recorder_arguments(args.record, [*DEFAULT_TOPICS, STATUS_TOPIC, EVENTS_TOPIC]))
    if args.enclave_root:
        root = '/' + args.enclave_root.strip('/')
        for n in extra:
            extra[n] += ['--enclave', f'{root}/{n}']
    if 'falcon_driver' in extra and not {'force_server', 'contact_detector'} <= set(extra):
        # no force source in this launch: the simulated hand must not wait for one
        extra['falcon_driver'] += ['-p', 'hold_until_force:=false']
    env = node_env(args.domain_id, localhost=args.localhost)
    log_dir = Path(args.log_dir) if args.log_dir else None
    if log_dir:
        log_dir.mkdir(parents=True, exist_ok=True)
    # The launcher's own monitor node joins the nodes' domain and discovery range.
    for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE'):
        if k in env:
            os.environ[k] = env[k]
    # The nodes run in their own sessions (a terminal's Ctrl-C reaches only this process): every
    # stop signal becomes KeyboardInterrupt here, so the nodes are always stopped in order and
    # none is left running.
    def _stop(signum, frame):
        raise KeyboardInterrupt
    stop_signals = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous = {sig: signal.signal(sig, _stop) for sig in stop_signals}
    from ..nodes.session import SessionMonitor
    mon = SessionMonitor(domain_id=args.domain_id, enclave=(
        f"/{args.enclave_root.strip('/')}/launch_monitor" if args.enclave_root else None))
    sup = Supervisor(env, log_dir, max_restarts=args.max_restarts)
    order = sorted(extra, key=lambda n: ORDER.index(n) if n in ORDER else len(ORDER))
    trace = launch_trace_path(extra, log_dir)  # the loop report at the end
    t0 = time.monotonic()
    failed: list[tuple[str, int]] = []
    codes: dict[str, int] = {}

    history: list[dict] = []
    replay = {'pending': False, 'known': set()}

    def say(event: str, **kw) -> None:
        e = mon.event(event=event, t=round(time.monotonic() - t0, 3), **kw)
        history.append(e)
        print('session: ' + ', '.join(f'{k} {v}' for k, v in e.items() if k != 'wall_time'),
              flush=True)

    def replay_to_new_recorder() -> None:
        """A restarted recorder joined after the events that explain its new bag: once it is
        ready and subscribed, publish the session's events again (``replayed: true``)."""
        if replay['pending'] and mon.state('recorder', sup.started_at['recorder']) == 'ready' \
                and mon.subscriber_gids() - replay['known']:
            replay['pending'] = False
            for e in list(history):
                mon.event(**{k: v for k, v in e.items() if k != 'wall_time'}, replayed=True)

    def start(name: str) -> None:
        p = sup.start(name, [*ros_args, *extra[name]])
        log = sup.logs.get(name)
        print(f'started {name:<17} pid {p.pid}' + (f', log {log.name}' if log else ''),
              flush=True)

    def handle_deaths() -> bool:
        """Restart what died and may be restarted; False when the launch must stop."""
        for name, code in sup.dead():
            say('died', node=name, code=code)
            if args.no_respawn or name in NO_RESPAWN or not sup.may_restart(name):
                why = ('--no-respawn' if args.no_respawn else 'the device owner is never '
                       'restarted' if name in NO_RESPAWN else
                       f'restart limit {args.max_restarts} reached')
                say('stopping', node=name, reason=why)
                failed.append((name, code))
                return False
            p = sup.restart(name, renamed_output if name == 'recorder' else None)
            say('restarted', node=name, pid=p.pid, restarts=sup.restarts[name])
            if name == 'recorder':
                replay['pending'], replay['known'] = True, mon.subscriber_gids()
        replay_to_new_recorder()
        return True

    def wait_for(pred, what: str) -> bool:
        end = time.monotonic() + args.ready_timeout
        while not pred():
            if time.monotonic() > end:
                print(f'not ready after {args.ready_timeout:g} s: {what()}', flush=True)
                failed.append(('ready-timeout', 1))
                return False
            mon.spin(0.1)
            if not handle_deaths():
                return False
        return True

    try:
        helpers = [n for n in order if n != 'falcon_driver']
        for name in helpers:
            start(name)
        ok = wait_for(lambda: all(mon.state(n, sup.started_at[n]) for n in helpers),
                      lambda: 'no status from ' + ', '.join(
                          n for n in helpers if not mon.state(n, sup.started_at[n])))
        if ok and 'falcon_driver' in extra:
            start('falcon_driver')
            ok = wait_for(lambda: mon.state('falcon_driver', sup.started_at['falcon_driver'])
                          == 'ready', lambda: 'the falcon driver has seen no force command; '
                          'states: ' + ', '.join(f'{n} {mon.state(n) or "none"}' for n in order))
        if ok:
            say('ready', after_s=round(time.monotonic() - t0, 1))
            print(f'ready after {time.monotonic() - t0:.1f} s: {len(sup.procs)} nodes running'
                  + (f' for {args.duration:g} s' if args.duration else '; Ctrl-C stops them'),
                  flush=True)
            t_ready = time.monotonic()
            while not (args.duration and time.monotonic() - t_ready >= args.duration):
                mon.spin(0.1)
                if not handle_deaths():
                    break
    except KeyboardInterrupt:
        print('interrupted: stopping the nodes', flush=True)
    finally:
        for sig in stop_signals:  # a second Ctrl-C must not cut the ordered stop short
            signal.signal(sig, lambda *_: print('stopping the nodes, please wait', flush=True))
        try:
            codes = sup.stop_all(list(reversed(order)), starting=[
                n for n in sup.procs if not mon.state(n, sup.started_at[n])])
        finally:
            mon.close()
            for sig, h in previous.items():
                signal.signal(sig, h)
    for n in reversed(order):
        if n in codes:
            print(f'stopped {n:<17} exit code {codes[n]}', flush=True)
    print_launch_report(trace, args.params_file, args.json)
    if failed:
        print('launch failed: ' + ', '.join(f'{n} (code {c})' for n, c in failed), flush=True)
        return 1
    return 0 if all(c == 0 for c in codes.values()) else 1
