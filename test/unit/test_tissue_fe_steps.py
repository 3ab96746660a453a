"""The FE load path after a cut-back: later increments stay at most the halved one (no second
failed attempt at the step size that already failed), and every requested depth is recorded."""
import felupe as fem
import numpy as np

from haptic_anfis.tissue.fe import solve_load_path
from haptic_anfis.tissue.mesh import Domain, build_mesh


def _flat_mesh():
    dom = Domain(ry=0.05, rz=0.05, height=lambda y, z: np.full(np.shape(y), 0.03), fix_rim=True)
    return build_mesh(dom, (0.0, 0.0), 0.008, 4)


def test_increments_after_a_cutback_stay_halved(monkeypatch):
    real = fem.newtonraphson
    calls = []

    def newton(*args, **kwargs):  # the second increment fails once, as a too-large step does
        calls.append(len(calls))
        if len(calls) == 2:
            raise ValueError('simulated divergence')
        return real(*args, **kwargs)

    monkeypatch.setattr(fem, 'newtonraphson', newton)
    res = solve_load_path(_flat_mesh(), 1e3, 5e4, (-1.0, 0.0, 0.0), [0.001, 0.002, 0.003],
                          max_step=0.001)
    # 0->1 mm, 1->2 mm fails, then 1->1.5->2->2.5->3 mm: four halved increments, one cut-back
    assert res.cutbacks == 1 and len(calls) == 6
    np.testing.assert_allclose(res.depths, [0.001, 0.002, 0.003])
    assert np.all(np.diff(-res.forces[:, 0]) < 0)  # the tissue pushes the probe out, harder deeper
