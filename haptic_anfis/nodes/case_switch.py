"""One case choice sent to the running case nodes, followed until each has answered.

The browser page's instructor chooses a case (or a blind one): the loop nodes must all switch,
or none, since a trainee pressing on one case while the page scores another learns the wrong
lesson. :class:`CaseSwitch` sets ``case`` / ``random_case_seed`` on every case node of the
graph (``/NAME/set_parameters_atomically``: one answer, and the node's callback sees the
parameters together), waiting for a node's parameter service to be discovered
rather than skipping it, and collects the answers (a node answers once its case is loaded);
:meth:`CaseSwitch.poll`, called from the owner's timer, returns the :class:`SwitchOutcome` once
every node has answered or the time is up. The owner then switches itself, or sends
:meth:`CaseSwitch.revert` to the nodes that may have switched. Nothing here blocks: the owner's
executor delivers the answers.
"""
from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ['CaseSwitch', 'SwitchOutcome']


@dataclass
class SwitchOutcome:
    """What the case nodes answered: ``switched`` (names), ``refused`` ({name: reason}),
    ``silent`` (names that did not answer in time), ``absent`` (case nodes not in the graph)."""
    switched: list[str] = field(default_factory=list)
    refused: dict[str, str] = field(default_factory=dict)
    silent: list[str] = field(default_factory=list)
    absent: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Every case node in the graph switched."""
        return not self.refused and not self.silent

    def describe(self) -> str:
        """One line for the page: who switched, who refused (why), who did not answer."""
        parts = []
        if self.switched:
            parts.append('switched: ' + ', '.join(self.switched))
        parts += [f'{n} refused: {r}' for n, r in self.refused.items()]
        if self.silent:
            parts.append('no answer from ' + ', '.join(self.silent))
        if self.absent:
            parts.append('not running: ' + ', '.join(self.absent))
        return '; '.join(parts) or 'no case node running'


class CaseSwitch:
    """Set ``params`` (rclpy ``Parameter`` s) on the nodes ``names`` of ``node`` 's graph.

    A name is in the switch when the graph lists a node of that name (any namespace) or its
    parameter service is already discovered; the others are ``absent``. ``clients``: the
    owner's ``{name: SetParametersAtomically client}`` cache (filled here). ``timeout`` [s] from ``now``
    (monotonic): a node that has not answered by then is ``silent``.
    """

    def __init__(self, node, names, params, clients: dict, now: float, timeout: float) -> None:
        self.node, self.params, self.clients = node, list(params), clients
        self.deadline = now + float(timeout)
        listed = {n for n, _ in node.get_node_names_and_namespaces()}
        self.futures: dict[str, object] = {}
        self.absent: list[str] = []
        for name in names:
            if name in listed or self._client(name).service_is_ready():
                self.futures[name] = None   # to send once its service is discovered
            else:
                self.absent.append(name)
        self.outcome: SwitchOutcome | None = None

    def _client(self, name: str):
        from rcl_interfaces.srv import SetParametersAtomically
        cli = self.clients.get(name)
        if cli is None:
            cli = self.clients[name] = self.node.create_client(
                SetParametersAtomically, f'/{name}/set_parameters_atomically')
        return cli

    def _send(self, name: str, params):
        from rcl_interfaces.srv import SetParametersAtomically
        return self._client(name).call_async(SetParametersAtomically.Request(
            parameters=[p.to_parameter_msg() for p in params]))

    def poll(self, now: float) -> SwitchOutcome | None:
        """Send to the nodes whose service has appeared; the outcome once every node answered
        or ``now`` is past the deadline (None before; the same outcome after)."""
        if self.outcome is not None:
            return self.outcome
        for name, fut in self.futures.items():
            if fut is None and self._client(name).service_is_ready():
                self.futures[name] = self._send(name, self.params)
        done = all(f is not None and f.done() for f in self.futures.values())
        if not done and now < self.deadline:
            return None
        out = SwitchOutcome(absent=list(self.absent))
        for name, fut in self.futures.items():
            if fut is None or not fut.done():
                out.silent.append(name)
                continue
            try:
                res = fut.result().result
            except Exception as exc:   # a service error
                out.refused[name] = str(exc) or type(exc).__name__
                continue
            if res.successful:
                out.switched.append(name)
            else:
                out.refused[name] = res.reason or 'refused'
        self.outcome = out
        return out

    def revert(self, params) -> list[str]:
        """Send ``params`` (the case before) to every node that may have switched: those that
        said so and those that had not answered (their request may still land). Returns their
        names. Nothing is awaited: the owner reports the failed switch, not the revert."""
        if self.outcome is None:
            return []
        names = [n for n in self.outcome.switched + self.outcome.silent
                 if self.futures.get(n) is not None]
        for name in names:
            self._send(name, params)
        return names
