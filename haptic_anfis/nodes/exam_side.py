"""``exam run`` in the process layout of ``haptic-anfis sim``: the examiner in a process of its own
(:class:`~haptic_anfis.nodes.side_nodes.SideNodes`), the loop (driver, contact detector, force
server) and the simulated trainee in the exam's process.

Why: in the loop's process the examiner's heat map (folding samples, serialising ~6k coloured
vertices) holds the interpreter lock the driver's servo thread needs; with the driver's default
``local_model`` force mode the one-process exam graph fell to ~280 poses/s under load.

:class:`CoverageWatch` (a node in the exam's process) reads the examiner's heat maps raw (no
deserialisation: it counts them, times them and reads the ``marks N`` of the summary text), so
the exam knows when the examiner has every mark before it stops it; the examiner writes
report.json and report.png into its ``report_dir`` when stopped (SIGINT).
"""
from __future__ import annotations

import re
import threading
import time
from typing import Sequence

from visualization_msgs.msg import MarkerArray

from .. import interfaces as ifc
from .base import HapticNode
from .side_nodes import recorder_matched

__all__ = ['EXAMINER_TOPICS', 'CoverageWatch', 'examiner_arguments', 'hold_until_examiner']

#: the topics the examiner subscribes to (absolute names)
EXAMINER_TOPICS = tuple('/' + t for t in (ifc.TOPIC_CONTACT, ifc.TOPIC_COMMAND, ifc.TOPIC_POSE,
                                          ifc.TOPIC_MARKS, ifc.TOPIC_BUTTONS))
_MARKS = re.compile(rb'marks (\d+)  samples (\d+)')


class CoverageWatch(HapticNode):
    """Counts the examiner's heat maps (``exam/coverage``) and their arrival times (monotonic
    [s]) and keeps the newest ``marks N  samples M`` of its summary text."""

    def __init__(self, name: str = 'exam_coverage_watch', **kw):
        super().__init__(name, **kw)
        self.times: list[float] = []
        self.marks = 0
        self.samples = 0   # contact samples the examiner has
        self.create_subscription(MarkerArray, ifc.TOPIC_COVERAGE, self._on_map, 10, raw=True)

    def _on_map(self, data: bytes) -> None:
        self.times.append(time.monotonic())
        m = _MARKS.findall(data)
        if m:
            self.marks, self.samples = int(m[-1][0]), int(m[-1][1])

    def rate(self, since: float | None = None) -> float:
        """Heat maps per second over the arrivals after ``since`` (monotonic s; None = all)."""
        t = [x for x in self.times if since is None or x >= since]
        return (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 and t[-1] > t[0] else 0.0


def examiner_arguments(scene: str, exam_config: str, case: str | None, report_dir: str,
                       params_files: Sequence[str] = ()) -> list[str]:
    """The side examiner's ``--ros-args`` (same parameters as the in-process one)."""
    a = [x for f in params_files for x in ('--params-file', f)]
    for name, v in (('scene', scene), ('exam_config', exam_config), ('report_dir', report_dir),
                    ('case', case)):
        if v:   # '' is every one's default (and rcl rejects an empty override)
            a += ['-p', f'{name}:={v}']
    return a


def hold_until_examiner(graph, timeout: float, examiner: str = 'examiner',
                        watch: CoverageWatch | None = None, gone=None) -> bool:
    """Hold the simulated hand of ``graph`` until the node ``examiner`` (another process)
    subscribes to every topic it scores and — with ``watch`` — has published its first heat map
    (its executor spins and its first fold is done: a subscribed examiner still starting up
    lost the first seconds of a short exam), so the session is scored from its first move;
    spins the graph meanwhile. False if that did not happen within ``timeout`` s, or as soon
    as ``gone()`` is true (its process exited)."""
    matched = threading.Event()
    graph.driver.release_gate = matched.is_set

    def check() -> bool:
        if not matched.is_set() and recorder_matched(graph.driver, EXAMINER_TOPICS, examiner) \
                and (watch is None or watch.times):
            matched.set()
        return matched.is_set()
    graph.spin_for(timeout, until=lambda: check() or bool(gone is not None and gone()))
    return matched.is_set()
