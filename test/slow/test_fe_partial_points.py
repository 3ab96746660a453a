"""A loading point whose FE stops before the deepest depth keeps the depths it reached: the
partial point record in the store, resuming a sweep past it, and a real (coarse, fast) FE path
that cannot reach its deepest depth."""
import concurrent.futures as cf
import dataclasses

import numpy as np
import pytest
from test_cases import _library  # a throw-away library of scene files
from test_cases_graded import TINY

from haptic_anfis.cases.sweeps import case_stores, store_status
from haptic_anfis.cli import main
from haptic_anfis.tissue import fe
from haptic_anfis.tissue.geometry import loading_points
from haptic_anfis.tissue.pointsweep import JOURNAL_ENV, run_point_sweep, solve_point
from haptic_anfis.tissue.scene import parse_scene
from haptic_anfis.tissue.store import PointStore, point_key, store_manifest
from haptic_anfis.tissue.sweep import records_to_dataset

#: deeper than the tissue can be squeezed at the apex (45 mm thick): the path stops on the way
TOO_DEEP = (0.002, 0.005, 0.044)


def _record(status: str, depths: list[float], point=(0.044, 0.012, -0.006)) -> dict:
    """A sweep record as :func:`solve_point` returns it (forces 1 N per mm of depth)."""
    rec = {'surface_point_m': list(point), 'direction': [-1.0, 0.0, 0.0], 'status': status,
           'depths_m': depths, 'forces_N': [[1e3 * d, 0.0, 0.0] for d in depths],
           'cpu_time_s': 2.0}
    if status != 'ok':
        rec.update(error='attempt 1 (step 4 mm): stopped at ...', attempts=2,
                   missing_depths_m=[d for d in (0.002, 0.005, 0.008) if d not in depths])
    return rec


def test_a_partial_point_record_round_trips_and_is_never_replaced_by_less(tmp_path):
    store = PointStore(tmp_path / 's', store_manifest(parse_scene(TINY, 'tinygraded'), 2))
    key = point_key(0.012, -0.006)
    store.save_record(key, _record('failed', []))
    assert store.failed().keys() == {key} and store.solved() == set()
    store.save_record(key, _record('partial', [0.002]))
    # the partial point replaces the failure record: it is solved, with what it lacks
    assert store.solved() == {key} and store.failed() == {}
    assert store.partial() == {key: [0.005, 0.008]}
    back = store.load(key)
    assert back['status'] == 'partial' and back['depths_m'] == [0.002]
    assert back['missing_depths_m'] == [0.005, 0.008] and back['attempts'] == 2
    assert back['error'].startswith('attempt 1')
    # a failed or shallower retry never hides the depths reached; a deeper one replaces them
    assert store.save_record(key, _record('failed', [])) is None
    assert store.save_record(key, _record('partial', [0.002])) is None
    assert store.failed() == {} and store.load(key)['depths_m'] == [0.002]
    store.save_record(key, _record('partial', [0.002, 0.005]))
    assert store.partial() == {key: [0.008]}
    store.save_record(key, _record('ok', [0.002, 0.005, 0.008]))
    assert store.partial() == {} and store.load(key)['status'] == 'ok'
    # an 'ok' point is never replaced by a partial one
    assert store.save_record(key, _record('partial', [0.002, 0.005])) is None


def test_a_partial_point_counts_as_solved_and_the_sweep_status_names_its_missing_depths(
        tmp_path, capsys):
    lib = _library(tmp_path, {'tinygraded': TINY})
    case = lib.get('tinygraded')
    stores = case_stores(case, tmp_path / 'store', coarse=True)
    p = loading_points(case.scene)[0]
    key = point_key(p[1], p[2])
    stores.main.save_record(key, _record('partial', [0.002], [float(v) for v in p]))
    st = store_status(stores)
    assert st.solved == 1 and st.failed == {} and st.partial == {key: [0.005, 0.008]}
    assert main(['cases', 'sweep', 'tinygraded', '--status', '--coarse',
                 '--store', str(tmp_path / 'store'), '--scene-dir', str(tmp_path / 'scenes'),
                 '--data-dir', str(tmp_path / 'data')]) == 0
    out = capsys.readouterr().out
    assert f'partial: {key} (no 5/8 mm)' in out and '0 failed' in out


