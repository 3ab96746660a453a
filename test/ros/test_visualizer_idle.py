"""The visualizer builds no picture nobody draws: with no subscriber to its marker topics (no RViz,
the install's usual case) it publishes nothing and computes no dent; a subscriber that appears
gets the markers and the dent from then on."""
from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from haptic_anfis import interfaces as ifc  # noqa: E402
from haptic_anfis.nodes.executor import node_in_thread  # noqa: E402
from haptic_anfis.nodes.visualizer import Visualizer  # noqa: E402

pytestmark = pytest.mark.ros


def _press(i: int) -> tuple[PoseStamped, JointState]:
    """A press on the default breast moving along y (a new dent every message)."""
    y, z, depth = 0.01 + 1e-4 * (i % 100), 0.01, 0.006
    x = 0.045 * np.sqrt(1 - (y / 0.07) ** 2 - (z / 0.07) ** 2)
    p = PoseStamped()
    p.header.frame_id = 'tissue'
    p.pose.position.x, p.pose.position.y, p.pose.position.z = x - depth, y, z
    v = [0.0] * len(ifc.CONTACT_FIELDS)
    v[0:3], v[ifc.I_DEPTH], v[ifc.I_DX], v[ifc.I_IN_CONTACT] = [x, y, z], depth, -1.0, 1.0
    c = JointState(name=list(ifc.CONTACT_FIELDS), position=v)
    return p, c


def test_no_subscriber_no_markers_no_dent_then_drawn_for_a_subscriber():
    with node_in_thread(Visualizer, other='vis_feeder') as (vis, feeder):
        pub_pose = feeder.create_publisher(PoseStamped, ifc.TOPIC_POSE, 10)
        pub_contact = feeder.create_publisher(JointState, ifc.TOPIC_CONTACT, 10)
        i = 0

        def feed_until(cond, timeout: float) -> bool:
            nonlocal i
            end = time.monotonic() + timeout
            while time.monotonic() < end:
                for pub, m in zip((pub_pose, pub_contact), _press(i)):
                    pub.publish(m)
                i += 1
                if cond():
                    return True
                time.sleep(0.01)
            return cond()

        # nobody subscribes: frames pass (30 Hz) and nothing is built
        assert feed_until(lambda: vis.frames_unwatched >= 30 and vis._contact is not None, 60.0)
        assert vis.n_published == 0
        assert vis.n_dent_frames == 0
        assert vis.surface is not None   # the default case has a dent to draw
        # a subscriber to the markers: they are published
        got = []
        feeder.create_subscription(MarkerArray, ifc.TOPIC_MARKERS, got.append, 10)
        assert feed_until(lambda: len(got) > 3, 30.0)
        assert vis.n_dent_frames == 0   # the dent's topic still has none
        # a subscriber to the surface: the dent follows the press
        feeder.create_subscription(MarkerArray, ifc.TOPIC_TISSUE, lambda m: None, QoSProfile(
            depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        assert feed_until(lambda: vis.n_dent_frames > 3, 30.0)
