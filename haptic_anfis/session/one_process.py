"""Runner 1: the session's haptic graph in ONE process (``sim``, ``exam run``, the benchmarks).

falcon_driver (1 kHz servo thread) -> contact_detector -> force_server -> falcon_driver on one
EventsExecutor (:func:`haptic_anfis.nodes.graph.build_graph`), the recorder in the loop's process
(or, ``recorder_process``, in one of its own) and the visualizer in a process of its own (or,
``in_process``, in the loop's): :class:`OneProcessSession` starts them in that order, holds the
simulated hand until everything is ready, and stops them with the device at zero force first.
"""
from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path
from typing import Callable, Mapping, Sequence

from rclpy.parameter import Parameter

from ..bag.reader import recorded_summary
from ..bag.topics import ALL_LOOP_TOPICS
from ..nodes.graph import build_graph
from ..nodes.recorder import Recorder
from ..nodes.side_nodes import SIDE_NICE, SideNodes, hold_until_recorded
from ..realtime.processes import (guard_realtime_time, leave_realtime, recorder_arguments,
                                  set_graph_priority)
from .domain import refuse_shared_domain
from .spec import SessionSpec

__all__ = ['OneProcessSession', 'finish_process', 'open_graph', 'RECORDED_TOPICS']


def _recorded_topics() -> tuple[str, ...]:
    return tuple(ALL_LOOP_TOPICS)


#: what the one-process recorder records: every loop topic (a function: no ROS import here)
RECORDED_TOPICS = _recorded_topics


def open_graph(spec: SessionSpec | None = None, *, overrides: dict | None = None, extra=(),
               program: str = 'haptic-anfis', visualizer: bool | None = None):
    """Build the one-process graph of ``spec`` (its parameter files, case and ``-p`` overrides;
    default: a plain sim) and return the :class:`~haptic_anfis.nodes.graph.Graph`, not spinning
    yet. ``overrides``: {node: [rclpy Parameter]}; ``extra``: factories ``f(context) -> Node``
    built before the driver. The benchmarks and tests use this instead of ``build_graph``.

    Raises:
        ParameterError: a node rejected its parameters (nothing is left running).
    """
    spec = spec or SessionSpec(nodes=('falcon_driver', 'contact_detector', 'force_server'))
    args = [*spec.params_arguments(), *spec.user_ros_args(), *spec.case_arguments(),
            *spec.driver_arguments()]
    return build_graph([program, '--ros-args', *args] if args else [program],
                       visualizer=spec.visualizer and spec.in_process
                       if visualizer is None else visualizer,
                       overrides=overrides, extra=extra)


#: [s] between the lines saying a side node is still finishing its output
FINISH_SAY_S = 10.0


def finish_process(p: subprocess.Popen, name: str, limit: float,
                   say: Callable[[str], None] = lambda line: print(line, flush=True)) -> int | None:
    """Ask ``p`` (the side node ``name``) to stop as Ctrl-C would and wait until it exits, at
    most ``limit`` s, saying every :data:`FINISH_SAY_S` s that it is still at work; its exit
    code, or None (after one line saying so) when it is still running at the limit (the
    caller's stop then kills it)."""
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    while True:
        left = limit - (time.monotonic() - t0)
        if left <= 0:
            if p.poll() is None:
                say(f'{name}: still writing its output after {limit:g} s; stopping it')
                return None
            return p.returncode
        try:
            return p.wait(min(FINISH_SAY_S, left))
        except subprocess.TimeoutExpired:
            say(f'{name}: finishing its output ({time.monotonic() - t0:.0f} s so far, at most '
                f'{limit:g} s)')


