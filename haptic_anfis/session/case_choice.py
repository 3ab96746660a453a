"""The browser page's case against the loop nodes' cases: the instructor's choice, a restarted
node given the page's case again, and a case set on a node from outside the page.

A trainee pressing on one case while the page scores another learns the wrong lesson, so the
loop nodes switch together or not at all. :class:`CaseChoices` is the page's side of that:

- the instructor chooses a case (or a blind one): every running case node is asked, phase by
  phase (:class:`~.case_switch.CaseSwitch`); all switched, the page takes the case; one refused or
  silent, the nodes that may have switched are sent back and a running exam starts afresh on the
  case kept; a node that cannot be sent back stops the exam (the loop may be split);
- a case node restarted in a new process comes back on the session's first case: after a choice
  on this page it is given the page's;
- a case set on a node from outside (``ros2 param set``) is seen in its parameter events
  (:class:`~.case_watch.CaseWatch`): the page follows when every running case node took one
  case, else it says which node runs what and nothing is collected until they agree.

Nothing is collected while a choice is being loaded or the nodes' cases differ (:attr:`busy`).
With the session's case, the falcon driver's ``force_scale`` follows the case chosen (each case
has its own tissue -> device force mapping, :mod:`haptic_anfis.cases.force_mapping`): the driver
is asked with the loop's first phase, so a case is never rendered with another case's scale.

No ROS here: the owner (:mod:`haptic_anfis.nodes.web_view`) gives it a :class:`Graph` (start a
switch over ROS, set the page's own case parameters, the case nodes running) and a :class:`Page`
(say a line, show the dropdown's entry, start the exam afresh or stop it), and calls it from
one thread.
"""
from __future__ import annotations

import random
import time
from collections import deque
from dataclasses import dataclass, replace
from typing import Callable, Protocol, Sequence

from ..cases import resolve_case
from ..cases.force_mapping import case_force_mapping
from ..cases.library import DEFAULT_CASE, library
from ..view.app import BLIND
from ..nodes.parameters import CASE_KEYS
from .case_watch import CaseWatch

__all__ = ['CASE_PHASES', 'CASE_NODE_NAMES', 'DRIVER', 'CaseChoices', 'Graph', 'Page',
           'SWITCHING', 'PAGE_SWITCHING', 'PAGE_SPLIT', 'case_force_scale']

#: nodes whose case the instructor's choice switches (those that are running), in phases: the
#: recorder (its case is the bag's label) only once every node of the loop has switched
CASE_PHASES = (('contact_detector', 'force_server', 'visualizer', 'examiner'), ('recorder',))
CASE_NODE_NAMES = frozenset(n for ph in CASE_PHASES for n in ph)
#: the node given the chosen case's force scale, with the loop's phase
DRIVER = 'falcon_driver'
#: what the console says while the loop nodes load a case
SWITCHING = 'switching to {} ...'
#: what the trainee's page says meanwhile (no case name: a blind draw stays blind)
PAGE_SWITCHING = 'the case is being switched: nothing is collected meanwhile'
#: what the trainee's page says while the loop nodes' cases differ
PAGE_SPLIT = 'the loop nodes are not on one case: nothing is collected until the instructor ' \
    'chooses one'


def case_force_scale(max_force: float) -> Callable[[str, int], float]:
    """``scale(case, random_case_seed)``: the driver's force scale for that case (the drawn one
    for a seed, the default case for neither) against the driver's clamp ``max_force`` [N]
    (:func:`~haptic_anfis.cases.force_mapping.case_force_mapping`)."""
    def scale(name: str, seed: int) -> float:
        case = resolve_case(name, seed) or library().get(DEFAULT_CASE)
        return case_force_mapping(case, max_force).force_scale
    return scale


class Switch(Protocol):
    """A case switch in progress (:class:`~.case_switch.CaseSwitch`)."""
    values: dict

    def poll(self, now: float): ...

    def revert(self, values: dict, now: float, per_node: dict | None = None): ...


