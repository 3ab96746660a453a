"""``player``: publish a bag's topics with their original timing (like ``ros2 bag play``).

Messages are published serialized (the recorded CDR bytes, no deserialisation) from a playback
thread that sleeps until each one is due: receive-time gaps of the recording, divided by ``rate``.
Options: start ``start_offset`` seconds into the bag, ``loop``, a topic selection, ``/clock``
(rosgraph_msgs/Clock with the recorded time, for nodes with ``use_sim_time``). With
``resimulate`` the recorded poses first go through the current contact tracker and force model
(:func:`haptic_anfis.nodes.resim.resimulate`): the comparison with the recorded force commands is
logged, and the force-command topic plays the RECOMPUTED wrenches (original stamps) instead of the
recorded ones.

Streaming: messages are read from the bag as they are played (one MCAP chunk at a time), so memory
stays flat however long the bag (README: measured on a 30-minute bag). Re-simulation keeps one
recomputed force per recorded command in memory (~0.2 KB each).

Safety: by default every topic is played under ``playback_namespace`` (``/falcon/servo_cf`` ->
``/playback/falcon/servo_cf``), never on the recorded names: there a running ``falcon_driver``
would apply the recorded force commands to the trainee's hand, and the recorded poses and contacts
would mix with the live ones (and drive a live force server). ``live: true`` plays on the recorded
names, with a warning; the start-up log line says which and why.
"""
from __future__ import annotations

import threading
import time

from geometry_msgs.msg import WrenchStamped
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock

from .. import interfaces as ifc
from ..bag import BagError, bag_info
from ..bag.playback import Recorded, check_timing, schedule
from ..bag.topics import WRENCH_TYPE, absolute, playback_topic
from .base import HapticNode
from .parameters import Param, declare_parameters, non_negative, positive
from .resim import resimulate
from .runtime import message_class, run_node

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
    Param('live', False, 'publish on the RECORDED topic names: a running falcon_driver then '
          'applies the recorded force commands (falcon/servo_cf) to the hand on the device, and '
          'recorded poses mix with live ones; false: every topic is played under '
          'playback_namespace'),
    Param('playback_namespace', 'playback', 'namespace the topics are played under unless live '
          '(/falcon/servo_cf plays as /playback/falcon/servo_cf)',
          lambda v: None if v.strip('/') else 'expected a non-empty namespace'),
]

PLAY_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)


class Player(HapticNode):
    def __init__(self, name: str = 'player', **kw):
        super().__init__(name, **kw)
        p = self.params = declare_parameters(self, PARAMS)
        if not p['bag_path']:
            raise BagError("parameter 'bag_path': expected the bag to play (a rosbag2 directory)")
        check_timing(p['rate'], p['start_offset'])
        info = bag_info(p['bag_path'])
        types = {t.topic: t.msgtype for t in info.topics}
        counts = {t.topic: t.count for t in info.topics}
        topics = [absolute(t.strip()) for t in p['topics'].split(',') if t.strip()] or None
        missing = [t for t in topics or () if t not in types]
        if missing:
            raise BagError(f"{p['bag_path']}: no topic(s) {', '.join(missing)} in the bag "
                           f"(it has {', '.join(sorted(types)) or 'none'})")
        self.topics = topics
        self.start_ns = info.start_ns
        self.resim = None
        if p['resimulate']:
            self._resimulate(p)
        ns = p['playback_namespace']
        #: recorded topic -> the topic it is played on
        self.topic_map = {t: t if p['live'] else playback_topic(t, ns)
                          for t in (topics or sorted(types))}
        self.pubs = {t: self.create_publisher(message_class(types[t]), out, PLAY_QOS)
                     for t, out in self.topic_map.items()}
        self.clock_pub = None
        if p['clock']:
            self._clock = Clock()
            self.clock_pub = self.create_publisher(Clock, '/clock', 10)
        self.published = 0
        self.loops = 0
        self.finished = False
        self._stop = threading.Event()
        log = self.get_logger()
        cmd = absolute(ifc.TOPIC_COMMAND)
        if p['live']:
            log.warning('live:=true: playing on the RECORDED topic names; a running falcon_driver '
                        f'applies the recorded force commands ({cmd}) to the device, and recorded '
                        'poses mix with live ones')
        else:
            log.info(f"playing under /{ns.strip('/')}/ (e.g. {cmd} -> {playback_topic(cmd, ns)}), "
                     'not on the recorded names: there a running falcon_driver would apply the '
                     'recorded force commands to the hand on the device; live:=true to override')
        log.info(f"playing {p['bag_path']}: {sum(counts[t] for t in self.topic_map)} messages on "
                 f"{len(self.pubs)} topics, rate {p['rate']:g}" + (', loop' if p['loop'] else ''))
        self._thread = threading.Thread(target=self._play, name='bag-player', daemon=True)
        self._thread.start()

    def _resimulate(self, p) -> None:
        files = [f for f in p['params_files'] if f]
        self.resim = resimulate(p['bag_path'], params_files=files)
        for line in self.resim.format().splitlines():
            self.get_logger().info(line)

    def _substitute(self, r: Recorded) -> Recorded:
        """The record to play: with ``resimulate``, a force command carries the recomputed force."""
        if self.resim is None or r.msgtype != WRENCH_TYPE or r.topic != absolute(ifc.TOPIC_COMMAND):
            return r
        m = deserialize_message(r.data, WrenchStamped)
        f = self.resim.recomputed.get(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec)
        if f is None:
            return r
        m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = f
        return Recorded(r.t_ns, r.topic, r.msgtype, serialize_message(m))

    def schedule(self):
        """``(due seconds after the start, record to publish)``, read from the bag as played."""
        p = self.params
        for due, r in schedule(p['bag_path'], self.topics, p['rate'], p['start_offset'],
                               self.start_ns):
            yield due, self._substitute(r)

    def _play(self) -> None:
        p = self.params
        if self._stop.wait(p['delay']):
            return
        clock_period = 1.0 / p['clock_rate']
        while not self._stop.is_set():
            start = time.monotonic()
            n0 = self.published
            try:
                self._play_once(start, clock_period)
            except BagError as exc:  # a damaged bag found mid-way: say so, end playback
                self.get_logger().error(str(exc))
                break
            if self._stop.is_set():
                return
            self.loops += 1
            if not p['loop'] or self.published == n0:
                break
        self.get_logger().info(f'played {self.published} messages')
        self.finished = True

    def _play_once(self, start: float, clock_period: float) -> None:
        """One pass over the schedule; returns early when stopped or the context is gone."""
        last_clock = -1e9
        for due, r in self.schedule():
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
                self._stop.set()
                return
            self.published += 1

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def main(args=None) -> None:
    raise SystemExit(run_node(Player, args))


if __name__ == '__main__':
    main()