class OneProcessSession:
    """Start, hold until ready, and stop a one-process session.

    ``hand``: a script object the simulated Falcon's hand plays instead of its
    ``palpation_script`` (``exam run``: the simulated trainee). Use: ``s =
    OneProcessSession(spec, extra=..., overrides=...)``; ``graph = s.start()``;
    ``s.wait_ready()``; spin ``graph`` as the command needs; ``s.stop()`` (always, in a
    ``finally``); then :meth:`recorded` for the recorder's summary.
    """

    def __init__(self, spec: SessionSpec, *, extra: Sequence[Callable] = (),
                 overrides: dict | None = None, side: bool = True, hand=None,
                 side_nodes: Mapping[str, Sequence[str]] | None = None,
                 side_nice: int | None = None):
        self.spec, self.overrides, self.hand = spec, overrides, hand
        self.extra = list(extra)
        self.graph = None
        #: how the graph's threads are scheduled once ready (``--graph-priority``), in words
        self.graph_scheduling = ''
        self.codes: dict[str, int] = {}
        if spec.record and not spec.recorder_process:
            self.extra.append(self._recorder)
        self.side = (self._side_nodes(side_nodes or {}, side_nice)
                     if side or side_nodes or spec.view else None)

    def _recorder(self, ctx):
        s = self.spec   # the case args reach it with the graph's (global); 'default' does not
        named = s.case_arguments()
        default = [Parameter('case', value='default')] if s.recorder_case_arguments() and not (
            named) else []
        scene = s.scene and not named   # exam run --case FILE (not a case's own scene file)
        return Recorder(context=ctx, output=s.record, topics=RECORDED_TOPICS(),
                        parameter_overrides=default,
                        custom_data={'scene': str(Path(s.scene).resolve())} if scene else None)

    def _side_nodes(self, more: Mapping[str, Sequence[str]], nice: int | None):
        """The visualizer (unless ``in_process`` / ``no_viz``), with ``recorder_process`` the
        recorder, and ``more`` ({node: its ``--ros-args``}, e.g. ``exam run``'s examiner) as
        processes of their own, at CPU priority ``nice`` (None: the side nodes' default)."""
        s = self.spec
        common = [*s.params_arguments(), *s.user_ros_args()]
        nodes: dict[str, list[str]] = {}
        if s.record and s.recorder_process:
            nodes['recorder'] = [*common, *s.recorder_case_arguments(),
                                 *recorder_arguments(s.record, RECORDED_TOPICS())]
        if s.visualizer and not s.in_process:
            nodes['visualizer'] = [*common, *s.case_arguments()]
        if s.view:   # the browser page (exam: no session buttons, the exam drives the hand)
            nodes['web_view'] = [*common, *s.case_arguments(),
                                 *s.view_arguments(controls=s.command != 'exam')]
        nodes.update({k: list(v) for k, v in more.items()})
        return SideNodes(nodes, nice=SIDE_NICE if nice is None else nice)

    def start(self):
        """Check the spec, build the graph, start the side nodes; returns the graph.

        Raises:
            SessionError / CaseError / ParameterError: bad input (nothing started);
            SideNodeError: a side node did not start (the graph is shut down).
        """
        self.spec.check()
        refuse_shared_domain(self.spec)
        self.graph = open_graph(self.spec, overrides=self.overrides, extra=self.extra,
                                program=f'haptic-anfis-{self.spec.command}')
        if self.hand is not None:  # the simulated Falcon plays it (from the script's start)
            self.graph.set_hand(self.hand)
        if self.side:
            try:
                # the graph's parameters are valid: start the side nodes (the hand is held)
                self.side.start(self.spec.ready_timeout)
            except BaseException:
                self.graph.shutdown()
                self.graph = None
                raise
        return self.graph

    def wait_ready(self) -> bool:
        """Spin the graph until a force command reached the driver and, with a recorder in its
        own process, until that recorder subscribes to every loop topic (the hand is held until
        then, so the bag has the session from its first move). False (said why) on the
        ready timeout. Resets the loop statistics: they cover the session, not the start."""
        g, s = self.graph, self.spec
        end = time.monotonic() + s.ready_timeout
        if self.side and 'recorder' in self.side.nodes:
            if not hold_until_recorded(g, s.ready_timeout):
                print(f'not ready after {s.ready_timeout:g} s: the recorder has not subscribed '
                      'to every loop topic' + ''.join(f'; {n} exited with code {c}'
                                                       for n, c in self.side.dead()), flush=True)
                return False
        if g.wait_ready(max(end - time.monotonic(), 0.0)) is None:
            print(f'not ready after {s.ready_timeout:g} s: no force command reached the driver',
                  flush=True)
            return False
        guard_realtime_time()  # rtkit's run-time limit ends no graph
        # now, not before: a cold numba compile at real-time priority would hold a core
        self.graph_scheduling = set_graph_priority(s.graph_priority)
        if 'refused' in self.graph_scheduling:
            print(f'graph: {self.graph_scheduling}', flush=True)
        g.driver.servo.stats.reset()
        return True

    def view_url(self) -> str | None:
        """The page's address with ``view`` (None without)."""
        return f'http://127.0.0.1:{int(self.spec.view_port)}/' if self.spec.view else None

    def where(self) -> str:
        """', visualizer in pid N, ...' for the side nodes."""
        return ''.join(f', {n} in pid {pid}' for n, pid in (self.side.pids if self.side
                                                             else {}).items())

    def stop(self, finish: Mapping[str, float] | None = None) -> dict[str, int]:
        """The device to zero force and the graph down first, then the side nodes (the recorder
        has every message sent to it); the side nodes' exit codes. ``finish``: {side node: the
        longest it may take [s]} for nodes whose output the caller needs (the examiner writes
        its report when stopped): each is asked to stop first and waited for that long (a line
        every :data:`FINISH_SAY_S` s), instead of the other nodes' short grace before a kill."""
        try:
            # the shutdown computes (an hour's tick trace written): at rtkit's real-time
            # priority its run-time limit would SIGKILL the session for it
            leave_realtime()
            if self.graph is not None:
                self.graph.shutdown()
        finally:
            if self.side:
                try:   # a Ctrl-C while waiting still stops every side node
                    for name, limit in (finish or {}).items():
                        p = self.side.sup.procs.get(name)
                        if p is not None:
                            finish_process(p, name, limit)
                finally:
                    self.codes = self.side.stop()
        return self.codes

    def recorded(self) -> dict | None:
        """The recorder's summary (written, dropped, topics, output), None without recording."""
        for n in (self.graph.extra if self.graph is not None else ()):
            if hasattr(n, 'writer'):
                return n.summary()
        if self.spec.record:
            return recorded_summary(self.spec.record)
        return None

    def print_recorded(self, recorded: dict | None = None) -> dict | None:
        """Print the one ``recorded ...`` line; returns the summary."""
        r = recorded if recorded is not None else self.recorded()
        if r is not None:
            print(f"recorded       {r['written']} messages on {len(r['topics'])} topics to "
                  f"{r['output']} (dropped {r['dropped']})", flush=True)
        return r

