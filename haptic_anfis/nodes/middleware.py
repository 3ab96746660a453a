"""The middleware settings of a haptic process: Fast DDS over UDP only, no shared memory.

Why (docs/sessions.md): Fast DDS checks a shared-memory port's health whenever a
process opens another process's port, which it does on the first message to a newly discovered
participant. When the port's listener has been idle and was checked a moment before, the opening
thread sleeps a full listener period — a third of ``healthy_check_timeout_ms`` (default 1000), so
~333 ms — and it is the thread that publishes (rmw_fastrtps publishes synchronously) or the
discovery thread holding the writer's lock. Measured with ``launch``: one pose -> command latency
of 333-342 ms in about one start in four, the local model expiring mid-press; over UDP only, none
(docs/sessions.md, *The middleware*). For
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` rmw_fastrtps adds its shared-memory transport itself,
so the same discovery (this machine only) is given as a Fast DDS profile instead
(``data/dds/localhost_udp.xml``) with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT``; other
ranges keep theirs with the profile ``data/dds/udp.xml`` (Fast DDS's default discovery). Both
profiles ask for 4 MiB socket buffers: with the system's ~200 KiB a reader process waiting for
the CPU had datagrams dropped, and the loop's writers keep one sample (a dropped one never
arrives). Applied by ``run_node`` (every node process, ``ros2 run`` included) and by the
``haptic-anfis`` program for itself and what it starts (``sim``, ``exam run``, ``launch``); not
by a call from Python (``main([...])``, tests). Other ROS 2 programs (``ros2 topic echo``, rviz,
a user's own nodes) still find and talk to these nodes: over UDP.

Nothing is changed when the user configured the middleware: a Fast DDS profile of their own
(``FASTRTPS_DEFAULT_PROFILES_FILE`` / ``FASTDDS_DEFAULT_PROFILES_FILE``), a transport choice
(``FASTDDS_BUILTIN_TRANSPORTS``), static peers with the localhost range, the deprecated
``ROS_LOCALHOST_ONLY``, another RMW than Fast DDS, or ``HAPTIC_ANFIS_DDS_SHM=1``.
"""
from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping

from ..resources import DATA_DIR

__all__ = ['LOCALHOST_UDP_PROFILE', 'UDP_PROFILE', 'KEEP_SHM', 'loop_transport_env',
           'use_loop_transport']

#: the Fast DDS profile for discovery on this machine only, over UDP only
LOCALHOST_UDP_PROFILE = DATA_DIR / 'dds' / 'localhost_udp.xml'
#: the Fast DDS profile for the other discovery ranges: UDP only, Fast DDS's default discovery
UDP_PROFILE = DATA_DIR / 'dds' / 'udp.xml'
#: set to '1' to leave the middleware as configured (shared memory included)
KEEP_SHM = 'HAPTIC_ANFIS_DDS_SHM'
#: '1' when FASTDDS_BUILTIN_TRANSPORTS was set by this module (recomputed in a child process, not
#: taken for the user's)
_APPLIED = 'HAPTIC_ANFIS_DDS_UDP'

_RANGE = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
_PROFILE = 'FASTRTPS_DEFAULT_PROFILES_FILE'
_BUILTIN = 'FASTDDS_BUILTIN_TRANSPORTS'
_FAST_DDS = ('', 'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')


def loop_transport_env(environ: Mapping[str, str]) -> dict[str, str | None]:
    """The environment changes (None: unset) that make this process's DDS participant use UDP
    only, with the discovery range ``environ`` asks for; {} = nothing to change. Idempotent, and
    it composes: a process started with this one's environment and another range (a session
    runner sets ``ROS_AUTOMATIC_DISCOVERY_RANGE`` for its nodes) gets that range's setup."""
    ours_profile = environ.get(_PROFILE) in (str(LOCALHOST_UDP_PROFILE), str(UDP_PROFILE))
    ours_builtin = environ.get(_APPLIED) == '1' and environ.get(_BUILTIN) == 'UDPv4'
    users_own = ((environ.get(_PROFILE) and not ours_profile)
                 or environ.get('FASTDDS_DEFAULT_PROFILES_FILE')
                 or (environ.get(_BUILTIN) and not ours_builtin))
    if (environ.get(KEEP_SHM) == '1' or users_own or environ.get('ROS_LOCALHOST_ONLY') == '1'
            or environ.get('RMW_IMPLEMENTATION', '') not in _FAST_DDS):
        return {}
    discovery = environ.get(_RANGE, '')
    if discovery == 'LOCALHOST' and not environ.get('ROS_STATIC_PEERS'):
        want = {_RANGE: 'SYSTEM_DEFAULT', _PROFILE: str(LOCALHOST_UDP_PROFILE), _BUILTIN: None,
                _APPLIED: None}
    elif discovery == 'SYSTEM_DEFAULT' and ours_profile:
        want = {}  # applied already (LOCALHOST's profile says SYSTEM_DEFAULT)
    elif discovery in ('', 'SUBNET', 'SYSTEM_DEFAULT'):
        want = {_PROFILE: str(UDP_PROFILE), _BUILTIN: None, _APPLIED: None}
    else:  # OFF (no other participant), LOCALHOST with static peers (rmw's own setup), unknown
        want = {_PROFILE: None, _BUILTIN: None, _APPLIED: None}
    return {k: v for k, v in want.items() if environ.get(k) != v}


def use_loop_transport(environ: MutableMapping[str, str] | None = None) -> dict[str, str | None]:
    """Apply :func:`loop_transport_env` to ``environ`` (default: this process's environment,
    which rcl and Fast DDS read when the participant is made); returns what was changed."""
    env = os.environ if environ is None else environ
    changes = loop_transport_env(env)
    for k, v in changes.items():
        if v is None:
            env.pop(k, None)
        else:
            env[k] = v
    return changes
