"""Bags: record a session of the in-process graph, re-simulate it exactly, read it with an
independent MCAP reader, export it, recover a recording killed with SIGKILL, and clear errors for
bad bags. ROS tests use their own ROS_DOMAIN_ID and localhost discovery (see test_nodes_process)."""
from __future__ import annotations

import csv
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

from haptic_anfis.bag import (BagError, BagWriter, bag_info, format_info, read_messages,  # noqa: E402
                              recover_bag)
from haptic_anfis.nodes.resim import resimulate  # noqa: E402
from haptic_anfis.bag.topics import typestore  # noqa: E402
from haptic_anfis.cli import main as cli  # noqa: E402
from haptic_anfis.nodes.graph import build_graph  # noqa: E402
from haptic_anfis.nodes.recorder import Recorder  # noqa: E402
from test_nodes_process import BIN, ROOT, _domains, node_env  # noqa: E402

pytestmark = pytest.mark.ros
PRESS = {'loop': True, 'start_delay': 0.2, 'approach_height': 0.006, 'pattern': [
    {'press': {'points': [[0.0, 0.0], [0.01, 0.005]], 'depth': 0.012, 'hold': 0.4}},
    {'pause': {'duration': 0.3}}]}


@pytest.fixture(scope='module')
def session(tmp_path_factory):
    """A ~3 s recording of the in-process graph pressing the tissue (all loop topics)."""
    from haptic_anfis.bag.topics import ALL_LOOP_TOPICS
    d = tmp_path_factory.mktemp('session')
    script = d / 'press.yaml'
    script.write_text(yaml.safe_dump(PRESS))
    bag = d / 'bag'
    g = build_graph(['test'], visualizer=False,
                    overrides={'falcon_driver': [Parameter('palpation_script', value=str(script))]},
                    extra=[lambda ctx: Recorder(context=ctx, output=str(bag),
                                                topics=ALL_LOOP_TOPICS)])
    rec = g.extra[0]
    try:
        assert g.spin_for(60.0, lambda: g.contact.n_contact > 300), 'no contact in the session'
        g.spin_for(0.5)
    finally:
        g.shutdown()
    return bag, rec.summary(), g.summary()


def test_session_is_a_complete_bag(session):
    bag, rec, _ = session
    info = bag_info(bag)
    assert rec['dropped'] == 0 and rec['written'] == rec['received'] == info.message_count
    assert (bag / 'metadata.yaml').is_file() and (bag / 'bag.mcap').is_file()
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['version'] == 9 and meta['storage_identifier'] == 'mcap'
    topics = {t.topic: t for t in info.topics}
    assert topics['/falcon/measured_cp'].msgtype == 'geometry_msgs/msg/PoseStamped'
    assert topics['/contact'].msgtype == 'sensor_msgs/msg/JointState'
    assert all(topics[t].count > 0 for t in ('/falcon/measured_cp', '/contact', '/falcon/servo_cf'))


def test_resimulation_reproduces_recorded_wrenches(session):
    bag, _, _ = session
    r = resimulate(bag)
    assert r.missing_poses == 0
    assert r.wrenches > 300 and r.contacts > 300 and r.in_contact > 100
    assert r.max_force_N > 0.5
    assert r.max_diff_N <= 1e-9 and r.rms_diff_N <= 1e-9 and r.max_contact_diff <= 1e-12


def test_resimulation_with_another_model_differs(session, tmp_path, small_model):
    bag, _, _ = session
    m = small_model.save(tmp_path / 'other.json')
    r = resimulate(bag, force_overrides={'model_path': str(m)})
    assert r.max_diff_N > 1e-3 and r.rms_diff_N > 0
    assert cli(['bag', 'resim', str(bag), '--model', str(m), '--tolerance', '1e-9']) == 1
    assert cli(['bag', 'resim', str(bag), '--tolerance', '1e-9']) == 0


def test_independent_mcap_reader_decodes_every_message(session):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    bag, _, _ = session
    info = bag_info(bag)
    ours = [(t, ty, ts) for t, ty, ts, _ in read_messages(bag, deserialize=False)]
    theirs = []
    first_pose = None
    with (bag / 'bag.mcap').open('rb') as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == info.message_count
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            theirs.append((channel.topic, schema.name, message.log_time))
            if channel.topic == '/falcon/measured_cp' and first_pose is None:
                first_pose = decoded
    assert len(theirs) == info.message_count == len(ours)
    assert sorted(theirs) == sorted(ours)
    _, _, _, ours_pose = next(read_messages(bag, ['/falcon/measured_cp']))
    assert first_pose.pose.position.x == ours_pose.pose.position.x
    assert first_pose.header.frame_id == 'tissue'


