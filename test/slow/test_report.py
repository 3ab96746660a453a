"""The speed-against-error report: runs end to end on a small dataset, its numbers come from the
run (recomputed independently here), and a peer that fails is listed as failed, not dropped."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

pytest.importorskip('matplotlib')
pytest.importorskip('sklearn')

from haptic_anfis.tissue.dataset import save_dataset, split_indices  # noqa: E402
from haptic_anfis.report import peers as P  # noqa: E402
from haptic_anfis.report.measure import make_probes  # noqa: E402
from haptic_anfis.report.run import build_report, pareto_front  # noqa: E402
from haptic_anfis.tissue.synthetic import make_synthetic_dataset  # noqa: E402

FIGURES = ('speed_vs_error.png', 'pred_vs_fe.png', 'error_map.png', 'training_curves.png')


class BrokenPeer(P.Peer):
    name, family = 'broken peer', 'a simulated failure'

    def fit(self, X, Y, groups=None):
        raise RuntimeError('simulated training failure')


class ShapeLiar(P.LinearPeer):
    name = 'wrong-shape peer'

    def predict(self, X):
        return super().predict(X)[:, :2]


@pytest.fixture(scope='module')
def small_ds():
    return make_synthetic_dataset(seed=0, spacing=0.016)   # ~35 surface points x 5 depths


@pytest.fixture(scope='module')
def report(small_ds, tmp_path_factory):
    out = tmp_path_factory.mktemp('report')
    peers = [P.LinearPeer(), P.KnnPeer(3), P.RbfPeer(), BrokenPeer(), ShapeLiar(),
             P.XanfisPeer(python=out / 'no-such-python')]
    ours = [P.OursPeer((2, 2, 2, 2), epochs=5, form='plain'),
            P.OursPeer((3, 2, 2, 2), epochs=5, form='plain'), P.OursPeer((3, 2, 2), epochs=5)]
    res = build_report(small_ds, out, quick=True, peers=peers, ours=ours, repeats=200,
                       dataset_label='small', log=lambda *a: None, cv_seeds=(0, 1), cv_folds=3)
    return out, res


def _row(res, name):
    return next(r for r in res['rows'] if r['name'] == name)


def test_every_file_is_written(report):
    out, res = report
    for f in ('report.md', 'results.json', *FIGURES):
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    assert (out / 'speed_vs_error.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    md = (out / 'report.md').read_text()
    for f in FIGURES:
        assert f'({f})' in md
    doc = json.loads((out / 'results.json').read_text())
    assert [r['name'] for r in doc['rows']] == [r['name'] for r in res['rows']]


def test_table_rmse_is_an_independent_recomputation(report, small_ds):
    out, res = report
    tr, te = split_indices(small_ds, 0.2, 0, by='point')   # the split train_on_dataset uses
    assert res['split']['n_test'] == len(te)
    from sklearn.linear_model import LinearRegression
    pred = LinearRegression().fit(small_ds.X[tr], small_ds.Y[tr]).predict(small_ds.X[te])
    want = np.sqrt(np.mean((pred - small_ds.Y[te]) ** 2, axis=0))
    row = _row(res, 'linear regression')
    np.testing.assert_allclose(row['rmse'], want, rtol=1e-9)
    np.testing.assert_allclose(row['max_err'], np.abs(pred - small_ds.Y[te]).max(0), rtol=1e-9)
    # ... and the Markdown table shows exactly those numbers (3 significant digits)
    md = (out / 'report.md').read_text()
    line = next(ln for ln in md.splitlines() if ln.startswith('| linear regression'))
    shown = [float(v) for v in line.split('|')[2].split('/')]
    np.testing.assert_allclose(shown, want, rtol=5e-3)
    # ours: the same recomputation from the model the report trained
    from haptic_anfis.anfis import ForceModel
    m = ForceModel(structure=(2, 2, 2, 2), epochs=5, seed=0, form='plain').fit(
        small_ds.X[tr], small_ds.Y[tr], groups=small_ds.point[tr])
    np.testing.assert_allclose(_row(res, 'ours plain 2-2-2-2')['rmse'],
                               np.sqrt(np.mean((m.predict(small_ds.X[te]) - small_ds.Y[te]) ** 2, 0)),
                               rtol=1e-9)


def test_failed_peers_are_reported_not_hidden(report):
    out, res = report
    md = (out / 'report.md').read_text()
    broken = _row(res, 'broken peer')
    assert broken['status'].startswith('failed at fit') and 'simulated training failure' in broken['status']
    assert _row(res, 'wrong-shape peer')['status'].startswith('failed at predict')
    xa = next(r for r in res['rows'] if r['name'].startswith('xanfis'))
    assert 'not installed' in xa['status']
    for name in ('broken peer', 'wrong-shape peer', xa['name']):
        assert re.search(rf'^\| {re.escape(name)} \| \*\*failed', md, re.M), name
    assert '## Models that failed' in md


def test_table_has_reference_lines(report):
    out, res = report
    md = (out / 'report.md').read_text()
    assert '0.0791 / 0.0063 / 0.0181' in md and 'not this data' in md
    assert 'haptic budget' in md
    assert 'n/a' in md and 'synthetic placeholder' in md   # FE cost: the shipped data has none


def test_smoothness_measures(report, small_ds):
    _, res = report
    knn, lin = _row(res, 'k-NN (k=3, distance-weighted)'), _row(res, 'linear regression')
    # a linear model is exactly linear along each line: its largest jump is its slope x 0.1 mm
    assert 0 < lin['max_jump_N'] < 1.0
    assert lin['fx_monotone_frac'] in (0.0, 1.0)       # one slope for every point
    assert 0.0 <= knn['fx_monotone_frac'] <= 1.0
    probes = make_probes(small_ds, n_lines=2, n_depths=2, batch=10)
    for L in probes.lines:
        steps = np.linalg.norm(np.diff(L[:, 1:3], axis=0), axis=1)
        np.testing.assert_allclose(steps, 1e-4, rtol=1e-6)


def test_pareto_front():
    lat = np.array([1.0, 2.0, 3.0, 0.5])
    err = np.array([1.0, 0.5, 0.7, 2.0])
    assert pareto_front(lat, err).tolist() == [True, True, False, True]


def test_xanfis_worker_round_trip_when_installed(small_ds):
    """The real xanfis peer, if `make venv` installed its environment (skipped otherwise)."""
    if not P.xanfis_python().exists():
        pytest.skip('xanfis environment not installed')
    peer = P.XanfisPeer(num_rules=3, epochs=2)
    try:
        peer.fit(small_ds.X, small_ds.Y)
        F = peer.predict(small_ds.X[:7])
        assert F.shape == (7, 3) and np.all(np.isfinite(F))
        assert len(peer.time_single(small_ds.X[:3], 5)) == 5
    finally:
        peer.close()


def test_cli_quick_runs(tmp_path, small_ds):
    from haptic_anfis.cli import main
    csv = save_dataset(small_ds, tmp_path / 'small.csv')
    out = tmp_path / 'rep'
    assert main(['report', '--quick', '--dataset', str(csv), '--out', str(out)]) == 0
    for f in ('report.md', *FIGURES):
        assert (out / f).is_file()


def test_report_has_group_cv_and_contact_onset(report):
    out, res = report
    text = (out / 'report.md').read_text()
    assert '## Grouped cross-validation' in text and '## Contact onset' in text
    cv = res['cv']
    assert set(cv) == {'ours depth·g 3-3-2', 'RBF (thin plate spline)', 'linear regression'}
    for r in cv.values():
        assert r['rmse'].shape == (2, 3) and np.all(r['rmse'] > 0)
        np.testing.assert_allclose(r['mean'], r['rmse'].mean(0))
    scaled = _row(res, 'ours depth·g 3-2-2')['contact']
    assert scaled['max_force_at_zero_N'] == 0.0
    assert _row(res, 'ours plain 2-2-2-2')['contact']['max_force_at_zero_N'] > 0.0


def test_group_cv_is_out_of_fold_by_point(small_ds):
    """Recompute one seed's out-of-fold RMSE by hand; no held-out point is ever trained on."""
    from haptic_anfis.tissue.dataset import fold_indices
    from haptic_anfis.report.cv import group_cv

    seen = []

    class Spy(P.LinearPeer):
        def fit(self, X, Y, groups=None):
            seen.append(set(groups.tolist()))
            return super().fit(X, Y, groups)

    res = group_cv(small_ds, lambda s: Spy(), folds=4, seeds=(3,))
    pred = np.empty_like(small_ds.Y)
    for (keep, held), trained in zip(fold_indices(small_ds, 4, 3), seen):
        assert not trained & set(small_ds.point[held].tolist())
        m = P.LinearPeer().fit(small_ds.X[keep], small_ds.Y[keep])
        pred[held] = m.predict(small_ds.X[held])
    np.testing.assert_allclose(res['rmse'][0], np.sqrt(np.mean((pred - small_ds.Y) ** 2, axis=0)))


