"""The case a session ran is in its bag: the recorder writes it (and each switch) into the bag's
custom data, a crash keeps it (``bag recover`` reads it back from the MCAP), and ``exam report``
/ ``view BAG`` score against it when no ``--case`` is given (they scored every bag against the
default case: a small-breast case's bag got ~0 % coverage)."""
from __future__ import annotations

import json
import shutil
import time

import pytest

from haptic_anfis.bag import BagError, BagWriter, bag_info, read_messages, recover_bag
from haptic_anfis.cases import CaseError
from haptic_anfis.exam.from_bag import recorded_case
from haptic_anfis.bag.reader import RECORDER_MARK
from test_bag import _pose_bytes as _pose

TOPIC = '/falcon/measured_cp'
OURS = {'recorder': RECORDER_MARK}


def test_custom_data_set_while_recording_is_in_the_bag_and_survives_a_crash(tmp_path):
    """Set at the start and changed mid-recording: metadata.yaml has the latest value after a
    close; a copy of the live files (what a SIGKILL leaves: no metadata.yaml) recovers it."""
    bag = tmp_path / 'live'
    w = BagWriter(bag, flush_period=0.05, custom_data={**OURS, 'case': 'a', 'recorder': 'test'})
    w.add_topic(TOPIC, 'geometry_msgs/msg/PoseStamped')
    for i in range(50):
        w.write(TOPIC, _pose(i), 1_000_000_000 + i * 1_000_000)
    w.set_custom_data('case', 'a, b')
    for i in range(50, 100):
        w.write(TOPIC, _pose(i), 1_000_000_000 + i * 1_000_000)
    time.sleep(0.5)   # past the flush period: every message is in a closed chunk
    killed = tmp_path / 'killed'
    shutil.copytree(bag, killed)
    (killed / 'live.mcap').rename(killed / 'killed.mcap')
    w.close()
    info = bag_info(bag)
    assert info.custom_data == {**OURS, 'case': 'a, b', 'recorder': 'test', 'dropped_messages': '0'}
    assert info.message_count == 100
    # the extra metadata records do not disturb the readers (rosbags', and mcap's)
    got = [m.pose.position.x for _, _, _, m in read_messages(bag)]
    assert got == [float(i) for i in range(100)]
    from mcap.reader import make_reader
    with (bag / 'live.mcap').open('rb') as fh:
        assert sum(1 for _ in make_reader(fh).iter_messages()) == 100
    # the summary counts every metadata record (rosbags counts its own only)
    with (bag / 'live.mcap').open('rb') as fh:
        assert make_reader(fh).get_summary().statistics.metadata_count == 3
    assert bag_info(bag / 'live.mcap').custom_data['case'] == 'a, b'   # the file of the bag
    assert not (killed / 'metadata.yaml').exists()
    report = recover_bag(killed)
    assert report.messages == 100
    assert bag_info(killed).custom_data['case'] == 'a, b'
    assert bag_info(killed).custom_data['recorder'] == 'test'


def test_no_room_for_the_custom_data_is_a_bag_error(tmp_path):
    """A file-size limit (as a full disk) past the MCAP header but before the custom data: one
    clear error naming the bag, as for a bag that cannot be created at all."""
    import subprocess
    import sys
    script = (
        'import resource, signal, sys\n'
        'signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n'
        'from haptic_anfis.bag import BagError, BagWriter\n'
        'resource.setrlimit(resource.RLIMIT_FSIZE, (80, resource.RLIM_INFINITY))\n'
        'try:\n'
        '    BagWriter(sys.argv[1], custom_data={"case": "x" * 100})\n'
        'except BagError as exc:\n'
        '    print("BagError", exc)\n')
    out = subprocess.run([sys.executable, '-c', script, str(tmp_path / 'full')],
                         capture_output=True, text=True, timeout=60)
    assert out.stdout.startswith(f'BagError {tmp_path / "full"}: cannot create the bag:'), out


def test_a_bag_without_custom_data_has_no_metadata_record(tmp_path):
    """Nothing to keep: the file holds no record of ours (and reads as before)."""
    bag = tmp_path / 'plain'
    with BagWriter(bag) as w:
        w.add_topic(TOPIC, 'geometry_msgs/msg/PoseStamped')
        w.write(TOPIC, _pose(0), 1_000_000_000)
    from haptic_anfis.bag.segment import CUSTOM_RECORD
    assert CUSTOM_RECORD.encode() not in (bag / 'plain.mcap').read_bytes()
    assert bag_info(bag).custom_data == {'dropped_messages': '0'}


