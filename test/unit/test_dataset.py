"""Dataset files and splits."""
import numpy as np
import pytest

from haptic_anfis.tissue.dataset import (DEFAULT_DATASET, DatasetError, ForceDataset, fold_indices,
                                  load_dataset, save_dataset, split_indices)


def test_round_trip_is_exact(synthetic, tmp_path):
    p = save_dataset(synthetic, tmp_path / 'd.csv')
    back = load_dataset(p)
    assert np.array_equal(back.X, synthetic.X) and np.array_equal(back.Y, synthetic.Y)
    assert back.sha256() == synthetic.sha256()
    assert back.provenance['kind'].startswith('SYNTHETIC')


def test_shipped_default_dataset_loads():
    ds = load_dataset(DEFAULT_DATASET)
    assert len(ds) >= 500 and len(np.unique(ds.point)) >= 100
    assert set(np.round(np.unique(ds.X[:, 3]) * 1000, 6)) == {2, 5, 8, 12, 16}
    assert ds.provenance.get('kind')  # says what it is (synthetic placeholder or FE)


@pytest.mark.parametrize('text, message', [
    ('', 'empty'),
    ('point,x_m,y_m\n1,2,3\n', 'lacks column'),
    ('point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N\n', 'no samples'),
    ('point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N\n0,1,2,3,4,5,6,abc\n', r':2: cannot read'),
    ('point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N\n0,1,2,3,4,5,6,nan\n',
     r"bad\.csv:2: non-finite value in column\(s\) \['fz_N'\]"),
    ('point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N\n0,1,2,3,4,5,6,7\n1,1,NaN,3,4,5,6,7\n',
     r"bad\.csv:3: non-finite value in column\(s\) \['y_m'\]"),
    ('point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N\n0,1,2,3,inf,5,6,7\n', r"bad\.csv:2: .*'depth_m'"),
    ('point,x_m,y_m,z_m,depth_m,fx_N,fy_N,fz_N\n0.5,1,2,3,4,5,6,7\n', 'integers'),
])
def test_bad_files_fail_clearly(tmp_path, text, message):
    p = tmp_path / 'bad.csv'
    p.write_text(text)
    with pytest.raises(DatasetError, match=message):
        load_dataset(p)


def test_missing_file(tmp_path):
    with pytest.raises(DatasetError, match='does not exist'):
        load_dataset(tmp_path / 'none.csv')


def test_split_by_point_keeps_points_whole(synthetic):
    keep, out = split_indices(synthetic, 0.2, seed=3)
    assert not set(synthetic.point[keep]) & set(synthetic.point[out])
    assert len(keep) + len(out) == len(synthetic)
    n_pts = len(np.unique(synthetic.point))
    assert len(np.unique(synthetic.point[out])) == round(0.2 * n_pts)
    again = split_indices(synthetic, 0.2, seed=3)
    assert np.array_equal(again[1], out)  # seeded


def test_split_rejects_bad_arguments(synthetic):
    with pytest.raises(ValueError, match='fraction'):
        split_indices(synthetic, 1.5, 0)
    with pytest.raises(ValueError, match="'point' or 'sample'"):
        split_indices(synthetic, 0.2, 0, by='rows')
    one = ForceDataset(np.zeros((3, 4)), np.zeros((3, 3)), np.zeros(3))
    with pytest.raises(ValueError, match='fewer than two'):
        split_indices(one, 0.2, 0)


@pytest.mark.parametrize('by', ['point', 'sample'])
def test_folds_partition_the_data(synthetic, by):
    folds = fold_indices(synthetic, 5, seed=1, by=by)
    held = np.concatenate([v for _, v in folds])
    assert np.array_equal(np.sort(held), np.arange(len(synthetic)))  # each sample held out once
    for keep, out in folds:
        assert len(keep) + len(out) == len(synthetic) and len(out) > 0
        if by == 'point':
            assert not set(synthetic.point[keep]) & set(synthetic.point[out])
    again = fold_indices(synthetic, 5, seed=1, by=by)
    assert all(np.array_equal(a[1], b[1]) for a, b in zip(folds, again))  # seeded


def test_folds_reject_bad_arguments(synthetic):
    with pytest.raises(ValueError, match='folds'):
        fold_indices(synthetic, 1, 0)
    with pytest.raises(ValueError, match='folds'):
        fold_indices(synthetic, len(np.unique(synthetic.point)) + 1, 0)
    with pytest.raises(ValueError, match="'point' or 'sample'"):
        fold_indices(synthetic, 3, 0, by='rows')


def test_non_finite_arrays_name_column_and_sample_without_numpy_repr():
    X = np.zeros((3, 4))
    X[2, 1] = np.nan
    with pytest.raises(DatasetError, match=r"non-finite input value nan in column 'y_m', sample 2") as e:
        ForceDataset(X, np.zeros((3, 3)), np.zeros(3))
    assert 'np.float64' not in str(e.value)