def _partial_solve(scene, point, probe_cells):
    """Stands in for the FE: every point stops after its first depth."""
    return _record('partial', [scene.depths[0]], [float(v) for v in point])


def test_a_partial_point_is_not_solved_again_unless_failures_are_retried(tmp_path, monkeypatch):
    scene = parse_scene(TINY, 'tinygraded')
    store = PointStore(tmp_path / 's', store_manifest(scene, 2))
    pts = loading_points(scene)[:3]
    journal = tmp_path / 'journal.txt'
    monkeypatch.setenv(JOURNAL_ENV, str(journal))
    with cf.ThreadPoolExecutor(1) as pool:
        first = run_point_sweep(scene, store, pts, 2, executor=pool, progress=False,
                                solve=_partial_solve)
        keys = sorted(point_key(p[1], p[2]) for p in pts)
        assert sorted(first.solved) == keys and first.failed == {}
        assert first.partial == {k: [0.005, 0.008] for k in keys}
        assert store.partial().keys() == set(keys)
        again = run_point_sweep(scene, store, pts, 2, executor=pool, progress=False,
                                solve=_partial_solve)
        assert again.solved == [] and sorted(again.skipped) == keys
        assert again.partial == first.partial
        assert len(journal.read_text().splitlines()) == 3  # no point solved twice
        retried = run_point_sweep(scene, store, pts, 2, executor=pool, progress=False,
                                  solve=_partial_solve, retry_failed=True)
    assert sorted(retried.solved) == keys  # asked: solved again
    assert len(journal.read_text().splitlines()) == 6


def test_a_point_that_cannot_reach_its_deepest_depth_keeps_the_shallower_ones():
    """A real FE path (coarse mesh): 44 mm into 45 mm of tissue collapses the cells under the
    probe; the point keeps 2 and 5 mm, at the forces of a full solve of those depths, and no
    third attempt is made once two stopped at the same depth."""
    scene = dataclasses.replace(parse_scene(TINY, 'tinygraded'), depths=TOO_DEEP)
    p = loading_points(scene)[4]
    rec = solve_point(scene, p, 2)
    assert rec['status'] == 'partial', rec.get('error')
    assert rec['depths_m'] == pytest.approx([0.002, 0.005])
    assert rec['missing_depths_m'] == pytest.approx([0.044])
    assert rec['attempts'] == 2 and 'no further attempt' in rec['error']
    assert len(rec['displacement']['coeffs_m']) == 2  # the dent of each depth reached
    full = solve_point(dataclasses.replace(scene, depths=TOO_DEEP[:2]), p, 2)
    assert full['status'] == 'ok'
    np.testing.assert_allclose(rec['forces_N'], full['forces_N'], rtol=1e-6, atol=1e-9)
    # the dataset takes the depths reached and names the point as partial, not failed
    ds = records_to_dataset(scene, [{**rec, 'point': 0}, {**full, 'point': 1}])
    assert len(ds.X) == 4 and ds.provenance['failed_points'] == []
    assert ds.provenance['partial_points'] == {'0': pytest.approx([0.044])}


def test_the_smallest_increment_is_the_smallest_load_step_halved_cutbacks_times():
    """A path against a limit stops at the floor (the smallest planned load step, here 2 mm,
    halved max_cutbacks times) instead of creeping towards the limit in ever smaller
    increments; the error says where it stopped."""
    scene = dataclasses.replace(parse_scene(TINY, 'tinygraded'), depths=TOO_DEEP)
    p = loading_points(scene)[4]
    with pytest.raises(fe.FESolveError) as info:
        fe.solve_scene_point(scene, p, probe_cells=2, max_step=0.004, max_cutbacks=3)
    exc = info.value
    assert exc.increment >= 0.002 / 2 ** 3 - 1e-12
    assert 0.005 < exc.depth < 0.044
    assert exc.partial.depths.tolist() == pytest.approx([0.002, 0.005])
