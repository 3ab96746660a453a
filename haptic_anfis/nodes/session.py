"""Session plumbing every node shares: readiness status and session events (ROS topics).

``session/status`` (``std_msgs/String``, JSON, transient local, one sample per publisher): each
node says ``started`` once it is constructed (numba kernels compiled, mesh / model loaded), then
``ready`` when its readiness condition holds (by default: every topic it subscribes to has a
publisher; the falcon driver: a force command has arrived), ``waiting`` if that is lost again.
JSON fields: ``node``, ``state``, ``detail``, ``t`` (seconds since the node's process started),
``pid``. A late subscriber (``haptic-anfis launch``) gets every node's latest status.

``session/events`` (``std_msgs/String``, JSON, transient local): what the launcher did to the
session (a node died, was restarted, gave up); the recorder records it, so the bag says why force
stopped for a while.
"""
from __future__ import annotations

import json
import os
import time
from typing import Callable

import rclpy
from rclpy.context import Context
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

from .executor import make_executor

STATUS_TOPIC = '/session/status'
EVENTS_TOPIC = '/session/events'
STATUS_TYPE = EVENTS_TYPE = 'std_msgs/msg/String'
#: Latched status: each publisher keeps its newest sample for subscribers that join later.
STATUS_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
EVENTS_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: Topics that never count for readiness (ROS infrastructure and these session topics).
INFRA_TOPICS = ('/parameter_events', '/rosout', STATUS_TOPIC, EVENTS_TOPIC)


def process_age() -> float:
    """Seconds since this process started (Linux /proc; else since this module was imported)."""
    try:
        with open('/proc/self/stat') as f:
            start_ticks = int(f.read().rsplit(')', 1)[1].split()[19])
        with open('/proc/uptime') as f:
            uptime = float(f.read().split()[0])
        return max(0.0, uptime - start_ticks / os.sysconf('SC_CLK_TCK'))
    except (OSError, ValueError, IndexError):
        return time.monotonic() - _T_IMPORT


_T_IMPORT = time.monotonic()


def status_dict(node: str, state: str, detail: str = '') -> dict:
    return {'node': node, 'state': state, 'detail': detail, 't': round(process_age(), 3),
            'pid': os.getpid()}


class Readiness:
    """Publish ``node``'s status on :data:`STATUS_TOPIC` and log it.

    ``started`` is announced at once (call this after the node's slow construction). A timer
    every ``period`` s evaluates the readiness condition: ``node.ready_condition()`` ->
    ``(ready, detail)`` if the node defines one, else "every subscribed topic has a publisher".
    Transitions are published and logged (``ready after N s: ...``).
    """

    def __init__(self, node, period: float = 0.2):
        self.node = node
        self.pub = node.create_publisher(String, STATUS_TOPIC, STATUS_QOS)
        self.state = ''
        self.ready_after: float | None = None
        self._msg = String()
        # the process id: to find the node in ps, top or a scheduler trace
        self.announce('started', f'constructed (kernels compiled, files loaded), process '
                                 f'{os.getpid()}')
        self._check()
        self.timer = node.create_timer(period, self._check)

    def announce(self, state: str, detail: str = '') -> None:
        if state == self.state:
            return
        self.state = state
        d = status_dict(self.node.get_name(), state, detail)
        if state == 'ready' and self.ready_after is None:
            self.ready_after = d['t']
        self._msg.data = json.dumps(d)
        self.pub.publish(self._msg)
        text = f"{state} after {d['t']:.1f} s" + (f': {detail}' if detail else '')
        # INFO, also for 'waiting': a session stopping in order (the driver first) takes the
        # inputs of the nodes still running away, and a clean stop warns of nothing; a node
        # that really died mid-session is reported by the launcher (session/events).
        self.node.get_logger().info(text)

    def _check(self) -> None:
        cond: Callable | None = getattr(self.node, 'ready_condition', None)
        ok, detail = cond() if cond is not None else self._inputs_matched()
        if ok:
            self.announce('ready', detail)
        elif self.state == 'ready':
            self.announce('waiting', detail)

    def _inputs_matched(self) -> tuple[bool, str]:
        return inputs_matched(self.node, [s.topic_name for s in self.node.subscriptions])

    def destroy(self) -> None:
        self.node.destroy_timer(self.timer)


def inputs_matched(node, topics) -> tuple[bool, str]:
    """The default readiness condition: (every topic of ``topics`` but the session and ROS
    infrastructure ones has a publisher, in words)."""
    topics = sorted(set(topics) - set(INFRA_TOPICS))
    missing = [t for t in topics if node.count_publishers(t) == 0]
    if missing:
        return False, f'no publisher on {", ".join(missing)}'
    return True, ('inputs matched: ' + ', '.join(topics)) if topics else 'no inputs'


def parse_status(data: str) -> dict | None:
    """A status / event message's JSON, or None if it is not a JSON object."""
    try:
        d = json.loads(data)
    except ValueError:
        return None
    return d if isinstance(d, dict) else None


class SessionMonitor:
    """The launcher's window on the session (``haptic-anfis launch``): a node that keeps every
    node's latest status (``statuses[node] = (receive time [monotonic s], status dict)``) and
    publishes session events. Drive it with :meth:`spin` from the launcher's loop."""

    def __init__(self, name: str = 'launch_monitor', domain_id: int | None = None,
                 enclave: str | None = None):
        self.ctx = Context()

        # No rclpy signal handlers here: Ctrl-C must reach the launcher as KeyboardInterrupt so
        # that it stops the nodes in order.
        rclpy.init(args=['--ros-args', '--enclave', enclave] if enclave else [], context=self.ctx,
                   domain_id=domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.ctx,
                                      start_parameter_services=False)
        self.statuses: dict[str, tuple[float, dict]] = {}
        self.events_pub = self.node.create_publisher(String, EVENTS_TOPIC, EVENTS_QOS)
        self.node.create_subscription(String, STATUS_TOPIC, self._on_status,
                                      QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                                                 reliability=ReliabilityPolicy.RELIABLE,
                                                 durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.executor = make_executor(self.ctx)
        self.executor.add_node(self.node)

    def _on_status(self, msg: String) -> None:
        d = parse_status(msg.data)
        if d is not None and isinstance(d.get('node'), str):
            self.statuses[d['node']] = (time.monotonic(), d)

    def state(self, node: str, since: float = float('-inf')) -> str:
        """``node``'s latest state received after ``since`` (monotonic s), '' if none."""
        t, d = self.statuses.get(node, (None, None))
        return d.get('state', '') if t is not None and t >= since else ''

    def event(self, **fields) -> dict:
        """Publish one session event (JSON of ``fields``, plus ``wall_time``); returns it."""
        fields['wall_time'] = round(time.time(), 3)
        msg = String()
        msg.data = json.dumps(fields)
        self.events_pub.publish(msg)
        return fields

    def subscriber_gids(self, topic: str = EVENTS_TOPIC) -> set[bytes]:
        """Endpoint ids of the subscriptions to ``topic`` the graph shows (a killed process's
        stay listed until their DDS lease runs out, so compare sets, not counts)."""
        return {bytes(i.endpoint_gid) for i in self.node.get_subscriptions_info_by_topic(topic)}

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return
            self.executor.spin_once(timeout_sec=min(left, 0.05))

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)
