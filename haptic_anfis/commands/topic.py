"""``haptic-anfis topic list|echo|hz``: what ``ros2 topic`` would do, with rclpy only.

Graph introspection (``get_topic_names_and_types``) finds topics and their types; the message class
is imported from the type string, so any installed message type can be echoed. The subscription's
reliability follows the publishers (best effort if any publisher is), as ``ros2 topic echo`` does.
Uses the environment's ROS_DOMAIN_ID / ROS_AUTOMATIC_DISCOVERY_RANGE.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections import deque

import rclpy
import yaml
from rclpy.context import Context
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..nodes.executor import make_executor
from ..nodes.runtime import message_class

NAME = 'topic'


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest='topic_command', metavar='ACTION', required=True)
    a = sub.add_parser('list', help='topics in the graph')
    a.add_argument('-t', '--show-types', action='store_true', help='also print each type')
    a.add_argument('--wait', type=float, default=2.0, metavar='S',
                   help='discovery time before listing (default 2 s)')
    a = sub.add_parser('echo', help='print messages of a topic')
    a.add_argument('topic')
    a.add_argument('--type', default=None, help='message type (default: from the graph)')
    a.add_argument('--once', action='store_true', help='print one message and exit')
    a.add_argument('--count', type=int, default=0, metavar='N', help='exit after N messages')
    a.add_argument('--timeout', type=float, default=10.0, metavar='S',
                   help='give up when no message arrives for S seconds (default 10; 0 = never)')
    a.add_argument('--flat', action='store_true', help='one line per message: field=value ...')
    a = sub.add_parser('hz', help='receive rate of a topic')
    a.add_argument('topic')
    a.add_argument('--type', default=None, help='message type (default: from the graph)')
    a.add_argument('--window', type=int, default=1000, help='messages in the averaging window')
    a.add_argument('--period', type=float, default=1.0, metavar='S', help='print every S seconds')
    a.add_argument('--duration', type=float, default=0.0, metavar='S',
                   help='stop after S seconds of measuring (default: until Ctrl-C)')
    a.add_argument('--timeout', type=float, default=10.0, metavar='S',
                   help='give up when nothing arrives within S seconds (default 10; 0 = never)')


def run(args: argparse.Namespace) -> int:
    session = _Session()
    try:
        return {'list': _list, 'echo': _echo, 'hz': _hz}[args.topic_command](session, args)
    finally:
        session.close()


# --- message -> readable text ---------------------------------------------------------------------
def to_plain(msg):
    """An rclpy message as nested dicts/lists of plain Python values (field order kept)."""
    if hasattr(msg, 'get_fields_and_field_types'):
        return {f: to_plain(getattr(msg, f)) for f in msg.get_fields_and_field_types()}
    if isinstance(msg, (bytes, bytearray)):
        return list(msg)
    if isinstance(msg, (list, tuple)) or type(msg).__name__ in ('array', 'ndarray'):
        return [to_plain(v) for v in msg]
    if hasattr(msg, 'item') and not isinstance(msg, (int, float, str, bool)):
        return msg.item()
    return msg


def _flat(d, prefix=''):
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _flat(v, f'{prefix}{k}.')
        else:
            yield f'{prefix}{k}', v


def format_message(msg, flat: bool = False) -> str:
    d = to_plain(msg)
    if flat:
        return ' '.join(f'{k}={v!r}' for k, v in _flat(d))
    return yaml.safe_dump(d, sort_keys=False, default_flow_style=None, width=100).rstrip()


# --- rclpy session --------------------------------------------------------------------------------
class _Session:
    def __init__(self):

        self.rclpy = rclpy
        self.ctx = Context()
        rclpy.init(args=['haptic-anfis-topic'], context=self.ctx)
        self.node = rclpy.create_node(f'haptic_anfis_topic_{os.getpid()}', context=self.ctx,
                                      start_parameter_services=False)
        self.ex = make_executor(self.ctx)
        self.ex.add_node(self.node)

    def spin(self, seconds: float, until=None) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=min(0.05, max(end - time.monotonic(), 0.0)))
            if until is not None and until():
                return True
        return until is not None and until()

    def topic_type(self, topic: str, given: str | None, timeout: float) -> str:
        if given:
            return given
        found = {}

        def seen():
            found.update(dict(self.node.get_topic_names_and_types()))
            return topic in found
        if not self.spin(timeout if timeout > 0 else 1e9, seen):
            raise ValueError(f'topic {topic}: not in the graph after {timeout:g} s (nothing '
                             'publishes it? check "haptic-anfis topic list", ROS_DOMAIN_ID and '
                             'ROS_AUTOMATIC_DISCOVERY_RANGE), or pass --type')
        types = found[topic]
        if len(types) > 1:
            print(f'note: {topic} has several types {types}; using {types[0]}', file=sys.stderr)
        return types[0]

    def qos_for(self, topic: str):
        infos = self.node.get_publishers_info_by_topic(topic)
        best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
        return QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                          reliability=ReliabilityPolicy.BEST_EFFORT if best_effort
                          else ReliabilityPolicy.RELIABLE)

    def close(self):
        self.ex.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


def _absolute(topic: str) -> str:
    return topic if topic.startswith('/') else '/' + topic


def _list(s: _Session, args) -> int:
    s.spin(args.wait)
    for name, types in sorted(s.node.get_topic_names_and_types()):
        print(f'{name} [{", ".join(types)}]' if args.show_types else name)
    return 0


def _echo(s: _Session, args) -> int:
    topic = _absolute(args.topic)
    cls = message_class(s.topic_type(topic, args.type, args.timeout))
    want = 1 if args.once else args.count
    got = []
    printed = [0]

    def on(msg):
        got.append(msg)

    s.node.create_subscription(cls, topic, on, s.qos_for(topic))
    while not want or printed[0] < want:
        if not s.spin(args.timeout if args.timeout > 0 else 1e9, lambda: bool(got)):
            print(f'haptic-anfis topic echo: no message on {topic} within {args.timeout:g} s'
                  f'{" (after " + str(printed[0]) + " messages)" if printed[0] else ""}',
                  file=sys.stderr)
            return 1 if not printed[0] else 0 if not want else 1
        while got and (not want or printed[0] < want):
            print(format_message(got.pop(0), args.flat))
            if not args.flat:
                print('---')
            printed[0] += 1
        sys.stdout.flush()
    return 0


def _hz(s: _Session, args) -> int:

    topic = _absolute(args.topic)
    cls = message_class(s.topic_type(topic, args.type, args.timeout))
    times: deque = deque(maxlen=max(args.window, 2))
    s.node.create_subscription(cls, topic, lambda _m: times.append(time.monotonic()),
                               s.qos_for(topic), raw=True)
    if not s.spin(args.timeout if args.timeout > 0 else 1e9, lambda: len(times) >= 2):
        print(f'haptic-anfis topic hz: no messages on {topic} within {args.timeout:g} s',
              file=sys.stderr)
        return 1
    end = time.monotonic() + args.duration if args.duration > 0 else math.inf
    while time.monotonic() < end:
        s.spin(min(args.period, max(end - time.monotonic(), 0.0)))
        ts = list(times)
        if len(ts) < 2:
            print('no new messages', flush=True)
            continue
        d = [b - a for a, b in zip(ts, ts[1:])]
        mean = sum(d) / len(d)
        sd = math.sqrt(sum((x - mean) ** 2 for x in d) / len(d))
        print(f'average rate: {1.0 / mean:.3f} Hz  min: {min(d) * 1e3:.3f} ms  '
              f'max: {max(d) * 1e3:.3f} ms  std dev: {sd * 1e3:.3f} ms  window: {len(ts)}',
              flush=True)
    return 0
