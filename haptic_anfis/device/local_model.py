"""The local force model rendered in the servo loop (no ROS): an "intermediate representation".

The force server is slower than the 1 kHz servo loop and arrives late (1-20 ms across processes
on a loaded machine). A zero-order hold of its last force renders a stale force; at a stiff
surface that error is what buzzes. Following Adachi et al. 1995 (intermediate representation),
Mark et al. 1996 and Cavusoglu & Tendick 2000 (a local linearisation sent to the fast loop), the
force server sends with every force the local model of the force field at the contact, and the
servo loop evaluates it at the current probe position every tick::

    F(p) = F0 + K (p - p0)                                   (3,) N, p (3,) m, K (3, 3) N/m

with these rules (the compiled servo tick renders them, :mod:`.native_tick`):

- Depth and leaving contact. The model carries the contact's surface point ``c0``, outward normal
  ``n`` and indentation direction ``d``; the depth at ``p`` is measured along ``d`` to the tangent
  plane at ``c0``: ``depth(p) = (p - c0) . g`` with ``g = n / (n . d)`` (:func:`depth_gradient`).
  ``depth(p) <= 0`` (the probe is out along the local normal) gives zero force at once.
- No step at contact onset. Where the model's force is zero at depth 0 (``zero_at_surface``), the
  linear model is corrected between the surface and ``depth0`` so that it is zero on the surface:
  ``F = L(p) - (1 - depth/depth0)^2 L(p_s)`` with ``p_s`` the probe projected along ``d`` onto the
  tangent plane. The correction is zero at ``depth0`` with zero slope (the tangent stiffness is
  kept), zero for a linear field that is itself zero on the plane (exactness kept), and makes the
  force exactly zero at depth 0 whatever the tangential offset.
- Stiffness guard (:func:`condition_stiffness`): K's symmetric part ``S = (K + K^T) / 2`` is made
  negative-semidefinite ("the surface pushes back": a passive spring) with its eigenvalues clamped
  to ``-max_stiffness``; its skew part ``A = (K - K^T) / 2`` is kept, bounded to ``max_stiffness``
  (``A e = w x e``, ``|w| <= max_stiffness``). Bounds aside, the result is the K nearest the
  model's (Frobenius: the two parts are orthogonal) whose quadratic form is <= 0: a displacement
  ``e`` never gains force along itself (``e . K e = e . S e <= 0``). The skew part is the
  tissue field's own: the ANFIS force turns as the probe moves (its lateral components grow with
  the depth), which the force server's F0 carries at every model anyway; dropping it made the
  force between two models drift away from the tissue's by ~0.04 % of the force per ms of model
  age and jump back at the next model (with it ~0.01 %/ms; docs/servo_loop.md, *Parameters
  chosen by measurement*). It does not enter the sampling bound below: a zero-order
  hold's energy leak per period is ``-T^2 v . K v / 2``, and ``v . A v = 0``.
  The Falcon figure: 3000 N/m, the maximum linear stiffness CHAI3D's Falcon driver advertises
  (``cHapticDeviceInfo::m_maxLinearStiffness``, with 8 N and 20 N s/m damping). By Colgate & Brown
  1994 a sampled spring K is passive when the device's own damping b > K T / 2 + B: at T = 1 ms
  and 3000 N/m that asks 1.5 N s/m of mechanism damping. Tissue-frame stiffness maps to the
  device as ``force_scale * workspace_scale * K``, so the tissue-frame bound is
  ``max_stiffness / (force_scale * workspace_scale)`` (:func:`tissue_stiffness_limit`).
- Before contact (:attr:`LocalModel.approach`). A model made while the probe was free has depth
  0; with a normal it is the tangent plane of the surface ahead of the probe (p0 = the point it
  will touch, F0 = 0, K the stiffness at depth 0+): zero force outside the plane, ``K (p - p0)``
  the instant the probe is past it — so a press is rendered from its first tick instead of one
  force-server latency late. Without a normal (all zeros) it renders zero force. It is the
  plane of one point: with the probe further than ``approach_radius`` (:data:`APPROACH_RADIUS`)
  from that point along the plane (across the depth gradient, :func:`across_beyond`) it renders
  zero (free) — a convex surface lies under its tangent plane, so a stale plane followed sideways
  (a late graph, a stroke in free space) would press on the probe in free space; within the
  radius it is off by at most r^2 / 2R, 2.5 mm at 15 mm on the default breast (R >= 45 mm).
- Non-finite F0, p0, K, normal or direction: the model is rejected (the caller zeroes the force).
- Expiry: a model older than ``validity_time`` (measured from the time of the driver's own pose it
  answers, not from its arrival) is expired: the renderer stops extrapolating and the caller
  holds the last force and lets the watchdog ramp it to zero, as the zero-order hold does.
- Beyond ``validity_radius`` from ``p0`` (a late model under a fast stroke) the model (an
  approach plane: only within ``approach_radius``, above) is still rendered, with the depth
  followed exactly and the offset across the indentation direction held at the radius
  (:func:`hold_offset`): the force stays the tissue's at the probe's depth, a little behind along
  the surface; expiring it would drop the force to 0 N mid-press and bring it back with a
  jolt when the next model came. Counted (``ticks_beyond``).

The message (``falcon/servo_cf_local``, layout :data:`haptic_anfis.interfaces.LOCAL_MODEL_FIELDS`)
is encoded and decoded here, beside :class:`LocalModel`: :func:`model_values` /
:meth:`LocalModel.values` (encode), :func:`no_model` (the "no contact" model),
:meth:`LocalModel.from_values` (decode), :func:`check_values` (validate); the driver renders the
flat values directly (:meth:`~.tick_views.NativeRenderer.offer_values`).

Times are seconds on the caller's monotonic clock; lengths metres; forces newtons; tissue frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..interfaces import LM_C, LM_D, LM_DEPTH, LM_F0, LM_K, LM_N, LM_P0, LM_ZERO, LOCAL_MODEL_FIELDS

#: Falcon stiffness bound [N/m], device frame (CHAI3D's Falcon m_maxLinearStiffness; see above).
FALCON_MAX_STIFFNESS = 3000.0

#: [s] time constant of the tick periods the servo loop's passivity bound weighs (the measured
#: period T = sum(T_k^2) / sum(T_k), exponentially weighted; docs/servo_loop.md *Passivity*). A
#: late tick lowers the rendered stiffness for about this long; at 20 ms a gap of 7.5 ms at the
#: stiffness bound scaled the extrapolated force to a third and made ripple windows. Chosen by
#: replaying one run's trace (the shortest window that added no ripple window to the ideal
#: force's own), checked on another's (docs/servo_loop.md, *Parameters chosen by measurement*).
PASSIVITY_WINDOW = 0.05

#: How far [m] along an approach plane from its point it is rendered (module doc): the plane lies
#: r^2 / 2R above a convex surface of radius R there (2.5 mm at 15 mm on the default breast,
#: R >= 45 mm); past it the probe is free. Chosen by measurement: the largest radius
#: measured that adds no tick pressing on a free probe with the graph 500 ms late
#: (docs/servo_loop.md, *Parameters chosen by measurement*).
APPROACH_RADIUS = 0.015

#: [m] how far from its p0 the compiled tick renders a HELD model (older than its validity time,
#: younger than the hold time: an upstream stall); further, a held model that would press on
#: the probe is expired for those ticks (the watchdog ramps the force to zero; back inside the
#: radius it is rendered again: the tissue has not moved). A trainee who moved that far has left
#: the place the model describes: a held plane followed down a convex surface's flank pressed on
#: a free probe with up to 12 N (before the clamp) in 1 s stalls. Chosen by
#: replaying one session's trace: the smallest radius measured that adds no
#: dropout tick in stalls up to 0.6 s (the loaded sessions' longest pose -> model latency:
#: 0.40-0.57 s; 30 mm added some at 0.6 s, and cost a 0.54 s stall of a session 4 dropout
#: ticks); checked on another (docs/servo_loop.md, *Parameters chosen by measurement*).
HOLD_RADIUS = 0.04

#: [s] the longest the compiled tick takes to ramp out the step between two successive models:
#: where both press on the probe, a new model's force is reached over the old model's age at
#: the switch, at most this, not at once (native_tick._render_blended). Models a millisecond
#: apart disagree by a hair; one that comes after the graph was late disagrees with the old
#: model's extrapolation by tenths of a newton, and a step of 0.2 N already leaves the 50 ms
#: mean by 0.1 N (a ripple window); ramped over 20 ms, steps up to ~0.3 N make none.
#: Chosen by replaying recorded traces: the quiet error stays within its 0.2 % target
#: (docs/servo_loop.md, *Parameters chosen by measurement*).
MODEL_BLEND_TIME = 0.02

#: Tick status codes (also the trace's status column).
NONE, FRESH, EXTRAPOLATED, EXPIRED, FREE = 0, 1, 2, 3, 4
STATUS_NAMES = ('none', 'fresh', 'extrapolated', 'expired', 'free')

#: |n . d| below this is treated as this (a ray grazing the surface): bounds the depth gradient.
MIN_COS = 0.2


def depth_gradient(normal, direction) -> np.ndarray:
    """``g`` (3,) with depth(p) = depth0 + g . (p - p0): how the penetration depth measured along
    the unit indentation ``direction`` d to the plane with outward unit ``normal`` n moves with the
    probe, ``g = n / (n . d)`` (= -n when d = -n). ``n . d`` is held at or below ``-MIN_COS`` so a
    grazing ray cannot make the gradient explode."""
    return np.array(depth_gradient_values(*(float(c) for c in normal),
                                          *(float(c) for c in direction)))


def depth_gradient_values(nx: float, ny: float, nz: float, dx: float, dy: float, dz: float
                          ) -> tuple[float, float, float]:
    """:func:`depth_gradient` on plain floats (the driver's per-model path)."""
    c = min(nx * dx + ny * dy + nz * dz, -MIN_COS)
    return nx / c, ny / c, nz / c


def contact_jacobian(J, normal, direction) -> np.ndarray:
    """K = dF/dp (3, 3) [N/m] from the model's J = dF/d(x, y, z, depth) (3, 4) through the contact
    geometry, to first order in the tangent plane at the contact point:

    - depth(p) = depth0 + g . (p - p0), g from :func:`depth_gradient`;
    - contact point c(p) = p - depth(p) d, so dc/dp = I - d g^T (it slides in the plane);

    hence K = J_c (I - d g^T) + J_depth g^T = J_c + (J_depth - J_c d) g^T. Both contact-detector
    modes are this formula: a fixed ``direction`` d (the paper's axis), or the normal mode where
    d = -n (the tracker freezes d at entry; the stateless query has d = -n, giving
    dc/dp = I - n n^T and d depth/dp = -n^T). Plain floats: ~10 µs, called at 1 kHz."""
    return np.array(contact_stiffness(np.asarray(J, dtype=np.float64).reshape(3, 4).tolist(),
                                      [float(v) for v in normal],
                                      [float(v) for v in direction])).reshape(3, 3)


def contact_stiffness(J, normal, direction) -> list[float]:
    """:func:`contact_jacobian` on plain sequences: J 3 rows of 4, returns K row-major (9,)."""
    dx, dy, dz = direction
    gx, gy, gz = depth_gradient_values(*normal, dx, dy, dz)
    K = []
    for ja, jb, jc, jd in J:
        w = jd - (ja * dx + jb * dy + jc * dz)
        K += [ja + w * gx, jb + w * gy, jc + w * gz]
    return K


def stiffness_values(k) -> list[float]:
    """K's 9 values row-major as plain floats, from a (3, 3) array, 9 values, or 3 rows of 3.

    Raises:
        ValueError: not 9 values.
    """
    if type(k) is np.ndarray:
        v = k.ravel().tolist()
    else:
        v = list(k)
        if len(v) == 3 and all(hasattr(r, '__len__') for r in v):
            v = [c for r in v for c in r]
    if len(v) != 9:
        raise ValueError(f'stiffness K: expected a finite (3, 3) matrix [N/m], got {k!r}')
    return [float(c) for c in v]


def _clip(w: float, lo: float) -> float:
    return lo if w < lo else (0.0 if w > 0.0 else w)


def condition_stiffness_values(k, max_stiffness: float) -> tuple[tuple[float, ...], bool]:
    """:func:`condition_stiffness` on plain floats, in closed form (no numpy: ~10 µs instead of
    ~40 µs per model, which the driver pays once per received model on the thread that shares the
    servo thread's GIL). ``k``: 9 finite values row-major [N/m]. Returns (the conditioned K's 9
    values row-major, whether it differs from ``k`` by more than 1e-6 N/m).

    S = (K + K^T) / 2; its eigenvalues by the trigonometric closed form (Smith 1961). When they
    all lie in [-max_stiffness, 0], S is the answer as it is (the common case). Otherwise the
    eigenvector of the extreme eigenvalue with the larger gap to the middle one is taken from the
    largest cross product of two rows of S - lambda I (well conditioned: the gap is at least half
    the spectrum's width), the other two come from the exact 2 x 2 problem in its orthogonal
    complement (a Jacobi rotation), and S is rebuilt from the clipped eigenvalues — the same
    construction as a robust 3 x 3 symmetric eigensolver (cf. Eberly, Geometric Tools), written
    for this one job. The common case — one eigenvalue out of range, the other two in — is a
    rank-one correction with that eigenvalue's eigenvector only (:func:`_clip_one`). K's skew
    part is then added back, its |w| bounded to ``max_stiffness`` (:func:`skew_vector`; module
    docstring).
    """
    k00, k01, k02, k10, k11, k12, k20, k21, k22 = k
    a00, a11, a22 = k00, k11, k22
    a01, a02, a12 = 0.5 * (k01 + k10), 0.5 * (k02 + k20), 0.5 * (k12 + k21)
    lo = -max_stiffness
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
    if p2 <= 0.0:  # S = q I
        w = _clip(q, lo)
        out = (w, 0.0, 0.0, 0.0, w, 0.0, 0.0, 0.0, w)
    else:
        p = math.sqrt(p2 / 6.0)
        det = (b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02)
               + a02 * (a01 * a12 - b11 * a02))
        r = det / (2.0 * p * p * p)
        phi = math.acos(-1.0 if r < -1.0 else (1.0 if r > 1.0 else r)) / 3.0
        l1 = q + 2.0 * p * math.cos(phi)  # largest
        l3 = q + 2.0 * p * math.cos(phi + 2.0943951023931957)  # smallest (2 pi / 3)
        l2 = 3.0 * q - l1 - l3
        if l1 <= 0.0 and l3 >= lo:
            out = (a00, a01, a02, a01, a11, a12, a02, a12, a22)
        else:
            out = None
            if (l1 > 0.0) != (l3 < lo) and lo <= l2 <= 0.0:  # one eigenvalue out: rank one
                out = _clip_one(a00, a01, a02, a11, a12, a22, l1 if l1 > 0.0 else l3,
                                0.0 if l1 > 0.0 else lo)
            elif l2 > 0.0 and lo <= l3 <= 0.0:  # two pull (tangential, the usual): keep l3
                out = _keep_one(a00, a01, a02, a11, a12, a22, l3, 0.0, lo)
            elif l2 < lo and lo <= l1 <= 0.0:  # two too stiff: keep l1
                out = _keep_one(a00, a01, a02, a11, a12, a22, l1, lo, lo)
            if out is None:
                out = _rebuild_clipped(a00, a01, a02, a11, a12, a22, l1, l2, l3, lo)
    out = _with_skew(out, k, max_stiffness)
    changed = max(abs(out[i] - k[i]) for i in range(9)) > 1e-6
    return out, changed


