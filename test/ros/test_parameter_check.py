"""Parameter files and -p overrides are checked before any node starts (issue 27.3 / 27.4), and the
session is described once (issue 28.1): no rclpy started in these tests."""
from __future__ import annotations

import argparse

import pytest

from haptic_anfis.nodes.parameter_files import (check_parameter_sources, parse_overrides,
                                                read_parameter_file, resolve_parameters)
from haptic_anfis.nodes.parameters import CASE_PARAMS, Param, ParameterError, check_value, positive

DECLARED = {
    'falcon_driver': [Param('max_force', 8.9, 'force limit [N]', positive),
                      Param('rate', 1000.0, 'rate [Hz]', positive),
                      Param('workspace_offset', [0.03, 0.0, 0.0], 'offset [m]'),
                      Param('backend', 'sim', 'backend')],
    'force_server': [Param('model_path', '', 'model file'), *CASE_PARAMS],
}


def _write(tmp_path, text, name='p.yaml'):
    f = tmp_path / name
    f.write_text(text)
    return f


def test_misspelled_key_names_the_file_line_node_and_nearest_parameter(tmp_path):
    f = _write(tmp_path, 'force_server:\n  ros__parameters:\n    case: ""\n    modle_path: x\n')
    assert check_parameter_sources(DECLARED, [f]) == [
        f"{f}:4: force_server: unknown parameter 'modle_path' (did you mean 'model_path'?)"]


def test_wrong_type_says_what_was_given_and_what_is_expected(tmp_path):
    f = _write(tmp_path, 'falcon_driver:\n  ros__parameters:\n    max_force: lots\n'
                         '    rate: 500\n    workspace_offset: [0, 0, 0]\n')
    errors = check_parameter_sources(DECLARED, [f])
    assert errors == [
        f"{f}:3: falcon_driver: max_force: got 'lots' (a string), expected a double such as 8.9",
        f'{f}:4: falcon_driver: rate: got 500 (an integer), expected a double such as 1000.0 '
        '(write 500.0: a double needs the decimal point)',
        f'{f}:5: falcon_driver: workspace_offset: got [0, 0, 0] (a list of integers), expected a '
        'list of doubles such as [0.03, 0.0, 0.0] (write every number with a decimal point, '
        'e.g. 1.0)']


def test_rejected_value_and_overrides_are_checked_like_files():
    ovs = parse_overrides(['-p', 'max_force:=-1.0', '-p', 'max_forse:=2.0', '-p', 'backend:=sim'])
    assert check_parameter_sources(DECLARED, [], ovs) == [
        '-p max_force:=-1.0: falcon_driver: max_force: -1.0: expected a finite value > 0',
        "-p max_forse:=2.0: unknown parameter 'max_forse': no node of this session "
        "(falcon_driver, force_server) declares it (did you mean 'max_force'?)"]
    # rcl reads 1e3 as a double (YAML 1.1 would say a string): accepted as rclpy would
    assert check_parameter_sources(DECLARED, [], parse_overrides(['-p', 'rate:=1e3'])) == []
    with pytest.raises(ParameterError, match='expected -p name:=value'):
        parse_overrides(['-p', 'max_force'])


def test_node_targeted_overrides_are_checked_against_that_node():
    ovs = parse_overrides(['-p', 'falcon_driver:rate:=500.0', '-p', 'force_server:rate:=1.0',
                           '-p', 'falcon_driver:max_force:=-2.0'])
    assert check_parameter_sources(DECLARED, [], ovs) == [
        "-p force_server:rate:=1.0: force_server: unknown parameter 'rate'",
        '-p falcon_driver:max_force:=-2.0: falcon_driver: max_force: -2.0: expected a finite '
        'value > 0']


def test_malformed_or_missing_file_is_one_line_with_its_line(tmp_path):
    f = _write(tmp_path, 'force_server:\n  ros__parameters:\n    model_path: [x\n')
    (err,) = check_parameter_sources(DECLARED, [f])
    assert err.startswith(f'{f}:4: not valid YAML: ') and '\n' not in err
    (err,) = check_parameter_sources(DECLARED, [tmp_path / 'none.yaml'])
    assert err == f'{tmp_path / "none.yaml"}: cannot read the parameter file: No such file or ' \
                  'directory'
    g = _write(tmp_path, 'force_server:\n  parameters:\n    model_path: x\n', 'g.yaml')
    assert check_parameter_sources(DECLARED, [g]) == [
        f"{g}:2: force_server: expected ros__parameters, got 'parameters' (did you mean "
        "'ros__parameters'?)"]


def test_unknown_node_section_and_wildcard_keys(tmp_path):
    f = _write(tmp_path, 'force_sever:\n  ros__parameters:\n    model_path: x\n'
                         '/**:\n  ros__parameters:\n    backend: sim\n    use_sim_time: false\n'
                         '    bakend: sim\n')
    errors = check_parameter_sources(DECLARED, [f])
    assert errors[0] == f"{f}:3: unknown node 'force_sever' (did you mean 'force_server'?)"
    assert errors[1].startswith(f"{f}:8: unknown parameter 'bakend'") and \
        "did you mean 'backend'" in errors[1]
    assert len(errors) == 2
    # a node checking its own arguments leaves other nodes' sections to the session's check
    assert check_parameter_sources({'force_server': DECLARED['force_server']}, [f],
                                   whole_session=False, strict_globals=False) == []


