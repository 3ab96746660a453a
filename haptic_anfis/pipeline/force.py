"""Stage 2 of the per-message pipeline (:mod:`haptic_anfis.pipeline`): contact message values ->
force [N] and the local force model message values (F0 [N], p0 [m], K [N/m], ...; tissue frame)."""
from __future__ import annotations

import math
from pathlib import Path

from .. import interfaces as ifc
from ..anfis import ForceModel
from ..device.local_model import contact_stiffness, force_and_jacobian, model_values, no_model
from ..interfaces import I_DEPTH, I_DX, I_DY, I_DZ, I_IN_CONTACT, I_NX, I_NY, I_NZ, I_SATURATED
from ..tissue.dataset import DATA_DIR

__all__ = ['APPROACH_DEPTH', 'DEFAULT_MODEL', 'approach_model', 'contact_normal',
           'force_from_contact', 'load_model', 'local_model_from_contact', 'zero_at_surface']

#: The shipped force model (trained on the default scene's FE data).
DEFAULT_MODEL = DATA_DIR / 'default_model.json'
#: depth [m] the approach model's stiffness is taken at: 0+ (1 µm; at exactly 0 a depth-scaled
#: model's kink max(depth, 0) may give the derivative of the zero side)
APPROACH_DEPTH = 1e-6

_N_CONTACT = len(ifc.CONTACT_FIELDS)


def load_model(p: dict) -> tuple[Path, ForceModel]:
    """(path, model) from the force server's parameter values ``p`` (``model_path``, '' =
    :data:`DEFAULT_MODEL`). ``ForceModel.load`` compiles and warms the real-time path, so the first
    contact pays no compilation.

    Raises:
        ModelFileError: (a ValueError) a bad model file.
    """
    path = Path(p['model_path']) if p['model_path'] else DEFAULT_MODEL
    return path, ForceModel.load(path)


def _bad_contact(v) -> str:
    return (f'contact message with {len(v)} values, expected {_N_CONTACT} '
            f'({", ".join(ifc.CONTACT_FIELDS)})')


def contact_normal(v, d) -> list[float]:
    """The outward unit normal of contact values ``v`` in either layout: its normal fields (12
    values) when they hold a unit vector (within 0.5-1.5 in length), else -``d`` (the older
    9-value layout has none; ``d`` the contact's direction (3,))."""
    if len(v) == _N_CONTACT:
        n = [float(v[I_NX]), float(v[I_NY]), float(v[I_NZ])]
        if 0.25 < n[0] * n[0] + n[1] * n[1] + n[2] * n[2] < 2.25:
            return n
    return [-d[0], -d[1], -d[2]]


def force_from_contact(model: ForceModel, v) -> tuple[float, float, float, str | None]:
    """(fx, fy, fz [N], error or None) for the contact message values ``v``: the model's force in
    contact, zero when not in contact or on a malformed / non-finite contact (with the reason)."""
    if not ifc.is_contact_values(v):
        return 0.0, 0.0, 0.0, _bad_contact(v)
    if v[I_IN_CONTACT] > 0.5 and v[I_DEPTH] > 0.0:
        try:
            fx, fy, fz = model.predict_one(v[0], v[1], v[2], v[I_DEPTH])
        except ValueError as exc:  # NaN/Inf in the contact: zero force
            return 0.0, 0.0, 0.0, str(exc)
        return fx, fy, fz, None
    return 0.0, 0.0, 0.0, None