def skew_vector(k) -> tuple[float, float, float]:
    """w of the skew part ``A = (K - K^T) / 2`` of ``k`` (9 values row-major [N/m]):
    ``A e = w x e`` for every e."""
    return 0.5 * (k[7] - k[5]), 0.5 * (k[2] - k[6]), 0.5 * (k[3] - k[1])


def _with_skew(s, k, bound: float) -> tuple[float, ...]:
    """The symmetric ``s`` (9 values) plus the skew part of ``k``, its |w| scaled to ``bound``."""
    w0, w1, w2 = skew_vector(k)
    ww = w0 * w0 + w1 * w1 + w2 * w2
    if ww == 0.0:
        return s
    if ww > bound * bound:
        c = bound / math.sqrt(ww)
        w0, w1, w2 = c * w0, c * w1, c * w2
    return (s[0], s[1] - w2, s[2] + w1, s[3] + w2, s[4], s[5] - w0, s[6] - w1, s[7] + w0, s[8])


def symmetric_part(k) -> tuple[float, ...]:
    """``(K + K^T) / 2`` of ``k`` (9 values row-major), 9 values."""
    a01, a02, a12 = 0.5 * (k[1] + k[3]), 0.5 * (k[2] + k[6]), 0.5 * (k[5] + k[7])
    return (k[0], a01, a02, a01, k[4], a12, a02, a12, k[8])


