"""Kinematics of the Novint Falcon, a three-legged delta-type parallel robot (pure, no I/O).

SI units throughout (m, rad, N, N m); encoder ticks and motor-command counts appear only in
:func:`ticks_to_angles` / :func:`torques_to_commands` and their inverses, at the packet edge.

Model (R. E. Stamper, *A Three Degree of Freedom Parallel Manipulator with Only Translational
Degrees of Freedom*, PhD thesis, University of Maryland, 1997 — the leg model libnifalcon uses).
Falcon frame ("F"): origin on the device's axis of symmetry in the plane of the three motor
axes, +z out of the device towards the user, +y up, +x to the user's right (libnifalcon's frame).
Leg ``i`` sits at angle ``phi[i]`` about z; its frame (u, v, w) is the F frame turned by
``phi[i]`` and shifted by ``(r, s)``::

    pu =  cos(phi) x + sin(phi) y - r
    pv = -sin(phi) x + cos(phi) y - s
    pw =  z

The motor turns the upper arm (length ``a``) by ``theta`` in the u-w plane; the knee-to-effector
parallelogram (side ``b``, at angle ``theta3`` to v, so ``pv = b cos(theta3) - f``) plus the
joint offsets ``d + e`` reach, projected on the u-w plane, a length
``K = d + e + b sin(theta3)``; the effector's attachment is offset by ``c`` along u. Leg i closes
when

    g_i(p, theta_i) = (a cos(theta_i) - (pu + c))^2 + (pw - a sin(theta_i))^2 - K(pv)^2 = 0

(our own derivation from that model; it reproduces libnifalcon's closed-form inverse kinematics,
checked in the tests). Three legs, three unknowns: inverse kinematics solves each g_i for
theta_i in closed form; forward kinematics solves g(p, theta) = 0 for p by Newton's method; the
Jacobian ``J = dp/dtheta = -(dg/dp)^-1 diag(dg/dtheta)`` follows from the implicit function
theorem, and by virtual work the motor torques for a tip force F are ``tau = J^T F``.

Geometry constants: libnifalcon's ``include/falcon/core/FalconGeometry.h`` (measurements by Kevin
Ouellet, letters as in Stamper's thesis figure, p. 30), in metres, in its 2009 revision: c = 0.01443,
r = 0.0400, s = -0.02309 m replaced the 2007-08 values c = 0.014, r = 0.037233758,
s = -0.027330909 m (the later values are the ones libnifalcon ships and the ones its users run on
hardware; with the old ones the computed tip is 2-4.5 mm off, see the tests). Encoder: 320-slot wheel read in quadrature
(1280 ticks per motor turn), a 14.25 mm capstan on a 110 mm arm drum, ticks = 0 at about 35 deg
(libnifalcon ``getTheta``). Motor command scale: libnifalcon sends ``-10000 * tau`` [N m]
counts — an empirical scale from that project, not a measured motor constant. Nothing here has
been checked against a real Falcon in this project.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from ..errors import HapticAnfisError


@dataclass(frozen=True)
class FalconGeometry:
    """The Falcon's leg geometry [m, rad] and encoder / motor-command scales (see module doc)."""
    a: float = 0.060          # upper arm: motor axis to knee
    b: float = 0.1025         # parallelogram side (shin)
    c: float = 0.01443        # effector attachment offset along u (2009 value; was 0.014)
    d: float = 0.01125        # shin-to-effector joint offset
    e: float = 0.01125        # knee-to-shin joint offset
    f: float = -0.025         # effector attachment offset along v
    r: float = 0.0400         # leg base, u component (2009 value; was 0.037233758)
    s: float = -0.02309       # leg base, v component (2009 value; was -0.027330909)
    #: leg angles about z: 90, -30, -150 deg plus the 15 deg tilt of the legs to the desk plane.
    phi: tuple[float, float, float] = (math.radians(105.0), math.radians(-15.0),
                                       math.radians(-135.0))
    slots: int = 320                # encoder wheel slots (x4 quadrature)
    shaft_diameter: float = 0.01425  # motor capstan [m]
    arm_diameter: float = 0.110      # arm drum the capstan drives [m]
    theta_offset: float = math.radians(35.0)  # arm angle at encoder zero (approximate)
    counts_per_nm: float = 10000.0   # motor command counts per N m (libnifalcon's scale)
    command_sign: float = -1.0       # command = sign * counts_per_nm * torque

    @property
    def rad_per_tick(self) -> float:
        """Arm rotation per encoder tick: capstan arc per tick over the drum radius."""
        return (math.pi * self.shaft_diameter / (4 * self.slots)) / (self.arm_diameter / 2.0)


GEOMETRY = FalconGeometry()

#: A point near the middle of the reachable workspace, Falcon frame [m] (z along the axis).
WORKSPACE_CENTER = (0.0, 0.0, 0.11)
#: Standard gravity [m/s^2] and its direction in the Falcon frame (+y is up, desk level).
G = 9.80665
GRAVITY_DIRECTION = (0.0, -1.0, 0.0)


