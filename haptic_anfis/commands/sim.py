"""``haptic-anfis sim``: the whole haptic graph in one process, with a simulated Falcon.

falcon_driver (1 kHz servo thread, scripted virtual hand) -> contact_detector -> force_server ->
falcon_driver on one EventsExecutor, with the recorder (``--record``). The visualizer runs beside
it in a process of its own (``nodes/side_nodes.py``: in the loop's process its dent held the
interpreter lock the servo thread needs; ``--in-process`` puts it back there), and so does the
recorder with ``--recorder-process``. Prints
the loop rate, pose -> wrench latency percentiles, deadline misses, the largest applied force and
contact statistics; with ``--json`` the last line of output is one JSON object (see
``json_summary``).
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

NAME = 'sim'
HELP = 'run the haptic node graph in one process with the simulated Falcon and print loop statistics'


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument('--duration', type=float, default=10.0, help='seconds to run (default 10)')
    p.add_argument('--params-file', action='append', default=[], metavar='YAML',
                   help='ROS 2 parameter file for the nodes (repeatable), e.g. '
                        'config/falcon_driver.yaml')
    p.add_argument('--no-viz', action='store_true', help='leave the visualizer out')
    p.add_argument('--record', metavar='BAG', default=None,
                   help='record every loop topic (pose, velocity, applied force, buttons, contact, '
                        'force command) to this new bag directory (rosbag2, MCAP)')
    p.add_argument('--in-process', action='store_true',
                   help='run the visualizer in the haptic loop\'s process too (default: in a '
                        'process of its own, off the loop\'s interpreter lock)')
    p.add_argument('--recorder-process', action='store_true',
                   help='with --record: the recorder in a process of its own (default: in the '
                        'loop\'s process, which measured cheaper for the loop on 2 cores)')
    p.add_argument('--ready-timeout', type=float, default=300.0,
                   help='seconds to wait for the graph to be ready (first force command at the '
                        'driver) before giving up (default 300)')
    p.add_argument('--json', action='store_true',
                   help='end with one line of JSON: rate_hz, latency_p50_ms, latency_p99_ms, '
                        'latency_max_ms, deadline_misses, cycles, max_force_n, contact_s, ...')
    from ..cases.library import add_case_arguments
    add_case_arguments(p)
    from .view import add_view_arguments
    add_view_arguments(p)
    p.add_argument('ros_args', nargs=argparse.REMAINDER,
                   help='--ros-args ... passed to rclpy (e.g. --ros-args -p rate:=500.0)')


def run(args: argparse.Namespace) -> int:
    if args.record and Path(args.record).exists():
        raise ValueError(f'--record {args.record}: exists already; a recording needs a new '
                         'directory')
    if not (args.duration > 0 and math.isfinite(args.duration)):
        raise ValueError(f'--duration: expected > 0 s, got {args.duration}')
    from ..nodes._common import ParameterError
    from ..nodes.graph import build_graph
    ros_args = list(args.ros_args or [])
    if ros_args and ros_args[0] == '--':
        ros_args = ros_args[1:]
    from ..cases.library import case_node_arguments
    case_args = case_node_arguments(args)  # every node of the process gets case / seed
    if args.params_file or case_args:
        if '--ros-args' not in ros_args:
            ros_args = ['--ros-args', *ros_args]
        for f in args.params_file:
            ros_args += ['--params-file', f]
        ros_args += case_args
    side = _side_nodes(args, ros_args, case_args)
    extra = []
    if args.record and not args.recorder_process:
        from ..bag.topics import ALL_LOOP_TOPICS
        from ..nodes.recorder import Recorder
        extra.append(lambda ctx: Recorder(context=ctx, output=args.record,
                                          topics=ALL_LOOP_TOPICS))
    try:
        graph = build_graph(['haptic-anfis-sim', *ros_args],
                            visualizer=args.in_process and not args.no_viz, extra=extra)
    except ParameterError as exc:
        raise ValueError(str(exc)) from None
    from ..nodes.side_nodes import SideNodeError
    codes: dict[str, int] = {}
    try:
        # the graph's parameters are valid: start the side nodes (the hand is held meanwhile)
        side.start(args.ready_timeout)
        if not _wait_ready(graph, side, args):
            return 1
        # Statistics cover the session, not the start (the hand waited, force zero, until now).
        graph.driver.servo.stats.reset()
        from ..nodes.session import process_age
        where = ''.join(f', {n} in pid {pid}' for n, pid in side.pids.items())
        print(f'ready after {process_age():.1f} s; running the haptic graph for {args.duration:g} s '
              f'(one process, EventsExecutor{where})', flush=True)
        graph.spin_for(args.duration)
    except SideNodeError as exc:
        print(f'not ready: {exc}', flush=True)
        return 1
    except KeyboardInterrupt:
        print('interrupted', flush=True)
    finally:
        graph.shutdown()  # the device to zero force first
        codes = side.stop()  # then the side nodes: the recorder has every message sent to it
    summary = graph.summary()
    print_summary(summary)
    for name, code in codes.items():
        print(f'{name:<14} own process, exit code {code}')
    recorded = None
    for n in graph.extra:
        if hasattr(n, 'writer'):
            recorded = n.summary()
    if args.record and recorded is None:
        from ..bag.reader import recorded_summary
        recorded = recorded_summary(args.record)
    if recorded is not None:
        r = recorded
        print(f"recorded       {r['written']} messages on {len(r['topics'])} topics to "
              f"{r['output']} (dropped {r['dropped']})")
    if args.json:
        print(json.dumps(json_summary(summary, recorded)), flush=True)
    return 0


def _side_nodes(args: argparse.Namespace, ros_args: list[str], case_args: list[str]):
    """The visualizer (unless ``--in-process``) and, with ``--recorder-process``, the recorder
    as processes of their own."""
    from ..nodes.side_nodes import SideNodes
    common = [a for a in ros_args if a != '--ros-args']  # params files, case, the user's args
    nodes: dict[str, list[str]] = {}
    if args.record and args.recorder_process:
        from ..bag.topics import ALL_LOOP_TOPICS
        from ..nodes.processes import recorder_arguments
        nodes['recorder'] = [*common, *recorder_arguments(args.record, ALL_LOOP_TOPICS)]
    if not args.in_process and not args.no_viz:
        nodes['visualizer'] = common
    from .view import web_view_arguments
    if (wv := web_view_arguments(args, common)) is not None:   # --view: the browser page
        nodes['web_view'] = wv
    return SideNodes(nodes)


def _wait_ready(graph, side, args: argparse.Namespace) -> bool:
    """Spin the graph until a force command reached the driver and, with a recorder in its own
    process, until that recorder subscribes to every loop topic (the hand is held until then, so
    the bag has the session from its first move). False (said why) on ``--ready-timeout``."""
    import time
    end = time.monotonic() + args.ready_timeout
    if 'recorder' in side.nodes:
        from ..nodes.side_nodes import hold_until_recorded
        if not hold_until_recorded(graph, args.ready_timeout):
            print(f'not ready after {args.ready_timeout:g} s: the recorder has not subscribed '
                  'to every loop topic' + ''.join(f'; {n} exited with code {c}'
                                                   for n, c in side.dead()), flush=True)
            return False
    if graph.wait_ready(max(end - time.monotonic(), 0.0)) is None:
        print(f'not ready after {args.ready_timeout:g} s: no force command reached the driver',
              flush=True)
        return False
    return True


def json_summary(s: dict, recorded: dict | None = None) -> dict:
    """The run's headline figures as one flat JSON-able dict (non-finite numbers become null).

    ``contact_s`` is :func:`contact_seconds`; ``cycles`` counts servo ticks.
    """
    lp, c = s['loop'], s['contact']
    out = {'rate_hz': lp['rate_hz'], 'latency_p50_ms': lp['latency_p50_ms'],
           'latency_p99_ms': lp['latency_p99_ms'], 'latency_max_ms': lp['latency_max_ms'],
           'latency_next_tick_pct': lp.get('latency_next_tick_pct'),
           'deadline_misses': lp['deadline_misses'], 'cycles': lp['ticks'],
           'max_force_n': lp['max_force_N'], 'contact_s': contact_seconds(s),
           'seconds': lp['seconds'], 'commands': lp['latency_n'],
           'watchdog_trips': lp['watchdog_trips'], 'clamped': lp['clamped'],
           'rejected': lp['rejected_nonfinite'] + lp['rejected_frame'],
           'servo_scheduling': lp.get('servo_scheduling', ''),
           'max_depth_mm': c['max_depth_mm'], 'contact_fraction': c['contact_fraction']}
    if recorded is not None:
        out.update(recorded_messages=recorded['written'], dropped_messages=recorded['dropped'])
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()}


def contact_seconds(s: dict) -> float:
    """Time in contact [s]: the run time times the share of poses found in contact."""
    return s['loop']['seconds'] * s['contact']['contact_fraction']


def print_summary(s: dict) -> None:
    lp, c, f = s['loop'], s['contact'], s['force']
    print(f"servo loop     {lp['rate_hz']:8.1f} Hz over {lp['seconds']:.1f} s "
          f"({lp['ticks']} ticks), deadline misses {lp['deadline_misses']}")
    print(f"pose->wrench   p50 {lp['latency_p50_ms']:.3f} ms, p99 {lp['latency_p99_ms']:.3f} ms, "
          f"max {lp['latency_max_ms']:.3f} ms ({lp['latency_n']} commands; "
          f"{lp.get('latency_next_tick_pct', float('nan')):.1f} % taken at the next tick)")
    print(f"force          max applied {lp['max_force_N']:.2f} N, max model {f['max_model_force_N']:.2f} N, "
          f"clamped {lp['clamped']}, watchdog trips {lp['watchdog_trips']}, "
          f"rejected {lp['rejected_nonfinite'] + lp['rejected_frame']}")
    print(f"contact        {c['in_contact']} of {c['poses']} poses in contact "
          f"({100 * c['contact_fraction']:.1f} %, ~{contact_seconds(s):.1f} s), "
          f"max depth {c['max_depth_mm']:.2f} mm, bad poses {c['bad_poses']}")
    if 'visualizer' in s:
        print(f"visualizer     {s['visualizer']['marker_arrays']} marker arrays")
