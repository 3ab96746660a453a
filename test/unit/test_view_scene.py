"""The views' probe drawn about its centre (view/scene.py, no ROS, no viser): RViz's cylinder."""
from __future__ import annotations

import pytest

from haptic_anfis.view.scene import PROBE_LENGTH, probe_centred, probe_quaternion


def test_the_probe_drawn_about_its_centre_has_its_face_at_the_tip():
    """Half the probe's length behind the tip, against the indentation direction; no direction
    (or a zero or non-finite one): along the nipple axis."""
    c, q = probe_centred((0.04, 0.01, 0.0), (0.0, -2.0, 0.0))
    assert c == pytest.approx((0.04, 0.01 + PROBE_LENGTH / 2, 0.0))
    assert q == pytest.approx(probe_quaternion((0.0, -1.0, 0.0)))
    for d in (None, (0.0, 0.0, 0.0), (float('nan'), 0.0, 0.0)):
        c, q = probe_centred((0.04, 0.0, 0.0), d)
        assert c == pytest.approx((0.04 + PROBE_LENGTH / 2, 0.0, 0.0))
        assert q == pytest.approx(probe_quaternion((-1.0, 0.0, 0.0)))
