"""The middleware settings of a haptic process: Fast DDS over UDP only, no shared memory.

Why (issue 32, docs/servo_loop.md): Fast DDS checks a shared-memory port's health whenever a
process opens another process's port, which it does on the first message to a newly discovered
participant. When the port's listener has been idle and was checked a moment before, the opening
thread sleeps a full listener period — a third of ``healthy_check_timeout_ms`` (default 1000), so
~333 ms — and it is the thread that publishes (rmw_fastrtps publishes synchronously) or the
discovery thread holding the writer's lock. Measured with ``launch``: one pose -> command latency
of 333-342 ms in about one start in four, the local model expiring mid-press; over UDP only, no
such latency in 16 starts (docs/servo_loop.md has the commands). For
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` rmw_fastrtps adds its shared-memory transport itself,
so the same discovery (this machine only) is given as a Fast DDS profile instead
(``data/dds/localhost_udp.xml``) with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT``; other
ranges keep theirs and get ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``. Other ROS 2 programs (``ros2
topic echo``, rviz, a user's own nodes) still find and talk to these nodes: over UDP.

Nothing is changed when the user configured the middleware: a Fast DDS profile of their own
(``FASTRTPS_DEFAULT_PROFILES_FILE`` / ``FASTDDS_DEFAULT_PROFILES_FILE``), a transport choice
(``FASTDDS_BUILTIN_TRANSPORTS``), static peers with the localhost range, the deprecated
``ROS_LOCALHOST_ONLY``, another RMW than Fast DDS, or ``HAPTIC_ANFIS_DDS_SHM=1``.
"""
from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping

from ..resources import DATA_DIR

__all__ = ['LOCALHOST_UDP_PROFILE', 'KEEP_SHM', 'loop_transport_env', 'use_loop_transport']

#: the Fast DDS profile for discovery on this machine only, over UDP only
LOCALHOST_UDP_PROFILE = DATA_DIR / 'dds' / 'localhost_udp.xml'
#: set to '1' to leave the middleware as configured (shared memory included)
KEEP_SHM = 'HAPTIC_ANFIS_DDS_SHM'

_RANGE = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
_OWN_CHOICES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                'FASTDDS_BUILTIN_TRANSPORTS')
_FAST_DDS = ('', 'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')


def loop_transport_env(environ: Mapping[str, str]) -> dict[str, str]:
    """The environment variables to set (before ``rclpy.init``) so that this process's DDS
    participant uses UDP only, with the discovery range ``environ`` asks for; {} = leave it."""
    if (environ.get(KEEP_SHM) == '1' or any(environ.get(k) for k in _OWN_CHOICES)
            or environ.get('RMW_IMPLEMENTATION', '') not in _FAST_DDS
            or environ.get('ROS_LOCALHOST_ONLY') == '1'):
        return {}
    discovery = environ.get(_RANGE, '')
    if discovery == 'LOCALHOST':
        if environ.get('ROS_STATIC_PEERS'):  # the profile has no place for them: rmw's own setup
            return {}
        return {_RANGE: 'SYSTEM_DEFAULT', 'FASTRTPS_DEFAULT_PROFILES_FILE': str(LOCALHOST_UDP_PROFILE)}
    if discovery in ('', 'SUBNET', 'SYSTEM_DEFAULT'):
        return {'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'}
    return {}  # OFF (no other participant) or a value rcl will warn about


def use_loop_transport(environ: MutableMapping[str, str] | None = None) -> dict[str, str]:
    """Apply :func:`loop_transport_env` to ``environ`` (default: this process's environment,
    which rcl and Fast DDS read when the participant is made); returns what was set."""
    env = os.environ if environ is None else environ
    changes = loop_transport_env(env)
    env.update(changes)
    return changes
