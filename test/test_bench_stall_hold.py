"""The stall-hold benchmark's rendering: the compiled tick driven along a short synthetic press
(no session), with the stall's one model held or expired."""
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_model_age import models_along  # noqa: E402
from bench_stall_hold import driver_loop, held_forces  # noqa: E402
from test_bench_model_age import press_and_stroke  # noqa: E402


@pytest.mark.parametrize('hold', [0.03, 0.08])
def test_the_stalls_model_is_held_up_to_the_hold_time_then_expires(hold):
    times, positions = press_and_stroke()
    models, F, contact = models_along(positions)
    i0 = int(np.argmax(contact & (np.linalg.norm(F, axis=1) > 0.5)))  # stalled in the press
    f, expired = held_forces(driver_loop(hold), models[i0], times[i0], positions[i0:],
                             times[i0:])
    np.testing.assert_allclose(f[0], F[i0], atol=1e-9)  # its own pose: the force server's force
    age = times[i0:] - times[i0]
    # valid for model_validity_time (0.05 s), then held up to the hold time (off below it)
    np.testing.assert_array_equal(expired, age > max(hold, 0.05) + 1e-12)
    assert np.all(f[expired] == 0.0)
    assert np.abs(f[~expired][1:] - F[i0 + 1:][~expired[1:]]).max() > 1e-3  # it drifts: old


def test_a_held_model_expires_where_the_probe_left_the_hold_radius():
    """A 4 mm hold radius on the press (the probe goes ~3 mm deeper, then across): past its
    validity time the stall's model is expired exactly where the probe is more than 4 mm from
    its p0 and still pressing, rendered where it is nearer."""
    times, positions = press_and_stroke()
    models, F, contact = models_along(positions)
    i0 = int(np.argmax(contact & (np.linalg.norm(F, axis=1) > 0.5)))
    f, expired = held_forces(driver_loop(1.0, 0.004), models[i0], times[i0], positions[i0:],
                             times[i0:])
    far = np.linalg.norm(positions[i0:] - np.asarray(models[i0][3:6]), axis=1) > 0.004
    held = times[i0:] - times[i0] > 0.05
    assert (held & far).sum() > 10 and (held & ~far).sum() > 0
    np.testing.assert_array_equal(expired, held & far & contact[i0:])
    f_wide, expired_wide = held_forces(driver_loop(1.0, 1.0), models[i0], times[i0],
                                       positions[i0:], times[i0:])
    assert not expired_wide.any()
    np.testing.assert_allclose(f[~expired], f_wide[~expired], atol=1e-12)
