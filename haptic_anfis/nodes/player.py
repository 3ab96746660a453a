"""``player``: publish a bag's topics with their original timing (like ``ros2 bag play``).

Messages are published serialized (the recorded CDR bytes, no deserialisation) from a playback
thread that sleeps until each one is due: receive-time gaps of the recording, divided by ``rate``.
Options: start ``start_offset`` seconds into the bag, ``loop``, a topic selection, ``/clock``
(rosgraph_msgs/Clock with the recorded time, for nodes with ``use_sim_time``). With
``resimulate`` the recorded poses first go through the current contact tracker and force model
(:func:`haptic_anfis.bag.resim.resimulate`): the comparison with the recorded force commands is
logged, and the force-command topic plays the RECOMPUTED wrenches (original stamps) instead of the
recorded ones. The whole bag is loaded into memory (a 10 s session is a few MB).
"""
from __future__ import annotations

import threading
import time

from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..bag import BagError
from ..bag.playback import due_times, load
from ..bag.topics import WRENCH_TYPE, absolute
from . import interfaces as ifc
from ._common import Param, declare_parameters, message_class, non_negative, positive, run_node

PARAMS = [
    Param('bag_path', '', 'the bag to play (a rosbag2 directory); required'),
    Param('rate', 1.0, 'playback speed factor (2.0 = twice as fast)', positive),
    Param('start_offset', 0.0, 'start this many seconds into the bag [s]', non_negative),
    Param('loop', False, 'play again from the start offset when the bag ends'),
    Param('topics', '', "topics to play, comma-separated ('' = all)"),
    Param('clock', False, 'publish /clock (rosgraph_msgs/Clock) with the recorded time'),
    Param('clock_rate', 100.0, 'largest /clock publishing rate [Hz]', positive),
    Param('delay', 0.5, 'wait this long after start before the first message (lets '
          'subscribers match) [s]', non_negative),
    Param('resimulate', False, 'log the re-simulation comparison and play the force command '
          'topic recomputed by the current contact tracker and force model'),
    Param('params_files', [''], "parameter YAMLs for the re-simulated contact_detector and "
          "force_server ('' entries ignored)"),
]

PLAY_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)


class Player(Node):
    def __init__(self, name: str = 'player', **kw):
        super().__init__(name, **kw)
        p = self.params = declare_parameters(self, PARAMS)
        if not p['bag_path']:
            raise BagError("parameter 'bag_path': expected the bag to play (a rosbag2 directory)")
        topics = [absolute(t.strip()) for t in p['topics'].split(',') if t.strip()] or None
        self.records = load(p['bag_path'], topics)
        self.resim = None
        if p['resimulate']:
            self._resimulate(p)
        self.pubs = {}
        for r in self.records:
            if r.topic not in self.pubs:
                self.pubs[r.topic] = self.create_publisher(message_class(r.msgtype), r.topic,
                                                           PLAY_QOS)
        self.clock_pub = None
        if p['clock']:
            from rosgraph_msgs.msg import Clock
            self._clock = Clock()
            self.clock_pub = self.create_publisher(Clock, '/clock', 10)
        self.schedule = due_times(self.records, p['rate'], p['start_offset'])
        self.published = 0
        self.loops = 0
        self.finished = False
        self._stop = threading.Event()
        self.get_logger().info(
            f"playing {p['bag_path']}: {len(self.schedule)} messages on {len(self.pubs)} topics, "
            f"rate {p['rate']:g}" + (', loop' if p['loop'] else ''))
        self._thread = threading.Thread(target=self._play, name='bag-player', daemon=True)
        self._thread.start()

    def _resimulate(self, p) -> None:
        from ..bag.resim import resimulate
        files = [f for f in p['params_files'] if f]
        self.resim = resimulate(p['bag_path'], params_files=files)
        for line in self.resim.format().splitlines():
            self.get_logger().info(line)
        cmd = absolute(ifc.TOPIC_COMMAND)
        if not any(r.topic == cmd for r in self.records):
            return
        from geometry_msgs.msg import WrenchStamped
        from rclpy.serialization import deserialize_message, serialize_message
        out = []
        for r in self.records:
            if r.topic == cmd and r.msgtype == WRENCH_TYPE:
                m = deserialize_message(r.data, WrenchStamped)
                f = self.resim.recomputed.get(m.header.stamp.sec * 1_000_000_000
                                              + m.header.stamp.nanosec)
                if f is not None:
                    m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = f
                    r = type(r)(r.t_ns, r.topic, r.msgtype, serialize_message(m))
            out.append(r)
        self.records = out

    def _play(self) -> None:
        p = self.params
        time.sleep(p['delay'])
        clock_period = 1.0 / p['clock_rate']
        while not self._stop.is_set():
            start = time.monotonic()
            last_clock = -1e9
            for due, r in self.schedule:
                wait = start + due - time.monotonic()
                if wait > 0 and self._stop.wait(wait):
                    return
                if self.clock_pub is not None and due - last_clock >= clock_period:
                    self._clock.clock.sec, self._clock.clock.nanosec = divmod(r.t_ns, 1_000_000_000)
                    self.clock_pub.publish(self._clock)
                    last_clock = due
                try:
                    self.pubs[r.topic].publish(r.data)
                except Exception:  # context shut down under us
                    return
                self.published += 1
            self.loops += 1
            if not p['loop'] or not self.schedule:
                break
        self.get_logger().info(f'played {self.published} messages')
        self.finished = True

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def main(args=None) -> None:
    raise SystemExit(run_node(Player, args))


if __name__ == '__main__':
    main()
