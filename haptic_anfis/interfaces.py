"""Names and message layouts of the topics (no ROS): shared by the nodes, the bag
layer and the commands (core <- bag / nodes).

Topics (relative names: a node namespace or ``-r`` remapping moves them):

=========================  ==============================  ==========================================
topic                      type                            meaning
=========================  ==============================  ==========================================
``falcon/measured_cp``     geometry_msgs/PoseStamped       probe tip pose, tissue frame [m], 1 kHz
``falcon/measured_cv``     geometry_msgs/TwistStamped      probe tip velocity, tissue frame [m/s]
``falcon/measured_cf``     geometry_msgs/WrenchStamped     force the device applies (after the
                                                           safety layer), tissue frame [N]
``falcon/buttons``         sensor_msgs/Joy                 device buttons (0/1)
``falcon/servo_cf``        geometry_msgs/WrenchStamped     force command to the device, tissue
                                                           frame [N] (CRTK servo_cf)
``falcon/servo_cf_local``  sensor_msgs/JointState          local force model at the contact,
                                                           packed as below; with every servo_cf
``contact``                sensor_msgs/JointState          contact, packed as below
``visualization/markers``  visualization_msgs/MarkerArray  probe, contact point, force arrow,
                                                           tumours; ~30 Hz
``visualization/tissue``   visualization_msgs/MarkerArray  tissue mesh, latched (transient local)
``exam/marks``             geometry_msgs/PointStamped      "lump here" (button 1), probe tip [m]
``exam/coverage``          visualization_msgs/MarkerArray  examiner's live coverage heat map, 5 Hz
``exam/report``            std_msgs/String                 examiner's report JSON, at the end
=========================  ==============================  ==========================================

Contact message (``sensor_msgs/JointState``, no custom interfaces needed): ``header.stamp`` is the
stamp of the pose it was computed from, ``header.frame_id`` the tissue frame; ``name`` is exactly
:data:`CONTACT_FIELDS` and ``position[i]`` holds that field; ``velocity`` and ``effort`` are empty.

- ``contact_x/y/z`` [m]: contact point on the UNDEFORMED surface (the tracker's proxy), tissue
  frame — the force model's x, y, z inputs. The probe position when not in contact; 0 after a bad
  (NaN/Inf, wrong-frame) pose.
- ``depth`` [m]: penetration depth along the indentation direction, >= 0; 0 = no contact.
- ``direction_x/y/z``: unit indentation direction INTO the tissue (default (-1, 0, 0)).
- ``in_contact``: 1.0 in contact, 0.0 not.
- ``saturated``: 1.0 when the probe is deeper than the tissue is thick (or ``max_depth``), the
  depth then being held at that limit.
- ``normal_x/y/z``: outward unit surface normal at the contact point (zeros when not in contact).
  Added after the first nine: readers accept the older 9-value messages (:data:`N_CONTACT_V1`).
- ``effort`` (added with the approach; empty before, and whenever not free or nothing is near):
  the approach fields :data:`APPROACH_FIELDS` — while the probe is free and a front surface lies
  within the detector's ``approach_distance`` along the indentation direction, the surface point
  the probe will touch [m] and the outward unit normal there (normal mode: the closest surface
  point). The force server sends that tangent plane to the driver as a local model before contact
  (below), so a press is rendered from its first tick. ``position`` is unchanged by it.

Local force model message (``sensor_msgs/JointState`` on ``falcon/servo_cf_local``, published by
the force server with every ``falcon/servo_cf``, same stamp: the contact's, i.e. the driver's pose
it answers; ``header.frame_id`` the tissue frame; ``name`` is exactly :data:`LOCAL_MODEL_FIELDS`,
``position[i]`` holds that field; encoded and decoded beside ``LocalModel`` in
:mod:`haptic_anfis.device.local_model`). The driver renders F(p) = F0 + K (p - p0) at every servo
tick:

- ``f0_x/y/z`` [N]: the model's force at the contact (= the servo_cf force).
- ``p0_x/y/z`` [m]: probe position it was computed at (contact point + depth * direction).
- ``k_xx, k_xy, ... k_zz`` [N/m]: row-major K = dF/dp through the contact geometry (row = force
  component, column = position component), unconditioned (the driver symmetrises and clamps).
- ``contact_x/y/z`` [m], ``normal_x/y/z``, ``direction_x/y/z``, ``depth`` [m]: as in the contact
  message; depth 0 = no contact (the driver renders zero force).
- ``zero_at_surface``: 1.0 when the model's force at depth 0 at the contact point is below
  :data:`ZERO_FORCE_TOL` (the driver then makes the local model zero on the surface).

A model with depth 0 is "no contact": all zeros (zero force), or, when the contact carried the
approach fields and the force is zero on the surface, an approach model: F0 = 0, p0 = contact =
the surface point ahead, the normal there, K = dF/dp at depth 0+ through the geometry; the driver
renders zero on the outer side of that plane and K (p - p0) once the probe is past it.
"""
from __future__ import annotations

