"""``haptic-anfis falcon check`` and the force-scale calibration, against the protocol-derived fake
device (no hardware)."""
from __future__ import annotations

import math
import re

import pytest
import yaml
from falcon_fake import Clock, FakeFalcon, ftdi_class

from haptic_anfis import cli
from haptic_anfis.device import falcon_kinematics as k
from haptic_anfis.device.falcon_check import (calibrate, calibrated_counts_per_nm, run_check,
                                              write_counts_per_nm)
from haptic_anfis.device.falcon_usb import FalconUSB, PyFtdiTransport
from haptic_anfis.resources import config_file


class MovedGrip(FakeFalcon):
    """The user moves the grip in a slow circle (1 cm) while packets come in."""

    def _reply(self):
        i = len(self.commands)
        c = k.WORKSPACE_CENTER
        p = (c[0] + 0.01 * math.cos(i / 100), c[1] + 0.01 * math.sin(i / 100), c[2])
        self.encoders = k.angles_to_ticks(k.inverse_kinematics(p))
        return super()._reply()


def make(fake, clock, **kw):
    out = []
    dev = FalconUSB(transport=PyFtdiTransport(ftdi_class(fake)), clock=clock, sleep=clock.sleep,
                    log=out.append, guard_thread=False, **kw)
    return dev, out


def check(dev, out, clock):
    return run_check(dev, say=out.append, move_seconds=0.3, spring_seconds=0.3, clock=clock,
                     sleep=clock.sleep)


def test_check_passes_every_step_and_ends_at_zero_force():
    clock = Clock(0.0)
    fake = MovedGrip(firmware_running=True, homed=False, homes_after=20)
    dev, out = make(fake, clock)
    assert check(dev, out, clock) == 0
    text = '\n'.join(out)
    for step in ('1. find', '2. firmware', '3. homing', '4. positions', '5. spring', '6. zero'):
        assert step in text
    assert text.count('[ok]') == 6 and 'FAKE0001' in text and 'LED red' in text
    m = re.search(r'range x ([\d.]+), y ([\d.]+), z ([\d.]+) mm', text)
    spans = [float(v) for v in m.groups()]  # device x = Falcon z: still; y, z: the circle
    assert spans[0] < 0.5 and spans[1] > 10 and spans[2] > 10
    spring = [c for c in fake.commands if c.motors != (0, 0, 0)]
    assert spring  # some force was sent, never more than the 1 N asked for
    for c in spring:
        assert math.dist(k.torque_to_force(k.WORKSPACE_CENTER, k.commands_to_torques(c.motors)),
                         (0, 0, 0)) < 1.05
    assert fake.commands[-1].motors == (0, 0, 0) and fake.closed


def test_check_stops_at_the_failing_step_and_says_why(tmp_path):
    clock = Clock(0.0)
    gone = FakeFalcon()
    gone.unplug()
    dev, out = make(gone, clock)
    assert check(dev, out, clock) == 1 and 'no Falcon found' in out[-1]
    dev, out = make(FakeFalcon(), clock, io_timeout=0.02)  # powered, no firmware, no file
    assert check(dev, out, clock) == 2 and 'nvent_firmware.bin' in out[-1]
    dev, out = make(FakeFalcon(firmware_running=True, homed=False, homes_after=10 ** 9), clock,
                    homing_timeout=0.1)
    assert check(dev, out, clock) == 3 and 'homing timed out' in out[-1]
    still = FakeFalcon(firmware_running=True, encoders=k.angles_to_ticks(
        k.inverse_kinematics(k.WORKSPACE_CENTER)))
    dev, out = make(still, clock)
    assert check(dev, out, clock) == 4 and 'did not change by 1 mm' in out[-1]
    assert still.commands[-1].motors == (0, 0, 0) and still.closed


