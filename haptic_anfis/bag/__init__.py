"""rosbag2 sessions without ROS: record (a queue-fed writer thread that survives a failing disk),
read (streaming), inspect, recover, export (pure Python + rosbags; imports neither rclpy nor the
nodes: topic names come from :mod:`haptic_anfis.interfaces`). Re-simulation runs the nodes'
per-message code (:mod:`haptic_anfis.pipeline`) configured from the nodes' parameters, so it lives
with them: :mod:`haptic_anfis.nodes.resim`.

A bag is a rosbag2 directory: ``metadata.yaml`` (version 9) + one MCAP file, as ``ros2 bag record -s
mcap`` writes it, so a real ``ros2 bag info/play`` reads it.
"""
from __future__ import annotations

from .errors import BagError
from .reader import BagInfo, TopicStats, bag_info, format_info, open_bag, read_messages
from .recover import recover_bag
from .topics import ALL_LOOP_TOPICS, DEFAULT_TOPICS, KNOWN_TYPES, typestore
from .writer import BagWriter

__all__ = ['ALL_LOOP_TOPICS', 'BagError', 'BagInfo', 'BagWriter', 'DEFAULT_TOPICS', 'KNOWN_TYPES',
           'TopicStats', 'bag_info', 'format_info', 'open_bag', 'read_messages', 'recover_bag',
           'typestore']
