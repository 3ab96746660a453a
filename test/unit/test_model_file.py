"""Model files: bit-exact round trip, clear errors on anything else."""
import json

import numpy as np
import pytest

from haptic_anfis.anfis import FORMAT_VERSION, ForceModel, ModelFileError
from haptic_anfis.tissue.dataset import DATA_DIR


def test_save_load_round_trip_is_bit_exact(small_model, synthetic, tmp_path):
    path = small_model.save(tmp_path / 'm.json')
    loaded = ForceModel.load(path)
    for a, b in zip(small_model.models_, loaded.models_):
        assert a.structure == b.structure
        for P, Q in zip(a.mfs, b.mfs):
            assert np.array_equal(P, Q)
        assert np.array_equal(a.coef, b.coef)
        assert np.array_equal(a.lo, b.lo) and np.array_equal(a.hi, b.hi)
        assert np.array_equal(a.extrapolation, b.extrapolation)
    assert np.array_equal(loaded.predict(synthetic.X), small_model.predict(synthetic.X))
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
    (lambda d: d['outputs'][0]['consequents'].pop(), 'consequents must have shape'),
    (lambda d: d['outputs'][1]['membership'][0].pop(), 'structure'),
    (lambda d: d['outputs'][0]['consequents'][0].__setitem__(0, 'NaN'), 'malformed|non-finite'),
    (lambda d: d['outputs'][2]['membership'][3][0].reverse(), 'a < b < c|peaks'),
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
    first = json.dumps(small_model.models_[0].coef[0, 0])
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
    assert doc['format_version'] == FORMAT_VERSION == 2
    assert doc['form'] == {'name': 'depth_scaled', 'inputs': ['y', 'z', 'depth'], 'scale': 'depth'}
    loaded = ForceModel.load(path)
    assert loaded.input_cols_ == (1, 2, 3) and loaded.scale_col_ == 3
    np.testing.assert_array_equal(loaded.input_range_[0], scaled_model.input_range_[0])
    assert np.array_equal(loaded.predict(synthetic.X), scaled_model.predict(synthetic.X))
    q = synthetic.X[7]
    assert loaded.predict_one(*q) == scaled_model.predict_one(*q)


def test_version_1_files_load_as_the_plain_form(small_model, synthetic, tmp_path):
    doc = _doc(small_model)
    doc['format_version'] = 1
    del doc['form']
    loaded = ForceModel.load(_write(tmp_path, doc, 'v1.json'))
    assert loaded.scale_col_ == -1 and loaded.input_cols_ == (0, 1, 2, 3)
    assert np.array_equal(loaded.predict(synthetic.X), small_model.predict(synthetic.X))


@pytest.mark.parametrize('version', [3, 0, '2', None, True])
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