def rotating_mode(k) -> bool:
    """Whether the stiffness ``k`` (9 values row-major [N/m]) has a complex pair of eigenvalues:
    a mode in which its linear field turns the displacement instead of scaling it. A free handle
    of mass m and damping b in the field ``K e`` moves as m e'' + b e' - K e = 0; along a real
    eigenvalue -lambda >= 0 of K that is a damped spring, but along a complex pair with too
    little damping (or stiffness) the handle can spiral out (circulatory, "follower" forces).
    The tissue's skew part couples the depth with the surface (real modes: the normal stiffness
    dominates); a skew part turning the surface plane itself, where the guard left no stiffness,
    would not. By the sign of the discriminant of K's characteristic cubic (negative: a complex
    pair), relative to the scale of K so that a repeated real eigenvalue is not mistaken for one.
    """
    k00, k01, k02, k10, k11, k12, k20, k21, k22 = k
    tr = k00 + k11 + k22
    c2 = (k00 * k11 - k01 * k10) + (k00 * k22 - k02 * k20) + (k11 * k22 - k12 * k21)
    det = (k00 * (k11 * k22 - k12 * k21) - k01 * (k10 * k22 - k12 * k20)
           + k02 * (k10 * k21 - k11 * k20))
    # x^3 + b x^2 + c x + d with b = -tr, c = c2, d = -det
    b, c, d = -tr, c2, -det
    disc = 18.0 * b * c * d - 4.0 * b ** 3 * d + b * b * c * c - 4.0 * c ** 3 - 27.0 * d * d
    scale = max(abs(v) for v in k)
    return disc < -1e-9 * scale ** 6