class HangingGrip(FakeFalcon):
    """Quasi-static vertical physics: the grip moves (Falcon y) until the motors' REAL force
    (counts / ``true_counts`` N m through J^-T) balances the hung weight."""
    true_counts = 8000.0
    weight = 0.0  # N

    def __init__(self, **kw):
        super().__init__(**kw)
        self.p = list(k.WORKSPACE_CENTER)

    def _reply(self):
        m = self.commands[-1].motors if self.commands else (0, 0, 0)
        tau = tuple(-c / self.true_counts for c in m)  # command = -counts * tau
        f = k.torque_to_force(tuple(self.p), tau)
        self.p[1] += 2e-4 * (f[1] - self.weight)  # compliant: settles in a few hundred packets
        self.encoders = k.angles_to_ticks(k.inverse_kinematics(tuple(self.p)))
        return super()._reply()


def test_calibration_recovers_the_true_motor_scale():
    clock = Clock(0.0)
    fake = HangingGrip(firmware_running=True)
    dev, out = make(fake, clock)
    dev.connect()
    mass = 0.2

    def wait(prompt):
        if 'hang' in prompt:
            fake.weight = mass * k.G
    c = calibrate(dev, mass, wait, say=out.append, stiffness=300.0, settle=1.5, clock=clock,
                  sleep=clock.sleep)
    # tick quantisation of the sag (~0.05 mm at 300 N/m) limits it to about 1 %
    assert c == pytest.approx(fake.true_counts, rel=0.02)
    assert any('counts_per_nm: 10000 ->' in m for m in out)
    dev.close()
    with pytest.raises(ValueError, match='positive mass'):
        calibrated_counts_per_nm(10000.0, -1.0, 0.2)


def test_calibration_is_written_to_the_parameter_file_keeping_comments(tmp_path):
    p = tmp_path / 'falcon_driver.yaml'
    p.write_text(config_file('falcon_driver.yaml').read_text())
    write_counts_per_nm(p, 8123.456)
    doc = yaml.safe_load(p.read_text())['falcon_driver']['ros__parameters']
    assert doc['counts_per_nm'] == 8123.5 and doc['backend'] == 'sim'
    assert '# falcon: motor command counts per N m' in p.read_text()
    q = tmp_path / 'mine.yaml'
    q.write_text('falcon_driver:\n  ros__parameters:\n    backend: falcon\n')
    write_counts_per_nm(q, 9000.0)
    assert yaml.safe_load(q.read_text())['falcon_driver']['ros__parameters'] == {
        'backend': 'falcon', 'counts_per_nm': 9000.0}


def test_cli_check_without_usb_library_says_how_to_install(monkeypatch, capsys):
    monkeypatch.setitem(__import__('sys').modules, 'pyftdi', None)
    monkeypatch.setitem(__import__('sys').modules, 'pyftdi.ftdi', None)
    assert cli.main(['falcon', 'check']) == 1
    assert "pip install 'haptic_anfis[falcon]'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(['falcon', 'check', '--spring-force', 'x'])
    assert cli.main(['falcon', 'check', '--spring-force', '5']) == 1
    assert 'at most 3 N' in capsys.readouterr().err


def test_cli_check_runs_against_the_fake_device(monkeypatch, capsys, tmp_path):
    from haptic_anfis.device import falcon_usb
    fake = MovedGrip(firmware_running=True)
    monkeypatch.setattr(falcon_usb, 'import_ftdi', lambda: ftdi_class(fake))
    params = tmp_path / 'falcon_driver.yaml'
    params.write_text('falcon_driver:\n  ros__parameters:\n    counts_per_nm: 9000.0\n')
    assert cli.main(['falcon', 'check', '--move-seconds', '0.3', '--spring-seconds', '0.3',
                     '--params-file', str(params)]) == 0
    out = capsys.readouterr().out
    assert 'motor scale 9000 counts per N m' in out and 'all steps passed' in out
    assert fake.closed and fake.commands[-1].motors == (0, 0, 0)
    assert cli.main(['falcon', 'check', '--calibrate', '-1']) == 1
    assert '--calibrate: expected a mass' in capsys.readouterr().err
