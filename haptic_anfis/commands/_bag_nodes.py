"""``haptic-anfis bag play`` and ``bag record``: the player and recorder nodes in this process
(rclpy; see :mod:`haptic_anfis.commands.bag`)."""
from __future__ import annotations

import argparse

from rclpy.parameter import Parameter

from ..nodes.player import Player
from ..nodes.recorder import Recorder
from ..nodes.runtime import run_node


def _ros_node(cls, overrides: list, setup=None) -> int:
    def factory():
        node = cls(parameter_overrides=overrides)
        if setup is not None:
            setup(node)
        return node
    return run_node(factory, ['haptic-anfis-bag'])


def play(args: argparse.Namespace) -> int:
    ov = [Parameter('bag_path', value=str(args.path)), Parameter('rate', value=float(args.rate)),
          Parameter('start_offset', value=float(args.start_offset)),
          Parameter('loop', value=bool(args.loop)), Parameter('clock', value=bool(args.clock)),
          Parameter('topics', value=','.join(args.topics or [])),
          Parameter('resimulate', value=bool(args.resimulate)),
          Parameter('live', value=bool(args.live))]
    if args.params_file:
        ov.append(Parameter('params_files', value=list(args.params_file)))
    return _ros_node(Player, ov)


def record(args: argparse.Namespace) -> int:
    ov = [Parameter('output', value=args.output), Parameter('all_topics', value=bool(args.all))]
    if args.topics:
        ov.append(Parameter('topics', value=list(args.topics)))
    if args.flush_period is not None:
        ov.append(Parameter('flush_period', value=float(args.flush_period)))
    if args.fallback_dir:
        ov.append(Parameter('fallback_output_dir', value=str(args.fallback_dir)))
    if args.compression is not None:
        ov.append(Parameter('compression', value=args.compression))

    def stop_after(node):
        if args.duration > 0:
            node.create_timer(args.duration, lambda: setattr(node, 'finished', True))
    code = _ros_node(Recorder, ov, stop_after)
    return code