def test_report_measures_the_shipped_model_as_configured():
    """The report's default row retrains with the hyper-parameters the shipped model file records,
    and those are config/force_model.yaml's (the file the README says made it)."""
    from pathlib import Path

    from haptic_anfis.commands.train import load_config
    from haptic_anfis.report.run import cv_models, shipped_params
    from haptic_anfis.anfis.defaults import AUTO, SHIPPED_INPUTS, SHIPPED_STRUCTURE
    cfg = load_config(str(Path(__file__).resolve().parents[2] / 'config' / 'force_model.yaml'))
    sp = shipped_params()
    # 'auto' inputs and structure resolve, on the shipped data (x follows from (y, z)), to these
    assert cfg['inputs'] == cfg['structure'] == AUTO
    cfg['inputs'], cfg['structure'] = SHIPPED_INPUTS, [tuple(s) for s in SHIPPED_STRUCTURE]
    for key in ('form', 'inputs', 'extrapolation', 'ridge', 'epochs'):
        assert tuple(sp[key]) == tuple(cfg[key]) if isinstance(sp[key], tuple) else sp[key] == cfg[key]
    per_output = lambda st: [tuple(st)] * 3 if isinstance(st[0], int) else [tuple(s) for s in st]  # noqa: E731
    assert per_output(sp['structure']) == per_output(cfg['structure'])
    assert any(name.endswith('(shipped)') for name in cv_models(quick=False))