def test_info_and_csv_export(session, tmp_path, capsys):
    bag, _, _ = session
    assert cli(['bag', 'info', str(bag)]) == 0
    out = capsys.readouterr().out
    assert '/falcon/measured_cp' in out and 'geometry_msgs/msg/PoseStamped' in out
    assert 'Duration' in out and 'rate Hz' in out
    assert cli(['bag', 'export', str(bag), '--csv', str(tmp_path / 'csv')]) == 0
    counts = {t.topic: t.count for t in bag_info(bag).topics}
    with (tmp_path / 'csv' / 'contact.csv').open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == counts['/contact']
    assert {'t_recv', 'header.stamp', 'contact_x', 'depth', 'in_contact'} <= set(rows[0])
    with (tmp_path / 'csv' / 'falcon__servo_cf.csv').open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == counts['/falcon/servo_cf'] and 'wrench.force.x' in rows[0]
    assert max(abs(float(r['wrench.force.x'])) for r in rows) > 0.5


def _pose_bytes(i: int) -> bytes:
    ts = typestore()
    P = ts.types['geometry_msgs/msg/PoseStamped']
    H, T = ts.types['std_msgs/msg/Header'], ts.types['builtin_interfaces/msg/Time']
    Po, Pt, Q = (ts.types[f'geometry_msgs/msg/{n}'] for n in ('Pose', 'Point', 'Quaternion'))
    return ts.serialize_cdr(P(H(T(i, 0), 'tissue'), Po(Pt(float(i), 0.0, 0.0),
                                                       Q(0.0, 0.0, 0.0, 1.0))), P.__msgtype__)


def _small_bag(path: Path, n: int = 50, topic='/falcon/measured_cp',
               msgtype='geometry_msgs/msg/PoseStamped') -> Path:
    with BagWriter(path) as w:
        w.add_topic(topic, msgtype)
        for i in range(n):
            w.write(topic, _pose_bytes(i), 1_000_000_000 + i * 1_000_000)
    return path


def _error(capsys, *argv) -> str:
    assert cli(list(argv)) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1, err  # one line, no traceback
    return err


def test_bad_bags_give_clear_errors(tmp_path, capsys):
    # not there / not a bag
    assert 'no such file or directory' in _error(capsys, 'bag', 'info', str(tmp_path / 'nope'))
    (tmp_path / 'file.txt').write_text('hello')
    e = _error(capsys, 'bag', 'info', str(tmp_path / 'file.txt'))
    assert 'file.txt: not a bag' in e and 'metadata.yaml' in e
    (tmp_path / 'empty').mkdir()
    assert 'empty: not a bag: no metadata.yaml' in _error(capsys, 'bag', 'info',
                                                          str(tmp_path / 'empty'))
    # missing metadata: points at recover
    b = _small_bag(tmp_path / 'nometa')
    (b / 'metadata.yaml').unlink()
    e = _error(capsys, 'bag', 'info', str(b))
    assert 'nometa: metadata.yaml is missing' in e and 'bag recover' in e
    # truncated MCAP with its metadata
    b = _small_bag(tmp_path / 'trunc')
    data = (b / 'trunc.mcap').read_bytes()
    (b / 'trunc.mcap').write_bytes(data[:len(data) - 40])
    e = _error(capsys, 'bag', 'info', str(b))
    assert 'trunc' in e and 'bag recover' in e
    # a .mcap that is not MCAP
    (tmp_path / 'junk').mkdir()
    (tmp_path / 'junk' / 'junk.mcap').write_bytes(b'not an mcap file at all' * 10)
    assert 'not an MCAP file' in _error(capsys, 'bag', 'recover', str(tmp_path / 'junk'))
    # wrong topic type for re-simulation
    w = _small_bag(tmp_path / 'joy', topic='/falcon/measured_cp', msgtype='sensor_msgs/msg/Joy')
    e = _error(capsys, 'bag', 'resim', str(w))
    assert 'joy: topic /falcon/measured_cp has type sensor_msgs/msg/Joy, expected ' \
           'geometry_msgs/msg/PoseStamped' in e
    # unknown type without a definition
    from rosbags.rosbag2 import StoragePlugin, Writer
    u = tmp_path / 'unknown'
    with Writer(u, version=9, storage_plugin=StoragePlugin.MCAP) as wr:
        c = wr.add_connection('/x', 'my_pkg/msg/Mystery', msgdef='', rihs01='RIHS01_' + '0' * 64)
        wr.write(c, 1, b'\x00\x01\x00\x00')
    with pytest.raises(BagError, match=r"unknown.*topic /x: unknown message type 'my_pkg/msg/"
                                       r"Mystery'"):
        list(read_messages(u))
    # writer side: existing path, unknown type
    with pytest.raises(BagError, match='exists already'):
        BagWriter(b)
    with BagWriter(tmp_path / 'new') as bw, pytest.raises(BagError, match='unknown message type'):
        bw.add_topic('/y', 'my_pkg/msg/Mystery')