class KinematicsError(HapticAnfisError, ValueError):
    """A position the legs cannot reach, or angles no position matches."""


# -- one leg ---------------------------------------------------------------------------------------
def _leg(p, i: int, geo: FalconGeometry):
    """(pu + c, pv + f, pw, cos phi, sin phi) of point p in leg i's frame."""
    cp, sp = math.cos(geo.phi[i]), math.sin(geo.phi[i])
    x, y, z = p
    return cp * x + sp * y - geo.r + geo.c, -sp * x + cp * y - geo.s + geo.f, z, cp, sp


def _reach(vf: float, geo: FalconGeometry, i: int = 0):
    """K = d + e + b sin(theta3) and dK/d(pv) at pv + f = ``vf``."""
    q = vf / geo.b
    if not -1.0 < q < 1.0:
        raise KinematicsError(f'leg {i + 1}: |pv + f| = {abs(vf):.4f} m >= b (parallelogram '
                              'cannot reach)')
    sq = math.sqrt(1.0 - q * q)
    return geo.d + geo.e + geo.b * sq, -q / sq


def inverse_kinematics(p, geo: FalconGeometry = GEOMETRY) -> tuple[float, float, float]:
    """Motor arm angles theta (3,) [rad] that put the tip at ``p`` (3,) [m], Falcon frame.

    Each leg: ``2a (U cos t + W sin t) = a^2 + U^2 + W^2 - K^2`` with U = pu + c, W = pw, solved
    as ``t = atan2(W, U) - acos(rhs / (2 a R))`` (the knee-out branch the Falcon assembles in).

    Raises:
        KinematicsError: ``p`` is out of reach of some leg.
    """
    out = []
    for i in range(3):
        U, V, W, _, _ = _leg(p, i, geo)
        K, _ = _reach(V, geo, i)
        R = math.hypot(U, W)
        rhs = (geo.a * geo.a + R * R - K * K) / (2.0 * geo.a * R) if R > 0 else math.inf
        if not -1.0 <= rhs <= 1.0:
            raise KinematicsError(f'leg {i + 1}: point {tuple(p)} out of reach')
        out.append(math.atan2(W, U) - math.acos(rhs))
    return tuple(out)


def constraints(p, theta, geo: FalconGeometry = GEOMETRY) -> tuple[float, float, float]:
    """g (3,) [m^2]: zero where the three legs at angles ``theta`` close at ``p``."""
    out = []
    for i in range(3):
        U, V, W, _, _ = _leg(p, i, geo)
        K, _ = _reach(V, geo, i)
        t = theta[i]
        du, dw = geo.a * math.cos(t) - U, W - geo.a * math.sin(t)
        out.append(du * du + dw * dw - K * K)
    return tuple(out)


def constraint_derivatives(p, theta, geo: FalconGeometry = GEOMETRY):
    """(G_p, G_t): dg/dp as 3 rows of 3 [m], and the diagonal dg_i/dtheta_i (3,) [m^2]."""
    rows, gt = [], []
    for i in range(3):
        U, V, W, cp, sp = _leg(p, i, geo)
        K, dK = _reach(V, geo, i)
        t = theta[i]
        ct, st = math.cos(t), math.sin(t)
        dg_du = -2.0 * (geo.a * ct - U)
        dg_dv = -2.0 * K * dK
        dg_dw = 2.0 * (W - geo.a * st)
        rows.append((dg_du * cp - dg_dv * sp, dg_du * sp + dg_dv * cp, dg_dw))
        gt.append(2.0 * geo.a * (U * st - W * ct))
    return rows, tuple(gt)


# -- small dense helpers (pure Python: no numpy call overhead per 3x3 in the 1 kHz loop) -----------
def _det3(m) -> float:
    return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))


def _solve3(m, rhs):
    """x with m x = rhs (Cramer's rule); KinematicsError if m is singular."""
    det = _det3(m)
    if det == 0.0 or not math.isfinite(det):
        raise KinematicsError('singular configuration')
    out = []
    for k in range(3):
        mk = [list(row) for row in m]
        for j in range(3):
            mk[j][k] = rhs[j]
        out.append(_det3(mk) / det)
    return tuple(out)


def _transpose(m):
    return tuple(tuple(m[j][i] for j in range(3)) for i in range(3))


