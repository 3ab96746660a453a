"""``haptic-anfis launch``: the haptic graph as separate node processes (``ros2 launch`` stand-in).

Starts each node's console script in its own process, passes every ``--params-file`` to each of
them (ROS parameter files are keyed by node name, so the per-node YAMLs in config/ can all be
given), and runs the session (:class:`haptic_anfis.session.ProcessSession`: readiness, respawn,
ordered stop), then prints the loop report of the driver's tick trace.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ..cases.library import use_case_dir
from ..realtime.processes import rerun_command_in_own_session
from ..session import ProcessSession, add_session_arguments, spec_from_args
from .loop import launch_trace_path, print_launch_report

NAME = 'launch'


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_session_arguments(p, NAME)
    p.add_argument('--json', action='store_true',
                   help='end with the loop report (haptic-anfis loop) as one JSON object on the '
                        'last line')


def run(args: argparse.Namespace) -> int:
    use_case_dir(args.case_dir)   # before anything reads the library; the nodes inherit it
    if args.node_sessions == 'one':
        code = rerun_command_in_own_session(args)  # the nodes' one session
        if code is not None:
            return code
    spec = spec_from_args(args, NAME)
    spec.check()  # before the trace directory is made
    node_args: dict[str, list[str]] = {n: [] for n in spec.nodes}
    trace = launch_trace_path(node_args, Path(spec.log_dir) if spec.log_dir else None,
                              spec.trace)
    session = ProcessSession(spec, node_args)
    result = session.run()
    print_launch_report(trace, spec.params_files, args.json,
                        [*spec.case_arguments(), *spec.user_ros_args()],
                        graph_scheduling=session.graph_scheduling)
    if result.failed:
        print('launch failed: ' + ', '.join(f'{n} (code {c})' for n, c in result.failed),
              flush=True)
        return 1
    return 0 if result.ok else 1
