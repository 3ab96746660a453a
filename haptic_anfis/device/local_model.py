"""The local force model rendered in the servo loop (no ROS): an "intermediate representation".

The force server is slower than the 1 kHz servo loop and arrives late (1-20 ms across processes
on a loaded machine). A zero-order hold of its last force renders a stale force; at a stiff
surface that error is what buzzes. Following Adachi et al. 1995 (intermediate representation),
Mark et al. 1996 and Cavusoglu & Tendick 2000 (a local linearisation sent to the fast loop), the
force server sends with every force the local model of the force field at the contact, and the
servo loop evaluates it at the current probe position every tick::

    F(p) = F0 + K (p - p0)                                   (3,) N, p (3,) m, K (3, 3) N/m

with these rules (:class:`LocalModelRenderer`):

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
- Stiffness guard (:func:`condition_stiffness`): K is made symmetric and negative-semidefinite
  ("the surface pushes back": a passive spring) and its eigenvalues clamped to ``-max_stiffness``.
  The Falcon figure: 3000 N/m, the maximum linear stiffness CHAI3D's Falcon driver advertises
  (``cHapticDeviceInfo::m_maxLinearStiffness``, with 8 N and 20 N s/m damping). By Colgate & Brown
  1994 a sampled spring K is passive when the device's own damping b > K T / 2 + B: at T = 1 ms
  and 3000 N/m that asks 1.5 N s/m of mechanism damping. Tissue-frame stiffness maps to the
  device as ``force_scale * workspace_scale * K``, so the tissue-frame bound is
  ``max_stiffness / (force_scale * workspace_scale)`` (:func:`tissue_stiffness_limit`).
- Non-finite F0, p0, K, normal or direction: the model is rejected (the caller zeroes the force).
- Expiry: a model older than ``validity_time`` (measured from the time of the driver's own pose it
  answers, not from its arrival) or a probe further than ``validity_radius`` from ``p0`` is
  expired: the renderer stops extrapolating and the caller holds the last force and lets the
  watchdog ramp it to zero, as the zero-order hold does.

Times are seconds on the caller's monotonic clock; lengths metres; forces newtons; tissue frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Falcon stiffness bound [N/m], device frame (CHAI3D's Falcon m_maxLinearStiffness; see above).
FALCON_MAX_STIFFNESS = 3000.0

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
    n = np.asarray(normal, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    c = min(float(n @ d), -MIN_COS)
    return n / c


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
    nx, ny, nz = normal
    dx, dy, dz = direction
    c = min(nx * dx + ny * dy + nz * dz, -MIN_COS)
    gx, gy, gz = nx / c, ny / c, nz / c
    K = []
    for ja, jb, jc, jd in J:
        w = jd - (ja * dx + jb * dy + jc * dz)
        K += [ja + w * gx, jb + w * gy, jc + w * gz]
    return K


def condition_stiffness(K, max_stiffness: float) -> np.ndarray:
    """K (3, 3) made symmetric negative-semidefinite with eigenvalues in [-max_stiffness, 0] [N/m].

    Raises:
        ValueError: K is not a finite (3, 3) array, or max_stiffness is not > 0.
    """
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.isfinite(K).all():
        raise ValueError(f'stiffness K: expected a finite (3, 3) matrix [N/m], got {K!r}')
    if not (math.isfinite(max_stiffness) and max_stiffness > 0):
        raise ValueError(f'max_stiffness: expected a finite value > 0 [N/m], got {max_stiffness}')
    S = 0.5 * (K + K.T)
    w, V = np.linalg.eigh(S)
    w = np.clip(w, -max_stiffness, 0.0)
    return (V * w) @ V.T


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

    def check(self) -> None:
        """Raises ValueError naming the first non-finite or malformed field."""
        vals = [*self.f0, *self.p0, *self.contact, *self.normal, *self.direction]
        k = np.asarray(self.k, dtype=np.float64)
        if len(vals) != 15 or not math.isfinite(sum(map(float, vals))):
            for name in ('f0', 'p0', 'contact', 'normal', 'direction'):
                v = getattr(self, name)
                if len(v) != 3 or not all(math.isfinite(float(c)) for c in v):
                    raise ValueError(f'local model {name}: expected 3 finite numbers, got {v!r}')
        if k.size != 9 or not math.isfinite(float(k.sum())):
            raise ValueError(f'local model stiffness K: expected a finite (3, 3) matrix, got '
                             f'{k.tolist()!r}')
        if not (math.isfinite(self.depth0) and self.depth0 >= 0.0):
            raise ValueError(f'local model depth0: expected a finite value >= 0, got '
                             f'{self.depth0!r}')
        if self.in_contact:
            for name in ('normal', 'direction'):
                x, y, z = getattr(self, name)
                if abs(math.sqrt(x * x + y * y + z * z) - 1.0) > 1e-3:
                    raise ValueError(f'local model {name}: expected a unit vector, got '
                                     f'{(x, y, z)!r}')


@dataclass
class RenderStats:
    """Tick counts by status, and models accepted/rejected, since construction or reset."""
    ticks_fresh: int = 0
    ticks_extrapolated: int = 0
    ticks_expired: int = 0
    ticks_free: int = 0
    ticks_none: int = 0
    models: int = 0
    rejected: int = 0
    stiffness_clamped: int = 0


class LocalModelRenderer:
    """Evaluates the newest accepted :class:`LocalModel` at the probe position every servo tick.

    ``offer`` runs on the thread that receives models, ``render`` on the servo thread; the model
    is swapped in as one reference (atomic under the GIL).

    Args:
        max_stiffness: tissue-frame stiffness bound [N/m] (:func:`tissue_stiffness_limit`).
        validity_time: a model older than this [s] (from the time of its pose) is expired.
        validity_radius: a probe further than this [m] from the model's p0 is expired.
        fresh_age: a model no older than this [s] counts as fresh (default 1.5 servo periods at
            1 kHz: it answers the previous tick's pose), older and valid as extrapolated.
    """

    def __init__(self, max_stiffness: float = FALCON_MAX_STIFFNESS / 1.5,
                 validity_time: float = 0.05, validity_radius: float = 0.005,
                 fresh_age: float = 0.0015) -> None:
        for name, v in (('max_stiffness', max_stiffness), ('validity_time', validity_time),
                        ('validity_radius', validity_radius), ('fresh_age', fresh_age)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f'{name}: expected a finite number > 0, got {v!r}')
        self.max_stiffness = float(max_stiffness)
        self.validity_time = float(validity_time)
        self.validity_radius = float(validity_radius)
        self.fresh_age = float(fresh_age)
        self.stats = RenderStats()
        self._m: tuple | None = None  # the prepared model (plain floats for the servo thread)
        self.model: LocalModel | None = None

    def reset_stats(self) -> None:
        self.stats = RenderStats()

    def clear(self) -> None:
        """Forget the model (the next ticks render nothing: status NONE)."""
        self._m = None
        self.model = None

    def offer(self, m: LocalModel, checked: bool = False) -> None:
        """Accept ``m`` as the newest model: checked (unless ``checked``: the caller did),
        K conditioned (counted when the guard changed it by more than 1e-6 N/m).

        Raises:
            ValueError: a non-finite or malformed field (the model is not taken; the caller
            decides the safe output — zero force).
        """
        if not checked:
            try:
                m.check()
            except ValueError:
                self.stats.rejected += 1
                raise
        k_in = np.asarray(m.k, dtype=np.float64).reshape(3, 3)
        k = condition_stiffness(k_in, self.max_stiffness)
        if float(np.abs(k - k_in).max()) > 1e-6:
            self.stats.stiffness_clamped += 1
        f0 = tuple(float(v) for v in m.f0)
        p0 = tuple(float(v) for v in m.p0)
        if m.in_contact:
            g = tuple(depth_gradient(m.normal, m.direction).tolist())
            d = tuple(float(v) for v in m.direction)
        else:
            g = d = (0.0, 0.0, 0.0)
        self._m = (f0, p0, tuple(map(tuple, k.tolist())), g, d, float(m.depth0),
                   bool(m.zero_at_surface and m.in_contact), float(m.time), m.in_contact)
        self.model = m
        self.stats.models += 1

    def render(self, p, now: float) -> tuple[tuple[float, float, float] | None, int]:
        """(force (3,) [N] or None, status) for the probe at ``p`` (3,) [m] at time ``now``.

        Status FRESH / EXTRAPOLATED: the model's force at p; FREE: zero (the model says no contact,
        or p is out of the surface along the local normal); EXPIRED (too old or p too far) and
        NONE (no model yet): None — the caller holds the last force and its watchdog ramps it.
        """
        m = self._m
        st = self.stats
        if m is None:
            st.ticks_none += 1
            return None, NONE
        f0, p0, k, g, d, depth0, zero_surface, t0, contact = m
        age = now - t0
        px, py, pz = p
        ex, ey, ez = px - p0[0], py - p0[1], pz - p0[2]
        if age > self.validity_time:
            st.ticks_expired += 1
            return None, EXPIRED
        depth = depth0 + g[0] * ex + g[1] * ey + g[2] * ez
        if not contact or depth <= 0.0:  # out along the local normal: zero at once, any distance
            st.ticks_free += 1
            return (0.0, 0.0, 0.0), FREE
        if ex * ex + ey * ey + ez * ez > self.validity_radius ** 2:
            st.ticks_expired += 1
            return None, EXPIRED
        fresh = age <= self.fresh_age
        if fresh:
            st.ticks_fresh += 1
        else:
            st.ticks_extrapolated += 1
        k0, k1, k2 = k
        fx = f0[0] + k0[0] * ex + k0[1] * ey + k0[2] * ez
        fy = f0[1] + k1[0] * ex + k1[1] * ey + k1[2] * ez
        fz = f0[2] + k2[0] * ex + k2[1] * ey + k2[2] * ez
        if zero_surface and depth < depth0:
            # L(p_s), p_s = p - depth d on the tangent plane: subtract it with weight (1 - s)^2.
            sx, sy, sz = ex - depth * d[0], ey - depth * d[1], ez - depth * d[2]
            w = (1.0 - depth / depth0) ** 2
            fx -= w * (f0[0] + k0[0] * sx + k0[1] * sy + k0[2] * sz)
            fy -= w * (f0[1] + k1[0] * sx + k1[1] * sy + k1[2] * sz)
            fz -= w * (f0[2] + k2[0] * sx + k2[1] * sy + k2[2] * sz)
        return (fx, fy, fz), (FRESH if fresh else EXTRAPOLATED)


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
