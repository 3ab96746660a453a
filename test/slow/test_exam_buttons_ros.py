"""The driver's clutch and mark through the in-process graph: the simulated hand presses both
buttons; the recorded bag shows the frozen probe, the kept offset and the mark."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from rclpy.parameter import Parameter  # noqa: E402

from haptic_anfis.bag import read_messages  # noqa: E402
from haptic_anfis.bag.topics import ALL_LOOP_TOPICS  # noqa: E402
from haptic_anfis.nodes.graph import build_graph  # noqa: E402
from haptic_anfis.nodes.recorder import Recorder  # noqa: E402

pytestmark = pytest.mark.ros

SCRIPT = {'loop': False, 'start_delay': 0.2, 'approach_height': 0.006, 'pattern': [
    {'mark': {'points': [[0.010, 0.0]], 'depth': 0.012, 'hold': 0.4, 'click': 0.1}},
    {'clutch': {'shift': [0.0, 0.020, 0.0]}},
    {'press': {'points': [[0.0, 0.0]], 'depth': 0.012, 'hold': 0.3}}]}


def test_clutch_freezes_the_probe_keeps_the_offset_and_mark_is_recorded(tmp_path):
    script = tmp_path / 's.yaml'
    script.write_text(yaml.safe_dump(SCRIPT))
    bag = tmp_path / 'bag'
    g = build_graph(['test'], visualizer=False,
                    overrides={'falcon_driver': [Parameter('palpation_script', value=str(script))]},
                    extra=[lambda ctx: Recorder(context=ctx, output=str(bag),
                                                topics=ALL_LOOP_TOPICS)])
    dev = g.driver.device
    try:
        g.spin_for(dev.script.duration + 1.0)
    finally:
        g.shutdown()
    poses, joys, marks = [], [], []
    for topic, _, _, m in read_messages(bag):
        t = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        if topic == '/falcon/measured_cp':
            poses.append((t, m.pose.position.x, m.pose.position.y, m.pose.position.z))
        elif topic == '/falcon/buttons':
            joys.append((t, list(m.buttons)))
        elif topic == '/exam/marks':
            marks.append((m.point.x, m.point.y, m.point.z))
    poses = np.array(poses)
    assert len(marks) == 1
    assert marks[0][1] == pytest.approx(0.010, abs=0.003) and marks[0][0] < 0.045  # in the tissue
    # Joy comes on change (and every 100 ticks): clutch held from the first 1 to the next 0
    t_on = next(t for t, b in joys if b[0] == 1)
    t_off = next(t for t, b in joys if t > t_on and b[0] == 0)
    held = (poses[:, 0] >= t_on) & (poses[:, 0] < t_off)
    assert held.sum() > 20
    assert np.ptp(poses[held, 1:], axis=0).max() < 1e-9        # frozen while held
    # after the clutch the hand is 20 mm off in y, yet the probe presses at y = 0 as scripted
    last = poses[poses[:, 0] > t_off + 0.3]
    deepest = last[np.argmin(last[:, 1])]
    assert abs(deepest[2]) < 0.003
    assert g.driver.clutch.clutches == 1 and g.driver.clutch.marks == 1
