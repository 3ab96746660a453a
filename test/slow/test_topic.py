"""Player timing (in process) and ``haptic-anfis topic list|echo|hz`` against a running player
process. Own ROS_DOMAIN_ID per test, localhost discovery; no wall-clock assertions: playback timing
is checked by comparing receive-time gaps with the recorded gaps."""
from __future__ import annotations

import statistics
import subprocess
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from haptic_anfis.bag import BagWriter  # noqa: E402
from haptic_anfis.nodes.player import PLAY_QOS, Player  # noqa: E402
from test_bag import _pose_bytes  # noqa: E402
from test_nodes_process import BIN, ROOT, _domains, launch, node_env, stop  # noqa: E402

pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def irregular_bag(tmp_path_factory):
    """60 poses with irregular gaps of 10-80 ms (x = index), and a 200 Hz pose stream."""
    path = tmp_path_factory.mktemp('play') / 'irregular'
    rng = np.random.default_rng(7)
    gaps = rng.uniform(0.010, 0.080, 59)
    t = 1_000_000_000 + np.concatenate([[0], np.cumsum(gaps)]) * 1e9
    with BagWriter(path) as w:
        w.add_topic('/falcon/measured_cp', 'geometry_msgs/msg/PoseStamped')
        for i, ti in enumerate(t):
            w.write('/falcon/measured_cp', _pose_bytes(i), int(ti))
    return path, np.diff(t) * 1e-9


def _play_in_process(bag, rate: float, extra=(), topic='/playback/falcon/measured_cp'):
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    ctx = Context()
    rclpy.init(context=ctx, domain_id=next(_domains))
    sub_node = rclpy.create_node('listener', context=ctx)
    got: list[tuple[float, float]] = []
    sub_node.create_subscription(PoseStamped, topic,
                                 lambda m: got.append((time.monotonic(), m.pose.position.x)),
                                 PLAY_QOS)
    player = Player(context=ctx, parameter_overrides=[
        Parameter('bag_path', value=str(bag)), Parameter('rate', value=rate),
        Parameter('delay', value=1.0), *extra])
    ex = EventsExecutor(context=ctx)
    ex.add_node(sub_node)
    ex.add_node(player)
    try:
        end = time.monotonic() + 60
        while not player.finished and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.005)
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            ex.spin_once(timeout_sec=0.005)
    finally:
        player.close()
        ex.shutdown()
        player.destroy_node()
        sub_node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    return player, got


@pytest.mark.parametrize('rate', [1.0, 2.0])
def test_player_preserves_relative_timing(irregular_bag, rate):
    bag, gaps = irregular_bag
    player, got = _play_in_process(bag, rate)
    assert player.published == 60
    xs = [x for _, x in got]
    assert xs == list(range(60)), xs  # every message, in order
    recv = np.diff([t for t, _ in got])
    want = gaps / rate
    # Gaps follow the recording: the median error is small against the 10-80 ms gaps, and
    # the long gaps stay long (load can only delay single messages, not reorder the schedule).
    # Tolerances are loose on purpose: a shared 2-core machine delays single wake-ups by ~10 ms.
    assert statistics.median(np.abs(recv - want)) < 0.03, (recv - want)
    assert np.corrcoef(recv, want)[0, 1] > 0.8
    assert abs(recv.sum() - want.sum()) < 0.25 * want.sum()


def test_player_never_publishes_on_the_recorded_names_unless_live(irregular_bag):
    """Issue 21 item 6: a live driver / detector subscribes to the recorded names; by default the
    player publishes under /playback only; live:=true publishes on the recorded names."""
    bag, _ = irregular_bag
    player, got = _play_in_process(bag, 8.0, topic='/falcon/measured_cp')
    assert player.published == 60 and got == []
    assert player.topic_map == {'/falcon/measured_cp': '/playback/falcon/measured_cp'}
    player, got = _play_in_process(bag, 8.0, [Parameter('live', value=True)],
                                   topic='/falcon/measured_cp')
    assert [x for _, x in got] == list(range(60))


def test_player_start_offset_skips_the_beginning(irregular_bag):
    bag, gaps = irregular_bag
    offset = float(np.cumsum(gaps)[29]) - 1e-6  # message 30 is the first due
    player, got = _play_in_process(bag, 4.0, [Parameter('start_offset', value=offset)])
    assert [x for _, x in got] == list(range(30, 60))


@pytest.fixture
def running_player(irregular_bag, tmp_path):
    """A player process looping the bag (the running publisher for the topic commands)."""
    domain = next(_domains)
    bag, _ = irregular_bag
    env = node_env(domain)
    log = tmp_path / 'player.log'
    proc = launch('player', ['-p', f'bag_path:={bag}', '-p', 'loop:=true', '-p', 'rate:=4.0'],
                  domain, log)
    yield env, proc, log
    stop(proc)


def _cmd(env, *argv, timeout=90):
    return subprocess.run([str(BIN / 'haptic-anfis'), 'topic', *argv], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_topic_list_echo_hz_against_a_running_publisher(running_player):
    env, proc, log = running_player
    p = _cmd(env, 'list', '-t', '--wait', '3')
    assert p.returncode == 0, p.stderr
    if '/playback/falcon/measured_cp' not in p.stdout:  # slow discovery under load: one more try
        p = _cmd(env, 'list', '-t', '--wait', '10')
    assert '/playback/falcon/measured_cp [geometry_msgs/msg/PoseStamped]' in p.stdout, \
        p.stdout + log.read_text()
    p = _cmd(env, 'echo', 'playback/falcon/measured_cp', '--once', '--timeout', '30')
    assert p.returncode == 0, p.stderr + log.read_text()
    assert p.stdout.count('---') == 1
    assert 'frame_id: tissue' in p.stdout and 'position: {x: ' in p.stdout
    p = _cmd(env, 'echo', '/playback/falcon/measured_cp', '--count', '3', '--flat', '--timeout', '30')
    assert p.returncode == 0, p.stderr
    lines = p.stdout.strip().splitlines()
    assert len(lines) == 3 and all("header.frame_id='tissue'" in ln for ln in lines)
    assert all('pose.position.x=' in ln for ln in lines)
    p = _cmd(env, 'hz', 'playback/falcon/measured_cp', '--duration', '2', '--period', '1',
             '--timeout', '30')
    assert p.returncode == 0, p.stderr
    assert 'average rate:' in p.stdout and 'window:' in p.stdout
    assert proc.poll() is None


def test_topic_echo_times_out_with_a_clear_message(tmp_path):
    env = node_env(next(_domains))
    p = _cmd(env, 'echo', 'no/such/topic', '--timeout', '1')
    assert p.returncode == 1
    assert 'topic /no/such/topic: not in the graph after 1 s' in p.stderr
    # a known type but no publisher: nothing arrives
    p = _cmd(env, 'echo', 'falcon/measured_cp', '--type', 'geometry_msgs/msg/PoseStamped',
             '--timeout', '1')
    assert p.returncode == 1
    assert 'no message on /falcon/measured_cp within 1 s' in p.stderr
    p = _cmd(env, 'hz', 'falcon/measured_cp', '--type', 'geometry_msgs/msg/PoseStamped',
             '--timeout', '1')
    assert p.returncode == 1 and 'no messages on /falcon/measured_cp within 1 s' in p.stderr
    p = _cmd(env, 'echo', 'x', '--type', 'nope/msg/Nothing', '--timeout', '1')
    assert p.returncode == 1 and "message type 'nope/msg/Nothing': not installed" in p.stderr
