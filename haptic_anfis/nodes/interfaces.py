"""Names and message layouts shared by the nodes (pure Python: importable without ROS).

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
"""
from __future__ import annotations

CONTACT_FIELDS = ('contact_x', 'contact_y', 'contact_z', 'depth', 'direction_x', 'direction_y',
                  'direction_z', 'in_contact', 'saturated')
(I_X, I_Y, I_Z, I_DEPTH, I_DX, I_DY, I_DZ, I_IN_CONTACT, I_SATURATED) = range(len(CONTACT_FIELDS))

TOPIC_POSE = 'falcon/measured_cp'
TOPIC_TWIST = 'falcon/measured_cv'
TOPIC_APPLIED = 'falcon/measured_cf'
TOPIC_BUTTONS = 'falcon/buttons'
TOPIC_COMMAND = 'falcon/servo_cf'
TOPIC_CONTACT = 'contact'
TOPIC_MARKERS = 'visualization/markers'
TOPIC_TISSUE = 'visualization/tissue'
TOPIC_MARKS = 'exam/marks'
TOPIC_COVERAGE = 'exam/coverage'
TOPIC_EXAM_REPORT = 'exam/report'
SERVICE_RELOAD = '/force_server/reload'
