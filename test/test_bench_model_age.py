"""The model-age benchmark's rendering (a short synthetic press and stroke: no session)."""
import sys
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parents[1] / 'bench'
sys.path.insert(0, str(BENCH))
from bench_model_age import guard_figures, models_along, rendered  # noqa: E402

from haptic_anfis.device.palpation import dome_height  # noqa: E402


def press_and_stroke(n: int = 120) -> tuple[np.ndarray, np.ndarray]:
    """Poses 1 ms apart: down into the default dome's top, then across it (tissue frame [m])."""
    top = np.array([dome_height(0.0, 0.0), 0.0, 0.0])  # the default surface's apex, normal +x
    down = [top + [0.001 - 0.00005 * i, 0.0, 0.0] for i in range(n // 2)]
    across = [down[-1] + [0.0, 0.0001 * i, 0.00005 * i] for i in range(1, n - n // 2 + 1)]
    return np.arange(n) * 1e-3, np.array(down + across)


def test_a_fresh_model_renders_the_ideal_force_and_an_old_one_drifts():
    times, positions = press_and_stroke()
    models, F, contact = models_along(positions)
    assert contact.sum() > 50 and np.abs(F[contact]).max() > 0.5
    for sym in (True, False):
        np.testing.assert_allclose(rendered(models, positions, times, 0, sym)[contact],
                                   F[contact], atol=1e-9)
    err = {sym: np.abs(rendered(models, positions, times, 10, sym)[contact] - F[contact]).max()
           for sym in (True, False)}
    assert err[False] > 0.0
    assert err[False] < err[True]  # the skew part kept: closer to the tissue's force


def test_guard_figures_count_the_contact_models():
    times, positions = press_and_stroke()
    models, _, contact = models_along(positions)
    line, = guard_figures(models, contact)
    assert line.startswith(f'{int(contact.sum())} contact models')
    assert guard_figures(models, np.zeros_like(contact)) == ['no contact model']
