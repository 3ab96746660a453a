"""A small recorded session for the view's tests: vertical strips over the default breast at
three depths, one mark on the default lesion and one false mark (no ROS; seeded, ~1 s to write)."""
from __future__ import annotations

import numpy as np

RX, R = 0.045, 0.070


def skin_x(y, z):
    return RX * np.sqrt(np.clip(1 - (y / R) ** 2 - (z / R) ** 2, 0, None))


def write_session_bag(path, with_contact: bool = True, with_pose: bool = True) -> None:
    """Write a bag at ``path``: /contact (12-value layout), /falcon/measured_cp, /falcon/servo_cf,
    /exam/marks; 10 ms per sample."""
    from haptic_anfis.bag import typestore
    from haptic_anfis.bag.writer import BagWriter
    from haptic_anfis import interfaces as ifc
    ts = typestore()
    T, H = ts.types['builtin_interfaces/msg/Time'], ts.types['std_msgs/msg/Header']
    JS = ts.types['sensor_msgs/msg/JointState']
    PS, P = ts.types['geometry_msgs/msg/PointStamped'], ts.types['geometry_msgs/msg/Point']
    Pose, Q = ts.types['geometry_msgs/msg/Pose'], ts.types['geometry_msgs/msg/Quaternion']
    PoseS = ts.types['geometry_msgs/msg/PoseStamped']
    W, WS = ts.types['geometry_msgs/msg/Wrench'], ts.types['geometry_msgs/msg/WrenchStamped']
    V = ts.types['geometry_msgs/msg/Vector3']
    rng = np.random.default_rng(0)
    rows, t = [], 100.0
    for k, y in enumerate(np.arange(-0.036, 0.0361, 0.012)):
        depth = (0.003, 0.006, 0.010)[k % 3]
        h = np.sqrt(max(0.040 ** 2 - y * y, 0))
        zs = np.arange(-h, h, 0.001) if k % 2 == 0 else np.arange(h, -h, -0.001)
        for z in zs:
            rows.append((t, (skin_x(y, z), y, z), depth + rng.normal(0, 1e-4), True))
            t += 0.01
        rows.append((t, (skin_x(y, z) + 0.01, y, z), 0.0, False))
        t += 0.01

    def stamp(tt):
        return H(T(int(tt), int(round((tt % 1) * 1e9)) % 1_000_000_000), 'tissue')

    with BagWriter(path) as w:
        if with_contact:
            w.add_topic('/contact', JS.__msgtype__)
        if with_pose:
            w.add_topic('/falcon/measured_cp', PoseS.__msgtype__)
        w.add_topic('/falcon/servo_cf', WS.__msgtype__)
        w.add_topic('/exam/marks', PS.__msgtype__)
        for tt, p, d, c in rows:
            ns = int(tt * 1e9)
            if with_contact:
                v = np.zeros(len(ifc.CONTACT_FIELDS))
                v[0:3], v[ifc.I_DEPTH], v[ifc.I_IN_CONTACT] = p, d if c else 0.0, 1.0 if c else 0
                v[ifc.I_DX] = -1.0
                js = JS(stamp(tt), list(ifc.CONTACT_FIELDS), v, np.zeros(0), np.zeros(0))
                w.write('/contact', ts.serialize_cdr(js, JS.__msgtype__), ns)
            if with_pose:
                ps = PoseS(stamp(tt), Pose(P(p[0] - d, p[1], p[2]), Q(0.0, 0.0, 0.0, 1.0)))
                w.write('/falcon/measured_cp', ts.serialize_cdr(ps, PoseS.__msgtype__), ns)
            ws = WS(stamp(tt), W(V(600.0 * d if c else 0.0, 0.0, 0.0), V(0.0, 0.0, 0.0)))
            w.write('/falcon/servo_cf', ts.serialize_cdr(ws, WS.__msgtype__), ns)
        # a mark over the default lesion (y 15, z -10 mm) and a false one
        for tt, (y, z) in ((rows[len(rows) // 2][0], (0.015, -0.010)),
                           (rows[-5][0], (-0.030, 0.020))):
            m = PS(stamp(tt), P(skin_x(y, z) - 0.002, y, z))
            w.write('/exam/marks', ts.serialize_cdr(m, PS.__msgtype__), int(tt * 1e9))
