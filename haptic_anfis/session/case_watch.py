"""The case each case node reports on ``/parameter_events``, against the browser page's case.

The page's case choice switches every running case node together (:mod:`.case_switch`); a case
set on one node from outside (``ros2 param set /force_server case normal``) switches that node
alone, and the trainee would then press on one case while the page draws and scores another.
:class:`CaseWatch` keeps the case each node last reported (set on it while it runs, or declared
at its start) and says what the page must do: nothing (every node that reported is on the page's
case), follow (every running case node was set, from outside, to one other case: the page takes
it too), or stop collecting and say which node is on which case (split).

No ROS here: :mod:`haptic_anfis.nodes.web_view` feeds it the events' values and the names of the running nodes.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..nodes.parameters import CASE_KEYS, effective_case

__all__ = ['CaseWatch', 'Verdict']

@dataclass(frozen=True)
class Verdict:
    """What the page does: ``'ok'`` (nothing), ``'follow'`` (take ``case``), ``'split'`` (stop
    collecting; ``text`` says which node runs what)."""
    action: str
    case: tuple[str, int] | None = None
    text: str = ''


class CaseWatch:
    """The case each case node last reported. A node that never reported is taken to run
    ``start``, the session's case (the page's own at its start): it started before the page
    listened and was never set since.

    Reports carry the time their event was stamped [ns]: an older one than a node's last is
    dropped (an event that arrives after the answer of a newer set)."""

    def __init__(self, start: tuple[str, int] = ('', -1)) -> None:
        self.start = start
        self.reported: dict[str, tuple[str, int]] = {}
        self._set: set[str] = set()   # nodes whose last report was a set while running
        self._stamp: dict[str, int] = {}
        self._half: dict[str, dict] = {}   # a declaration seen without both parameters yet

    def report(self, node: str, values: dict, declared: bool = False,
               stamp_ns: int | None = None) -> None:
        """``node`` reported ``values`` ({name: value} of :data:`CASE_KEYS`): set while it ran,
        or ``declared`` at its start (its whole case: both parameters, maybe in two events)."""
        values = {k: v for k, v in values.items() if k in CASE_KEYS}
        if not values:
            return
        if stamp_ns is not None:
            if stamp_ns < self._stamp.get(node, -1):
                return
            self._stamp[node] = stamp_ns
        if declared:
            values = self._half.pop(node, {}) | values
            if len(values) < len(CASE_KEYS):   # half a case: wait for the other parameter
                self._half[node] = values
                return
            self._set.discard(node)
            self.reported[node] = effective_case(values, ('', -1))
            return
        self._set.add(node)
        self.reported[node] = effective_case(values, self.reported.get(node, self.start))

    def verdict(self, page: tuple[str, int], running: set[str] | None = None,
                blind: bool = False) -> Verdict:
        """Against the page's ``(case, random_case_seed)``; ``running``: the case nodes on the
        graph now (None: every node that reported); ``blind``: the page hides case names."""
        nodes = set(self.reported) if running is None else set(running)
        runs = {n: self.reported.get(n, self.start) for n in nodes}
        off = {n: c for n, c in runs.items() if _key(c) != _key(page)}
        if not off:
            return Verdict('ok')
        cases = {_key(c) for c in off.values()}
        if len(cases) == 1 and set(off) == nodes and set(off) <= self._set:
            return Verdict('follow', next(iter(off.values())))
        on_page = sorted(nodes - set(off))
        parts = [f'{n} on {_describe(c, blind)}' for n, c in sorted(off.items())]
        if on_page:
            parts.append(f"{', '.join(on_page)} on the page's case")
        return Verdict('split', text='; '.join(parts))


def _key(c: tuple[str, int]) -> tuple[str, int]:
    """The case ``c`` runs: no case ('': the node's own parameters) is the default scene, the
    case a session names ``default`` (the recorder's label when nothing changed the scene)."""
    return ('', -1) if c == ('default', -1) else c


def _describe(c: tuple[str, int], blind: bool) -> str:
    if c[1] >= 0:
        return 'a random case'
    if blind:   # the trainee sees the page: no case name while the session is blind
        return 'another case'
    return f'case {c[0]}' if c[0] else 'the default scene'
