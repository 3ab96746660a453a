"""A haptic process's DDS participant uses UDP only (nodes/middleware.py): opening a Fast DDS
shared-memory port held a publishing thread ~333 ms (issue 32)."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from haptic_anfis.nodes.middleware import (KEEP_SHM, LOCALHOST_UDP_PROFILE, UDP_PROFILE,
                                           loop_transport_env, use_loop_transport)

LOCALHOST = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}


PROFILE = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SYSTEM_DEFAULT',
           'FASTRTPS_DEFAULT_PROFILES_FILE': str(LOCALHOST_UDP_PROFILE)}
UDP = {'FASTRTPS_DEFAULT_PROFILES_FILE': str(UDP_PROFILE)}


def test_localhost_discovery_becomes_the_udp_only_profile():
    assert loop_transport_env(LOCALHOST) == PROFILE
    assert LOCALHOST_UDP_PROFILE.is_file()


@pytest.mark.parametrize('profile', [LOCALHOST_UDP_PROFILE, UDP_PROFILE])
def test_the_profiles_are_udp_only_with_large_socket_buffers(profile):
    """A reader that waits for the CPU must not have datagrams dropped: the loop's writers keep
    one sample, so a dropped one is lost for good (the system's ~200 KiB overflowed in a busy
    exam)."""
    import xml.etree.ElementTree as ET
    ns = {'d': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    root = ET.parse(profile).getroot()
    (t,) = root.findall('.//d:transport_descriptor', ns)
    assert t.find('d:type', ns).text == 'UDPv4'
    for tag in ('sendBufferSize', 'receiveBufferSize'):
        assert int(t.find(f'd:{tag}', ns).text) >= 4 * 2**20
    assert root.find('.//d:useBuiltinTransports', ns).text == 'false'


@pytest.mark.parametrize('discovery', [None, 'SUBNET', 'SYSTEM_DEFAULT'])
def test_other_ranges_keep_theirs_with_udp_only(discovery):
    env = {} if discovery is None else {'ROS_AUTOMATIC_DISCOVERY_RANGE': discovery}
    assert loop_transport_env(env) == UDP


@pytest.mark.parametrize('first,then,expected', [
    ('LOCALHOST', 'LOCALHOST', PROFILE),
    ('SUBNET', 'LOCALHOST', PROFILE),
    ('LOCALHOST', 'SUBNET', {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET', **UDP}),
    ('SUBNET', 'OFF', {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'}),
])
def test_it_composes_when_a_runner_sets_its_nodes_range(first, then, expected):
    """A session runner applies it to itself, then starts its nodes with its environment and
    the range they are to use: each node gets that range's setup, not the runner's."""
    env = {'ROS_AUTOMATIC_DISCOVERY_RANGE': first}
    use_loop_transport(env)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = then
    use_loop_transport(env)
    assert env == expected
    assert use_loop_transport(env) == {}  # idempotent


@pytest.mark.parametrize('own', [
    {KEEP_SHM: '1'},
    {'FASTRTPS_DEFAULT_PROFILES_FILE': '/etc/my_profile.xml'},
    {'FASTDDS_DEFAULT_PROFILES_FILE': '/etc/my_profile.xml'},
    {'FASTDDS_BUILTIN_TRANSPORTS': 'SHM'},
    {'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'},
    {'ROS_STATIC_PEERS': '192.168.0.7'},
    {'ROS_LOCALHOST_ONLY': '1'},
    {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'OFF'},
])
def test_a_users_own_middleware_choice_is_left_alone(own):
    env = {**LOCALHOST, **own}
    assert loop_transport_env(env) == {}
    before = dict(env)
    assert use_loop_transport(env) == {} and env == before


def test_use_applies_the_changes_to_the_given_environment():
    env = dict(LOCALHOST)
    changes = use_loop_transport(env)
    assert env == {**LOCALHOST, **changes} == PROFILE


def test_an_environment_from_the_builtin_transport_version_is_recomputed():
    """Before the profiles, other ranges got FASTDDS_BUILTIN_TRANSPORTS=UDPv4 with a marker: a
    process started with such an environment gets the profile, the old setting removed."""
    env = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET', 'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4',
           'HAPTIC_ANFIS_DDS_UDP': '1'}
    use_loop_transport(env)
    assert env == {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET', **UDP}


def test_a_users_own_udp_choice_is_not_taken_for_ours():
    env = {**LOCALHOST, 'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'}  # no marker: the user's
    assert loop_transport_env(env) == {}


NODE = """
import sys, time
from rclpy.node import Node
from std_msgs.msg import String
from haptic_anfis.nodes.runtime import run_node

class Talker(Node):
    def __init__(self):
        super().__init__('udp_talker')
        self.pub = self.create_publisher(String, 'udp_probe', 10)
        self.create_timer(0.02, lambda: self.pub.publish(String(data='hello')))
        self.t0 = time.monotonic()
        self.create_timer(0.1, self._end)
    def _end(self):
        if time.monotonic() - self.t0 > 20.0:
            self.finished = True

sys.exit(run_node(Talker, ['udp_talker']))
"""


def test_a_node_process_talks_udp_only_with_a_localhost_participant(tmp_path):
    """run_node's process has no shared-memory transport (no 'dds.shm' thread) and a participant
    of rmw's own localhost setup (this test process: shared memory and UDP) receives from it."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'  # conftest: isolation
    p = subprocess.Popen([sys.executable, '-c', NODE], cwd=tmp_path, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('udp_listener', context=ctx)
    got = []
    node.create_subscription(String, 'udp_probe', lambda m: got.append(m.data), 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        deadline = time.monotonic() + 30.0
        while not got and time.monotonic() < deadline and p.poll() is None:
            ex.spin_once(timeout_sec=0.05)
        threads = {open(f'/proc/{p.pid}/task/{t}/comm').read().strip()
                   for t in os.listdir(f'/proc/{p.pid}/task')} if p.poll() is None else set()
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        p.terminate()
        out = p.communicate(timeout=30)[0]
    assert got == got[:1] * len(got) and got, out
    assert any(t.startswith('dds.udp') for t in threads), threads
    assert not any(t.startswith('dds.shm') for t in threads), threads