class Graph(Protocol):
    """The ROS side the choices act through."""

    def switch(self, phases: Sequence[Sequence[str]], values: dict, per_node: dict,
               running: bool = False) -> Switch:
        """Start setting ``values`` ({parameter: value}) on the nodes of ``phases``, and
        ``per_node[name]`` on ``name`` instead where given."""

    def set_own(self, values: dict) -> str:
        """Set the page's own case parameters together: '' done, else the reason refused."""

    def own(self) -> tuple[str, int]:
        """The page's ``(case, random_case_seed)``."""

    def running_nodes(self) -> set[str]:
        """The names of the nodes in the graph now."""

    def now_ns(self) -> int:
        """The node's clock [ns] (the time parameter events are stamped with)."""

    def log(self, level: str, msg: str) -> None:
        """``msg`` in the node's log at ``level`` ('info', 'warning', 'error')."""


class Page(Protocol):
    """The page's side: :class:`~haptic_anfis.view.live.LivePage`."""
    blind: bool
    running: bool
    name: str

    def tell(self, msg: str, page: str | None = None) -> None: ...

    def show_case_choice(self, entry: str) -> None: ...

    def restart(self) -> None: ...

    def stop_exam(self, page_line: str) -> None: ...


@dataclass(frozen=True)
class _Choice:
    """The instructor's case choice while the loop nodes load it: the switch, what the page
    calls it, whether it is blind, its dropdown entry, the case values before (to go back to)
    and the dropdown entry before (a case name or the blind entry); ``failed``: the page's line
    once the choice was refused and ``switch`` is its revert."""
    switch: Switch
    label: str
    blind: bool
    entry: str
    before: dict
    shown: str
    failed: str = ''
    resync: bool = False   # a restarted node given the page's case (no choice of its own)


