"""What a running node needs: the loop QoS, time stamps, message classes by name, and
:func:`run_node`, the ``main`` of every node process (checks its parameters before rclpy starts,
spins, shuts down quietly)."""
from __future__ import annotations

import contextlib
import importlib
import inspect
import os
import sys
import time
from typing import Any, Callable, Collection

import rclpy
from builtin_interfaces.msg import Time
from rclpy.executors import ExternalShutdownException
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from ..bag.topics import absolute
from ..realtime.processes import (HOLD_FOR_RECORDER, RECORDED_TOPICS, SESSION_CHECKED,
                                  guard_realtime_time, leave_realtime)
from .executor import make_executor, settle_and_start
from .middleware import use_loop_transport
from .parameter_files import check_parameter_sources, ros_args_sources
from .parameters import CASE_PARAMS, ParameterError
from .session import INFRA_TOPICS, Readiness
from .sigint import SigintStop

__all__ = ['LOOP_QOS', 'stamp_ns', 'set_stamp', 'interrupted', 'run_node', 'message_class',
           'check_node_arguments', 'hold_until_recorder_matched', 'HOLD_TIMEOUT_S']

#: [s] the longest a restarted node holds its output for the recorder (then it goes on, warned:
#: a killed process's endpoints stay listed until their DDS lease runs out)
HOLD_TIMEOUT_S = 3.0

#: QoS of the 1 kHz loop topics: reliable, keep only the newest sample (a late one is useless).
LOOP_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)


def stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def set_stamp(stamp: Time, ns: int) -> None:
    stamp.sec, stamp.nanosec = divmod(ns, 1_000_000_000)


def interrupted(context=None) -> bool:
    """True once rclpy's context was shut down (Ctrl-C / SIGTERM handled by rclpy)."""
    return not rclpy.ok(context=context)


def run_node(factory: Callable[[], Any], args=None) -> int:
    """Init rclpy, build the node, spin it until shut down or ``node.finished``; 1 on bad params.

    Uses EventsExecutor with a ``spin_once(timeout_sec=...)`` loop (its ``spin()`` runs no
    callbacks with the rclpy wheels here, see docs/design.md). Calls ``node.close()`` (if defined)
    before destroying the node. A node with a ``start_loop()`` (the falcon driver's servo loop)
    has it called once built and the garbage collector settled, before the first spin: a loop
    thread started earlier shares the interpreter lock with the rest of the process's start.
    Once built, the node announces its status on ``session/status``
    (:class:`~haptic_anfis.nodes.session.Readiness`). Interrupted while starting (Ctrl-C or SIGTERM
    during a long compile), the node exits with code 0 and a one-line message, no traceback.
    """
    errors = check_node_arguments(factory, sys.argv if args is None else args)
    if errors:
        for e in errors:
            print(f'error: {e}', file=sys.stderr, flush=True)
        return 1

    # SIGINT (Ctrl-C, a launcher's stop) is ours, not rclpy's: rclpy's handler shut the context
    # down under the node, whose close() then failed to log ("publisher's context is invalid").
    # While the node is being built it raises KeyboardInterrupt (a long compile stops at once);
    # once it spins it only ends the spin loop (raised inside a callback it was logged FATAL),
    # so close() logs and the node and the context go, in that order. SIGTERM stays rclpy's.
    use_loop_transport()  # DDS over UDP only: a shared-memory port's opening held publishes ~333 ms
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.SIGTERM)
    stop = SigintStop()
    node = executor = None
    code = 0
    try:
        try:
            node = factory()
            recorder = os.environ.get(HOLD_FOR_RECORDER)
            if recorder:  # a restart in a recording session: nothing unrecorded leaves this node
                recorded = os.environ.get(RECORDED_TOPICS)
                hold_until_recorder_matched(
                    node, recorder, topics=recorded.split(',') if recorded else None)
            node.readiness = Readiness(node)
            executor = make_executor()
            executor.add_node(node)
            guard_realtime_time()  # before it can be raised: rtkit's run-time limit ends no node
            settle_and_start([node])
        except (ParameterError, ValueError, OSError) as exc:
            if interrupted():
                return _interrupted_while_starting()
            print(f'error: {exc}', file=sys.stderr, flush=True)
            return 1
        except (KeyboardInterrupt, ExternalShutdownException):
            return _interrupted_while_starting()
        except Exception:
            if interrupted():  # e.g. "rcl node's context is invalid" after Ctrl-C
                return _interrupted_while_starting()
            raise
        try:
            stop.spinning = True
            while rclpy.ok() and not stop.requested and not getattr(node, 'finished', False):
                executor.spin_once(timeout_sec=0.05)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except Exception:
            if not interrupted():
                raise
        code = int(getattr(node, 'exit_code', 0) or 0)
    except KeyboardInterrupt:  # a second Ctrl-C while shutting down
        pass
    finally:
        stop.spinning = False  # a second Ctrl-C while closing raises KeyboardInterrupt
        try:
            # closing computes (the driver writes an hour's tick trace: seconds of CPU); at
            # rtkit's real-time priority its run-time limit would SIGKILL the node for it
            leave_realtime()
            if executor is not None:
                with contextlib.suppress(KeyboardInterrupt):  # a second Ctrl-C: still close
                    executor.shutdown(timeout_sec=1.0)
            if node is not None:
                if hasattr(node, 'close'):
                    node.close()
                node.destroy_node()
            rclpy.try_shutdown()
        finally:
            stop.restore()
    return code


