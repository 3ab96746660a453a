"""ForceModel's defaults are the shipped configuration (one source of truth: anfis.defaults.SHIPPED,
which config/force_model.yaml and the trainer repeat), and the depth-scaled form drops x only
when the data show that x is a function of (y, z)."""
import inspect
from pathlib import Path

import numpy as np
import pytest
import yaml

from haptic_anfis.anfis import ForceModel
from haptic_anfis.anfis.defaults import (AUTO, SHIPPED, SHIPPED_INPUTS, SHIPPED_STRUCTURE,
                                         x_explained_by_yz)
from haptic_anfis.tissue.dataset import INPUT_NAMES
from haptic_anfis.tissue.synthetic import make_synthetic_dataset

ROOT = Path(__file__).resolve().parents[2]


def _norm(v):
    return tuple(_norm(x) for x in v) if isinstance(v, (list, tuple)) else v


def test_the_yaml_the_api_and_the_trainer_agree_with_the_one_constant():
    section = yaml.safe_load((ROOT / 'config' / 'force_model.yaml').read_text())['force_model']
    assert set(section) == set(SHIPPED)
    for k, v in SHIPPED.items():
        assert _norm(section[k]) == _norm(v), k
    sig = inspect.signature(ForceModel).parameters
    for k, v in SHIPPED.items():
        if k in sig and k != 'extrapolation':
            assert sig[k].default == v, k
    assert tuple(ForceModel(form='depth_scaled')._form()[2]) == SHIPPED['extrapolation']
    trainer = yaml.safe_load((ROOT / 'config' / 'trainer.yaml').read_text())['trainer']
    p = trainer['ros__parameters']
    assert p['structure'] == '' and p['epochs'] == 0   # 0: SHIPPED's per-output epochs
    assert p['test_fraction'] == SHIPPED['test_fraction'] and p['seed'] == SHIPPED['seed']


def test_the_shipped_data_and_the_skin_drop_x_and_get_the_shipped_structure(synthetic):
    from haptic_anfis.tissue.dataset import DEFAULT_DATASET, load_dataset
    chk = x_explained_by_yz(load_dataset(DEFAULT_DATASET).X)
    assert chk['drop_x'] and chk['rel_rmse'] < 0.01, chk
    m = ForceModel(epochs=1).fit(synthetic.X, synthetic.Y, groups=synthetic.point)
    t = m.metadata_['training']
    assert tuple(t['inputs']) == SHIPPED_INPUTS and t['structure'] == 'shipped'
    assert t["input_check"]["drop_x"] and t["input_check"]["rel_rmse"] < 0.05
    assert [tuple(s) for s in m.structures_] == [tuple(s) for s in SHIPPED_STRUCTURE]


def test_x_that_varies_independently_is_kept_and_named_inputs_are_used_exactly():
    ds = make_synthetic_dataset(seed=1, spacing=0.012, x_range=(0.02, 0.045))
    chk = x_explained_by_yz(ds.X)
    assert not chk['drop_x'] and chk['rel_rmse'] > 0.5, chk
    m = ForceModel(structure=(2, 2, 2, 2), epochs=1).fit(ds.X, ds.Y, groups=ds.point)
    assert tuple(m.metadata_['training']['inputs']) == INPUT_NAMES
    assert m.metadata_['training']['input_check']['drop_x'] is False
    # with x kept, 'auto' has no shipped structure for (x, y, z, depth): it searches
    assert ForceModel()._structures(INPUT_NAMES) == [None, None, None]
    # named inputs: exactly those, no check, on either kind of data
    named = ForceModel(inputs=('y', 'z', 'depth'), structure=(2, 2, 2), epochs=1).fit(
        ds.X, ds.Y, groups=ds.point)
    assert tuple(named.metadata_['training']['inputs']) == ('y', 'z', 'depth')
    assert named.metadata_['training']['input_check'] == {'inputs': 'given'}
    skin = make_synthetic_dataset(seed=1, spacing=0.012)
    four = ForceModel(inputs=INPUT_NAMES, structure=(2, 2, 2, 2), epochs=1).fit(
        skin.X, skin.Y, groups=skin.point)
    assert tuple(four.metadata_['training']['inputs']) == INPUT_NAMES


def test_x_matters_on_data_where_it_varies_independently():
    """Same fixed budget, x kept vs dropped, on data whose force depends on the thickness x:
    keeping x (what 'auto' decides there) fits Fx better on held-out points."""
    ds = make_synthetic_dataset(seed=2, spacing=0.010, x_range=(0.02, 0.045))
    pts = np.unique(ds.point)
    held = np.isin(ds.point, pts[::5])
    kw = dict(epochs=5, extrapolation=(0.0, 0.15, 0.15, 0.0))
    keep = ForceModel(structure=(2, 3, 3, 2), **kw).fit(ds.X[~held], ds.Y[~held],
                                                        groups=ds.point[~held])
    drop = ForceModel(inputs=('y', 'z', 'depth'), structure=(3, 3, 2), **kw).fit(
        ds.X[~held], ds.Y[~held], groups=ds.point[~held])
    assert keep.metadata_['training']['inputs'] == list(INPUT_NAMES)

    def err(m):
        return float(np.sqrt(np.mean((m.predict(ds.X[held])[:, 0] - ds.Y[held, 0]) ** 2)))
    assert err(keep) < 0.5 * err(drop), (err(keep), err(drop))


def test_few_points_or_constant_x_and_bad_values():
    X = np.c_[np.linspace(0.01, 0.04, 10), np.linspace(-0.02, 0.02, 10), np.zeros(10),
              np.full(10, 0.005)]
    assert not x_explained_by_yz(X)['drop_x']          # 10 points: cannot show it
    X[:, 0] = 0.03
    assert x_explained_by_yz(X)['drop_x']              # constant x carries nothing
    with pytest.raises(ValueError, match='inputs'):
        ForceModel(inputs='everything')._form()
    with pytest.raises(ValueError, match='structure'):
        ForceModel(structure='big')._structures(SHIPPED_INPUTS)
    assert SHIPPED['inputs'] == SHIPPED['structure'] == AUTO
