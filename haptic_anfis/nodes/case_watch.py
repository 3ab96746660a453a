"""The case each case node reports on ``/parameter_events``, against the browser page's case.

The page's case choice switches every running case node together (:mod:`.case_switch`); a case
set on one node from outside (``ros2 param set /force_server case normal``) switches that node
alone, and the trainee would then press on one case while the page draws and scores another.
:class:`CaseWatch` keeps the case each node last reported (set on it while it runs, or declared
at its start) and says what the page must do: nothing (every node that reported is on the page's
case), follow (every running case node was set, from outside, to one other case: the page takes
it too), or stop collecting and say which node is on which case (split).

No ROS here: :mod:`.web_view` feeds it the events' values and the names of the running nodes.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ['CASE_KEYS', 'CaseWatch', 'Verdict', 'effective_case']

#: the parameters that say a node's case
CASE_KEYS = ('case', 'random_case_seed')


def effective_case(new: dict, current: tuple[str, int]) -> tuple[str, int]:
    """The ``(case, random_case_seed)`` a node runs after ``new`` ({name: value} of
    :data:`CASE_KEYS`) is set on it while it ran ``current``: a name set alone ends the random
    draw, a seed set alone replaces the name (the rule of ``_case.declare_case``)."""
    n = new.get('case', current[0])
    s = new.get('random_case_seed', current[1])
    if 'case' in new and n and 'random_case_seed' not in new:
        s = -1
    if 'random_case_seed' in new and s >= 0 and 'case' not in new:
        n = ''
    return n, s


@dataclass(frozen=True)
class Verdict:
    """What the page does: ``'ok'`` (nothing), ``'follow'`` (take ``case``), ``'split'`` (stop
    collecting; ``text`` says which node runs what)."""
    action: str
    case: tuple[str, int] | None = None
    text: str = ''


class CaseWatch:
    """The case each case node last reported. Nodes that never reported are taken to run the
    page's case (a node started before the page, never set since)."""

    def __init__(self) -> None:
        self.reported: dict[str, tuple[str, int]] = {}
        self._set: set[str] = set()   # nodes whose last report was a set while running

    def report(self, node: str, values: dict, declared: bool = False) -> None:
        """``node`` reported ``values`` ({name: value} of :data:`CASE_KEYS`): set while it ran,
        or ``declared`` at its start (its whole case)."""
        values = {k: v for k, v in values.items() if k in CASE_KEYS}
        if not values:
            return
        # a node declares its two parameters one at a time: each event adds to the last
        self.reported[node] = effective_case(values, self.reported.get(node, ('', -1)))
        (self._set.discard if declared else self._set.add)(node)

    def verdict(self, page: tuple[str, int], running: set[str] | None = None,
                blind: bool = False) -> Verdict:
        """Against the page's ``(case, random_case_seed)``; ``running``: the case nodes on the
        graph now (None: every node that reported); ``blind``: the page hides case names."""
        nodes = set(self.reported) if running is None else set(running)
        off = {n: c for n, c in self.reported.items() if n in nodes and _key(c) != _key(page)}
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