@contextmanager
def _pose_publisher(domain: int, proc: subprocess.Popen, why=lambda: ''):
    """A PoseStamped publisher on falcon/measured_cp in its own context, yielded once the process
    ``proc`` subscribes to it; on exit the process is killed if still running and ROS shut down."""
    from rclpy.context import Context
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node('pose_publisher', context=ctx)
    pub = node.create_publisher(PoseStamped, '/falcon/measured_cp', QoSProfile(
        depth=1000, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE))
    try:
        end = time.monotonic() + 60
        while pub.get_subscription_count() == 0:
            assert time.monotonic() < end and proc.poll() is None, why()
            time.sleep(0.05)
        time.sleep(0.5)  # let the match complete on the subscriber's side too
        yield pub
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)


def test_recorder_killed_with_sigkill_is_recovered(tmp_path):
    """A recorder process is SIGKILLed while a 1 kHz publisher runs: recover keeps >= 95 %."""
    domain = next(_domains)
    bag = tmp_path / 'killed'
    log = (tmp_path / 'recorder.log').open('w')
    proc = subprocess.Popen([str(BIN / 'recorder'), '--ros-args', '-p', f'output:={bag}',
                             '-p', 'topics:=[falcon/measured_cp]', '-p', 'flush_period:=0.2'],
                            env=node_env(domain), cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    with _pose_publisher(domain, proc, lambda: (tmp_path / 'recorder.log').read_text()) as pub:
        msg = PoseStamped()
        msg.header.frame_id = 'tissue'
        published = 0
        t0 = time.monotonic()
        while time.monotonic() - t0 < 6.0:
            msg.pose.position.x = float(published)
            pub.publish(msg)
            published += 1
            time.sleep(0.001)
        proc.send_signal(signal.SIGKILL)  # while "publishing": nothing closes the bag
        proc.wait(10)
    assert not (bag / 'metadata.yaml').exists()
    with pytest.raises(BagError, match='metadata.yaml is missing'):
        bag_info(bag)
    report = recover_bag(bag)
    got = [m.pose.position.x for _, _, _, m in read_messages(bag)]
    assert report.messages == len(got) == bag_info(bag).message_count
    assert len(got) >= 0.95 * published, (len(got), published)
    assert got == sorted(got) and len(set(got)) == len(got)
    assert (bag / 'killed.mcap.damaged').is_file()
    info = bag_info(bag)
    assert [f for f, _ in info.kept] == ['killed.mcap.damaged']
    assert 'Kept files:    killed.mcap.damaged (' in format_info(info)
    assert recover_bag(bag).already_valid


def test_record_command_closes_bag_on_sigint(tmp_path):
    """``haptic-anfis bag record`` stopped by Ctrl-C writes a complete bag (metadata included)."""
    domain = next(_domains)
    bag = tmp_path / 'rec'
    proc = subprocess.Popen([str(BIN / 'haptic-anfis'), 'bag', 'record', '-o', str(bag),
                             'falcon/measured_cp'], env=node_env(domain), cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    with _pose_publisher(domain, proc) as pub:
        msg = PoseStamped()
        msg.header.frame_id = 'tissue'
        for i in range(300):
            msg.pose.position.x = float(i)
            pub.publish(msg)
            time.sleep(0.001)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, out
    assert (bag / 'metadata.yaml').is_file(), out
    assert bag_info(bag).message_count == 300, out


def _joint_state_bag(path: Path, topic: str, msgs, more_topics=()) -> Path:
    """A bag of JointState messages on ``topic``, one per ``(names, position, effort)`` of
    ``msgs``; ``more_topics``: (topic, type) added without messages."""
    import numpy as np
    ts = typestore()
    J = ts.types['sensor_msgs/msg/JointState']
    H, T = ts.types['std_msgs/msg/Header'], ts.types['builtin_interfaces/msg/Time']
    with BagWriter(path) as w:
        w.add_topic(topic, J.__msgtype__)
        for t, msgtype in more_topics:
            w.add_topic(t, msgtype)
        for i, (names, position, effort) in enumerate(msgs):
            msg = J(H(T(i, 0), 'tissue'), list(names), np.asarray(position, dtype=float),
                    np.zeros(0), np.asarray(effort, dtype=float))
            w.write(topic, ts.serialize_cdr(msg, J.__msgtype__), 1_000 + i)
    return path


def test_export_keeps_rows_when_joint_names_change(tmp_path):
    """A JointState topic whose names change mid-bag: every message still gets a CSV row."""
    bag = _joint_state_bag(tmp_path / 'names', '/joints',
                           [(n, range(len(n)), ()) for n in [['a', 'b']] * 3 + [['c']] * 2])
    assert cli(['bag', 'export', str(bag), '--csv', str(tmp_path / 'csv')]) == 0
    with (tmp_path / 'csv' / 'joints.csv').open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 5


def test_export_keeps_the_contact_approach_values_and_says_when_there_is_nothing(
        tmp_path, capsys):
    """The contact message carries the six approach values in ``effort`` while the probe is
    free (a length other than its names'): they were dropped. A bag or a topic without
    messages exported nothing and said nothing."""
    from haptic_anfis.interfaces import APPROACH_FIELDS, CONTACT_FIELDS
    approach = [0.01, 0.02, 0.03, 1.0, 0.0, 0.0]
    bag = _joint_state_bag(tmp_path / 'contact', '/contact',
                           [(CONTACT_FIELDS, [0.0] * len(CONTACT_FIELDS), e)
                            for e in (approach, approach, ())],
                           more_topics=[('/falcon/servo_cf', 'geometry_msgs/msg/WrenchStamped')])
    assert cli(['bag', 'export', str(bag), '--csv', str(tmp_path / 'csv')]) == 0
    out = capsys.readouterr().out
    assert '/falcon/servo_cf: no messages (no file)' in out and '/contact: 3 rows' in out
    with (tmp_path / 'csv' / 'contact.csv').open() as fh:
        rows = list(csv.DictReader(fh))
    assert [r['effort.surface_x'] for r in rows] == ['0.01', '0.01', '']
    assert {'effort.' + n for n in APPROACH_FIELDS} <= set(rows[0])
    assert rows[2]['effort.normal_x'] == ''   # in contact: no approach values
    assert not list((tmp_path / 'csv').glob('.export-*'))   # its spill files are gone
    e = _error(capsys, 'bag', 'export', str(bag), '--csv', str(tmp_path / 'c2'), '--topics',
               '/falcon/servo_cf')
    assert 'no messages on /falcon/servo_cf; nothing to export' in e


def test_a_bag_being_recorded_is_not_called_interrupted_nor_recovered(tmp_path, capsys):
    """While a recording runs its bag has no metadata.yaml, as an interrupted one; `bag
    recover` then moved the live file aside and the rest of the session went into a file
    nothing reads. The writer holds a lock on its file: info and recover say it is being
    recorded, and after the close the bag is whole."""
    from haptic_anfis.bag import recover_bag
    bag = tmp_path / 'live'
    w = BagWriter(bag)
    w.add_topic('/falcon/measured_cp', 'geometry_msgs/msg/PoseStamped')
    for i in range(20):
        w.write('/falcon/measured_cp', _pose_bytes(i), 1_000_000_000 + i * 1_000_000)
    assert 'being recorded' in _error(capsys, 'bag', 'info', str(bag))
    with pytest.raises(BagError, match='being recorded'):
        recover_bag(bag)
    for i in range(20, 40):
        w.write('/falcon/measured_cp', _pose_bytes(i), 1_000_000_000 + i * 1_000_000)
    w.close()
    assert bag_info(bag).message_count == 40 and sorted(p.name for p in bag.iterdir()) == [
        'live.mcap', 'metadata.yaml']


def test_a_forked_child_does_not_keep_a_closed_recording_locked(tmp_path):
    """The driver forks its servo process while the recorder (in `sim`, the same process) has
    its bag open: the child's copy of the lock's descriptor must not keep the bag 'being
    recorded' after the recorder closed it."""
    import os

    from haptic_anfis.bag.lock import being_recorded
    bag = tmp_path / 'forked'
    w = BagWriter(bag)
    w.add_topic('/falcon/measured_cp', 'geometry_msgs/msg/PoseStamped')
    w.write('/falcon/measured_cp', _pose_bytes(0), 1_000_000_000)
    r, wr = os.pipe()
    pid = os.fork()
    if pid == 0:   # the child waits until the parent has checked, then leaves
        os.close(wr)
        os.read(r, 1)
        os._exit(0)
    try:
        os.close(r)
        assert being_recorded(bag / 'forked.mcap')
        w.close()
        assert not being_recorded(bag / 'forked.mcap')
    finally:
        os.write(wr, b'x')
        os.close(wr)
        os.waitpid(pid, 0)


def test_bag_info_ends_at_the_last_message(tmp_path):
    """`bag info`'s end was 1 ns past the last message (rosbags' exclusive end)."""
    bag = tmp_path / 'three'
    with BagWriter(bag) as w:
        w.add_topic('/falcon/measured_cp', 'geometry_msgs/msg/PoseStamped')
        for i in range(3):
            w.write('/falcon/measured_cp', _pose_bytes(i), 1_000_000_000 + i * 1_000_000)
    for path in (bag, bag / 'three.mcap'):
        info = bag_info(path)
        assert (info.start_ns, info.end_ns) == (1_000_000_000, 1_002_000_000), path
        assert info.duration_s == pytest.approx(0.002, abs=1e-12)


def test_recover_from_inside_the_bag_directory(tmp_path, monkeypatch, capsys):
    """`bag recover .`: the path has no name to build the temporary bag's from; it was a
    traceback and a stray '..recovering' folder inside the bag."""
    bag = _small_bag(tmp_path / 'b', n=30)
    (bag / 'metadata.yaml').unlink()   # as a killed recording leaves it
    monkeypatch.chdir(bag)
    assert cli(['bag', 'recover', '.']) == 0
    assert 'recovered 30 messages' in capsys.readouterr().out
    assert bag_info(bag).message_count == 30
    assert not list(bag.glob('*recovering*')) and not list(tmp_path.glob('*recovering*'))


def test_a_write_that_fails_hands_its_message_on():
    """rosbags closes a chunk by itself inside a write once it passes its size limit: if that
    close fails (a full disk) the message is in the lost chunk, so it must be among those
    handed to the next bag (it was neither written, handed on nor counted lost)."""
    import tempfile

    from haptic_anfis.bag.segment import Segment
    with tempfile.TemporaryDirectory() as d:
        seg = Segment(Path(d) / 'b', {})
        seg.add_connection('/p', 'geometry_msgs/msg/PoseStamped')
        seg.write('/p', 1, _pose_bytes(1))

        def full(*a):
            raise OSError(28, 'No space left on device')
        seg.w.write = full
        with pytest.raises(OSError):
            seg.write('/p', 2, _pose_bytes(2))
        assert [t for _, t, _ in seg.unflushed] == [1, 2]
        seg.seal()


def test_player_resimulate_mode_plays_the_recomputed_wrenches(session, monkeypatch):
    """The player's re-simulate mode: the comparison matches (0 N), and the force-command topic it
    plays carries the recomputed forces (shifted by +1 N here to see the swap) at the same stamps."""
    from geometry_msgs.msg import WrenchStamped
    from rclpy.context import Context
    from rclpy.serialization import deserialize_message

    import haptic_anfis.nodes.player as player_mod
    from haptic_anfis.nodes.player import Player

    bag, _, _ = session
    real = player_mod.resimulate

    def shifted(*a, **kw):
        r = real(*a, **kw)
        assert r.wrenches > 0 and r.max_diff_N < 1e-9  # the real comparison, through the player
        r.recomputed = {k: (f[0] + 1.0, f[1], f[2]) for k, f in r.recomputed.items()}
        return r

    monkeypatch.setattr(player_mod, 'resimulate', shifted)  # the name the player calls
    ctx = Context()
    rclpy.init(context=ctx)
    try:
        p = Player(context=ctx, parameter_overrides=[
            Parameter('bag_path', value=str(bag)), Parameter('resimulate', value=True),
            Parameter('delay', value=60.0)])  # nothing is published during the test
        try:
            recorded = {m.header.stamp.sec * 10**9 + m.header.stamp.nanosec: m.wrench.force.x
                        for _, _, _, m in read_messages(bag, ['/falcon/servo_cf'])}
            played = [deserialize_message(r.data, WrenchStamped) for _, r in p.schedule()
                      if r.topic == '/falcon/servo_cf']
            assert len(played) == len(recorded) > 0
            for m in played:
                stamp = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                assert m.wrench.force.x == pytest.approx(recorded[stamp] + 1.0, abs=1e-9)
        finally:
            p.close()
            p.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