def check_node_arguments(factory: Callable, args) -> list[str]:
    """Check the parameter files and ``-p`` overrides in ``args`` against the parameters the
    node ``factory`` (a node class whose module lists ``PARAMS``) declares, before rclpy reads
    them: one line per problem (file:line, the parameter, what was given and what is expected).
    A malformed YAML would otherwise end in rcl's multi-line traceback. Sections for other nodes
    are left alone; so are ``/**`` keys and ``-p`` overrides this node does not declare when a
    session started it (:data:`SESSION_CHECKED` set: the session checked them against all its
    nodes); started alone, such a key is an error naming the nearest parameter."""
    module = sys.modules.get(getattr(factory, '__module__', ''), None)
    params = list(getattr(module, 'PARAMS', None) or [])
    if hasattr(module, 'CASE_PARAMS'):
        params += CASE_PARAMS
    try:
        files, overrides, remap = ros_args_sources(args)
    except ParameterError as exc:
        return [str(exc)]
    if not files and not overrides:
        return []
    try:
        default = inspect.signature(factory).parameters['name'].default
    except (KeyError, TypeError, ValueError):
        default = inspect.Parameter.empty
    name = remap or (default if isinstance(default, str) else '')
    if not name or not params:  # nothing known to check against: the YAML syntax only
        return check_parameter_sources({}, files, whole_session=False, strict_globals=False)
    return check_parameter_sources({name: params}, files, overrides, nodes=[name],
                                   whole_session=False,
                                   strict_globals=not os.environ.get(SESSION_CHECKED))


def hold_until_recorder_matched(node, recorder: str = 'recorder',
                                timeout: float = HOLD_TIMEOUT_S, poll: float = 0.01,
                                topics: Collection[str] | None = None) -> bool:
    """Before ``node`` spins (so none of its callbacks publishes yet): wait until every
    publisher of ``node`` on a topic the node ``recorder`` records has matched all the
    subscriptions the graph shows on that topic, the recorder's among them. A node restarted
    in a recording session would otherwise publish (force commands the driver applies) before
    the recorder had matched it, and the bag would miss its first seconds.

    ``topics``: what the recorder records (the session knows). With them, a publisher on one of
    them waits until the recorder's own subscription on it has been discovered: a fresh node
    learns the recorder's name before its endpoints, and the graph alone would let it publish
    in between. Without them, the topics the graph shows the recorder subscribed to (that gap
    open). True when matched, False (warned) after ``timeout`` s."""
    wanted = None if topics is None else {absolute(t) for t in topics}
    pubs = [p for p in node.publishers if p.topic_name not in INFRA_TOPICS
            and (wanted is None or p.topic_name in wanted)]
    end = time.monotonic() + timeout
    pending: list[str] = []
    while True:
        if recorder in node.get_node_names():
            pending = []
            for p in pubs:
                subs = node.get_subscriptions_info_by_topic(p.topic_name)
                seen = any(i.node_name == recorder for i in subs)
                if (wanted is not None and not seen) or \
                        (seen and p.get_subscription_count() < len(subs)):
                    pending.append(p.topic_name)
            if not pending:
                return True
        if time.monotonic() > end:
            node.get_logger().warning(
                f'publishing after {timeout:g} s although the {recorder} may not have matched '
                + (', '.join(pending) if pending else 'this node (not seen in the graph)'))
            return False
        time.sleep(poll)


def _interrupted_while_starting() -> int:
    print('interrupted while starting: exiting', file=sys.stderr, flush=True)
    return 0


def message_class(type_name: str):
    """'geometry_msgs/msg/PoseStamped' (or 'geometry_msgs/PoseStamped') -> the rclpy message class.

    Raises:
        ValueError: malformed name, or no such installed message package / type.
    """
    parts = type_name.strip('/').split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f'message type {type_name!r}: expected package/msg/Name')
    try:
        cls = getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError):
        raise ValueError(f'message type {type_name!r}: not installed (no {parts[0]}.{parts[1]}.'
                         f'{parts[2]} importable)') from None
    return cls