def local_model_from_contact(model: ForceModel, v, jacobian=force_and_jacobian, approach=()
                             ) -> tuple[tuple[float, float, float], list[float], str | None]:
    """(force (3,) [N], local model message values (:data:`~haptic_anfis.interfaces.
    LOCAL_MODEL_FIELDS`), error or None) for the contact message values ``v``.

    In contact: F0 and J = dF/d(x, y, z, depth) from ``jacobian`` (the model's analytic one when
    it has it), chained through the contact geometry into K = dF/dp
    (:func:`~haptic_anfis.device.local_model.contact_jacobian`; the depth column is dropped when
    the depth is saturated, since the force then no longer grows with it); the normal from
    :func:`contact_normal`. Not in contact, or a bad contact: zero force and a model with depth 0
    (the driver renders zero) — or, when the contact message's ``approach`` fields (its
    ``effort``, :data:`~haptic_anfis.interfaces.APPROACH_FIELDS`) name the surface ahead of the
    free probe, the approach model there (:func:`approach_model`)."""
    if not ifc.is_contact_values(v):
        return (0.0, 0.0, 0.0), no_model(), _bad_contact(v)
    if not (v[I_IN_CONTACT] > 0.5 and v[I_DEPTH] > 0.0):
        return (0.0, 0.0, 0.0), approach_model(model, v, approach, jacobian), None
    x, y, z, depth = float(v[0]), float(v[1]), float(v[2]), float(v[I_DEPTH])
    d = [float(v[I_DX]), float(v[I_DY]), float(v[I_DZ])]
    n = contact_normal(v, d)
    try:
        F, J = jacobian(model, x, y, z, depth)
        J = J.tolist()
        if v[I_SATURATED] > 0.5:
            for row in J:
                row[3] = 0.0
        K = contact_stiffness(J, n, d)
        zero = zero_at_surface(model, x, y, z)
    except ValueError as exc:
        return (0.0, 0.0, 0.0), no_model(), str(exc)
    if not math.isfinite(sum(K)):
        return ((0.0, 0.0, 0.0), no_model(),
                f'non-finite stiffness at contact ({x}, {y}, {z}, {depth})')
    p0 = (x + depth * d[0], y + depth * d[1], z + depth * d[2])
    return F, model_values(F, p0, K, (x, y, z), n, d, depth, zero), None


def approach_model(model: ForceModel, v, approach, jacobian=force_and_jacobian) -> list[float]:
    """The local model message values for a free probe: the approach model when ``approach`` holds
    the surface point s ahead and its outward normal n (:data:`~haptic_anfis.interfaces.
    APPROACH_FIELDS`), the force is zero there (a model with a force step at the surface cannot
    be rendered from before contact) and everything is finite: F0 = 0, p0 = contact = s, depth 0,
    K = dF/dp at depth 0+ (J at (s, 0) through the geometry: the force the probe meets the instant
    it crosses the plane); else all zeros (no contact). d: the contact's direction, or -n when it
    has none."""
    if len(approach) != len(ifc.APPROACH_FIELDS):
        return no_model()
    sx, sy, sz, nx, ny, nz = (float(c) for c in approach)
    d = [float(v[I_DX]), float(v[I_DY]), float(v[I_DZ])]
    nn = nx * nx + ny * ny + nz * nz
    if not (math.isfinite(sx + sy + sz + sum(d)) and 0.25 < nn < 2.25):
        return no_model()
    if not 0.25 < d[0] * d[0] + d[1] * d[1] + d[2] * d[2] < 2.25:
        d = [-nx, -ny, -nz]
    try:
        if not zero_at_surface(model, sx, sy, sz):
            return no_model()
        _, J = jacobian(model, sx, sy, sz, APPROACH_DEPTH)  # the one-sided derivative at 0+
        K = contact_stiffness(J.tolist(), (nx, ny, nz), d)
    except ValueError:
        return no_model()
    if not math.isfinite(sum(K)):
        return no_model()
    s = (sx, sy, sz)
    return model_values((0.0, 0.0, 0.0), s, K, s, (nx, ny, nz), d, 0.0, True)


def zero_at_surface(model: ForceModel, x: float, y: float, z: float) -> bool:
    """The model's force at depth 0 at the contact point (x, y, z) [m] is below
    :data:`~haptic_anfis.interfaces.ZERO_FORCE_TOL`. The depth-scaled form (F = depth g(...)) is
    exactly zero there by construction: no evaluation needed; any other form is evaluated."""
    if getattr(model, 'form', None) == 'depth_scaled':
        return True
    f0, f1, f2 = model.predict_one(x, y, z, 0.0)
    return f0 * f0 + f1 * f1 + f2 * f2 < ifc.ZERO_FORCE_TOL ** 2