def test_read_parameter_file_flattens_nested_names_with_lines(tmp_path):
    f = _write(tmp_path, 'recorder:\n  ros__parameters:\n    qos:\n      depth: 3\n    a: 1\n')
    assert read_parameter_file(f) == [('recorder', 'qos.depth', 3, f'{f}:4'),
                                      ('recorder', 'a', 1, f'{f}:5')]


def test_resolve_parameters_rejects_an_unknown_key_of_the_nodes_own_section(tmp_path):
    """bag resim / loop read the files without rclpy: a misspelling is no longer ignored."""
    f = _write(tmp_path, 'force_server:\n  ros__parameters:\n    case: ""\n    modle_path: x\n')
    with pytest.raises(ParameterError, match=r"^force_server: bad parameters: .*:4: unknown "
                                             r"parameter 'modle_path' \(did you mean "
                                             r"'model_path'\?\)$"):
        resolve_parameters(DECLARED['force_server'][:1], 'force_server', [f])
    g = _write(tmp_path, 'force_server:\n  ros__parameters:\n    model_path: m.json\n', 'g.yaml')
    assert resolve_parameters(DECLARED['force_server'][:1], 'force_server', [g]) == \
        {'model_path': 'm.json'}


def test_check_value_accepts_what_rclpy_accepts():
    p = Param('v', [0.0, 1.0], 'v')
    assert check_value(p, [1.0, 2.0]) is None
    assert check_value(Param('s', [], 's'), ['a']) is None  # an empty default takes any list
    assert check_value(Param('b', False, 'b'), 1).startswith('got 1 (an integer), expected a bool')


def test_the_shipped_parameter_files_pass_against_every_nodes_declarations():
    pytest.importorskip('rclpy')
    from haptic_anfis.nodes.registry import declared_parameters
    from haptic_anfis.resources import config_dir
    files = sorted(config_dir().glob('*.yaml'))
    params = [f for f in files if 'ros__parameters' in f.read_text()]
    assert len(params) >= 8
    assert check_parameter_sources(declared_parameters(), params) == []


def test_every_node_ships_a_parameter_file_with_each_parameter_it_declares():
    """README: every node's parameters are in config/NODE.yaml (rclpy's own two aside)."""
    pytest.importorskip('rclpy')
    import yaml

    from haptic_anfis.nodes.parameters import ROS_BUILTIN
    from haptic_anfis.nodes.registry import declared_parameters
    from haptic_anfis.resources import config_dir
    builtin = {p.name for p in ROS_BUILTIN}
    for node, params in declared_parameters().items():
        f = config_dir() / f'{node}.yaml'
        assert f.is_file(), f'no config/{node}.yaml'
        written = yaml.safe_load(f.read_text())[node]['ros__parameters']
        assert list(written) == [p.name for p in params if p.name not in builtin], node


def test_every_session_option_fills_a_spec_field_and_one_row_adds_one():
    import dataclasses

    from haptic_anfis.session import spec as sp
    fields = {f.name for f in dataclasses.fields(sp.SessionSpec)}
    assert all(o.dest in fields for o in sp.OPTIONS), [o.dest for o in sp.OPTIONS
                                                       if o.dest not in fields]
    for cmd in sp.COMMANDS:
        p = argparse.ArgumentParser()
        sp.add_session_arguments(p, cmd)
        spec = sp.spec_from_args(p.parse_args(['--params-file', 'a.yaml', '--record', 'b']), cmd)
        assert spec.params_files == ('a.yaml',) and spec.record == 'b' and spec.command == cmd
    p = argparse.ArgumentParser()
    sp.add_session_arguments(p, 'launch')
    spec = sp.spec_from_args(p.parse_args(['--nodes', 'falcon_driver, force_server']), 'launch')
    assert spec.nodes == ('falcon_driver', 'force_server') and spec.duration == 0.0


def test_spec_check_names_the_bad_option(tmp_path):
    from haptic_anfis.session import SessionError, SessionSpec
    (tmp_path / 'bag').mkdir()
    for spec, match in [(SessionSpec(duration=-1.0), '--duration'),
                        (SessionSpec(nodes=('teleporter',)), "teleporter"),
                        (SessionSpec(params_files=(str(tmp_path / 'x.yaml'),)), 'no such file'),
                        (SessionSpec(record=str(tmp_path / 'bag')), 'exists already'),
                        (SessionSpec(max_restarts=-1), '--max-restarts'),
                        (SessionSpec(trace=str(tmp_path / 'bag')), '--trace.*new .npz'),
                        (SessionSpec(command='launch', nodes=('force_server',),
                                     trace=str(tmp_path / 't.npz')), 'falcon driver writes')]:
        with pytest.raises(SessionError, match=match):
            spec.check(check_parameters=False)


def test_launch_record_merges_a_params_files_recorder_topics_and_says_what_it_overrides(tmp_path):
    from haptic_anfis.session import SessionSpec, recorder_settings
    f = _write(tmp_path, "recorder:\n  ros__parameters:\n    output: mine\n"
                         "    topics: ['contact', 'extra/topic']\n")
    topics, notes = recorder_settings(SessionSpec(record='bag', params_files=(str(f),)),
                                      ['contact', '/session/events'])
    assert topics == ['contact', '/session/events', 'extra/topic']
    assert notes == [f"--record bag overrides the recorder output 'mine' of {f}:3",
                     f'recording the topics of {f}:4 too: extra/topic']
