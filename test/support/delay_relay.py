"""A slow force server for the cross-process tests: republish the force server's outputs DELAY
seconds late.

Run as ``python test/delay_relay.py DELAY`` on the test's ROS domain, beside a force server whose
outputs are remapped under ``delayed/`` (:data:`FORCE_SERVER_REMAP`): each message read there
(as raw bytes) is published again on the loop topic DELAY seconds after it arrived. Messages due
together go out as the newest one only (the loop topics keep the last sample anyway), so a late
wake-up on a loaded machine cannot build a backlog. Stops on SIGINT / SIGTERM.
"""
from __future__ import annotations

import queue
import signal
import sys
import threading
import time

import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from sensor_msgs.msg import JointState

from haptic_anfis import interfaces as ifc
from haptic_anfis.nodes.runtime import LOOP_QOS

#: where the force server publishes (``-r`` arguments) when the relay republishes its outputs
FORCE_SERVER_REMAP = [f'{ifc.TOPIC_COMMAND}:=delayed/servo_cf', '-r',
                      f'{ifc.TOPIC_LOCAL_MODEL}:=delayed/servo_cf_local']


def delay_line(lines: queue.Queue, publish, delay: float) -> None:
    """Publish each (arrival time [s], raw message) of ``lines`` ``delay`` seconds after it
    arrived, skipping to the newest one that is due."""
    pending = None
    while True:
        item = pending if pending is not None else lines.get()
        pending = None
        wait = item[0] + delay - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        while True:
            try:
                nxt = lines.get_nowait()
            except queue.Empty:
                break
            if nxt[0] + delay > time.monotonic():
                pending = nxt
                break
            item = nxt
        try:
            publish(item[1])
        except Exception:  # the node is shutting down
            return


def main(delay: float) -> None:
    rclpy.init()
    node = rclpy.create_node('delay_relay')
    for msg_type, topic in ((WrenchStamped, ifc.TOPIC_COMMAND),
                            (JointState, ifc.TOPIC_LOCAL_MODEL)):
        pub = node.create_publisher(msg_type, topic, LOOP_QOS)
        lines: queue.Queue = queue.Queue()
        node.create_subscription(msg_type, f'delayed/{topic.rsplit("/", 1)[1]}',
                                 lambda raw, q=lines: q.put((time.monotonic(), raw)), LOOP_QOS,
                                 raw=True)
        threading.Thread(target=delay_line, args=(lines, pub.publish, delay), daemon=True).start()
    ex = EventsExecutor()
    ex.add_node(node)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        while not stop.is_set() and rclpy.ok():
            ex.spin_once(timeout_sec=0.05)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    main(float(sys.argv[1]))