# --- which case a report scores against --------------------------------------------------------

def test_the_recorded_case_is_the_default_for_scoring():
    assert recorded_case('b', {**OURS, 'case': 'normal'}, None) == ('normal', '')
    assert recorded_case('b', {**OURS, 'case': 'default'}, None) == (None, '')


def test_a_bag_that_does_not_say_is_scored_against_the_default_and_says_so():
    case, note = recorded_case('b', OURS, None)
    assert case is None and 'does not say which case' in note and '--case' in note
    # another recorder's entries of these names are not ours
    case, note = recorded_case('b', {'recorder': 'other', 'case': 'normal', 'scene': 'x'}, None)
    assert case is None and 'does not say which case' in note


def test_an_explicit_case_wins_and_a_different_one_is_noted():
    assert recorded_case('b', {**OURS, 'case': 'normal'}, 'normal') == ('normal', '')
    case, note = recorded_case('b', {**OURS, 'case': 'normal'}, 'default')
    assert case == 'default'
    assert note == 'scored against --case default; the bag was recorded with case normal'
    assert recorded_case('b', OURS, 'default') == ('default', '')


def test_a_bag_of_several_cases_needs_a_case():
    with pytest.raises(BagError, match=r"b: the session switched cases while recording "
                                       r"\(normal, default\): give --case NAME"):
        recorded_case('b', {**OURS, 'case': 'normal, default'}, None)
    assert recorded_case('b', {**OURS, 'case': 'normal, default'}, 'normal')[0] == 'normal'


def test_a_case_this_library_does_not_have_is_named_with_the_bag():
    with pytest.raises(CaseError, match="^b: recorded with case no_such_case: "):
        recorded_case('b', {**OURS, 'case': 'no_such_case'}, None)


def test_the_scene_file_of_an_exam_is_used_and_one_that_is_gone_is_said(tmp_path):
    scene = tmp_path / 'scene.yaml'
    scene.write_text('x: 1\n')
    said = {**OURS, 'case': 'default', 'scene': str(scene)}
    assert recorded_case('b', said, None) == (str(scene), '')
    assert recorded_case('b', said, str(scene))[1] == ''
    with pytest.raises(BagError, match='switched cases'):   # its exam switched case afterwards
        recorded_case('b', {**said, 'case': 'unknown, normal'}, None)
    scene.unlink()
    with pytest.raises(BagError, match='scene.yaml, which is gone: give --case'):
        recorded_case('b', said, None)


# --- the recorder node ------------------------------------------------------------------------

@pytest.mark.ros
def test_the_recorder_writes_the_case_and_follows_a_switch(tmp_path):
    """``case`` at start, then two switches (the browser page's instructor, ``ros2 param set``),
    one of them back: the bag names them in order; a blind draw is named too (the instructor
    scores it; the bag is read after the session)."""
    rclpy = pytest.importorskip('rclpy')
    from rclpy.parameter import Parameter

    from haptic_anfis.cases import library
    from haptic_anfis.nodes.recorder import Recorder
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        rec = Recorder(context=ctx, output=str(tmp_path / 'bag'), topics=[TOPIC],
                       parameter_overrides=[Parameter('case', value='normal')])
        assert rec.set_parameters([Parameter('case', value='')])[0].successful
        assert not rec.set_parameters([Parameter('case', value='no_such_case')])[0].successful
        drawn = library().random(7).name
        assert rec.set_parameters([Parameter('random_case_seed', value=7)])[0].successful
        rec.close()
        rec.destroy_node()
        blind = Recorder(context=ctx, output=str(tmp_path / 'blind'), topics=[TOPIC],
                         parameter_overrides=[Parameter('random_case_seed', value=7)])
        blind.close()
        blind.destroy_node()
        for name, switch in (('none', False), ('none_then', True)):   # it cannot know
            r = Recorder(context=ctx, output=str(tmp_path / name), topics=[TOPIC])
            if switch:
                assert r.set_parameters([Parameter('case', value='normal')])[0].successful
            r.close()
            r.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    assert bag_info(tmp_path / 'bag').custom_data['case'] == f'normal, default, {drawn}'
    # the force mapping in force: the last case's (each case renders with its own scale)
    from haptic_anfis.cases.force_mapping import case_force_mapping
    want = case_force_mapping(library().get(drawn)).as_dict()
    assert json.loads(bag_info(tmp_path / 'bag').custom_data['force_mapping']) == want
    assert case_force_mapping(library().get('normal')).force_scale != want['force_scale']
    assert bag_info(tmp_path / 'blind').custom_data['case'] == drawn
    assert json.loads(bag_info(tmp_path / 'blind').custom_data['force_mapping']) == want
    assert 'case' not in bag_info(tmp_path / 'none').custom_data
    assert bag_info(tmp_path / 'none_then').custom_data['case'] == 'unknown, normal'


