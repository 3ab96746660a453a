"""The stateful contact proxy (god-object) for the 1 kHz haptic loop.

A stateless closest-point query jumps when the probe is deep: below the centres of curvature the
nearest face can switch to a distant one. The force model needs a contact point that moves
smoothly, so the tracker keeps a proxy on the surface and moves it with the probe:

- The proxy is where the line through the probe along the indentation direction d crosses the
  surface going back out (-d), on a face that faces the probe (n . d < 0). For a height field
  along d (the breast over the chest wall, d = -x) this point moves continuously with the probe,
  however deep. With ``direction=None`` the direction is frozen at contact entry to the inward
  normal of the face the probe entered through.
- Contact starts only when the probe crosses a front face from outside (checked on the segment
  between the last two samples). A probe that appears inside (first sample, after a NaN), or that
  enters through a face pointing along d (the chest wall, from behind) is ``'rejected'``: zero
  depth until it is outside again.
- Contact ends when the probe is back out through the proxy's surface (depth <= 0).
- Depth saturates at the tissue thickness under the proxy (distance along d from the proxy to the
  next crossing, e.g. the chest wall) and at ``max_depth``: a probe pushed through the whole tissue
  keeps the deepest force instead of dropping to zero, and ``saturated`` says so.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import bvh
from .detector import ContactDetector

FREE, CONTACT, REJECTED = 'free', 'contact', 'rejected'
_object_new = object.__new__


@dataclass(frozen=True)
class TrackedContact:
    """The tracker's answer for one probe sample (metres, tissue frame).

    Attributes:
        state: ``'free'``, ``'contact'`` or ``'rejected'`` (inside, but not entered through the
            front surface).
        in_contact: ``state == 'contact'`` and ``depth > 0``.
        contact_point: (3,) proxy on the undeformed surface (the probe position when not in
            contact).
        triangle: face index of the proxy, -1 when not in contact.
        depth: penetration along ``direction`` [m], >= 0, saturated (see module docstring).
        direction: (3,) unit indentation direction into the tissue.
        normal: (3,) outward unit normal of the proxy's face (zeros when not in contact).
        saturated: the probe is deeper than the tissue is thick (or than ``max_depth``).
    """
    state: str
    in_contact: bool
    contact_point: np.ndarray
    triangle: int
    depth: float
    direction: np.ndarray
    normal: np.ndarray
    saturated: bool


class ContactTracker:
    """Stateful contact for a probe sampled in time (see the module docstring).

    Args:
        detector: the surface; its ``direction`` is the indentation direction (None: per contact).
        max_step: largest probe motion between two samples [m] the tracker follows; a probe that
            has left the surface by less than this since the last sample is recognised as out.
            1 cm at 1 kHz is 10 m/s, far above hand speed.
        max_depth: optional cap on the depth [m] (e.g. the deepest depth the force model was
            trained on); None: only the tissue thickness caps it.
    """

    def __init__(self, detector: ContactDetector, max_step: float = 0.01,
                 max_depth: float | None = None):
        if not max_step > 0:
            raise ValueError(f'max_step: expected > 0 [m], got {max_step}')
        if max_depth is not None and not max_depth > 0:
            raise ValueError(f'max_depth: expected None or > 0 [m], got {max_depth}')
        self.detector = detector
        self.max_step = float(max_step)
        self.max_depth = np.inf if max_depth is None else float(max_depth)
        self.reset()

    def reset(self) -> None:
        """Forget the history: the next sample is treated as the first."""
        self.state = FREE
        self._prev: np.ndarray | None = None  # last probe sample while free and outside
        self._face = -1
        self._dir: np.ndarray | None = self.detector.direction

    def update(self, p) -> TrackedContact:
        """Advance with the probe sample ``p`` (3,) [m].

        Raises:
            ValueError: ``p`` is not a finite 3-vector. The tracker is reset (a pose glitch must
            not teleport the proxy); the node outputs zero force.
        """
        if not (type(p) is np.ndarray and p.shape == (3,) and p.dtype == np.float64
                and math.isfinite(sum(p.tolist()))):
            # Not the 1 kHz loop's plain finite float64 (3,) array (a sum with a NaN or Inf is
            # not finite; an overflowing sum of finite values only takes this slower path).
            try:
                p = self.detector._check_points(p, 'p').reshape(-1)
                if p.shape != (3,):
                    raise ValueError(f'p: expected one point of shape (3,), got {p.shape}')
            except ValueError:
                self.reset()
                raise
        if self.state == CONTACT:
            res = self._follow(p)
            if res is not None:
                return res
            # Out through the surface: fall through to the free-state logic with no history.
        det = self.detector
        q = det.query(p, hint=self._face)
        self._face = q.triangle
        if self.state == REJECTED:
            if q.signed_distance >= 0.0:
                self.state = FREE
                self._prev = p
            return self._idle(p)
        # FREE
        inside = q.signed_distance < 0.0
        if not inside:
            self._prev = p
            return self._idle(p)
        prev, self._prev = self._prev, None
        entry = self._entry(prev, p) if prev is not None else None
        if entry is None:
            self.state = REJECTED
            return self._idle(p)
        self.state = CONTACT
        self._dir = entry
        res = self._follow(p)
        if res is None:  # on the surface exactly: treat as still free
            self.state = FREE
            self._prev = p
            return self._idle(p)
        return res

    # -- internals ----------------------------------------------------------------------------

    def _entry(self, prev: np.ndarray, p: np.ndarray) -> np.ndarray | None:
        """Indentation direction if prev -> p enters through a front face, else None."""
        det = self.detector
        hit = det._raycast(prev, p - prev, 0.0, 1.0, -1)  # a face the segment enters through
        if hit is None:
            return None
        n = det._tri[det._row_of[hit[0]], 9:12]
        if det.direction is None:
            return -n.copy()
        if float(n @ det.direction) >= 0.0:  # the face points along d: the chest wall side
            return None
        return det.direction

    def _follow(self, p: np.ndarray) -> TrackedContact | None:
        """Move the proxy with the probe; None when the probe has come out."""
        det, d = self.detector, self._dir
        o = np.empty(6)
        x, y, z = p.tolist()
        dx, dy, dz = d.tolist()
        # One kernel call: the ray back out along -d to the proxy, then the thickness behind it.
        face, t, thick = bvh.follow_packed(det._buf, x, y, z, dx, dy, dz, self.max_step, o)
        if face < 0 or t <= 0.0:
            self.state = FREE
            self._face = -1
            self._dir = det.direction
            return None
        limit = min(thick, self.max_depth)
        self._face = face
        r = _object_new(TrackedContact)  # no frozen-dataclass __init__ (~1 us of setattr calls)
        f = r.__dict__
        f['state'] = CONTACT
        f['in_contact'] = True
        f['contact_point'] = o[0:3]
        f['triangle'] = face
        f['depth'] = min(t, limit)
        f['direction'] = d
        f['normal'] = o[3:6]
        f['saturated'] = t > limit
        return r

    def _idle(self, p: np.ndarray) -> TrackedContact:
        r = _object_new(TrackedContact)  # as in _follow
        f = r.__dict__
        f['state'] = self.state
        f['in_contact'] = False
        f['contact_point'] = p
        f['triangle'] = -1
        f['depth'] = 0.0
        f['direction'] = self._dir if self._dir is not None else np.zeros(3)
        f['normal'] = np.zeros(3)
        f['saturated'] = False
        return r
