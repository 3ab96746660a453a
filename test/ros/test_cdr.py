"""The loop's hot messages on the wire (nodes/cdr.py): read and written exactly as rclpy does."""
from __future__ import annotations

import math
from array import array

import numpy as np
import pytest

pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from haptic_anfis.nodes import cdr  # noqa: E402
from haptic_anfis import interfaces as ifc  # noqa: E402

FRAMES = ['', 't', 'ti', 'tis', 'tiss', 'tissue', 'tissue_', 'tissue_fr', 'é-frame']


@pytest.mark.parametrize('frame', FRAMES)
def test_wrench_stamped_both_ways(frame):
    rng = np.random.default_rng(len(frame))
    for f in (rng.normal(size=3), (math.nan, 0.0, 1.0), (math.inf, -math.inf, 0.0)):
        m = WrenchStamped()
        m.header.frame_id = frame
        m.header.stamp.sec, m.header.stamp.nanosec = 1_763_900_000, 123_456_789
        m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = (float(c) for c in f)
        stamp, fr, got = cdr.read_wrench_stamped(serialize_message(m))
        assert stamp == 1_763_900_000_123_456_789 and fr == frame
        np.testing.assert_array_equal(got, np.asarray(f, dtype=float))
        back = deserialize_message(cdr.WrenchStampedWriter(frame).pack(stamp, f), WrenchStamped)
        assert back.header.frame_id == frame and back.header.stamp.nanosec == 123_456_789
        np.testing.assert_array_equal([back.wrench.force.x, back.wrench.force.y,
                                       back.wrench.force.z], np.asarray(f, dtype=float))
        assert (back.wrench.torque.x, back.wrench.torque.y, back.wrench.torque.z) == (0, 0, 0)


@pytest.mark.parametrize('frame', FRAMES)
def test_pose_position_reads_what_rclpy_wrote(frame):
    rng = np.random.default_rng(7 + len(frame))
    m = PoseStamped()
    m.header.frame_id = frame
    m.header.stamp.sec, m.header.stamp.nanosec = 1_763_900_001, 5
    p = rng.normal(size=3)
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(c) for c in p)
    m.pose.orientation.w = 0.5
    stamp, fr, got = cdr.read_pose_position(serialize_message(m))
    assert stamp == 1_763_900_001_000_000_005 and fr == frame
    np.testing.assert_array_equal(got, p)
    with pytest.raises(ValueError, match='malformed PoseStamped'):
        cdr.read_pose_position(serialize_message(m)[:20])


@pytest.mark.parametrize('frame', FRAMES)
@pytest.mark.parametrize('names', [[], ['a'], list(ifc.CONTACT_FIELDS), list(ifc.LOCAL_MODEL_FIELDS)])
def test_joint_state_both_ways(frame, names):
    rng = np.random.default_rng(len(frame) + len(names))
    pos = rng.normal(size=len(names) or 3).tolist()
    effort = rng.normal(size=6).tolist() if len(names) == len(ifc.CONTACT_FIELDS) else []
    m = JointState(name=names, position=array('d', pos), effort=array('d', effort))
    m.header.frame_id = frame
    m.header.stamp.sec, m.header.stamp.nanosec = 7, 999_999_999
    stamp, fr, p, e = cdr.read_joint_state(serialize_message(m))
    assert stamp == 7_999_999_999 and fr == frame
    assert list(p) == pos and list(e) == effort
    w = cdr.JointStateWriter(frame, names, len(pos))
    back = deserialize_message(w.pack(stamp, pos), JointState)
    assert list(back.name) == names and list(back.position) == pos
    assert back.header.frame_id == frame and back.header.stamp.sec == 7
    assert len(back.velocity) == 0 and len(back.effort) == 0
    with pytest.raises(ValueError, match='positions'):
        w.pack(stamp, pos + [1.0])


def test_malformed_bytes_are_a_value_error():
    good = serialize_message(JointState(name=['a'], position=array('d', [1.0])))
    for bad in (good[:10], good[:4] + b'\xff' * 12, b''):
        with pytest.raises(ValueError, match='JointState'):
            cdr.read_joint_state(bad)
    w = serialize_message(WrenchStamped())
    for bad in (w[:20], b'\x00\x01\x00\x00' + b'\xff' * 30):
        with pytest.raises(ValueError, match='WrenchStamped'):
            cdr.read_wrench_stamped(bad)


@pytest.mark.parametrize('frame', FRAMES)
def test_the_layout_reader_takes_its_own_and_any_other_message(frame):
    """JointStateWriter.read: its own bytes at the known offset; rclpy's (other padding bytes),
    other names, other frames, or non-empty effort through the general reader; same answers."""
    names = list(ifc.LOCAL_MODEL_FIELDS)
    w = cdr.JointStateWriter(frame, names, len(names))
    pos = np.random.default_rng(1).normal(size=len(names)).tolist()
    assert w.read(w.pack(42, pos)) == (42, frame, tuple(pos), ())
    for m in (JointState(name=names, position=array('d', pos)),
              JointState(name=names[:-1] + ['zz'], position=array('d', pos)),
              JointState(name=names, position=array('d', pos), effort=array('d', [1.0])),
              JointState(name=[], position=array('d', pos[:3]))):
        m.header.frame_id = frame + 'x' if m.name == [] else frame
        m.header.stamp.sec = 3
        raw = serialize_message(m)
        assert w.read(raw) == cdr.read_joint_state(raw)
        assert w.read(raw)[2] == tuple(m.position)
    with pytest.raises(ValueError, match='JointState'):
        w.read(w.pack(42, pos)[:40])
