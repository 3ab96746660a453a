"""The ROS-free per-message pipeline (haptic_anfis.pipeline) and the local force model codec
(haptic_anfis.device.local_model): recorded messages still decode, the pipeline answers recorded
contacts with the recorded local models, and the core imports neither ROS nor the node modules."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from haptic_anfis import interfaces as ifc
from haptic_anfis.bag.reader import read_messages
from haptic_anfis.bag.topics import absolute
from haptic_anfis.device.local_model import LocalModel, check_values, model_values, no_model

ROOT = Path(__file__).resolve().parents[2]
#: written by main at b517df5 (before the pipeline left the node modules): test/support/data/make_*.py
BAG = Path(__file__).resolve().parents[1] / 'support' / 'data' / 'servo_cf_local_b517df5'
#: the shipped default model the bag's local models came from (format version 2, read migrated)
BAG_MODEL = BAG.parent / 'default_model_eeac250.json'


@pytest.fixture(scope='module')
def recorded():
    """[(stamp, contact position, contact effort, local model raw CDR bytes)] from the bag."""
    from haptic_anfis.nodes import cdr
    contacts, models = {}, {}
    for topic, _, _, raw in read_messages(BAG, deserialize=False):
        stamp, _, position, effort = cdr.read_joint_state(raw)
        if topic == absolute(ifc.TOPIC_CONTACT):
            contacts[stamp] = (list(position), list(effort))
        elif topic == absolute(ifc.TOPIC_LOCAL_MODEL):
            models[stamp] = raw
    assert set(contacts) == set(models) and len(models) == 60
    return [(s, *contacts[s], models[s]) for s in sorted(models)]


def test_recorded_local_models_decode_and_encode_to_the_same_bytes(recorded):
    """Every recorded servo_cf_local decodes into a LocalModel whose encoding, packed as the
    force server packs it, is the recorded message byte for byte; the bag holds each kind."""
    from haptic_anfis.nodes import cdr
    writer = cdr.JointStateWriter('tissue', ifc.LOCAL_MODEL_FIELDS, len(ifc.LOCAL_MODEL_FIELDS))
    kinds = {'contact': 0, 'approach': 0, 'none': 0}
    for stamp, _, _, raw in recorded:
        position = cdr.read_joint_state(raw)[2]
        m = LocalModel.from_values(position, 1.5)
        m.check()
        assert m.time == 1.5
        assert writer.pack(stamp, m.values()) == raw
        kinds['contact' if m.in_contact else 'approach' if m.approach else 'none'] += 1
    assert min(kinds.values()) > 0, kinds


def test_pipeline_answers_recorded_contacts_with_the_recorded_local_models(recorded):
    """The recorded contacts (both layouts, with and without approach fields) through today's
    pipeline give the recorded local models (to rounding of the compiled model), with the model
    file they were made with."""
    from haptic_anfis.nodes import cdr
    from haptic_anfis.pipeline.force import load_model, local_model_from_contact
    _, model = load_model({'model_path': str(BAG_MODEL)})
    layouts = set()
    for _, position, effort, raw in recorded:
        want = cdr.read_joint_state(raw)[2]
        F, got, err = local_model_from_contact(model, position, approach=effort)
        assert err is None
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
        assert list(F) == got[ifc.LM_F0]
        layouts.add(len(position))
    assert layouts == {len(ifc.CONTACT_FIELDS), ifc.N_CONTACT_V1}


def test_model_values_is_the_layout_of_local_model_fields():
    """The encoder puts each part at its field's slice (names from interfaces.LOCAL_MODEL_FIELDS);
    the decoder reads them back; a wrong length is one clear error."""
    rng = np.random.default_rng(7)
    parts = [tuple(rng.normal(size=3)), tuple(rng.normal(size=3)), list(rng.normal(size=9)),
             tuple(rng.normal(size=3)), (0.0, 0.6, 0.8), (-1.0, 0.0, 0.0)]
    v = model_values(*parts, 0.004, True)
    assert len(v) == len(ifc.LOCAL_MODEL_FIELDS)
    for part, sl in zip(parts, (ifc.LM_F0, ifc.LM_P0, ifc.LM_K, ifc.LM_C, ifc.LM_N, ifc.LM_D)):
        assert v[sl] == list(part)
    assert v[ifc.LM_DEPTH] == 0.004 and v[ifc.LM_ZERO] == 1.0
    check_values(v)
    m = LocalModel.from_values(np.array(v))
    assert m.values() == v and m.in_contact and m.zero_at_surface
    assert no_model() == [0.0] * len(ifc.LOCAL_MODEL_FIELDS) and no_model() is not no_model()
    with pytest.raises(ValueError, match=f'with 25 values, expected {len(v)}'):
        LocalModel.from_values(v[:-1])


def _imports(path: Path) -> set[str]:
    """Absolute names of the haptic_anfis modules ``path`` imports (function-level included)."""
    pkg = path.relative_to(ROOT).with_suffix('').parts[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = list(pkg[:len(pkg) - node.level + 1]) if node.level else []
            mod = '.'.join(base + ([node.module] if node.module else []))
            out.add(mod)
            out.update(f'{mod}.{a.name}' for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m.startswith('haptic_anfis')}


def test_the_local_model_record_is_the_one_layout_of_names_slices_and_values():
    """interfaces.LOCAL_MODEL is the message's layout: the names are its fields' components in
    order, each LM_* position is its field's, and an encoded message views as one record whose
    fields are the parts given to the encoder."""
    L = ifc.LOCAL_MODEL
    assert L.itemsize == 8 * len(ifc.LOCAL_MODEL_FIELDS)
    assert ifc.LOCAL_MODEL_FIELDS[:4] == ('f0_x', 'f0_y', 'f0_z', 'p0_x')
    assert ifc.LOCAL_MODEL_FIELDS[6:9] == ('k_xx', 'k_xy', 'k_xz')
    assert ifc.LOCAL_MODEL_FIELDS[-2:] == ('depth', 'zero_at_surface')
    for name in L.names:
        at = ifc.field_index(L, name)
        names = ifc.LOCAL_MODEL_FIELDS[at] if isinstance(at, slice) else (
            ifc.LOCAL_MODEL_FIELDS[at],)
        assert all(n == name or n.startswith(f'{name}_') for n in names), (name, names)
    rng = np.random.default_rng(3)
    f0, p0, k, c = rng.normal(size=3), rng.normal(size=3), rng.normal(size=9), rng.normal(size=3)
    v = model_values(tuple(f0), tuple(p0), list(k), tuple(c), (0.0, 0.6, 0.8), (-1.0, 0.0, 0.0),
                     0.004, True)
    r = np.asarray(v).view(L)[0]
    np.testing.assert_array_equal(r['f0'], f0)
    np.testing.assert_array_equal(r['k'], k)
    np.testing.assert_array_equal(r['contact'], c)
    assert tuple(r['normal']) == (0.0, 0.6, 0.8) and tuple(r['direction']) == (-1.0, 0.0, 0.0)
    assert r['depth'] == 0.004 == v[ifc.LM_DEPTH] and r['zero_at_surface'] == 1.0


def test_core_imports_no_node_module_and_interfaces_imports_nothing():
    """interfaces is a leaf (no interfaces <-> device.local_model cycle); the pipeline and the
    core rooms import no node module, at any level (function-level imports count)."""
    assert _imports(ROOT / 'haptic_anfis' / 'interfaces.py') == set()
    core = ['device', 'contact', 'anfis', 'tissue', 'exam', 'cases', 'bag', 'realtime']
    files = [f for room in ['pipeline'] + core
             for f in sorted((ROOT / 'haptic_anfis' / room).glob('*.py'))]
    bad = {str(f.relative_to(ROOT)): sorted(m for m in _imports(f)
                                            if m.startswith('haptic_anfis.nodes'))
           for f in files}
    assert not {k: v for k, v in bad.items() if v}


def test_pipeline_loads_without_ros_and_the_force_stage_without_the_mesh_library():
    """The force stage (what the force server loads) loads no mesh library; all three pipeline
    modules together load no rclpy and no node module."""
    code = ('import sys\n'
            'import haptic_anfis.pipeline.force\n'
            'assert "trimesh" not in sys.modules, "the force stage loaded trimesh"\n'
            'import haptic_anfis.pipeline.contact, haptic_anfis.pipeline.replay\n'
            'bad = [m for m in sys.modules if m.split(".")[0] in ("rclpy", "rosidl_runtime_py")'
            ' or m.startswith("haptic_anfis.nodes")]\n'
            'assert not bad, bad\n')
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
