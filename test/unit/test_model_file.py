"""Model files: bit-exact round trip, clear errors on anything else."""
import json

import numpy as np
import pytest

from haptic_anfis.anfis import FORMAT_VERSION, ForceModel, ModelFileError, SugenoModel
from haptic_anfis.anfis import membership as mf
from haptic_anfis.anfis.force_model import numpy_forces
from haptic_anfis.tissue.dataset import DATA_DIR

#: Every shipped model file of an older format version (each case's: version 2, migrated).
SHIPPED_MODELS = sorted(p for p in [DATA_DIR / 'default_model.json',
                                    *DATA_DIR.glob('cases/**/model.json')]
                        if json.loads(p.read_text())['format_version'] < FORMAT_VERSION)


def test_save_load_round_trip_is_bit_exact(small_model, synthetic, tmp_path):
    path = small_model.save(tmp_path / 'm.json')
    loaded = ForceModel.load(path)
    for a, b in zip(small_model.estimators_, loaded.estimators_):
        assert a.mf == b.mf == 'triangular'
        for P, Q in zip(a.mf_params_, b.mf_params_):
            assert np.allclose(P, Q, rtol=1e-15, atol=0)
        assert np.allclose(a.consequents_, b.consequents_, rtol=1e-14, atol=0)
        assert np.array_equal(a.input_min_, b.input_min_)
        assert np.array_equal(a.input_max_, b.input_max_)
        assert np.array_equal(a.extrapolation, b.extrapolation)
    np.testing.assert_allclose(loaded.predict(synthetic.X), small_model.predict(synthetic.X),
                               rtol=1e-13, atol=1e-15)
    again = ForceModel.load(loaded.save(tmp_path / 'again.json'))   # file -> file: bit exact
    assert (tmp_path / 'again.json').read_text().split('"created_utc"')[0] == \
        path.read_text().split('"created_utc"')[0]
    assert np.array_equal(again.predict(synthetic.X), loaded.predict(synthetic.X))
    assert not list(tmp_path.glob('*.tmp'))  # atomic write leaves nothing behind


def test_shipped_default_model_loads_and_records_provenance():
    model = ForceModel.load(DATA_DIR / 'default_model.json')
    doc = json.loads((DATA_DIR / 'default_model.json').read_text())
    assert doc['format_version'] == FORMAT_VERSION
    assert len(doc['dataset']['sha256']) == 64
    assert all(0 < o['rmse']['test'] < 1 for o in doc['outputs'])
    assert all(o['best_epoch'] >= 1 for o in doc['outputs'])
    assert [i['unit'] for i in doc['inputs']] == ['m'] * 4
    assert np.all(np.isfinite(model.predict_one(0.04, 0.0, 0.0, 0.008)))


def _doc(small_model):
    return json.loads(json.dumps(small_model.to_dict()))


def _write(tmp_path, doc, name='bad.json'):
    p = tmp_path / name
    p.write_text(json.dumps(doc) if not isinstance(doc, str) else doc)
    return p


@pytest.mark.parametrize('mutate, message', [
    (lambda d: d.update(format_version=FORMAT_VERSION + 1), 'format_version'),
    (lambda d: d.update(format='something.else'), 'not a haptic_anfis force-model file'),
    (lambda d: d['outputs'][0]['consequents'].pop(), 'consequents: expected'),
    (lambda d: d['outputs'][1]['membership'][0].pop(), 'structure'),
    (lambda d: d['outputs'][0]['consequents'][0].__setitem__(0, 'NaN'), 'malformed|finite'),
    (lambda d: d['outputs'][2]['membership'][3][0].reverse(), 'ordered corners|centres'),
    (lambda d: d['outputs'][1].update(mf='sigmoid'), '"mf" is .sigmoid.; expected one of'),
    (lambda d: d['inputs'][0].update(min=1.0, max=0.0), 'range'),
    (lambda d: d['inputs'].pop(), 'inputs'),
    (lambda d: d['outputs'][0].update(name='Fq'), 'outputs'),
    (lambda d: d['outputs'][0].pop('extrapolation'), 'malformed'),
    # hand-edited fields of the wrong type: one line naming the file, not a traceback
    (lambda d: d.update(outputs=[1, 2, 3]), 'malformed .*AttributeError'),
    (lambda d: d.update(training='x'), '"training" is str; expected a mapping'),
    (lambda d: d.update(dataset='x'), '"dataset" is str; expected a mapping'),
    (lambda d: d['inputs'][0].update(min='zero'), 'numeric "min" and "max"'),
])
def test_bad_model_files_fail_with_clear_errors(small_model, tmp_path, mutate, message):
    doc = _doc(small_model)
    mutate(doc)
    with pytest.raises(ModelFileError, match=message):
        ForceModel.load(_write(tmp_path, doc))


