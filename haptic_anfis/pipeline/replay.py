"""Both stages of the per-message pipeline (:mod:`haptic_anfis.pipeline`) for offline users: the
bag re-simulation, ``haptic-anfis loop`` replays, tests and benchmarks."""
from __future__ import annotations

from ..anfis import ForceModel
from ..contact import ContactTracker
from .contact import contact_values
from .force import force_from_contact

__all__ = ['pose_to_force']


def pose_to_force(tracker: ContactTracker, model: ForceModel, frame_id: str, pose_frame: str,
                  xyz) -> tuple[list[float], object, tuple[float, float, float], str | None]:
    """One pose through both stages as the two nodes run them (zero-order-hold force):
    ``(contact values, TrackedContact or None, force (3,) [N], error or None)``
    (:func:`contact_values`, then :func:`force_from_contact`)."""
    values, c, error = contact_values(tracker, frame_id, pose_frame, xyz)
    fx, fy, fz, ferr = force_from_contact(model, values)
    return values, c, (fx, fy, fz), error or ferr
