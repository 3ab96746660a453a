"""Training from a recorded session: contact/force-command pairs become a force dataset."""
from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip('rclpy')

from haptic_anfis.bag import BagError, BagWriter  # noqa: E402
from haptic_anfis.bag.topics import typestore  # noqa: E402
from haptic_anfis.bag.training_data import dataset_from_bag, load_training_data  # noqa: E402
from haptic_anfis.cli import main as cli  # noqa: E402
from haptic_anfis import interfaces as ifc  # noqa: E402


def _session_bag(path, ds, extra_free: int = 20):
    """A bag as the graph records it: per sample a contact (JointState) and the force command
    (WrenchStamped) with the same stamp, plus free-space contacts with zero force."""
    ts = typestore()
    T = ts.types['builtin_interfaces/msg/Time']
    H = ts.types['std_msgs/msg/Header']
    JS = ts.types['sensor_msgs/msg/JointState']
    WS, W, V = (ts.types[f'geometry_msgs/msg/{n}'] for n in ('WrenchStamped', 'Wrench', 'Vector3'))
    with BagWriter(path) as w:
        w.add_topic('/contact', JS.__msgtype__)
        w.add_topic('/falcon/servo_cf', WS.__msgtype__)
        rows = [(x, f, 1.0) for x, f in zip(ds.X, ds.Y)]
        rows += [((0.05, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)] * extra_free
        for i, (x, f, inside) in enumerate(rows):
            stamp = T(1 + i // 1000, (i % 1000) * 1_000_000)
            pos = np.array([x[0], x[1], x[2], x[3], -1.0, 0.0, 0.0, inside, 0.0])
            js = JS(H(stamp, 'tissue'), list(ifc.CONTACT_FIELDS), pos, np.zeros(0), np.zeros(0))
            wr = WS(H(stamp, 'tissue'), W(V(*map(float, f)), V(0.0, 0.0, 0.0)))
            t = 1_000_000_000 + i * 1_000_000
            w.write('/contact', ts.serialize_cdr(js, JS.__msgtype__), t)
            w.write('/falcon/servo_cf', ts.serialize_cdr(wr, WS.__msgtype__), t + 1000)
    return path


def test_pairs_in_contact_samples_exactly(synthetic, tmp_path):
    bag = _session_bag(tmp_path / 'bag', synthetic)
    ds = dataset_from_bag(bag)
    assert len(ds) == len(synthetic)  # free-space contacts are not samples
    order = np.lexsort(synthetic.X.T)
    got = np.lexsort(ds.X.T)
    np.testing.assert_array_equal(ds.X[got], synthetic.X[order])
    np.testing.assert_array_equal(ds.Y[got], synthetic.Y[order])
    assert len(np.unique(ds.point)) >= 20  # surface patches for a split by point
    assert ds.provenance['kind'].startswith('recorded session')


def test_train_command_accepts_a_session_bag(synthetic, tmp_path, capsys):
    bag = _session_bag(tmp_path / 'bag', synthetic)
    out = tmp_path / 'model.json'
    assert cli(['train', str(bag), '--out', str(out), '--structure', '2-2-2', '--epochs', '5']) == 0
    assert 'recorded session' in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc['dataset']['kind'].startswith('recorded session')
    assert all(o['rmse']['test'] < 0.5 for o in doc['outputs'])


def test_bags_without_contact_samples_fail_clearly(tmp_path):
    from haptic_anfis.tissue.dataset import ForceDataset
    # One "sample" at depth 0 plus free-space contacts: nothing in contact, so no samples.
    touching = ForceDataset(np.zeros((1, 4)), np.zeros((1, 3)), np.zeros(1))
    bag = _session_bag(tmp_path / 'bag', touching, extra_free=5)
    with pytest.raises(BagError, match='no in-contact samples'):
        dataset_from_bag(bag)
    with pytest.raises(ValueError, match='not a bag|no such file'):
        load_training_data(tmp_path / 'nothing.mcap')