def test_non_finite_numbers_in_json_are_rejected(small_model, tmp_path):
    text = json.dumps(_doc(small_model))
    first = json.dumps(small_model.estimators_[0].consequents_[0, 0])
    p = _write(tmp_path, text.replace(first, 'Infinity', 1))
    with pytest.raises(ModelFileError, match='non-finite|not a valid'):
        ForceModel.load(p)


def test_missing_and_garbage_files(tmp_path):
    with pytest.raises(ModelFileError, match='does not exist'):
        ForceModel.load(tmp_path / 'nope.json')
    with pytest.raises(ModelFileError, match='not a valid model file'):
        ForceModel.load(_write(tmp_path, '{"format": '))


def test_unfitted_model_says_so():
    with pytest.raises(RuntimeError, match='not trained'):
        ForceModel().predict(np.zeros((1, 4)))


@pytest.fixture(scope='module')
def scaled_model(synthetic):
    return ForceModel(structure=(2, 3, 2), epochs=3).fit(synthetic.X, synthetic.Y,
                                                         groups=synthetic.point)


def test_depth_scaled_round_trip_is_bit_exact(scaled_model, synthetic, tmp_path):
    path = scaled_model.save(tmp_path / 's.json')
    doc = json.loads(path.read_text())
    assert doc['format_version'] == FORMAT_VERSION == 3
    assert [o['mf'] for o in doc['outputs']] == ['triangular'] * 3
    assert doc['form'] == {'name': 'depth_scaled', 'inputs': ['y', 'z', 'depth'], 'scale': 'depth'}
    loaded = ForceModel.load(path)
    assert loaded.input_cols_ == (1, 2, 3) and loaded.scale_col_ == 3
    np.testing.assert_array_equal(loaded.input_range_[0], scaled_model.input_range_[0])
    assert np.array_equal(loaded.predict(synthetic.X), scaled_model.predict(synthetic.X))
    q = synthetic.X[7]
    assert loaded.predict_one(*q) == scaled_model.predict_one(*q)


def _pinned_sugeno(structure, lo, hi, rng):
    """A version-2 output: triangles on the pinned partition, moved inside its constraints."""
    mfs = [mf.project(mf.grid_partition(lo[i], hi[i], m)
                      + 0.3 * (hi[i] - lo[i]) / max(m, 2) * rng.uniform(-1, 1, (m, 3)),
                      lo[i], hi[i]) for i, m in enumerate(structure)]
    R = int(np.prod(structure))
    coef = rng.normal(size=(R, len(lo) + 1)) * np.concatenate([1.0 / (hi - lo), [1.0]])
    return SugenoModel(mfs=mfs, coef=coef, lo=lo, hi=hi, extrapolation=(0.0, 0.2, 0.0, 0.25))


def _v2_doc(small_model, rng):
    """small_model's file rewritten as format version 2 with pinned-partition outputs."""
    doc = _doc(small_model)
    lo, hi = small_model.input_range_
    models = [_pinned_sugeno(st, lo, hi, rng) for st in [(3, 2, 2, 2), (2, 3, 1, 2), (2, 2, 2, 3)]]
    doc['format_version'] = 2
    for o, m in zip(doc['outputs'], models):
        del o['mf']
        o.update(structure=list(m.structure), membership=[P.tolist() for P in m.mfs],
                 consequents=m.coef.tolist(), extrapolation=list(m.extrapolation))
    return doc, models


def _queries(lo, hi, rng, n=3000):
    """Inside the range, in the extrapolation bands and beyond, plus the corners."""
    corners = np.array([np.where(np.array(c), hi, lo) for c in np.ndindex(2, 2, 2, 2)])
    return np.vstack([corners, lo + (hi - lo) * rng.uniform(-0.5, 1.5, (n, 4))])


