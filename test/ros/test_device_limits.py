"""The driver's safety parameters are bound by the device: a parameter file, a ``-p`` override or
a session command asking for more gets one line naming the parameter, the value and the bound,
and exit status 1."""
from __future__ import annotations

import math

import pytest

from haptic_anfis.device.limits import (RATE_RANGE, RATED_FORCE_BY_BACKEND, WATCHDOG_RANGE,
                                        check_max_force, check_rate, check_watchdog, rated_force)

#: (parameter, a value beyond its bound, the bound as the message writes it)
BEYOND = [('max_force', 1e9, '<= 8.9 N'), ('max_force', 9.0, '<= 8.9 N'),
          ('watchdog_timeout', 1e9, '<= 0.05 s'), ('watchdog_timeout', 0.0005, '>= 0.001'),
          ('rate', 1e9, '<= 1000 Hz'), ('rate', 50.0, '>= 100')]


def test_the_bounds_are_the_falcons_and_take_their_edges():
    assert RATED_FORCE_BY_BACKEND == {'sim': 8.9, 'falcon': 8.9} and rated_force('sim') == 8.9
    assert check_max_force(8.9) is None and check_max_force(8.9, 'falcon') is None
    assert check_watchdog(WATCHDOG_RANGE[0]) is None and check_watchdog(WATCHDOG_RANGE[1]) is None
    assert check_rate(RATE_RANGE[0]) is None and check_rate(RATE_RANGE[1]) is None
    for check, bad in ((check_max_force, (0.0, -1.0, 8.9001, math.nan, math.inf)),
                       (check_watchdog, (0.0, 0.0009, 0.0501, math.nan)),
                       (check_rate, (99.9, 1000.1, math.inf, math.nan))):
        for v in bad:
            assert check(v), (check.__name__, v)


@pytest.mark.parametrize('name, value, bound', BEYOND)
def test_a_parameter_file_beyond_the_bound_is_one_line_for_every_session_command(
        tmp_path, capsys, name, value, bound):
    pytest.importorskip('rclpy')
    from haptic_anfis.cli import main
    f = tmp_path / 'p.yaml'
    f.write_text(f'falcon_driver:\n  ros__parameters:\n    {name}: {value!r}\n')
    for cmd in (['sim'], ['launch'], ['exam', 'run', '--trainee', 't1']):
        assert main([*cmd, '--params-file', str(f)]) == 1, cmd
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1, err
        assert f'{f}:3: falcon_driver: {name}: {float(value)!r}: expected' in err and bound in err


@pytest.mark.parametrize('name, value, bound', BEYOND)
def test_a_p_override_beyond_the_bound_is_one_line(capsys, name, value, bound):
    pytest.importorskip('rclpy')
    from haptic_anfis.cli import main
    assert main(['sim', '--', '--ros-args', '-p', f'{name}:={value!r}']) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert f'-p {name}:={value!r}: falcon_driver: {name}: {float(value)!r}' in err and bound in err


def test_the_shipped_defaults_are_within_the_bounds():
    pytest.importorskip('rclpy')
    from haptic_anfis.nodes.falcon_driver import PARAMS
    from haptic_anfis.nodes.parameters import check_value
    for p in PARAMS:
        if p.name in ('max_force', 'rate', 'watchdog_timeout'):
            assert check_value(p, p.default) is None, p.name