import math

import numpy as np

CONTACT_FIELDS = ('contact_x', 'contact_y', 'contact_z', 'depth', 'direction_x', 'direction_y',
                  'direction_z', 'in_contact', 'saturated', 'normal_x', 'normal_y', 'normal_z')
(I_X, I_Y, I_Z, I_DEPTH, I_DX, I_DY, I_DZ, I_IN_CONTACT, I_SATURATED, I_NX, I_NY,
 I_NZ) = range(len(CONTACT_FIELDS))
#: values in a contact message without the normal (the first nine fields; bags recorded in
#: that layout stay readable, so readers accept it)
N_CONTACT_V1 = 9


#: the contact message's ``effort`` while free and near the surface (else empty)
APPROACH_FIELDS = ('surface_x', 'surface_y', 'surface_z', 'normal_x', 'normal_y', 'normal_z')


#: the lengths a contact message's ``position`` may have (with the normal, without it)
CONTACT_LENGTHS = (len(CONTACT_FIELDS), N_CONTACT_V1)


def is_contact_values(v) -> bool:
    """``v`` has the length of a contact message (current or the older 9-value layout); a
    reader that must report what it skipped counts through :class:`ContactLayouts`."""
    return len(v) in CONTACT_LENGTHS


def contact_geometry(v) -> tuple[tuple[float, ...], tuple[float, ...], float] | None:
    """(contact point (3,) [m], indentation direction (3,), depth [m]) of the contact values
    ``v`` (either layout) while in contact with these fields finite; None otherwise (not a
    contact, not in contact, or a NaN / Inf among them): what the view nodes draw."""
    if not is_contact_values(v) or not v[I_IN_CONTACT] >= 0.5:
        return None
    x, y, z, depth, dx, dy, dz = (float(c) for c in v[:I_IN_CONTACT])
    if not math.isfinite(x + y + z + depth + dx + dy + dz):
        return None
    return (x, y, z), (dx, dy, dz), depth


class ContactLayouts:
    """The one reader check of contact messages: :meth:`accept` says whether a message's
    ``position`` values ``v`` are a contact (current layout or the older 9-value one, whose first
    nine fields mean the same) and counts each message by layout, so a reader reports what it
    could not read instead of dropping it in silence (:meth:`note`, :meth:`as_dict`)."""

    __slots__ = ('current', 'v1', 'other')

    def __init__(self) -> None:
        self.current = 0                 # messages of len(CONTACT_FIELDS) values
        self.v1 = 0                      # messages of N_CONTACT_V1 values (older layout)
        self.other: dict[int, int] = {}  # length -> messages of any other length (not read)

    def accept(self, v) -> bool:
        """True when ``v`` is a contact message's values (read it), False otherwise (counted)."""
        n = len(v)
        if is_contact_values(v):
            if n == N_CONTACT_V1:
                self.v1 += 1
            else:
                self.current += 1
            return True
        self.other[n] = self.other.get(n, 0) + 1
        return False

    @property
    def rejected(self) -> int:
        """Messages not read (any length but the two layouts)."""
        return sum(self.other.values())

    def as_dict(self) -> dict:
        """JSON-able counts: ``{'current': n, 'v1_9_values': n, 'other': {length: n}}``."""
        return {'current': self.current, 'v1_9_values': self.v1,
                'other': {str(k): v for k, v in sorted(self.other.items())}}

    def note(self) -> str | None:
        """One line for a report when messages were skipped or read in the older layout."""
        parts = []
        if self.other:
            lens = ', '.join(f'{v} of {k} values' for k, v in sorted(self.other.items()))
            parts.append(f'{self.rejected} contact message(s) not read ({lens}; expected '
                         f'{len(CONTACT_FIELDS)} or {N_CONTACT_V1} values)')
        if self.v1:
            parts.append(f'{self.v1} contact message(s) in the older {N_CONTACT_V1}-value layout '
                         '(read, no surface normal)')
        return '; '.join(parts) or None


