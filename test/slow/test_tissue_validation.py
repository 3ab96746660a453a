"""FE vs analytic flat-punch solutions (Sneddon 1965; Hayes et al. 1972), and the layer kernel."""
import numpy as np
import pytest

from haptic_anfis.tissue.fe import load_steps
from haptic_anfis.tissue.scene import load_scene
from haptic_anfis.tissue.validation import (fe_punch_on_layer, hayes_kappa, sneddon_force)


def test_sneddon_formula():
    # F = 2 a E delta / (1 - nu^2): 8 mm, 33 kPa, 1 mm, nu = 0.5 -> 0.704 N
    assert sneddon_force(0.008, 33e3, 0.5, 0.001) == pytest.approx(0.704)


def test_hayes_kappa_matches_paper_value_and_limits():
    # a = 8 mm on a 40 mm layer, nu ~ 0.5: kappa ~ 1.28 (Hayes et al. 1972, Table)
    assert hayes_kappa(0.2, 0.5) == pytest.approx(1.28, abs=0.005)
    assert hayes_kappa(1e-3, 0.5) == pytest.approx(1.0, abs=2e-3)
    k = [hayes_kappa(x, 0.5) for x in (0.05, 0.1, 0.2, 0.5, 1.0)]
    assert np.all(np.diff(k) > 0)
    # compressible layers are less stiffened
    assert hayes_kappa(0.5, 0.3) < hayes_kappa(0.5, 0.5)


def test_load_steps_hit_every_depth_with_small_increments():
    steps = load_steps((0.002, 0.005, 0.008, 0.012, 0.016), 0.002)
    assert np.max(np.diff([0.0, *steps])) <= 0.002 + 1e-12
    for d in (0.002, 0.005, 0.008, 0.012, 0.016):
        assert min(abs(s - d) for s in steps) < 1e-12


# Validation in the normal test run, at the dataset's mesh: 6 cells across the probe, no edge
# grading, the footprint outline pulled 0.2 of the first outer cell inside the probe radius
# (mesh.edge_offset; without it the bonded footprint on linear cells over-predicts by O(h), +7 %).
# The offset is fixed by mesh consistency (6 and 8 cells give the same force), not by the analytic
# solutions below. Full tables and plots: `haptic-anfis dataset --report DIR` (README, "Tissue
# scene and FE data").
SMALL = 0.2e-3  # m, delta / a = 0.025: small-strain regime of the analytic solutions


@pytest.fixture(scope='module')
def scene():
    return load_scene()


def _err(scene, h, n, refine, radius=None, bonded=True, edge_offset=0.0):
    a, E, nu = scene.probe_radius, scene.material.youngs, scene.material.poisson
    res = fe_punch_on_layer(h, a, E, nu, depths=(SMALL,), probe_cells=n, refine=refine,
                            radius=radius, bonded=bonded, edge_offset=edge_offset)
    sned = sneddon_force(a, E, nu, SMALL)
    return res, res.forces[0, 0] / (hayes_kappa(a / h, nu) * sned) - 1, res.forces[0, 0] / sned - 1


def _dataset_mesh(scene):
    return dict(n=scene.mesh.probe_cells, refine=scene.mesh.edge_refine,
                edge_offset=scene.mesh.edge_offset)


def test_fe_layer_vs_hayes_within_3_percent_at_dataset_mesh(scene):
    res, err, _ = _err(scene, 0.040, **_dataset_mesh(scene))
    assert abs(err) < 0.03, f'{100 * err:+.2f} %'  # measured +0.57 %
    assert np.abs(res.forces[0, 1:]).max() < 1e-6 * res.forces[0, 0]  # axisymmetric


def test_fe_thick_block_vs_sneddon_within_3_percent_at_dataset_mesh(scene):
    h = 40 * scene.probe_radius  # a/h = 1/40: kappa = 1.029, close to the half-space
    _, err_k, err_s = _err(scene, h, radius=h, **_dataset_mesh(scene))
    # measured -0.36 % vs Sneddon x kappa, +2.52 % vs plain Sneddon
    assert abs(err_k) < 0.03 and abs(err_s) < 0.03, (err_k, err_s)


def test_edge_offset_makes_6_and_8_cells_agree(scene):
    """The criterion that fixes edge_offset: the force no longer depends on the edge cell size
    (layer: 6 vs 8 cells differ by 0.6 % with the offset, 2.2 % without)."""
    f = {(n, o): _err(scene, 0.040, n, 0, edge_offset=o)[0].forces[0, 0]
         for n in (6, 8) for o in (0.0, scene.mesh.edge_offset)}
    off = scene.mesh.edge_offset
    assert abs(f[6, off] / f[8, off] - 1) < 0.01
    assert f[6, 0.0] / f[8, 0.0] - 1 > 0.015


def test_fe_layer_vs_hayes_within_3_percent_with_edge_grading(scene):
    # without the offset, grading the cells towards the edge also converges to Hayes (but graded
    # meshes cannot follow the dataset's 16 mm load path on the dome's steep points)
    _, err, _ = _err(scene, 0.040, 6, 3)
    assert abs(err) < 0.03, f'{100 * err:+.2f} %'  # measured +2.45 %


def test_bonded_and_frictionless_probe_agree_for_incompressible_layer(scene):
    _, e_b, _ = _err(scene, 0.040, 4, 0)
    _, e_f, _ = _err(scene, 0.040, 4, 0, bonded=False)
    assert 0.0 <= e_b - e_f < 0.01


def test_mesh_convergence_small(scene):
    """Small version of the report's convergence study: apex at 2 and 5 mm on 4 and 6 cells
    across the probe; the force decreases towards the limit (measured: -2.2 / -1.8 %)."""
    import dataclasses

    from haptic_anfis.tissue.fe import solve_scene_point
    from haptic_anfis.tissue.geometry import loading_points

    s = dataclasses.replace(scene, depths=(0.002, 0.005))
    pts = loading_points(s)
    apex = pts[int(np.argmin(np.hypot(pts[:, 1], pts[:, 2])))]
    f = [solve_scene_point(s, apex, probe_cells=n).forces[:, 0] for n in (4, 6)]
    change = f[1] / f[0] - 1
    assert np.all(change < 0) and np.all(change > -0.03), change
