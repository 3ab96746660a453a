"""Runner 2: one process per node under the supervisor (``haptic-anfis launch``).

1. Readiness: the recorder and the other nodes start first; the falcon driver starts once each of
   them has said ``started`` on ``session/status``; the session is ready when the driver says
   ``ready`` (a force command arrived). ``duration`` counts from then.
2. Respawn: a node that dies is started again, at most ``max_restarts`` times, while the others
   keep running; each death and restart is printed and published on ``session/events``. The
   recorder restarts into ``BAG.restartN``. The falcon driver is never restarted: its death
   stops the session, as does a node past its restart limit, or any death with ``no_respawn``.
3. Stop: at the end of ``duration`` or Ctrl-C the nodes are stopped in reverse start order with
   SIGINT (the driver zeroes the force first, the recorder closes its bag last).
"""
from __future__ import annotations

import os
import secrets
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..bag.topics import ALL_LOOP_TOPICS
from ..nodes.session import EVENTS_TOPIC, STATUS_TOPIC, SessionMonitor
from ..realtime.processes import (HOLD_FOR_RECORDER, RECORDED_TOPICS, SESSION_CHECKED, VIEW_NODES,
                                  Supervisor, graph_cores, node_env, on_stop_signals,
                                  recorder_arguments, renamed_output, restore_signals)
from ..view.doors import TOKEN_ENV
from .domain import refuse_shared_domain
from .spec import CASE_NODES, SessionSpec, recorder_settings

__all__ = ['ProcessSession', 'ProcessResult', 'ORDER', 'NO_RESPAWN', 'recorded_topics']

#: start order: consumers before producers, the device last (it starts publishing poses at once)
ORDER = ('recorder', 'trainer', 'force_server', 'contact_detector', 'visualizer', 'web_view',
         'player', 'examiner', 'falcon_driver')
#: never restarted: the device owner (a restart would re-home a real Falcon mid-session)
NO_RESPAWN = ('falcon_driver',)


def recorded_topics() -> list[str]:
    """What the launched recorder records: every loop topic, as the one-process runner records
    (:data:`~haptic_anfis.bag.topics.ALL_LOOP_TOPICS`: the applied force and velocity too), and
    the session's own status and events."""
    return [*ALL_LOOP_TOPICS, STATUS_TOPIC, EVENTS_TOPIC]


@dataclass
class ProcessResult:
    """How a launched session ended: ``failed`` (node, code) that stopped it, ``codes`` every
    node's exit code at the stop."""
    failed: list[tuple[str, int]] = field(default_factory=list)
    codes: dict[str, int] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.failed and all(c == 0 for c in self.codes.values())