# -- whole mechanism -------------------------------------------------------------------------------
def forward_kinematics(theta, guess=WORKSPACE_CENTER, geo: FalconGeometry = GEOMETRY,
                       tol: float = 1e-13, max_iter: int = 30) -> tuple[float, float, float]:
    """Tip position p (3,) [m], Falcon frame, of the arm angles ``theta`` (3,) [rad].

    Newton's method on g(p, theta) = 0 from ``guess`` (pass the previous position in a servo
    loop: it then converges in 2-3 steps), with step halving while a step leaves the legs'
    reach. Converged when the step is below ``tol`` metres.

    Raises:
        KinematicsError: no convergence (angles no position matches, or a singular pose).
    """
    p = tuple(float(v) for v in guess)
    for _ in range(max_iter):
        try:
            g = constraints(p, theta, geo)
            gp, _ = constraint_derivatives(p, theta, geo)
        except KinematicsError:
            raise KinematicsError(f'angles {tuple(theta)}: Newton left the workspace') from None
        step = _solve3(gp, g)
        lam = 1.0
        for _ in range(30):
            q = (p[0] - lam * step[0], p[1] - lam * step[1], p[2] - lam * step[2])
            try:
                constraints(q, theta, geo)
                break
            except KinematicsError:
                lam *= 0.5
        p = q
        if lam * max(abs(step[0]), abs(step[1]), abs(step[2])) < tol:
            _check_branch(p, theta, geo)
            return p
    raise KinematicsError(f'angles {tuple(theta)}: forward kinematics did not converge')


def _check_branch(p, theta, geo: FalconGeometry) -> None:
    """g = 0 also holds for the mirrored (knee-in) assembly: accept p only if the physical
    branch of the inverse kinematics gives back ``theta``."""
    back = inverse_kinematics(p, geo)
    for t, u in zip(theta, back):
        if abs(math.remainder(t - u, 2.0 * math.pi)) > 1e-6:
            raise KinematicsError(f'angles {tuple(theta)}: no physical assembly reaches them '
                                  f'(Newton found the mirrored one at {p})')


def jacobian(p, theta=None, geo: FalconGeometry = GEOMETRY):
    """J = dp/dtheta (3 rows of 3) [m/rad] at tip position ``p`` (angles from
    :func:`inverse_kinematics` unless given)."""
    if theta is None:
        theta = inverse_kinematics(p, geo)
    gp, gt = constraint_derivatives(p, theta, geo)
    cols = [_solve3(gp, tuple(-gt[k] if j == k else 0.0 for j in range(3))) for k in range(3)]
    return tuple(tuple(cols[k][i] for k in range(3)) for i in range(3))


def force_to_torque(p, force, theta=None, geo: FalconGeometry = GEOMETRY):
    """Motor torques tau (3,) [N m] that push the tip at ``p`` with ``force`` (3,) [N]:
    ``tau = J^T F`` (computed as ``tau_i = -dg_i/dtheta_i * w_i`` with ``G_p^T w = F``)."""
    if theta is None:
        theta = inverse_kinematics(p, geo)
    gp, gt = constraint_derivatives(p, theta, geo)
    w = _solve3(_transpose(gp), force)
    return tuple(-gt[i] * w[i] for i in range(3))


def torque_to_force(p, torque, theta=None, geo: FalconGeometry = GEOMETRY):
    """The tip force (3,) [N] motor torques ``torque`` (3,) [N m] produce at ``p``:
    ``F = J^-T tau = -G_p^T (tau / G_t)``."""
    if theta is None:
        theta = inverse_kinematics(p, geo)
    gp, gt = constraint_derivatives(p, theta, geo)
    w = [-torque[i] / gt[i] for i in range(3)]
    return tuple(sum(gp[j][i] * w[j] for j in range(3)) for i in range(3))


# -- the packet edge: ticks and counts -------------------------------------------------------------
def ticks_to_angles(ticks, geo: FalconGeometry = GEOMETRY) -> tuple[float, float, float]:
    """Encoder ticks (3 ints) -> arm angles theta (3,) [rad]."""
    k = geo.rad_per_tick
    return tuple(geo.theta_offset + k * t for t in ticks)


def angles_to_ticks(theta, geo: FalconGeometry = GEOMETRY) -> tuple[int, int, int]:
    """Arm angles [rad] -> the nearest encoder ticks (for fake devices and tests)."""
    k = geo.rad_per_tick
    return tuple(int(round((t - geo.theta_offset) / k)) for t in theta)


def torques_to_commands(torque, geo: FalconGeometry = GEOMETRY) -> tuple[float, float, float]:
    """Motor torques [N m] -> motor command counts (floats; saturate with
    :func:`haptic_anfis.device.falcon_protocol.saturate_int16` before encoding)."""
    k = geo.command_sign * geo.counts_per_nm
    return tuple(k * t for t in torque)


def commands_to_torques(commands, geo: FalconGeometry = GEOMETRY) -> tuple[float, float, float]:
    """Inverse of :func:`torques_to_commands`."""
    k = geo.command_sign * geo.counts_per_nm
    return tuple(c / k for c in commands)


def gravity_force(mass: float) -> tuple[float, float, float]:
    """The force [N], Falcon frame, that holds up ``mass`` kg at the tip (gravity compensation:
    the grip and the arms' weight lumped at the tip)."""
    return tuple(-mass * G * g for g in GRAVITY_DIRECTION)
