"""Falcon delta-robot kinematics (haptic_anfis.device.falcon_kinematics), SI units."""
from __future__ import annotations

import math

import numpy as np
import pytest

from haptic_anfis.device import falcon_kinematics as k

C = np.array(k.WORKSPACE_CENTER)
H = 0.04  # the +-4 cm cube around the centre is inside the reach of every leg


def cube(n=7):
    s = np.linspace(-H, H, n)
    return [C + (x, y, z) for x in s for y in s for z in s]


def random_points(rng, n=200):
    return C + rng.uniform(-H, H, size=(n, 3))


def test_ik_matches_the_published_closed_form():
    """libnifalcon's (Stamper's) per-leg quadratic in t = tan(theta/2), written out here as an
    independent check of our atan2/acos form and its branch."""
    g = k.GEOMETRY
    a, b, c, d, e, f = g.a, g.b, g.c, g.d, g.e, g.f
    for p in cube(5):
        ours = k.inverse_kinematics(p)
        for i, phi in enumerate(g.phi):
            pu = math.cos(phi) * p[0] + math.sin(phi) * p[1] - g.r
            pv = -math.sin(phi) * p[0] + math.cos(phi) * p[1] - g.s
            pw = p[2]
            s3 = math.sin(math.acos((pv + f) / b))
            common = pw ** 2 + pu ** 2 + 2 * c * pu + a * a + c * c - (d + e + b * s3) ** 2
            l0 = common - 2 * a * pu - 2 * a * c
            l1 = -4 * a * pw
            l2 = common + 2 * a * pu + 2 * a * c
            t = (-l1 - math.sqrt(l1 * l1 - 4 * l0 * l2)) / (2 * l2)
            assert ours[i] == pytest.approx(2 * math.atan(t), abs=1e-12)


def test_forward_of_inverse_is_identity_over_the_workspace(rng):
    worst = 0.0
    for p in cube(7) + list(random_points(rng)):
        theta = k.inverse_kinematics(p)
        assert max(abs(v) for v in k.constraints(p, theta)) < 1e-15
        q = k.forward_kinematics(theta)                    # from the default guess
        worst = max(worst, float(np.max(np.abs(np.array(q) - p))))
        q2 = k.forward_kinematics(theta, guess=p + 0.002)  # from a nearby guess (servo loop)
        worst = max(worst, float(np.max(np.abs(np.array(q2) - p))))
    assert worst < 1e-9


def test_inverse_of_forward_is_identity(rng):
    for p in random_points(rng, 50):
        theta = k.inverse_kinematics(p)
        assert np.allclose(k.inverse_kinematics(k.forward_kinematics(theta)), theta,
                           atol=1e-10, rtol=0)


def test_symmetric_angles_put_the_tip_on_the_axis():
    p = k.forward_kinematics((0.6, 0.6, 0.6))
    assert abs(p[0]) < 1e-12 and abs(p[1]) < 1e-12 and 0.05 < p[2] < 0.2


def test_jacobian_against_finite_differences(rng):
    h = 1e-6
    for p in list(random_points(rng, 40)) + [C, C + (H, H, H), C - (H, H, H)]:
        theta = np.array(k.inverse_kinematics(p))
        J = np.array(k.jacobian(p))
        fd = np.empty((3, 3))
        for j in range(3):
            dt = np.zeros(3)
            dt[j] = h
            fd[:, j] = (np.array(k.forward_kinematics(theta + dt, guess=p))
                        - np.array(k.forward_kinematics(theta - dt, guess=p))) / (2 * h)
        assert np.allclose(J, fd, rtol=1e-6, atol=1e-9 * np.abs(J).max()), (p, J, fd)


def test_force_torque_force_round_trip_and_virtual_work(rng):
    for p in random_points(rng, 60):
        F = rng.normal(size=3) * 4.0
        tau = k.force_to_torque(p, F)
        assert np.allclose(k.torque_to_force(p, tau), F, rtol=1e-10, atol=1e-10)
        J = np.array(k.jacobian(p))
        assert np.allclose(tau, J.T @ F, rtol=1e-10, atol=1e-12)
        dtheta = rng.normal(size=3) * 1e-3
        assert np.dot(tau, dtheta) == pytest.approx(np.dot(F, J @ dtheta), rel=1e-10)


def test_ten_newtons_needs_plausible_torques():
    """10 N on a ~6 cm lever: torques of the order of 0.1-1 N m, well inside int16 counts."""
    for F in ((10.0, 0, 0), (0, 10.0, 0), (0, 0, 10.0)):
        tau = k.force_to_torque(k.WORKSPACE_CENTER, F)
        assert 0.05 < max(map(abs, tau)) < 1.5
        assert max(map(abs, k.torques_to_commands(tau))) < 32767


def test_ticks_and_commands_conversions():
    g = k.GEOMETRY
    assert g.rad_per_tick == pytest.approx(math.radians(360 * 14.25 / (1280 * 110)))
    assert k.ticks_to_angles((0, 0, 0)) == (g.theta_offset,) * 3
    ticks = (-1234, 0, 4321)
    assert k.angles_to_ticks(k.ticks_to_angles(ticks)) == ticks
    tau = (0.1, -0.2, 0.3)
    assert k.commands_to_torques(k.torques_to_commands(tau)) == pytest.approx(tau)
    assert k.torques_to_commands((0.1, 0, 0))[0] == pytest.approx(-1000.0)


def test_unreachable_points_raise():
    for p in ((0.0, 0.0, 0.5), (0.3, 0.0, 0.1), (0.0, 0.0, -0.2)):
        with pytest.raises(k.KinematicsError):
            k.inverse_kinematics(p)
    with pytest.raises(k.KinematicsError):
        k.forward_kinematics((3.0, -3.0, 3.0))


def test_gravity_force_points_up():
    f = k.gravity_force(0.1)
    assert f[1] == pytest.approx(0.1 * k.G) and f[0] == 0 and f[2] == 0