def test_version_2_files_migrate_to_identical_predictions(small_model, tmp_path, rng):
    """A v2 triangular model is a triangular ANFIS with the same MFs: numpy and compiled paths of
    the migrated model equal the v2 model's own evaluation to 1e-12 N, and saving writes v3."""
    doc, models = _v2_doc(small_model, rng)
    loaded = ForceModel.load(_write(tmp_path, doc, 'v2.json'))
    assert loaded.source_['format_version'] == 2
    X = _queries(*small_model.input_range_, rng)
    ref = np.column_stack([m.predict(X) for m in models])
    np.testing.assert_allclose(numpy_forces(loaded, X), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(loaded.predict(X), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose([loaded.predict_one(*q) for q in X[:300]], ref[:300], rtol=0,
                               atol=1e-12)
    v3 = json.loads(loaded.save(tmp_path / 'v3.json').read_text())
    assert v3['format_version'] == 3
    np.testing.assert_array_equal(ForceModel.load(tmp_path / 'v3.json').predict(X),
                                  loaded.predict(X))


@pytest.mark.parametrize('path', SHIPPED_MODELS, ids=lambda p: p.parent.name)
def test_every_shipped_model_file_migrates_exactly(path, rng):
    """Each shipped file's outputs evaluated as written (pinned triangular Sugeno models) and as
    the migrated estimators, numpy and compiled: identical to 1e-12 N on random inputs."""
    doc = json.loads(path.read_text())
    model = ForceModel.load(path)
    lo = np.array([i['min'] for i in doc['inputs']])
    hi = np.array([i['max'] for i in doc['inputs']])
    cols = list(model.input_cols_)
    X = _queries(lo, hi, rng, 1000)
    ref = np.column_stack([SugenoModel(mfs=[np.array(P) for P in o['membership']],
                                       coef=np.array(o['consequents']), lo=lo[cols], hi=hi[cols],
                                       extrapolation=o['extrapolation']).predict(X[:, cols])
                           for o in doc['outputs']])
    if model.scale_col_ >= 0:
        ref *= np.maximum(X[:, model.scale_col_], 0.0)[:, None]
    np.testing.assert_allclose(numpy_forces(model, X), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(model.predict(X), ref, rtol=0, atol=1e-12)


def test_version_2_files_are_checked_against_their_own_constraints(small_model, tmp_path, rng):
    """A v2 file promised pinned outer peaks; one that breaks that promise is refused."""
    doc, _ = _v2_doc(small_model, rng)
    doc['outputs'][0]['membership'][0][0][1] -= 0.001
    with pytest.raises(ModelFileError, match='outer MF peaks'):
        ForceModel.load(_write(tmp_path, doc, 'v2.json'))


def test_version_1_files_load_as_the_plain_form(small_model, tmp_path, rng):
    doc, models = _v2_doc(small_model, rng)
    doc['format_version'] = 1
    del doc['form']
    loaded = ForceModel.load(_write(tmp_path, doc, 'v1.json'))
    assert loaded.scale_col_ == -1 and loaded.input_cols_ == (0, 1, 2, 3)
    X = _queries(*small_model.input_range_, rng, 500)
    np.testing.assert_allclose(loaded.predict(X), np.column_stack([m.predict(X) for m in models]),
                               rtol=0, atol=1e-12)


def test_a_newer_version_says_so_in_one_line(small_model, tmp_path):
    doc = _doc(small_model)
    doc['format_version'] = FORMAT_VERSION + 1
    with pytest.raises(ModelFileError) as err:
        ForceModel.load(_write(tmp_path, doc, 'new.json'))
    msg = str(err.value)
    assert '\n' not in msg and 'new.json' in msg
    assert f'format_version {FORMAT_VERSION + 1}, newer than this software reads' in msg


@pytest.mark.parametrize('version', [FORMAT_VERSION + 1, 0, '2', None, True])
def test_unknown_versions_name_the_file_and_version(small_model, tmp_path, version):
    doc = _doc(small_model)
    doc['format_version'] = version
    with pytest.raises(ModelFileError, match=rf"v\.json' has format_version {version!r}"):
        ForceModel.load(_write(tmp_path, doc, 'v.json'))


@pytest.mark.parametrize('form', [None, {'name': 'depth_scaled', 'inputs': ['y', 'z'], 'scale': 'x'},
                                  {'name': 'plain', 'inputs': ['z', 'y'], 'scale': None},
                                  {'name': 'plain', 'inputs': ['q'], 'scale': None}, 'text'])
def test_bad_form_names_the_file(scaled_model, tmp_path, form):
    doc = json.loads(json.dumps(scaled_model.to_dict()))
    doc['form'] = form
    with pytest.raises(ModelFileError, match=r"f\.json'.*\"form\""):
        ForceModel.load(_write(tmp_path, doc, 'f.json'))


def test_form_not_matching_the_consequents_fails(scaled_model, tmp_path):
    doc = json.loads(json.dumps(scaled_model.to_dict()))
    doc['form']['inputs'] = ['x', 'y', 'z', 'depth']
    with pytest.raises(ModelFileError, match=r"m\.json'.*needs 4 numbers"):
        ForceModel.load(_write(tmp_path, doc, 'm.json'))


@pytest.mark.parametrize('lo, hi', [(36.0, 45.0), (-1e9, 0.01), (0.0, 2.0)])
def test_absurd_input_range_names_the_file(small_model, tmp_path, lo, hi):
    doc = _doc(small_model)
    doc['inputs'][0].update(min=lo, max=hi)
    with pytest.raises(ModelFileError, match=r"mm\.json'.*input 'x' has range.*millimetres"):
        ForceModel.load(_write(tmp_path, doc, 'mm.json'))