#: The local force model message's layout, its one definition: a record of float64 fields in
#: the order of the message's ``position`` values (see the module doc). The names
#: (:data:`LOCAL_MODEL_FIELDS`) and the flat positions (``LM_*``) derive from it, and a flat
#: values array views as one record (``np.asarray(v).view(LOCAL_MODEL)[0]['k']``).
LOCAL_MODEL = np.dtype([('f0', 'f8', 3), ('p0', 'f8', 3), ('k', 'f8', 9), ('contact', 'f8', 3),
                        ('normal', 'f8', 3), ('direction', 'f8', 3), ('depth', 'f8'),
                        ('zero_at_surface', 'f8')])
#: the component suffixes of a vector field's flat names: (x, y, z); K row-major (xx, xy, ...)
_AXES = {3: ('x', 'y', 'z'), 9: tuple(r + c for r in 'xyz' for c in 'xyz')}


def field_names(layout: np.dtype) -> tuple[str, ...]:
    """The flat names of a float64 record layout: a scalar field's own name, a vector's
    ``name_x``, ... (K's ``k_xx``, ...)."""
    names: list[str] = []
    for name in layout.names:
        n = layout[name].shape[0] if layout[name].shape else 1
        names += [name] if n == 1 else [f'{name}_{a}' for a in _AXES[n]]
    return tuple(names)


def field_index(layout: np.dtype, name: str) -> int | slice:
    """Where field ``name`` of a float64 record layout sits in its flat values: an index
    (scalar) or a slice (vector)."""
    sub, offset = layout.fields[name][:2]
    i = offset // 8
    return slice(i, i + sub.shape[0]) if sub.shape else i


LOCAL_MODEL_FIELDS = field_names(LOCAL_MODEL)
#: the flat positions of LOCAL_MODEL's fields
LM_F0, LM_P0, LM_K, LM_C, LM_N, LM_D, LM_DEPTH, LM_ZERO = (field_index(LOCAL_MODEL, n)
                                                           for n in LOCAL_MODEL.names)
#: |F| [N] at depth 0 below which a model counts as zero at the surface
ZERO_FORCE_TOL = 0.05

TOPIC_POSE = 'falcon/measured_cp'
TOPIC_TWIST = 'falcon/measured_cv'
TOPIC_APPLIED = 'falcon/measured_cf'
TOPIC_BUTTONS = 'falcon/buttons'
TOPIC_COMMAND = 'falcon/servo_cf'
TOPIC_LOCAL_MODEL = 'falcon/servo_cf_local'
TOPIC_CONTACT = 'contact'
TOPIC_MARKERS = 'visualization/markers'
TOPIC_TISSUE = 'visualization/tissue'
TOPIC_MARKS = 'exam/marks'
TOPIC_COVERAGE = 'exam/coverage'
TOPIC_EXAM_REPORT = 'exam/report'
#: ROS's diagnostics topic (diagnostic_msgs/DiagnosticArray): rqt_robot_monitor and the page show
#: the servo loop's health from it (status :data:`LOOP_DIAGNOSTIC`)
TOPIC_DIAGNOSTICS = '/diagnostics'
LOOP_DIAGNOSTIC = 'falcon_driver: servo loop'
SERVICE_RELOAD = '/force_server/reload'

