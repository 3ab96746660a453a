"""The package's topics and their types (fully qualified, as a bag stores them), and the typestore
that (de)serialises them."""
from __future__ import annotations

from functools import lru_cache

from rosbags.typesys import Stores, get_typestore

from .. import interfaces as ifc

POSE_TYPE = 'geometry_msgs/msg/PoseStamped'
TWIST_TYPE = 'geometry_msgs/msg/TwistStamped'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'
JOINT_STATE_TYPE = 'sensor_msgs/msg/JointState'
JOY_TYPE = 'sensor_msgs/msg/Joy'
MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'
POINT_TYPE = 'geometry_msgs/msg/PointStamped'


def absolute(topic: str) -> str:
    """'falcon/measured_cp' -> '/falcon/measured_cp' (the root namespace, as the nodes run)."""
    return topic if topic.startswith('/') else '/' + topic


#: Types of the package's topics (absolute names, root namespace).
KNOWN_TYPES: dict[str, str] = {
    absolute(ifc.TOPIC_POSE): POSE_TYPE,
    absolute(ifc.TOPIC_TWIST): TWIST_TYPE,
    absolute(ifc.TOPIC_APPLIED): WRENCH_TYPE,
    absolute(ifc.TOPIC_BUTTONS): JOY_TYPE,
    absolute(ifc.TOPIC_COMMAND): WRENCH_TYPE,
    absolute(ifc.TOPIC_CONTACT): JOINT_STATE_TYPE,
    absolute(ifc.TOPIC_MARKERS): MARKERS_TYPE,
    absolute(ifc.TOPIC_TISSUE): MARKERS_TYPE,
    absolute(ifc.TOPIC_MARKS): POINT_TYPE,
}

#: What the recorder records by default: pose, contact, force command, buttons.
DEFAULT_TOPICS = (ifc.TOPIC_POSE, ifc.TOPIC_CONTACT, ifc.TOPIC_COMMAND, ifc.TOPIC_BUTTONS,
                  ifc.TOPIC_MARKS)
#: Every topic of the haptic loop (``haptic-anfis sim --record``): the visualization is left out.
ALL_LOOP_TOPICS = (ifc.TOPIC_POSE, ifc.TOPIC_TWIST, ifc.TOPIC_APPLIED, ifc.TOPIC_BUTTONS,
                   ifc.TOPIC_CONTACT, ifc.TOPIC_COMMAND, ifc.TOPIC_MARKS)


@lru_cache(maxsize=1)
def typestore():
    """rosbags' ROS 2 Jazzy typestore (all the standard message types this package uses)."""
    return get_typestore(Stores.ROS2_JAZZY)


def playback_topic(topic: str, namespace: str = 'playback') -> str:
    """The topic a recorded ``topic`` is played on when not live: '/falcon/servo_cf' ->
    '/playback/falcon/servo_cf' (no live node subscribes there)."""
    return '/' + namespace.strip('/') + absolute(topic)
