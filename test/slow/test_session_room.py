"""The session room with ROS: one session per domain (issue 27.5) and a restarted node's output
held until the recorder has matched it (issue 27.2). Plain rclpy nodes stand in for the real ones:
no graph is built, each test takes a second or two."""
from __future__ import annotations

import contextlib

import pytest

rclpy = pytest.importorskip('rclpy')
pytestmark = pytest.mark.ros


@contextlib.contextmanager
def _node(name: str):
    from rclpy.context import Context
    ctx = Context()
    rclpy.init(args=[], context=ctx)
    node = rclpy.create_node(name, context=ctx, start_parameter_services=False)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def test_a_session_refuses_a_domain_with_another_sessions_driver_unless_told_to_share():
    from haptic_anfis.session import SessionError, SessionSpec
    from haptic_anfis.session.domain import others_on_domain, refuse_shared_domain
    assert others_on_domain(wait=0.3) == []
    refuse_shared_domain(SessionSpec())  # nothing there: no error
    with _node('falcon_driver'):
        assert others_on_domain(wait=5.0) == ['falcon_driver']
        with pytest.raises(SessionError, match=r'already has a running session \(falcon_driver '
                                               r'seen\).*--share-domain'):
            refuse_shared_domain(SessionSpec())
        refuse_shared_domain(SessionSpec(share_domain=True))


def test_a_restarted_node_holds_its_output_until_the_recorder_matched_it():
    from std_msgs.msg import String

    from haptic_anfis.nodes.runtime import hold_until_recorder_matched
    with _node('recorder') as rec, _node('force_server') as fs:
        rec.create_subscription(String, '/falcon/servo_cf_test', lambda m: None, 10)
        pub = fs.create_publisher(String, '/falcon/servo_cf_test', 10)
        # told the recorded topics: the recorder's subscription has been discovered and matched
        # (the recorder's name alone may be known before its endpoints)
        assert hold_until_recorder_matched(fs, 'recorder', timeout=10.0,
                                           topics=['falcon/servo_cf_test'])
        assert pub.get_subscription_count() >= 1
    with _node('force_server') as alone:  # no recorder on the domain: gives up, warned
        alone.create_publisher(String, '/falcon/servo_cf_test', 10)
        assert not hold_until_recorder_matched(alone, 'recorder', timeout=0.3)
    with _node('recorder'), _node('force_server') as fs:  # the recorder without that topic yet
        fs.create_publisher(String, '/falcon/servo_cf_test', 10)
        assert not hold_until_recorder_matched(fs, 'recorder', timeout=1.0,
                                               topics=['/falcon/servo_cf_test'])


def test_a_node_stopped_with_sigint_closes_without_a_warning(tmp_path):
    """Issue 27.6: the recorder (timers and a taker thread; its close() logs its summary)
    stopped as a session stops it: exit 0, its summary logged, no warning, no FATAL callback
    exception, nothing about an invalid context (rclpy's own SIGINT handler shut the context
    down before close() logged: "Failed to publish log message to rosout")."""
    import os
    import signal
    import time
    from pathlib import Path

    from haptic_anfis.realtime.processes import node_env, start_node
    root = Path(__file__).resolve().parents[2]
    log = tmp_path / 'recorder.log'
    env = {**node_env(int(os.environ['ROS_DOMAIN_ID']) + 1, localhost=True),
           'PYTHONPATH': str(root)}
    p = start_node('recorder', ['-p', f'output:={tmp_path / "bag"}'], env=env,
                   log=log.open('w'))
    try:
        end = time.monotonic() + 180
        while 'started after' not in log.read_text() and time.monotonic() < end \
                and p.poll() is None:
            time.sleep(0.1)
        time.sleep(1.0)  # its timers run
        p.send_signal(signal.SIGINT)
        assert p.wait(60) == 0, log.read_text()
    finally:
        if p.poll() is None:
            p.kill()
    text = log.read_text()
    assert 'interrupted while starting' not in text, text  # it was running
    assert 'recorded 0 messages' in text, text  # close() logged its summary
    for bad in ('[WARN]', '[ERROR]', '[FATAL]', 'Failed to publish', 'Traceback'):
        assert bad not in text, text
