"""The servo trace across a live force-scale switch: each tick in the tissue frame with the scale
it was rendered at; an older trace (one ``max_force``) still reads."""
import time

import numpy as np
import pytest

from haptic_anfis.device.driver_loops import DriverLoop
from haptic_anfis.device.falcon import HandParams, WorkspaceMapping
from haptic_anfis.device.force_input import ForceInput
from haptic_anfis.device.local_model import FALCON_MAX_STIFFNESS, LocalModel
from haptic_anfis.device.palpation import PalpationScript
from haptic_anfis.device.servo_native import NativeServoLoop
from haptic_anfis.device.trace import (DISABLED, TickTrace, load_trace, max_force_per_tick,
                                       save_trace, scale_per_tick)
from haptic_anfis.device import native_tick as nt

MAP = WorkspaceMapping(1.5, (0.03, 0.0, 0.0), 1.0)
AT = (0.06, 0.0, 0.0)
PARAMS = {'max_force': 8.9, 'rate': 1000.0, 'model_hold_time': 20.0, 'model_hold_radius': 0.01,
          'model_blend_time': 0.0, 'passivity_window': 0.0}


def _driver_loop() -> DriverLoop:
    script = PalpationScript(np.array([0.0, 100.0]), np.array([AT, AT]), np.array([False]),
                             loop=False)
    lp = NativeServoLoop(script, MAP, HandParams(), mode='local_model', max_force=8.9,
                         max_force_rate=1e6, validity_time=10.0, hold_time=20.0,
                         trace=TickTrace())
    return DriverLoop(lp, lp, lp.safety, lp.clutch,
                      ForceInput(lp.safety, MAP, lp.renderer, 'local_model'))


def _tick_at_rest(lp: NativeServoLoop, n: int) -> tuple:
    """``n`` ticks on the monotonic clock (the one the switch times are on), the handle held;
    the last tick's device force [N]."""
    f = (0.0, 0.0, 0.0)
    for _ in range(n):
        now = time.monotonic()
        lp.st[nt.S.x0:nt.S.x0 + 3] = MAP.to_device(AT)
        lp.st[nt.S.v0:nt.S.v0 + 3] = 0.0
        lp.st[nt.S.t_dev] = now
        f = lp.tick(now)
        time.sleep(0.0005)
    return f


def test_a_trace_across_a_force_scale_switch_gives_the_tissue_force_on_both_sides(tmp_path):
    d = _driver_loop()
    lp = d.servo
    lp.safety.start()
    # 2 N of tissue force along +x wherever the probe is within the model's radius
    model = LocalModel((2.0, 0.0, 0.0), AT, np.zeros((3, 3)), (AT[0] + 0.005, 0.0, 0.0),
                       (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), 0.005, False, 0.0).values()
    lp.renderer.offer_values(model, time.monotonic())
    assert _tick_at_rest(lp, 20)[0] == pytest.approx(2.0)   # device frame, scale 1
    d.set_force_scale(0.4, FALCON_MAX_STIFFNESS)
    assert _tick_at_rest(lp, 20)[0] == pytest.approx(0.8)   # device frame, scale 0.4
    lp._drain()
    d.save_trace(str(tmp_path / 't.npz'), lp.mapping, PARAMS, 'tissue', {})
    rows, meta = load_trace(tmp_path / 't.npz')
    on = rows[(rows[:, 7] != DISABLED) & (rows[:, 4] > 0.0)]
    t_switch = d.force_scales[-1][0]
    before, after = on[on[:, 0] < t_switch], on[on[:, 0] >= t_switch]
    assert len(before) >= 10 and len(after) >= 10
    np.testing.assert_allclose(before[1:, 4], 2.0, rtol=1e-9)   # the first may be ramping
    np.testing.assert_allclose(after[1:, 4], 2.0, rtol=1e-9)
    lim = max_force_per_tick(rows, meta)
    assert lim[rows[:, 0] < t_switch] == pytest.approx(8.9)
    assert lim[rows[:, 0] >= t_switch] == pytest.approx(8.9 / 0.4)
    assert meta['force_scales'][0] == [None, 1.0] and meta['max_force'] == pytest.approx(22.25)


def test_an_older_trace_reads_with_its_one_max_force(tmp_path):
    rows = np.zeros((3, 8))
    path = save_trace(tmp_path / 'old.npz', rows, max_force=8.9)
    r, meta = load_trace(path)
    assert max_force_per_tick(r, meta) == 8.9
    assert max_force_per_tick(r, {}) == np.inf


def test_scale_per_tick_takes_the_newest_switch_at_or_before_each_tick():
    t = np.array([0.0, 1.0, 2.0, 2.5, 3.0])
    s = scale_per_tick(t, [(None, 1.0), (2.0, 0.5), (3.0, 0.25)])
    np.testing.assert_array_equal(s, [1.0, 1.0, 0.5, 0.5, 0.25])
    with pytest.raises(ValueError, match='force scales > 0'):
        scale_per_tick(t, [(None, 0.0)])
    with pytest.raises(ValueError, match='at least one'):
        scale_per_tick(t, [])
