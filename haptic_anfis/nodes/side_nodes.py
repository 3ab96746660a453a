"""Nodes that run beside the one-process haptic graph, each in a process of its own
(``haptic-anfis sim``: the visualizer; the recorder with ``--recorder-process``).

Why: in the graph's process their Python work (the dent's drawing at 30 Hz) holds the interpreter
lock the 1 kHz servo thread needs, and the loop lost its rate (measured in the README, *Tissue
deformation*). In a process of their own they only share the machine's cores — at the price of
every loop message they read crossing to another process (why the recorder stays in the loop's
process by default: *Long runs*).

:class:`SideNodes` starts them (output to standard error, so ``--json``'s last line stays the
JSON), waits until each has said ``started`` on ``session/status``, and stops them in order
(SIGINT, as Ctrl-C: the recorder writes its summary). A side node also gets SIGINT if the process
that started it dies (``realtime/processes.py``), so none is left running.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Mapping, Sequence

from ..bag.topics import ALL_LOOP_TOPICS, absolute
from ..errors import HapticAnfisError
from ..realtime.processes import SESSION_CHECKED, SIDE_NICE, Supervisor, node_env
from .session import SessionMonitor




class SideNodeError(HapticAnfisError, RuntimeError):
    """A side node exited or said nothing before the timeout (the message names it)."""


class SideNodes:
    """``nodes``: {node name: its ``--ros-args`` arguments}, started in that order."""

    def __init__(self, nodes: Mapping[str, Sequence[str]], nice: int = SIDE_NICE):
        self.nodes = {n: list(a) for n, a in nodes.items()}
        # the user's domain and discovery range: the side nodes join the graph the user sees
        env = node_env(localhost=False)
        env[SESSION_CHECKED] = '1'  # the session checked their parameters against all its nodes
        self.sup = Supervisor(env, max_restarts=0, stream=sys.stderr, nice=nice)
        self._mon = None

    def __bool__(self) -> bool:
        return bool(self.nodes)

    def start(self, timeout: float = 300.0) -> None:
        """Start every node and wait until each says ``started`` (constructed: kernels compiled,
        files loaded, subscriptions made).

        Raises:
            SideNodeError: a node exited (its exit code) or said nothing within ``timeout`` s; the
                nodes already started are stopped.
        """
        if not self.nodes:
            return
        self._mon = mon = SessionMonitor(name='sim_side_monitor')
        try:
            for name, args in self.nodes.items():
                self.sup.start(name, args)
            end = time.monotonic() + timeout
            while True:
                dead = self.sup.dead()
                if dead:
                    raise SideNodeError(', '.join(f'{n} exited with code {c} while starting'
                                                  for n, c in dead))
                waiting = [n for n in self.nodes if not mon.state(n, self.sup.started_at[n])]
                if not waiting:
                    return
                if time.monotonic() > end:
                    raise SideNodeError(f'no status from {", ".join(waiting)} after '
                                        f'{timeout:g} s')
                mon.spin(0.1)
        except BaseException:
            self.stop()
            raise

    @property
    def pids(self) -> dict[str, int]:
        return {n: p.pid for n, p in self.sup.procs.items()}

    def dead(self) -> list[tuple[str, int]]:
        """(name, exit code) of every side node that has exited."""
        return self.sup.dead()

    def stop(self) -> dict[str, int]:
        """Stop the nodes, last started first (SIGINT; kill after 10 s); their exit codes."""
        try:
            starting = [n for n in self.sup.procs
                        if self._mon is None or not self._mon.state(n, self.sup.started_at[n])]
            return self.sup.stop_all(list(reversed(list(self.nodes))), starting=starting)
        finally:
            if self._mon is not None:
                self._mon.close()
                self._mon = None


def recorder_matched(node, topics: Sequence[str], recorder: str = 'recorder') -> bool:
    """Whether ``node``'s graph shows a subscription of the node named ``recorder`` on every
    topic of ``topics`` (absolute names): a recorder in another process will get what is
    published from now on."""
    for t in topics:
        if not any(i.node_name == recorder for i in node.get_subscriptions_info_by_topic(t)):
            return False
    return True


def hold_until_recorded(graph, timeout: float, recorder: str = 'recorder') -> bool:
    """Hold the simulated hand of ``graph`` (a :class:`~haptic_anfis.nodes.graph.Graph` whose
    executor has not spun yet) until the node ``recorder`` (in another process) subscribes to
    every loop topic, spinning the graph meanwhile: the bag then has the session from its first
    move. False if that did not happen within ``timeout`` s."""
    topics = [absolute(t) for t in ALL_LOOP_TOPICS]
    matched = threading.Event()
    graph.driver.release_gate = matched.is_set  # read by the driver when commands arrive

    def check() -> bool:
        if not matched.is_set() and recorder_matched(graph.driver, topics, recorder):
            matched.set()
        return matched.is_set()
    return graph.spin_for(timeout, until=check)
