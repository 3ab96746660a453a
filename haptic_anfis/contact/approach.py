"""The surface ahead of a free probe: where it will touch, before it does (no ROS).

The haptic loop's local force model (:mod:`haptic_anfis.device.local_model`) renders the force at
every servo tick from the newest model the force server sent; a model made while the probe was
free says "no contact", so without more the first pose inside renders zero until the force
server's answer to it arrives: every press starts one loop latency late. Sending, while the probe
is free but near the surface, the tangent plane it is about to cross (Adachi et al. 1995's
intermediate representation exists before contact too) lets the servo loop render the force the
instant the probe crosses it. This module finds that plane: the front-facing surface point the
probe reaches moving along the indentation direction, and the outward normal there.
"""
from __future__ import annotations

import numpy as np

from .detector import ContactDetector


def surface_ahead(detector: ContactDetector, p, direction, max_distance: float
                  ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(s (3,) surface point [m], n (3,) outward unit normal there, t [m]) for the probe at ``p``
    (3,) [m] outside the surface, or None when no front-facing surface lies within
    ``max_distance`` [m].

    - ``direction`` (3,) unit indentation direction d (a fixed direction, the paper's axis): s is
      the first crossing of the ray p + t d, 0 <= t <= max_distance, through a face whose outward
      normal n has n . d < 0 (the face the tracker's contact would start on).
    - ``direction`` None (the contact detector's normal mode: d is fixed at entry to the inward
      normal): s is the closest surface point and t its distance, d = -n.
    """
    if max_distance <= 0.0:
        return None
    p = np.asarray(p, dtype=np.float64)
    if direction is None:
        q = detector.query(p)
        t = float(q.signed_distance)
        if not 0.0 <= t <= max_distance:
            return None
        return q.point.copy(), q.normal.copy(), t
    d = np.asarray(direction, dtype=np.float64)
    hit = detector._raycast(p, d, 0.0, max_distance, -1)  # a face the ray enters through
    if hit is None:
        return None
    face, t = hit
    s = p + t * d
    n = detector._normal_at(p, face, s)
    if float(n @ d) >= 0.0:  # a face pointing along d (the chest wall side): no contact there
        return None
    return s, n, t