class CaseChoices:
    """The page's case against the loop nodes' (module docstring).

    Args:
        graph, page: the owner's sides (:class:`Graph`, :class:`Page`).
        timeout: how long each phase of a switch waits for the nodes [s].
        requests: the owner's queue of ``(what, arg)`` handled on its timer; a restarted node
            is queued there.
        force_scale: ``force_scale(case, seed)``: the falcon driver's force scale for that case
            (None: the driver's scale is not the page's to set, e.g. the user set it).
    """

    def __init__(self, graph: Graph, page: Page, timeout: float, requests: deque,
                 force_scale: Callable[[str, int], float] | None = None) -> None:
        self.graph, self.page, self.timeout = graph, page, float(timeout)
        self.requests, self.force_scale = requests, force_scale
        self.watch = CaseWatch(graph.own())
        self.switch: _Choice | None = None   # the choice while the loop nodes load it
        self.split = ''    # which node runs what, while the loop nodes' cases differ
        self.chosen = False   # the instructor chose a case here: a restarted node needs it
        self.pids: dict[str, int] = {}   # case node -> the process it last said it runs in
        self.checked = time.monotonic()

    @property
    def busy(self) -> bool:
        """A choice is being loaded or the loop nodes' cases differ: nothing is collected."""
        return self.switch is not None or bool(self.split)

    # -- what the owner hears ---------------------------------------------------------------

    def on_status(self, name, pid) -> None:
        """A node said it runs in process ``pid``: a case node in a new process (restarted
        after it died) comes back on the session's first case, the driver on its first force
        scale; after a choice here they are given the page's."""
        followed = CASE_NODE_NAMES | ({DRIVER} if self.force_scale is not None else set())
        if name not in followed or not isinstance(pid, int):
            return
        old, self.pids[name] = self.pids.get(name), pid
        if old is not None and old != pid and self.chosen:
            self.requests.append(('restarted', name))

    def tick(self) -> None:
        """Each frame: follow a choice in progress, else look again at the nodes every second
        (one that left or came back)."""
        if self.switch is not None:
            self.follow()
        elif time.monotonic() - self.checked > 1.0:
            self.check()

    def reported(self, node: str, values: dict, declared: bool, stamp_ns: int) -> None:
        """A case node's case parameters declared (at its start) or set (while it runs)."""
        self.watch.report(node, values, declared, stamp_ns)
        self.check()

    # -- the instructor's choice ------------------------------------------------------------

    def choose(self, name: str) -> None:
        """The instructor chose ``name`` (or the blind entry): ask the running case nodes to
        switch; the page follows once they all have (:meth:`follow`). One choice at a time.

        Raises:
            ValueError: a choice is still being loaded.
        """
        if self.switch is not None:
            self.page.show_case_choice(self.switch.entry)   # the dropdown shows the pending one
            raise ValueError(f'{self.switch.label} is still being loaded; choose again when '
                             'it is done')
        blind = name == BLIND
        # both, set together: every node's parameters then say what it runs (a seed alone
        # would leave the old name readable with `ros2 param get`)
        values = {'case': '' if blind else name,
                  'random_case_seed': random.SystemRandom().randrange(2**31) if blind else -1}
        before, shown = self._current()
        self.switch = _Choice(
            self.graph.switch(self._phases(), values, self._driver(values)),
            'a blind random case' if blind else f'case {name}', blind, name, before, shown)
        self.page.tell(SWITCHING.format(self.switch.label), page=PAGE_SWITCHING)
        self.follow()

    def resync(self, name: str) -> None:
        """Set the page's case on the restarted node ``name`` (after a choice in progress, if
        one is: asked again then); no samples meanwhile, as for a choice."""
        if self.switch is not None:
            self.requests.append(('restarted', name))   # after the one in progress
            return
        values, entry = self._current()
        per_node = self._driver(values) if name == DRIVER else {}
        ch = _Choice(self.graph.switch([[name]], values, per_node, running=True),
                     f'{name} (restarted) back on the case chosen', self.page.blind, entry,
                     values, entry, resync=True)
        self.switch = ch
        self.page.tell(SWITCHING.format(ch.label), page=PAGE_SWITCHING)

    def _rescale(self, entry: str, what: str) -> None:
        """The driver given the force scale of the page's case (set from outside on the case
        nodes, which the driver is not); no samples until it answered, a refusal stops the
        exam (the hand would feel the case at another case's scale)."""
        values = dict(zip(CASE_KEYS, self.graph.own()))
        self.switch = _Choice(self.graph.switch([[DRIVER]], values, self._driver(values),
                                                running=True),
                              f"{DRIVER} on {what}'s force scale", self.page.blind, entry,
                              values, entry, resync=True)

    def follow(self) -> None:
        """The case nodes' answers: all switched, the page switches too; one refused or silent,
        the others are sent back to the case before (no samples collected until they answered),
        then the exam starts afresh on it; a node that cannot be sent back stops the exam.
        ``switch`` changes once, at the end (other threads read it: never None in between)."""
        ch = self.switch
        nxt = None   # what follows: the revert of a refused choice, else nothing
        try:
            out = ch.switch.poll(time.monotonic())
            if out is not None:   # what they run now (their events may come later: older)
                now = self.graph.now_ns()
                for name in out.switched:
                    if name in CASE_NODE_NAMES:
                        self.watch.report(name, ch.switch.values, stamp_ns=now)
            if out is None:
                nxt = ch
            elif ch.resync:   # a restarted node given the page's case
                self._resynced(ch, out)
            elif ch.failed:   # the revert of a refused choice has been answered
                self._reverted(ch, out)
            else:
                nxt = self._answered(ch, out)
        finally:   # an error ends the choice (the owner says it on the page)
            self.switch = nxt
        if nxt is None:   # the choice's own line stays (it says what it left split, if any)
            self.check(quiet=True)

    def _answered(self, ch: _Choice, out) -> _Choice | None:
        """Every case node answered ``ch``: the page switches, or the choice is refused and the
        nodes that may have switched are sent back (returned: the revert to follow)."""
        # ours, in one set: the page's own case callback switches once
        why = self.graph.set_own(ch.switch.values) if out.ok else None
        if why == '':
            self.page.blind, self.chosen = ch.blind, True
            self.graph.log('info', f'{ch.label}: {out.describe()}')
            self.page.show_case_choice(ch.entry)
            self.page.tell(('blind random case chosen' if ch.blind else ch.label)
                           + f' ({out.describe()})')
            return None
        why = out.describe() if why is None else f'the page cannot show it: {why}'
        msg = f'{ch.label} NOT chosen: {why}'
        self.graph.log('error', msg)
        self.page.show_case_choice(ch.shown)
        back = ch.switch.revert(ch.before, time.monotonic(), self._driver(ch.before))
        if back is None:
            self._reverted(replace(ch, failed=msg), None)
            return None
        self.page.tell(f'{msg}; sending back: {", ".join(back.names)} ...')
        return replace(ch, switch=back, failed=msg, label=f'the return to {_kept(ch)}')

    def _resynced(self, ch: _Choice, out) -> None:
        """The restarted node answered: on the page's case again, or (refused, silent) the
        loop is split: the exam stops, as when a revert fails."""
        if out.ok:
            self._say(f'{ch.label}: {out.describe()}')
            return
        self._stop_split(ch, f'{ch.label} FAILED ({out.describe()})')

    def _reverted(self, ch: _Choice, out) -> None:
        """A refused choice's end: the nodes sent back answered (``out``; None: none to send
        back). The samples of the attempt were not collected: a running exam starts afresh on
        the case kept; a node that could not be sent back stops it (the loop may be split)."""
        msg = ch.failed
        if out is not None and not out.ok:
            self._stop_split(ch, f'{msg}; sending back FAILED ({out.describe()})')
            return
        if out is not None:
            msg += f'; sent back: {", ".join(out.switched)}'
        if self.page.running:
            self.page.restart()
            msg += f'; the exam starts afresh on {_kept(ch)}'
        self.page.tell(msg)

    def _stop_split(self, ch: _Choice, msg: str) -> None:
        """A node could not be put on the page's case: the loop may be split between two, so
        the exam stops (nothing more collected) and the page says ``msg`` and why."""
        msg += f': the loop may not be on {_kept(ch)}; the exam is stopped: choose a case again'
        self.graph.log('error', msg)
        self.page.stop_exam(msg)

    # -- cases set from outside the page ----------------------------------------------------

    def check(self, quiet: bool = False) -> None:
        """The cases the loop nodes reported against the page's (not during a choice: its own
        answers decide): all on it, the page goes on (collecting again after a split); every
        running one set from outside to one other case, the page takes it and the exam starts
        afresh; else samples stop until they agree, and the page says which node runs what."""
        if self.switch is not None:
            return
        self.checked = time.monotonic()
        running = self.graph.running_nodes() & CASE_NODE_NAMES
        v = self.watch.verdict(self.graph.own(), running, self.page.blind)
        if v.action == 'follow':
            why = self.graph.set_own(dict(zip(CASE_KEYS, v.case)))
            if not why:   # the page loads it at the next frame (its own case callback)
                self.page.blind, self.chosen, self.split = v.case[1] >= 0, True, ''
                entry = BLIND if self.page.blind else v.case[0] or 'default'
                self.page.show_case_choice(entry)
                what = 'a random case' if self.page.blind else f'case {entry}'
                self._say(f'every loop node was switched to {what} outside this page: the page '
                          'follows, the exam starts afresh')
                if self.force_scale is not None and DRIVER in self.graph.running_nodes():
                    self._rescale(entry, what)
                return
            text = f'the page cannot show it ({why})'
            if text != self.split:
                self.split = text  # before it is said: whoever reads the line sees the state
                self._say(f'every loop node was switched to another case outside this page, but '
                          f'{text}. Nothing is collected: choose a case here', error=True)
            return
        if v.action == 'split' and v.text != self.split:
            self.split = v.text  # before it is said (a reader of the line saw it collecting)
            if not quiet:
                self._say(f'the loop nodes are on different cases (set outside this page): '
                          f'{v.text}. Nothing is collected: choose a case here to put them on '
                          'one', error=True)
        elif v.action == 'ok' and self.split:
            self.split = ''
            if not quiet and self.page.running:
                self._say("every loop node is on the page's case again: collecting again")

    # -- helpers ----------------------------------------------------------------------------

    def _say(self, msg: str, error: bool = False) -> None:
        """``msg`` in the log and to the instructor; an error says on the trainee's page that
        nothing is collected (without the node and case names)."""
        self.graph.log('warning' if error else 'info', msg)
        self.page.tell(msg, page=PAGE_SPLIT if error else None)

    def _current(self) -> tuple[dict, str]:
        """The page's case values and its dropdown entry (a case name or the blind entry)."""
        return (dict(zip(CASE_KEYS, self.graph.own())),
                BLIND if self.page.blind else (self.page.name or 'default'))

    def _phases(self) -> list[list[str]]:
        """The switch's phases: the driver with the loop when its scale follows the case."""
        first, *rest = (list(ph) for ph in CASE_PHASES)
        return [first + ([DRIVER] if self.force_scale is not None else []), *rest]

    def _driver(self, values: dict) -> dict:
        """The driver's own values for the case ``values``: its force scale ({} when the page
        does not set it)."""
        if self.force_scale is None:
            return {}
        return {DRIVER: {'force_scale': float(self.force_scale(values['case'],
                                                              values['random_case_seed']))}}


def _kept(ch: _Choice) -> str:
    return 'its blind case' if ch.shown == BLIND else f'case {ch.shown}'