def _eigenvector(a00, a01, a02, a11, a12, a22, la):
    """(u, |u|^2) with u an unnormalised eigenvector of the simple eigenvalue ``la``: the largest
    cross product of two rows of S - la I; None when all are ~0 (la repeated)."""
    r0 = (a00 - la, a01, a02)
    r1 = (a01, a11 - la, a12)
    r2 = (a02, a12, a22 - la)
    best, u = 0.0, None
    for ra, rb in ((r0, r1), (r0, r2), (r1, r2)):
        c = (ra[1] * rb[2] - ra[2] * rb[1], ra[2] * rb[0] - ra[0] * rb[2],
             ra[0] * rb[1] - ra[1] * rb[0])
        nn = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
        if nn > best:
            best, u = nn, c
    scale = a00 * a00 + a11 * a11 + a22 * a22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)
    if u is None or best <= 1e-24 * scale * scale:
        return None
    return u, best


def _rayleigh(a00, a01, a02, a11, a12, a22, ux, uy, uz) -> float:
    """u^T S u for the symmetric S (its upper triangle) and u (not normalised)."""
    return (ux * (a00 * ux + a01 * uy + a02 * uz) + uy * (a01 * ux + a11 * uy + a12 * uz)
            + uz * (a02 * ux + a12 * uy + a22 * uz))