def test_a_seed_set_alone_replaces_the_case_name():
    """The browser page's blind choice sets only ``random_case_seed``: on nodes started with
    ``case:=NAME`` it was refused ("not both") and the session kept its case."""
    from types import SimpleNamespace

    from haptic_anfis.nodes._case import requested_case
    node = SimpleNamespace(get_parameter=lambda n: SimpleNamespace(
        value={'case': 'normal', 'random_case_seed': -1}[n]))
    p = lambda n, v: SimpleNamespace(name=n, value=v)   # noqa: E731
    assert requested_case(node, [p('random_case_seed', 5)]) == ('', 5)
    assert requested_case(node, [p('case', 'default')]) == ('default', -1)
    assert requested_case(node, [p('case', 'x'), p('random_case_seed', 5)]) == ('x', 5)
    assert requested_case(node, [p('rate', 3.0)]) is None
    with pytest.raises(CaseError, match='must be a string'):
        requested_case(node, [p('case', 3)])


def test_the_session_tells_its_recorder_the_default_only_when_nothing_can_change_it(tmp_path):
    from haptic_anfis.session import SessionSpec
    assert SessionSpec().recorder_case_arguments() == ['-p', 'case:=default']
    assert SessionSpec(case='normal').recorder_case_arguments() == ['-p', 'case:=normal']
    assert SessionSpec(random_case=True, seed=3).recorder_case_arguments() == [
        '-p', 'random_case_seed:=3']
    mesh, driver = tmp_path / 'mesh.yaml', tmp_path / 'driver.yaml'
    mesh.write_text('contact_detector:\n  ros__parameters:\n    mesh_path: my.stl\n')
    driver.write_text('falcon_driver:\n  ros__parameters:\n    servo_priority: 0\n')
    for other in (dict(params_files=(str(driver), str(mesh))), dict(scene='s.yaml'),
                  dict(ros_args=('-p', 'model_path:=m.json')),
                  dict(ros_args=('-p', 'force_server:model_path:=m.json')),
                  dict(ros_args=('--params-file', 'x.yaml')),
                  dict(ros_args=('-p', 'examiner:scene:=/tmp/lesions.yaml'))):
        assert SessionSpec(**other).recorder_case_arguments() == [], other
    # the shipped parameter files set the scene's parameters to their defaults
    from haptic_anfis.resources import config_dir
    shipped = tuple(str(config_dir() / f'{n}.yaml') for n in (
        'contact_detector', 'force_server', 'visualizer', 'falcon_driver', 'examiner', 'recorder'))
    assert SessionSpec(params_files=shipped).recorder_case_arguments() == ['-p', 'case:=default']
    # settings that do not touch the scene: still the default
    assert SessionSpec(params_files=(str(driver),), ros_args=('-p', 'rate:=20.0')
                       ).recorder_case_arguments() == ['-p', 'case:=default']


@pytest.mark.parametrize('value', ['no', 'on', 'yes', 'null', '0012', '1e3', '~'])
def test_custom_data_reads_back_as_the_string_written(tmp_path, value):
    """rosbags writes custom data unquoted; a value YAML 1.1 would read as a boolean, a null or a
    number ('no', '0012') still reads back as written, as rosbag2's own reader (strings) does."""
    bag = tmp_path / 'b'
    w = BagWriter(bag, custom_data={**OURS, 'case': value})
    w.add_topic(TOPIC, 'geometry_msgs/msg/PoseStamped')
    w.write(TOPIC, _pose(0), 1_000_000_000)
    w.close()
    assert bag_info(bag).custom_data['case'] == value
    assert bag_info(bag / 'b.mcap').custom_data['case'] == value
