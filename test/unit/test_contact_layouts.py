"""Both contact message layouts (12 values, and the older 9 without the normal) are read by every
reader through one helper; a message of any other length is counted and reported, not dropped in
silence. The bags here are written by a plain ``rosbags`` writer, not by the project's recorder."""
import json
import math

import numpy as np
import pytest

from haptic_anfis import interfaces as ifc
from haptic_anfis.cli import main

RX, R = 0.045, 0.070


def skin(y, z):
    return RX * np.sqrt(np.clip(1 - (y / R) ** 2 - (z / R) ** 2, 0, None))


def session_rows():
    """(t [s], contact values in the current layout) of vertical strips pressed 12 mm deep over
    the default breast, lifted at each strip's end, plus a mark over the default lesion."""
    rows, t = [], 1.0
    for y in np.arange(-0.040, 0.041, 0.008):
        h = np.sqrt(max(0.042 ** 2 - y * y, 0))
        for z in np.arange(-h, h, 0.001):
            rows.append((t, [skin(y, z), y, z, 0.012, -1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0]))
            t += 0.01
        rows.append((t, [skin(y, h) + 0.01, y, h, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
        t += 0.01
    return rows


def write_bag(path, rows, n_values, junk=()):
    """A session bag written by a plain rosbags Writer (MCAP, version 9): contact messages cut
    to ``n_values`` values, force commands, and the given ``junk`` (t, values) messages too."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_JAZZY)
    T = ts.types
    JointState, Header, Time = (T['sensor_msgs/msg/JointState'], T['std_msgs/msg/Header'],
                                T['builtin_interfaces/msg/Time'])
    W, Wr, V3 = (T['geometry_msgs/msg/WrenchStamped'], T['geometry_msgs/msg/Wrench'],
                 T['geometry_msgs/msg/Vector3'])
    names = list(ifc.CONTACT_FIELDS[:n_values])

    def header(t):
        return Header(Time(int(t), int(round((t % 1) * 1e9))), 'tissue')

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection('/contact', JointState.__msgtype__, typestore=ts)
        f = w.add_connection('/falcon/servo_cf', W.__msgtype__, typestore=ts)
        for t, v in sorted([(t, v[:n_values]) for t, v in rows] + list(junk),
                           key=lambda r: r[0]):
            js = JointState(header(t), names[:len(v)] if len(v) <= n_values else
                            [f'v{i}' for i in range(len(v))], np.array(v, float),
                            np.zeros(0), np.zeros(0))
            w.write(c, int(t * 1e9), ts.serialize_cdr(js, JointState.__msgtype__))
            fx = 900.0 * v[3] ** 1.2 if len(v) > 3 else 0.0
            wr = W(header(t), Wr(V3(fx, 0.0, 0.0), V3(0.0, 0.0, 0.0)))
            w.write(f, int(t * 1e9), ts.serialize_cdr(wr, W.__msgtype__))


def report_of(bag, capfd) -> dict:
    assert main(['exam', 'report', str(bag), '--json']) == 0
    return json.loads(capfd.readouterr().out.strip().splitlines()[-1])


def test_layouts_are_counted_by_the_one_helper():
    c = ifc.ContactLayouts()
    assert c.accept([0.0] * 12) and c.accept([0.0] * 9)
    assert not c.accept([0.0] * 7) and not c.accept([]) and not c.accept([0.0] * 13)
    assert c.as_dict() == {'current': 1, 'v1_9_values': 1, 'other': {'0': 1, '7': 1, '13': 1}}
    assert '3 contact message(s) not read' in c.note() and '9-value' in c.note()
    assert ifc.ContactLayouts().note() is None


def test_old_layout_bag_scores_as_the_new_and_other_lengths_are_reported(tmp_path, capfd):
    rows = session_rows()
    write_bag(tmp_path / 'new', rows, 12)
    write_bag(tmp_path / 'old', rows, 9)
    junk = [(0.5 + 0.001 * i, [0.01] * 7) for i in range(5)]
    write_bag(tmp_path / 'junk', rows, 12, junk=junk)
    new, old, bad = (report_of(tmp_path / n, capfd) for n in ('new', 'old', 'junk'))
    assert new['coverage_pct']['deep'] > 80, new   # the bag was read: strips cover the breast
    for k in ('coverage_pct', 'pattern', 'score', 'hits', 'misses', 'contact_s', 'max_depth_mm'):
        assert old[k] == new[k] == bad[k], k
    assert old['contact_messages'] == {'current': 0, 'v1_9_values': len(rows), 'other': {}}
    assert new['contact_messages'] == {'current': len(rows), 'v1_9_values': 0, 'other': {}}
    assert bad['contact_messages']['other'] == {'7': 5}
    assert any('5 contact message(s) not read (5 of 7 values' in n for n in bad['notes']), bad
    assert any('9-value layout' in n for n in old['notes'])


@pytest.mark.parametrize('n_values', [12, 9])
def test_training_data_from_either_layout(tmp_path, n_values):
    from haptic_anfis.bag.training_data import dataset_from_bag
    rows = session_rows()
    write_bag(tmp_path / 'b', rows, n_values, junk=[(0.5, [0.0] * 4)])
    ds = dataset_from_bag(tmp_path / 'b')
    assert len(ds.X) == sum(1 for _, v in rows if v[7] > 0.5)
    assert ds.provenance['contact_messages']['other'] == {'4': 1}


def test_contact_geometry_of_either_layout_and_what_is_not_drawn():
    """What the view nodes draw: point, direction and depth while in contact and finite."""
    cur = [0.01, 0.02, 0.03, 0.004, -1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0]
    assert ifc.contact_geometry(cur) == ((0.01, 0.02, 0.03), (-1.0, 0.0, 0.0), 0.004)
    assert ifc.contact_geometry(cur[:9]) == ifc.contact_geometry(cur)  # the older layout
    assert ifc.contact_geometry(cur[:8] + [0.0, math.nan, 0.0, 0.0]) is not None  # normal unused
    for bad in ([*cur[:7], 0.0, *cur[8:]],            # not in contact
                [*cur[:7], math.nan, *cur[8:]],       # in_contact NaN
                [math.inf, *cur[1:]],                 # a non-finite point
                [*cur[:3], math.nan, *cur[4:]],       # a non-finite depth
                cur[:10]):                            # no known layout
        assert ifc.contact_geometry(bad) is None