def _keep_one(a00, a01, a02, a11, a12, a22, la, target, lo) -> tuple[float, ...] | None:
    """t I + (clip(rq) - t) u u^T: the two eigenvalues other than ``la`` are both out of range on
    the same side and go to ``target``; only la's eigenvector u is needed (rq its Rayleigh
    quotient, clipped to [lo, 0]). Accurate for the same reason as :func:`_clip_one`: the
    correction is at most la's gap to the other two. None: the general path."""
    e = _eigenvector(a00, a01, a02, a11, a12, a22, la)
    if e is None:
        return None
    (ux, uy, uz), nn = e
    rq = _rayleigh(a00, a01, a02, a11, a12, a22, ux, uy, uz) / nn
    w = (_clip(rq, lo) - target) / nn
    s01, s02, s12 = w * ux * uy, w * ux * uz, w * uy * uz
    s00, s11, s22 = target + w * ux * ux, target + w * uy * uy, target + w * uz * uz
    return (s00, s01, s02, s01, s11, s12, s02, s12, s22)


def _clip_one(a00, a01, a02, a11, a12, a22, la, target) -> tuple[float, ...] | None:
    """S - (la - target) u u^T, u the unit eigenvector of the one eigenvalue ``la`` that is out
    of range (the largest cross product of two rows of S - la I), or None when S - la I has
    rank < 2 (a repeated eigenvalue: the general path). Accurate because the other two are in
    range: |la - target| is at most la's gap to them, which bounds the eigenvector's error
    times the correction by rounding."""
    e = _eigenvector(a00, a01, a02, a11, a12, a22, la)
    if e is None:
        return None
    (ux, uy, uz), best = e
    # the Rayleigh quotient, not the closed-form la: exact to second order in u's error (the
    # trigonometric eigenvalue carries ~sqrt(eps) of the spectrum's width near a double root)
    rq = _rayleigh(a00, a01, a02, a11, a12, a22, ux, uy, uz) / best
    if (rq <= target) if target == 0.0 else (rq >= target):  # in range after all: S as it is
        return (a00, a01, a02, a01, a11, a12, a02, a12, a22)
    w = (rq - target) / best  # (rq - target) u u^T / |u|^2
    s00, s01, s02 = a00 - w * ux * ux, a01 - w * ux * uy, a02 - w * ux * uz
    s11, s12, s22 = a11 - w * uy * uy, a12 - w * uy * uz, a22 - w * uz * uz
    return (s00, s01, s02, s01, s11, s12, s02, s12, s22)


def _rebuild_clipped(a00, a01, a02, a11, a12, a22, l1, l2, l3, lo) -> tuple[float, ...]:
    """S (upper triangle) rebuilt with its eigenvalues clipped to [lo, 0]; l1 >= l2 >= l3 are
    its eigenvalues (see :func:`condition_stiffness_values`)."""
    la = l1 if l1 - l2 >= l2 - l3 else l3
    e = _eigenvector(a00, a01, a02, a11, a12, a22, la)
    if e is None:  # S - la I ~ 0: S = la I
        w = _clip(la, lo)
        return (w, 0.0, 0.0, 0.0, w, 0.0, 0.0, 0.0, w)
    u, best = e
    s = 1.0 / math.sqrt(best)
    ux, uy, uz = u[0] * s, u[1] * s, u[2] * s
    # an orthonormal basis (v, w) of u's complement
    if abs(ux) > abs(uy):
        s = 1.0 / math.sqrt(ux * ux + uz * uz)
        vx, vy, vz = -uz * s, 0.0, ux * s
    else:
        s = 1.0 / math.sqrt(uy * uy + uz * uz)
        vx, vy, vz = 0.0, uz * s, -uy * s
    wx, wy, wz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    # S u, S v, S w, then the Rayleigh quotient of u and the 2 x 2 block in (v, w)
    su0, su1, su2 = a00 * ux + a01 * uy + a02 * uz, a01 * ux + a11 * uy + a12 * uz, \
        a02 * ux + a12 * uy + a22 * uz
    sv0, sv1, sv2 = a00 * vx + a01 * vy + a02 * vz, a01 * vx + a11 * vy + a12 * vz, \
        a02 * vx + a12 * vy + a22 * vz
    sw0, sw1, sw2 = a00 * wx + a01 * wy + a02 * wz, a01 * wx + a11 * wy + a12 * wz, \
        a02 * wx + a12 * wy + a22 * wz
    mu = _clip(ux * su0 + uy * su1 + uz * su2, lo)
    mvv = vx * sv0 + vy * sv1 + vz * sv2
    mww = wx * sw0 + wy * sw1 + wz * sw2
    mvw = wx * sv0 + wy * sv1 + wz * sv2
    half, mean = 0.5 * (mvv - mww), 0.5 * (mvv + mww)
    rad = math.hypot(half, mvw)
    e1, e2 = _clip(mean + rad, lo), _clip(mean - rad, lo)
    th = 0.5 * math.atan2(mvw, half)
    c, s = math.cos(th), math.sin(th)
    xx, xy, xz = c * vx + s * wx, c * vy + s * wy, c * vz + s * wz
    yx, yy, yz = c * wx - s * vx, c * wy - s * vy, c * wz - s * vz
    s00 = mu * ux * ux + e1 * xx * xx + e2 * yx * yx
    s01 = mu * ux * uy + e1 * xx * xy + e2 * yx * yy
    s02 = mu * ux * uz + e1 * xx * xz + e2 * yx * yz
    s11 = mu * uy * uy + e1 * xy * xy + e2 * yy * yy
    s12 = mu * uy * uz + e1 * xy * xz + e2 * yy * yz
    s22 = mu * uz * uz + e1 * xz * xz + e2 * yz * yz
    return (s00, s01, s02, s01, s11, s12, s02, s12, s22)