class ProcessSession:
    """The nodes of ``spec`` as separate processes. ``node_args``: extra ``--ros-args`` per node
    (e.g. the driver's trace path). Call :meth:`run` once."""

    def __init__(self, spec: SessionSpec, node_args: dict[str, list[str]] | None = None):
        self.spec = spec
        self.extra: dict[str, list[str]] = {n: (spec.case_arguments() if n in CASE_NODES
                                                else []) for n in spec.nodes}
        if 'falcon_driver' in self.extra:   # the case's force scale (cases/force_mapping.py)
            self.extra['falcon_driver'] += spec.driver_arguments()
        for n, a in (node_args or {}).items():
            self.extra.setdefault(n, []).extend(a)
        if spec.view:   # --view: the browser page as one more node
            self.extra.setdefault('web_view', spec.case_arguments()).extend(
                spec.view_arguments(controls=True))
        if 'web_view' in self.extra and not spec.console_token_file:
            # one console token for the session: a web_view the launch restarts keeps the
            # instructor's address (the node takes it from the environment it inherits)
            os.environ.setdefault(TOKEN_ENV, secrets.token_urlsafe(24))
        self.notes: list[str] = []
        self.recorded: list[str] = []  # the topics the session's recorder records
        if spec.record:
            topics, self.notes = recorder_settings(spec, recorded_topics())
            self.recorded = topics
            self.extra['recorder'] = [*spec.recorder_case_arguments(),
                                      *self.extra.get('recorder', []),
                                      *recorder_arguments(spec.record, topics)]
        if spec.enclave_root:
            root = '/' + spec.enclave_root.strip('/')
            for n in self.extra:
                self.extra[n] += ['--enclave', f'{root}/{n}']
        if 'falcon_driver' in self.extra and not {'force_server', 'contact_detector'} <= set(
                self.extra):
            # no force source in this session: the simulated hand must not wait for one
            self.extra['falcon_driver'] += ['-p', 'hold_until_force:=false']
        self.order = sorted(self.extra, key=lambda n: ORDER.index(n) if n in ORDER
                            else len(ORDER))
        self.result = ProcessResult()
        self.history: list[dict] = []
        #: {node: how it is scheduled once ready} (``--graph-priority``), in words
        self.graph_scheduling: dict[str, str] = {}
        self._replay_pending = False
        self._replay_known: set[bytes] = set()
        self.mon = self.sup = None
        self.t0 = time.monotonic()

    # -- the run ------------------------------------------------------------------------------
    def run(self) -> ProcessResult:
        """Check, start, supervise until the end, stop in order. Prints as it goes.

        Raises:
            SessionError / CaseError / ParameterError: bad input (nothing started).
        """
        s = self.spec
        s.check()
        for n in self.notes:
            print(f'recorder: {n}', flush=True)
        env = node_env(s.domain_id, localhost=s.localhost)
        env[SESSION_CHECKED] = '1'
        log_dir = Path(s.log_dir) if s.log_dir else None
        if log_dir:
            log_dir.mkdir(parents=True, exist_ok=True)
        # The launcher's own monitor node joins the nodes' domain and discovery range.
        for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE'):
            if k in env:
                os.environ[k] = env[k]
        # The nodes run in their own sessions (a terminal's Ctrl-C reaches only this process):
        # every stop signal becomes KeyboardInterrupt here, so the nodes are always stopped in
        # order and none is left running.
        def _stop(signum, frame):
            raise KeyboardInterrupt
        previous = on_stop_signals(_stop)
        self.mon = SessionMonitor(domain_id=s.domain_id, enclave=(
            f"/{s.enclave_root.strip('/')}/launch_monitor" if s.enclave_root else None))
        self.sup = Supervisor(env, log_dir, max_restarts=s.max_restarts)
        self.sup.pinning = s.graph_pinning
        # one session for the graph only where this launcher leads one of its own (launch's
        # re-run); called from Python (a test) it may share its caller's: each node its own
        self.sup.own_sessions = s.node_sessions == 'each' or os.getsid(0) != os.getpid()
        self.sup.cores = {} if s.graph_pinning == 'off' else graph_cores(
            [n for n in self.order if n not in VIEW_NODES])
        self.t0 = time.monotonic()
        try:
            refuse_shared_domain(s, node=self.mon.node)
            self._start_and_supervise()
        except KeyboardInterrupt:
            print('interrupted: stopping the nodes', flush=True)
        finally:
            # a second Ctrl-C must not cut the ordered stop short
            on_stop_signals(lambda *_: print('stopping the nodes, please wait', flush=True))
            try:
                self.result.codes = self.sup.stop_all(list(reversed(self.order)), starting=[
                    n for n in self.sup.procs if not self.mon.state(n, self.sup.started_at[n])])
            finally:
                self.mon.close()
                restore_signals(previous)
        for n in reversed(self.order):
            if n in self.result.codes:
                print(f'stopped {n:<17} exit code {self.result.codes[n]}', flush=True)
        return self.result

    def _start_and_supervise(self) -> None:
        s, mon, sup = self.spec, self.mon, self.sup
        helpers = [n for n in self.order if n != 'falcon_driver']
        for name in helpers:
            self._start(name)
        ok = self._wait_for(lambda: all(mon.state(n, sup.started_at[n]) for n in helpers),
                            lambda: 'no status from ' + ', '.join(
                                n for n in helpers if not mon.state(n, sup.started_at[n])))
        if ok and 'falcon_driver' in self.extra:
            self._start('falcon_driver')
            ok = self._wait_for(
                lambda: mon.state('falcon_driver', sup.started_at['falcon_driver']) == 'ready',
                lambda: 'the falcon driver has seen no force command; states: ' + ', '.join(
                    f'{n} {mon.state(n) or "none"}' for n in self.order))
        if not ok:
            return
        self._raise_priority()
        self.say('ready', after_s=round(time.monotonic() - self.t0, 1))
        print(f'ready after {time.monotonic() - self.t0:.1f} s: {len(sup.procs)} nodes running'
              + (f' for {s.duration:g} s' if s.duration else '; Ctrl-C stops them'), flush=True)
        t_ready = time.monotonic()
        while not (s.duration and time.monotonic() - t_ready >= s.duration):
            mon.spin(0.1)
            if not self._handle_deaths():
                break
            self._raise_priority()

    # -- steps --------------------------------------------------------------------------------
    def say(self, event: str, **kw) -> None:
        """Publish a session event (recorded in the bag) and print it."""
        e = self.mon.event(event=event, t=round(time.monotonic() - self.t0, 3), **kw)
        self.history.append(e)
        print('session: ' + ', '.join(f'{k} {v}' for k, v in e.items() if k != 'wall_time'),
              flush=True)

    def _raise_priority(self) -> None:
        """The ready nodes on the haptic path to ``--graph-priority`` (once per start: a
        restarted node when it is ready again); the first time, and any refusal, is said."""
        s, mon, sup = self.spec, self.mon, self.sup
        ready = [n for n in self.order if n in sup.procs and mon.state(n, sup.started_at[n])]
        for n, what in sup.raise_priority(s.graph_priority, ready).items():
            if 'refused' in what or 'not kept' in what or n not in self.graph_scheduling:
                print(f'scheduling {n:<16} {what}', flush=True)
            self.graph_scheduling[n] = what

    def _start(self, name: str) -> None:
        p = self.sup.start(name, [*self.spec.params_arguments(), *self.extra[name]])
        log = self.sup.logs.get(name)
        print(f'started {name:<17} pid {p.pid}' + (f', log {log.name}' if log else ''),
              flush=True)

    def _replay_to_new_recorder(self) -> None:
        """A restarted recorder joined after the events that explain its new bag: once it is
        ready and subscribed, publish the session's events again (``replayed: true``)."""
        mon = self.mon
        if self._replay_pending and mon.state('recorder', self.sup.started_at['recorder']) == \
                'ready' and mon.subscriber_gids() - self._replay_known:
            self._replay_pending = False
            for e in list(self.history):
                mon.event(**{k: v for k, v in e.items() if k != 'wall_time'}, replayed=True)

    def _handle_deaths(self) -> bool:
        """Restart what died and may be restarted; False when the session must stop."""
        s, sup = self.spec, self.sup
        for name, code in sup.dead():
            self.say('died', node=name, code=code)
            if s.no_respawn or name in NO_RESPAWN or not sup.may_restart(name):
                why = ('--no-respawn' if s.no_respawn else 'the device owner is never '
                       'restarted' if name in NO_RESPAWN else
                       f'restart limit {s.max_restarts} reached')
                self.say('stopping', node=name, reason=why)
                self.result.failed.append((name, code))
                return False
            hold = None  # a restarted node's output waits until the recorder matched it
            if 'recorder' in self.extra and name != 'recorder':
                hold = {HOLD_FOR_RECORDER: 'recorder'}
                if self.recorded:
                    hold[RECORDED_TOPICS] = ','.join(self.recorded)
            p = sup.restart(name, renamed_output if name == 'recorder' else None, env=hold)
            self.say('restarted', node=name, pid=p.pid, restarts=sup.restarts[name])
            if name == 'recorder':
                self._replay_pending, self._replay_known = True, self.mon.subscriber_gids()
        self._replay_to_new_recorder()
        return True

    def _wait_for(self, pred, what) -> bool:
        end = time.monotonic() + self.spec.ready_timeout
        while not pred():
            if time.monotonic() > end:
                print(f'not ready after {self.spec.ready_timeout:g} s: {what()}', flush=True)
                self.result.failed.append(('ready-timeout', 1))
                return False
            self.mon.spin(0.1)
            if not self._handle_deaths():
                return False
        return True
