"""One case choice sent to the running case nodes, followed until each has answered.

The browser page's instructor chooses a case (or a blind one): the loop nodes must all switch,
or none, since a trainee pressing on one case while the page scores another learns the wrong
lesson. :class:`CaseSwitch` sets ``case`` / ``random_case_seed`` on every case node of the
graph (``/NAME/set_parameters_atomically``: one answer, and the node's callback sees the
parameters together), waiting for a node's parameter service to be discovered rather than
skipping it, and collects the answers (a node answers once its case is loaded). The nodes go in
phases: the next phase is asked only when every node of the one before has switched, so the
recorder (last: its case is a label in the bag) never records a choice the loop refused.
:meth:`CaseSwitch.poll`, called from the owner's timer, returns the :class:`SwitchOutcome` once
every node has answered or the time is up. The owner then switches itself, or sends
:meth:`CaseSwitch.revert` to the nodes that may have switched and follows the revert the same
way. Nothing here blocks: the owner's executor delivers the answers.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import rclpy.client
import rclpy.task
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.parameter import Parameter

__all__ = ['CaseSwitch', 'SwitchOutcome']


@dataclass
class SwitchOutcome:
    """What the case nodes answered: ``switched`` (names), ``refused`` ({name: reason}),
    ``silent`` (names that did not answer in time), ``absent`` (case nodes not in the graph),
    ``not_asked`` (nodes of a later phase, after a phase that failed)."""
    switched: list[str] = field(default_factory=list)
    refused: dict[str, str] = field(default_factory=dict)
    silent: list[str] = field(default_factory=list)
    absent: list[str] = field(default_factory=list)
    not_asked: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Every case node in the graph switched."""
        return not self.refused and not self.silent and not self.not_asked

    def describe(self) -> str:
        """One line for the page: who switched, who refused (why), who did not answer."""
        parts = []
        if self.switched:
            parts.append('switched: ' + ', '.join(self.switched))
        parts += [f'{n} refused: {r}' for n, r in self.refused.items()]
        if self.silent:
            parts.append('no answer from ' + ', '.join(self.silent))
        if self.not_asked:
            parts.append('not asked: ' + ', '.join(self.not_asked))
        if self.absent:
            parts.append('not running: ' + ', '.join(self.absent))
        return '; '.join(parts) or 'no case node running'


class CaseSwitch:
    """Set ``values`` ({parameter: value}) on the nodes of ``phases`` (names, phase by phase) of
    ``node`` 's graph; ``per_node``: {name: values} a node gets instead (the falcon driver: its
    force scale for the case).

    A name is in the switch when the graph lists a node of that name (any namespace) or its
    parameter service is already discovered; the others are ``absent``. ``clients``: the
    owner's ``{name: SetParametersAtomically client}`` cache (filled here). ``timeout`` [s]
    per phase, from ``now`` (monotonic) for the first: a node that has not answered by then is
    ``silent``. ``running``: every node named runs (none is ``absent``).
    """

    def __init__(self, node, phases: Sequence[Sequence[str]], values: dict, clients: dict,
                 now: float, timeout: float, running: bool = False,
                 per_node: dict[str, dict] | None = None) -> None:
        self.node, self.values, self.clients = node, dict(values), clients
        self.per_node = dict(per_node or {})
        self.timeout = float(timeout)
        self.deadline = now + self.timeout
        listed = {n for n, _ in node.get_node_names_and_namespaces()}
        if running:   # the caller knows they run (e.g. one said so): wait for every one
            listed |= {n for ph in phases for n in ph}
        self.phases: list[list[str]] = []
        self.absent: list[str] = []
        for names in phases:
            here = [n for n in names if n in listed or self._client(n).service_is_ready()]
            self.absent += [n for n in names if n not in here]
            if here:
                self.phases.append(here)
        self.futures: dict[str, object] = {n: None for n in self.phases[0]} \
            if self.phases else {}   # the current phase's: None until its service is there
        self.phase = 0
        self.outcome: SwitchOutcome | None = None
        self._done = SwitchOutcome()
        self._sent: set[str] = set()   # the nodes asked (a revert goes only to them)

    def _client(self, name: str) -> rclpy.client.Client:
        cli = self.clients.get(name)
        if cli is None:
            cli = self.clients[name] = self.node.create_client(
                SetParametersAtomically, f'/{name}/set_parameters_atomically')
        return cli

    def _send(self, name: str) -> rclpy.task.Future:
        """The request's future (rclpy ``Future``)."""
        values = self.per_node.get(name, self.values)
        return self._client(name).call_async(SetParametersAtomically.Request(
            parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]))

    def poll(self, now: float) -> SwitchOutcome | None:
        """Send to the nodes whose service has appeared; the outcome once every node answered
        or a phase's time is up (None before; the same outcome after)."""
        while self.outcome is None:
            for name, fut in self.futures.items():
                if fut is None and self._client(name).service_is_ready():
                    self.futures[name] = self._send(name)
            done = all(f is not None and f.done() for f in self.futures.values())
            if not done and now < self.deadline:
                return None
            self._collect()
            last = self.phase + 1 >= len(self.phases)
            if not self._done.ok or last:
                self.outcome = SwitchOutcome(
                    self._done.switched, self._done.refused, self._done.silent,
                    list(self.absent), [n for ph in self.phases[self.phase + 1:] for n in ph])
                break
            self.phase += 1   # every node of this phase switched: ask the next
            self.futures = {n: None for n in self.phases[self.phase]}
            self.deadline = now + self.timeout
        return self.outcome

    def _collect(self) -> None:
        """The current phase's answers into ``_done``."""
        d = self._done
        for name, fut in self.futures.items():
            if fut is None or not fut.done():
                d.silent.append(name)
                continue
            try:
                res = fut.result().result
            except Exception as exc:   # a service error
                d.refused[name] = str(exc) or type(exc).__name__
                continue
            if res.successful:
                d.switched.append(name)
            else:
                d.refused[name] = res.reason or 'refused'
        self._sent |= {n for n, f in self.futures.items() if f is not None}

    def revert(self, values: dict, now: float,
               per_node: dict[str, dict] | None = None) -> CaseSwitch | None:
        """Send ``values`` (the case before; ``per_node`` as for a switch) to every node that may
        have switched: those that said so and those that had not answered (their request lands
        before the revert). Returns
        the revert as a switch of its own, to follow as this one (its nodes: ``names``), or None
        when no node was asked."""
        if self.outcome is None:
            return None
        names = [n for n in self.outcome.switched + self.outcome.silent if n in self._sent]
        if not names:
            return None
        return CaseSwitch(self.node, [names], values, self.clients, now, self.timeout,
                          running=True, per_node=per_node)

    @property
    def names(self) -> list[str]:
        """The nodes this switch asks (every phase)."""
        return [n for ph in self.phases for n in ph]