def condition_stiffness(K, max_stiffness: float) -> np.ndarray:
    """K (3, 3) [N/m] with its symmetric part made negative-semidefinite with eigenvalues in
    [-max_stiffness, 0] and its skew part kept, bounded to ``max_stiffness``
    (:func:`condition_stiffness_values`).

    Raises:
        ValueError: K is not a finite (3, 3) array, or max_stiffness is not > 0.
    """
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.isfinite(K).all():
        raise ValueError(f'stiffness K: expected a finite (3, 3) matrix [N/m], got {K!r}')
    if not (math.isfinite(max_stiffness) and max_stiffness > 0):
        raise ValueError(f'max_stiffness: expected a finite value > 0 [N/m], got {max_stiffness}')
    return np.array(condition_stiffness_values(K.ravel().tolist(), max_stiffness)[0]).reshape(3, 3)


def tissue_stiffness_limit(max_device_stiffness: float, force_scale: float,
                           workspace_scale: float) -> float:
    """The tissue-frame stiffness [N/m] the device renders as ``max_device_stiffness``: device
    force = force_scale * F, tissue position = offset + workspace_scale * device position."""
    return max_device_stiffness / (force_scale * workspace_scale)


@dataclass(frozen=True)
class LocalModel:
    """One local force model, tissue frame (see the module docstring).

    Attributes:
        f0: (3,) force at p0 [N].
        p0: (3,) probe position the model was computed at [m].
        k: (3, 3) stiffness dF/dp [N/m], or its 9 values row-major (conditioned by the renderer).
        contact: (3,) contact point on the undeformed surface [m].
        normal: (3,) outward unit surface normal there.
        direction: (3,) unit indentation direction (into the tissue).
        depth0: depth at p0 [m] (> 0 in contact; 0 = a "no contact" model: zero force).
        zero_at_surface: the model's force at depth 0 is zero (the onset correction applies).
        time: the driver's monotonic time of the pose p0 came from [s].
    """
    f0: tuple
    p0: tuple
    k: np.ndarray
    contact: tuple
    normal: tuple
    direction: tuple
    depth0: float
    zero_at_surface: bool
    time: float

    @property
    def in_contact(self) -> bool:
        return self.depth0 > 0.0

    @property
    def approach(self) -> bool:
        """An approach model: made while the probe was free (depth 0) with the surface plane
        ahead (a non-zero normal): zero force outside the plane, K (p - p0) past it."""
        if self.depth0 != 0.0:
            return False
        x, y, z = self.normal
        return x * x + y * y + z * z > 0.0

    def values(self) -> list[float]:
        """The model as the flat values of a local force model message
        (:data:`haptic_anfis.interfaces.LOCAL_MODEL_FIELDS` order; ``time`` is not among them).

        Raises:
            ValueError: a field of the wrong length (named).
        """
        for name in ('f0', 'p0', 'contact', 'normal', 'direction'):
            if len(getattr(self, name)) != 3:
                raise ValueError(f'local model {name}: expected 3 finite numbers, got '
                                 f'{getattr(self, name)!r}')
        try:
            k = stiffness_values(self.k)
        except (TypeError, ValueError):
            k = self.k.tolist() if type(self.k) is np.ndarray else self.k
            raise ValueError(f'local model stiffness K: expected a finite (3, 3) matrix, got '
                             f'{k!r}') from None
        return model_values(tuple(map(float, self.f0)), tuple(map(float, self.p0)), k,
                            tuple(map(float, self.contact)), tuple(map(float, self.normal)),
                            tuple(map(float, self.direction)), float(self.depth0),
                            self.zero_at_surface)

    @classmethod
    def from_values(cls, v, time: float = 0.0) -> LocalModel:
        """The model in a local force model message's ``position`` values ``v``
        (:data:`~haptic_anfis.interfaces.LOCAL_MODEL_FIELDS`, as recorded in any bag); ``time``
        [s] as given (the driver sets the time of the pose it answers). Not checked for
        finiteness (:meth:`check`).

        Raises:
            ValueError: not exactly len(LOCAL_MODEL_FIELDS) values.
        """
        if len(v) != N_VALUES:
            raise ValueError(f'local force model message with {len(v)} values, expected '
                             f'{N_VALUES} ({", ".join(LOCAL_MODEL_FIELDS)})')
        v = v.tolist() if hasattr(v, 'tolist') else [float(c) for c in v]  # array.array: floats
        # Filled directly (no frozen-dataclass __init__: ~2 us of setattr calls per message).
        m = _object_new(cls)
        d = m.__dict__
        d['f0'], d['p0'], d['k'] = tuple(v[LM_F0]), tuple(v[LM_P0]), v[LM_K]
        d['contact'], d['normal'], d['direction'] = tuple(v[LM_C]), tuple(v[LM_N]), tuple(v[LM_D])
        d['depth0'], d['zero_at_surface'], d['time'] = v[LM_DEPTH], v[LM_ZERO] > 0.5, time
        return m

    def check(self) -> None:
        """Raises ValueError naming the first non-finite or malformed field
        (:func:`check_values`)."""
        check_values(self.values())


_object_new = object.__new__

#: values in a local force model message (:data:`haptic_anfis.interfaces.LOCAL_MODEL_FIELDS`)
N_VALUES = len(LOCAL_MODEL_FIELDS)
#: the fields of the flat values, for error messages: (name, start, stop)
_FIELDS = tuple((name, s.start, s.stop) for name, s in (
    ('f0', LM_F0), ('p0', LM_P0), ('stiffness K', LM_K), ('contact', LM_C), ('normal', LM_N),
    ('direction', LM_D)))


def model_values(f0, p0, k, contact, normal, direction, depth0: float, zero_at_surface: bool
                 ) -> list[float]:
    """Encode: a local force model message's ``position`` values (26, the order of
    :data:`~haptic_anfis.interfaces.LOCAL_MODEL_FIELDS`) from f0 (3,) [N], p0 (3,) [m], K's 9
    values row-major [N/m], contact (3,) [m], outward unit normal (3,), unit indentation
    direction (3,), depth0 [m] and whether the force is zero at the surface. The parts must
    already be floats (the force server's per-message path: no conversion, no check; the
    receiver checks, :func:`check_values`)."""
    return [*f0, *p0, *k, *contact, *normal, *direction, depth0,
            1.0 if zero_at_surface else 0.0]


def no_model() -> list[float]:
    """The values of the "no contact" model (all zeros: depth 0, no normal; the driver renders
    zero force), a new list each call (callers may scale it in place)."""
    return [0.0] * N_VALUES


def check_values(v) -> None:
    """Check a local force model's flat values (:meth:`LocalModel.values`; a message's
    ``position``): 26 finite numbers, depth >= 0, and unit normal and direction in contact or in
    an approach model (depth 0 with a non-zero normal). One sum tests finiteness in the common
    case (the driver checks every model it receives).

    Raises:
        ValueError: naming the first malformed field.
    """
    if len(v) != N_VALUES:
        raise ValueError(f'local model: expected {N_VALUES} values, got {len(v)}')
    if not math.isfinite(sum(v)):  # NaN/Inf anywhere (or an overflow: then nothing is named)
        for name, a, b in _FIELDS:
            if not all(math.isfinite(c) for c in v[a:b]):
                what = 'a finite (3, 3) matrix' if b - a == 9 else '3 finite numbers'
                raise ValueError(f'local model {name}: expected {what}, got {list(v[a:b])!r}')
    depth0 = v[LM_DEPTH]
    if not (math.isfinite(depth0) and depth0 >= 0.0):
        raise ValueError(f'local model depth0: expected a finite value >= 0, got {depth0!r}')
    nx, ny, nz = v[LM_N]
    nn = nx * nx + ny * ny + nz * nz
    if depth0 > 0.0 or nn > 0.0:
        dx, dy, dz = v[LM_D]
        for name, sq, vec in (('normal', nn, (nx, ny, nz)),
                              ('direction', dx * dx + dy * dy + dz * dz, (dx, dy, dz))):
            if abs(math.sqrt(sq) - 1.0) > 1e-3:
                raise ValueError(f'local model {name}: expected a unit vector, got {vec!r}')


def accept_values(v, max_stiffness: float, stats, checked: bool = False):
    """What a renderer keeps of a received model's flat values ``v`` (26,): checked (unless
    ``checked``: the caller did), K conditioned; ``stats`` (a :class:`RenderStats`) counts a
    rejected model and a K the guard changed by more than 1e-6 N/m. Plain floats: this runs
    once per received model. Both renderers (Python and compiled) take models through it.

    Returns:
        ``(f0, p0, k, g, d, depth0, zero, contact)``: force [N] and point [m] (3-tuples), K
        conditioned (9,) [N/m], depth gradient and direction (3-tuples; zero when neither in
        contact nor an approach model), depth0 [m], whether to render zero at depth 0, and
        whether the model renders past its plane (in contact, or an approach model).

    Raises:
        ValueError: a non-finite or malformed field (the model is not taken).
    """
    if not checked:
        try:
            check_values(v)
        except ValueError:
            stats.rejected += 1
            raise
    f0, p0, depth0, zero = tuple(v[LM_F0]), tuple(v[LM_P0]), v[LM_DEPTH], v[LM_ZERO]
    nx, ny, nz = v[LM_N]
    k, changed = condition_stiffness_values(v[LM_K], max_stiffness)
    if changed:
        stats.stiffness_clamped += 1
    # in contact, or an approach model (free, with the plane ahead): renders past its plane
    contact = depth0 > 0.0 or nx * nx + ny * ny + nz * nz > 0.0
    if contact:
        dx, dy, dz = v[LM_D]
        g, d = depth_gradient_values(nx, ny, nz, dx, dy, dz), (dx, dy, dz)
    else:
        g = d = (0.0, 0.0, 0.0)
    return f0, p0, k, g, d, float(depth0), zero > 0.5 and contact, contact


# split_offset, hold_offset and across_beyond are compiled into native_tick's kernels (it
# registers them; this module stays free of numba), whose cache keys on native_tick.py alone:
# native_tick.INLINED_SOURCE_HASH (checked by a test) makes a change here change that file.
def split_offset(gx: float, gy: float, gz: float, ex: float, ey: float, ez: float
                 ) -> tuple[float, float, float, float, float, float]:
    """The probe's offset ``e`` [m] from a model's p0 as (its part along the depth gradient
    ``g``, its part across ``g``): six floats. A depth gradient has a length of 1 or more (1 / cos
    of the angle between the indentation direction and the normal); one of length <= 1e-6 gives
    no direction: the whole offset is across."""
    gg = gx * gx + gy * gy + gz * gz
    a = (gx * ex + gy * ey + gz * ez) / gg if gg > 1e-12 else 0.0
    nx, ny, nz = a * gx, a * gy, a * gz
    return nx, ny, nz, ex - nx, ey - ny, ez - nz


def hold_offset(gx: float, gy: float, gz: float, ex: float, ey: float, ez: float, r: float
                ) -> tuple[float, float, float]:
    """The probe's offset ``e`` [m] from a model's p0 with its part across the depth gradient
    ``g`` held at ``r`` [m] (:func:`split_offset`); its part along ``g`` (so the depth ``g . e``)
    unchanged."""
    nx, ny, nz, tx, ty, tz = split_offset(gx, gy, gz, ex, ey, ez)
    tt = tx * tx + ty * ty + tz * tz
    if tt <= r * r:
        return ex, ey, ez
    c = r / math.sqrt(tt)
    return nx + c * tx, ny + c * ty, nz + c * tz


def across_beyond(gx: float, gy: float, gz: float, ex: float, ey: float, ez: float,
                  r: float) -> bool:
    """The probe's offset ``e`` [m] from a model's p0 has a part across the depth gradient ``g``
    (:func:`split_offset`) longer than ``r`` [m]."""
    _, _, _, tx, ty, tz = split_offset(gx, gy, gz, ex, ey, ez)
    return tx * tx + ty * ty + tz * tz > r * r


@dataclass
class RenderStats:
    """Tick counts by status, and models accepted/rejected, since construction or reset."""
    ticks_fresh: int = 0
    ticks_extrapolated: int = 0
    ticks_expired: int = 0
    ticks_free: int = 0
    ticks_none: int = 0
    ticks_approach: int = 0  # of the fresh + extrapolated: from an approach model (contact onset)
    ticks_beyond: int = 0  # of the fresh + extrapolated: beyond the validity radius (hold_offset)
    models: int = 0
    rejected: int = 0
    stiffness_clamped: int = 0


def force_and_jacobian(model, x: float, y: float, z: float, depth: float
                       ) -> tuple[tuple[float, float, float], np.ndarray]:
    """The model's force F (3,) [N] and J = dF/d(x, y, z, depth) (3, 4) [N/m] at one contact, from
    its compiled analytic derivative (``ForceModel.jacobian_one``).

    Raises:
        ValueError: a non-finite input.
    """
    F, J = model.jacobian_one(x, y, z, depth)
    return (float(F[0]), float(F[1]), float(F[2])), J


def force_and_jacobian_fd(model, x: float, y: float, z: float, depth: float, h: float = 1e-6
                          ) -> tuple[tuple[float, float, float], np.ndarray]:
    """:func:`force_and_jacobian` by central differences of ``model.predict_one`` (step h [m];
    one-sided in depth where depth < h, so the model is never asked for a negative depth): the
    test reference for the analytic path (~40x slower)."""
    f = model.predict_one
    F = f(x, y, z, depth)
    X = (x, y, z, depth)
    cols = []
    for b in range(4):
        hi = list(X)
        hi[b] += h
        fh = f(*hi)
        if b == 3 and depth < h:
            cols.append([(fh[a] - F[a]) / h for a in range(3)])
            continue
        lo = list(X)
        lo[b] -= h
        fl = f(*lo)
        cols.append([(fh[a] - fl[a]) / (2 * h) for a in range(3)])
    return (float(F[0]), float(F[1]), float(F[2])), np.array(cols).T
