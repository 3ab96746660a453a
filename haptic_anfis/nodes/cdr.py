"""The haptic loop's hot messages on the wire (CDR), read and written with ``struct``.

rclpy turns every received message into Python message objects (one per nested message, each
field set through a checking setter) and back when publishing: measured here, 25-35 µs to
serialise and 25-100 µs to deserialise a ``WrenchStamped`` or a ``JointState`` of 26 values, all
of it holding the process's GIL. The falcon driver's servo thread needs that GIL every
millisecond, so the driver takes ``falcon/servo_cf`` and ``falcon/servo_cf_local`` as raw bytes
(``create_subscription(..., raw=True)``) and the force server publishes them as bytes
(``Publisher.publish`` accepts serialized messages) through these few functions — plain CDR,
little-endian (the encapsulation ROS 2 uses; XCDR1 alignment: each primitive aligned to its size
from the start of the payload after the 4-byte encapsulation header). A message in any other
encapsulation is read through rclpy's own deserialiser (:func:`rclpy.serialization.
deserialize_message`), so nothing depends on the fast path being taken.

Layouts (``std_msgs/Header`` = int32 sec, uint32 nanosec, string frame_id; a string is a uint32
length counting its NUL, the bytes and the NUL; a sequence a uint32 count then its elements):
``geometry_msgs/WrenchStamped`` = header, 3 float64 force, 3 float64 torque;
``sensor_msgs/JointState`` = header, string[] name, float64[] position, velocity, effort.
"""
from __future__ import annotations

import struct

import numpy as np
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from .runtime import stamp_ns

_LE = b'\x00\x01\x00\x00'  # CDR little-endian encapsulation, no options
_HEAD = struct.Struct('<iII')  # sec, nanosec, frame_id length (payload offset 0)
_U32 = struct.Struct('<I')
_F3 = struct.Struct('<3d')


def _header(b: bytes) -> tuple[int, str, int]:
    """(stamp [ns], frame_id, payload offset after it) of the ``std_msgs/Header`` a message
    starts with."""
    sec, nsec, n = _HEAD.unpack_from(b, 4)
    if n < 1 or 16 + n > len(b):
        raise struct.error(f'frame_id length {n} out of the message')  # reported by the caller
    return sec * 1_000_000_000 + nsec, b[16:15 + n].decode('utf-8', errors='replace'), 12 + n


def _first_vector(b: bytes, what: str) -> tuple[int, str, tuple[float, float, float]]:
    """(stamp [ns], frame_id, the three doubles after the header) of a little-endian message
    that starts with a Header and then a Vector3 / Point (``WrenchStamped``: the force;
    ``PoseStamped``: the position)."""
    try:
        stamp, frame, o = _header(b)
        o = (o + 7) & ~7
        v = _F3.unpack_from(b, 4 + o)
    except struct.error as exc:
        raise ValueError(f'malformed {what} ({len(b)} bytes): {exc}') from None
    return stamp, frame, v


def read_wrench_stamped(b: bytes) -> tuple[int, str, tuple[float, float, float]]:
    """(stamp [ns], frame_id, force (3,) [N]) of a serialized ``geometry_msgs/WrenchStamped``.

    Raises:
        ValueError: not a WrenchStamped (too short, bad lengths).
    """
    return _first_vector(b, 'WrenchStamped') if b[:4] == _LE else _slow_wrench(b)


def read_pose_position(b: bytes) -> tuple[int, str, tuple[float, float, float]]:
    """(stamp [ns], frame_id, position (3,) [m]) of a serialized ``geometry_msgs/PoseStamped``
    (the orientation is not read).

    Raises:
        ValueError: not a PoseStamped (too short, bad lengths).
    """
    return _first_vector(b, 'PoseStamped') if b[:4] == _LE else _slow_pose(b)


def read_joint_state(b: bytes) -> tuple[int, str, tuple[float, ...], tuple[float, ...]]:
    """(stamp [ns], frame_id, position, effort) of a serialized ``sensor_msgs/JointState``
    (names and velocities skipped).

    Raises:
        ValueError: not a JointState (too short, bad lengths).
    """
    if b[:4] != _LE:
        return _slow_joint_state(b)
    try:
        stamp, frame, o = _header(b)
        u32 = _U32.unpack_from
        o = (o + 3) & ~3
        count = u32(b, 4 + o)[0]
        o += 4
        for _ in range(count):  # skip the names: aligned uint32 length, bytes
            o = (o + 3) & ~3
            o += 4 + u32(b, 4 + o)[0]
        seqs = []
        for _ in range(3):  # position, velocity, effort
            o = (o + 3) & ~3
            m = u32(b, 4 + o)[0]
            o += 4
            if m:
                o = (o + 7) & ~7
                seqs.append(struct.unpack_from(f'<{m}d', b, 4 + o))
                o += 8 * m
            else:
                seqs.append(())
    except struct.error as exc:
        raise ValueError(f'malformed JointState ({len(b)} bytes): {exc}') from None
    return stamp, frame, seqs[0], seqs[2]


class WrenchStampedWriter:
    """Serialized ``geometry_msgs/WrenchStamped`` with a fixed ``frame_id`` and zero torque."""

    def __init__(self, frame_id: str) -> None:
        fb = frame_id.encode('utf-8') + b'\x00'
        o = 12 + len(fb)
        pad = ((o + 7) & ~7) - o
        self._fmt = struct.Struct(f'<4siII{len(fb)}s{pad}x6d')
        self._fb, self._n = fb, len(fb)

    def pack(self, stamp_ns: int, force) -> bytes:
        """The message stamped ``stamp_ns`` [ns] with ``force`` (3,) [N]."""
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        fx, fy, fz = force
        return self._fmt.pack(_LE, sec, nsec, self._n, self._fb, fx, fy, fz, 0.0, 0.0, 0.0)


class JointStateWriter:
    """Serialized ``sensor_msgs/JointState`` with a fixed ``frame_id`` and ``names``, ``n``
    positions, empty velocity and effort; and the fast reader of that layout (:meth:`read`)."""

    def __init__(self, frame_id: str, names, n: int) -> None:
        fb = frame_id.encode('utf-8') + b'\x00'
        parts = [_U32.pack(len(fb)), fb]
        o = 12 + len(fb)
        body = bytearray()

        def align(a: int) -> None:
            nonlocal o
            k = ((o + a - 1) & ~(a - 1)) - o
            body.extend(b'\x00' * k)
            o += k
        align(4)
        body += _U32.pack(len(names))
        o += 4
        for name in names:
            s = str(name).encode('utf-8') + b'\x00'
            align(4)
            body += _U32.pack(len(s)) + s
            o += 4 + len(s)
        align(4)
        body += _U32.pack(n)
        o += 4
        if n:
            align(8)
        self._prefix = b''.join(parts) + bytes(body)
        self._tail = _U32.pack(0) * 2  # velocity, effort: empty (8-aligned + 8n: 4-aligned)
        self._fmt = struct.Struct(f'<4siI{len(self._prefix)}s{n}d8s')
        self._pos = struct.Struct(f'<{n}d')
        self._empty = struct.Struct('<II')
        self.n, self.frame_id = n, frame_id

    def read(self, b: bytes) -> tuple[int, str, tuple[float, ...], tuple[float, ...]]:
        """:func:`read_joint_state` of ``b``, fast when ``b`` has exactly this layout: the bytes
        from the frame_id to the positions (frame, every name, their padding) equal this
        writer's, so the positions are at a known offset (one comparison instead of walking
        the names); any other message takes the general path."""
        p = self._prefix
        if b[:4] == _LE and b[12:12 + len(p)] == p:
            o = 12 + len(p)
            try:
                pos = self._pos.unpack_from(b, o)
                if self._empty.unpack_from(b, o + 8 * self.n) == (0, 0):
                    sec, nsec = _HEAD.unpack_from(b, 4)[:2]
                    return sec * 1_000_000_000 + nsec, self.frame_id, pos, ()
            except struct.error:
                pass
        return read_joint_state(b)

    def pack(self, stamp_ns: int, position) -> bytes:
        """The message stamped ``stamp_ns`` [ns] with ``position`` (exactly ``n`` values)."""
        if len(position) != self.n:
            raise ValueError(f'JointStateWriter: expected {self.n} positions, got '
                             f'{len(position)}')
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        return self._fmt.pack(_LE, sec, nsec, self._prefix, *position, self._tail)


class _Buffer:
    """A CDR payload being written: each primitive aligned to its size from the payload start."""

    def __init__(self) -> None:
        self.parts: list[bytes] = [_LE]
        self.n = 0  # payload bytes so far (after the encapsulation header)

    def align(self, a: int) -> None:
        pad = -self.n % a
        if pad:
            self.parts.append(bytes(pad))
            self.n += pad

    def raw(self, b: bytes, align: int = 1) -> None:
        self.align(align)
        self.parts.append(b)
        self.n += len(b)

    def pack(self, st: struct.Struct, *values, align: int) -> None:
        self.raw(st.pack(*values), align)

    def string(self, text: str) -> None:
        b = text.encode('utf-8') + b'\x00'
        self.pack(_U32, len(b), align=4)
        self.raw(b)

    def bytes(self) -> bytes:
        return b''.join(self.parts)


_I3 = struct.Struct('<3i')
_STAMP = struct.Struct('<iI')
_POSE_SCALE = struct.Struct('<10d')  # pose (position 3, orientation 4), scale 3
_F4 = struct.Struct('<4f')
_DURATION_BOOL = struct.Struct('<iI?')
_TRIANGLE_LIST = 11  # visualization_msgs/Marker.TRIANGLE_LIST
_ADD = 0


def triangle_markers(frame_id: str, ns: str, markers, stamp_ns: int = 0) -> bytes:
    """A serialized ``visualization_msgs/MarkerArray`` of TRIANGLE_LIST markers (ADD, identity
    pose, scale 1, colour white, the per-corner colours drawn), one per ``(id, corners (n, 3)
    [m], colours (n, 4) RGBA 0..1)`` of ``markers``; what the visualizer re-sends of the dented
    skin at 30 Hz. The corners and colours go in as whole numpy buffers (``float64`` / ``float32``
    in CDR order), not as one message object per point: rclpy's own path cost ~17 ms of the
    interpreter per frame of ~3 000 corners, this ~0.2 ms (``test_cdr.py`` checks it against
    rclpy's serializer, field by field)."""
    w = _Buffer()
    w.pack(_U32, len(markers), align=4)
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    for mid, corners, colours in markers:
        c = np.ascontiguousarray(corners, dtype='<f8').reshape(-1, 3)
        k = np.ascontiguousarray(colours, dtype='<f4').reshape(-1, 4)
        if len(k) != len(c):
            raise ValueError(f'marker {mid}: {len(c)} corners but {len(k)} colours')
        w.pack(_STAMP, sec, nsec, align=4)           # header
        w.string(frame_id)
        w.string(ns)
        w.pack(_I3, int(mid), _TRIANGLE_LIST, _ADD, align=4)
        w.pack(_POSE_SCALE, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, align=8)
        w.pack(_F4, 1.0, 1.0, 1.0, 1.0, align=4)
        w.pack(_DURATION_BOOL, 0, 0, False, align=4)  # lifetime, frame_locked
        w.pack(_U32, len(c), align=4)
        if len(c):
            w.raw(c.tobytes(), align=8)
        w.pack(_U32, len(k), align=4)
        if len(k):
            w.raw(k.tobytes(), align=4)
        w.string('')                                 # texture_resource
        w.pack(_I3, 0, 0, 1, align=4)                # texture: header stamp, frame_id ''
        w.raw(b'\x00')
        w.string('')                                 # texture.format
        w.pack(_U32, 0, align=4)                     # texture.data
        w.pack(_U32, 0, align=4)                     # uv_coordinates
        w.string('')                                 # text
        w.string('')                                 # mesh_resource
        w.string('')                                 # mesh_file.filename
        w.pack(_U32, 0, align=4)                     # mesh_file.data
        w.raw(b'\x00')                               # mesh_use_embedded_materials
    return w.bytes()


def _deserialize(b: bytes, msg_type):
    """(``b`` read by rclpy as ``msg_type`` (any byte order), its header stamp [ns]); ValueError
    naming the type when malformed."""
    try:
        m = deserialize_message(b, msg_type)
    except Exception as exc:  # the rmw's error type varies
        raise ValueError(f'malformed {msg_type.__name__} ({len(b)} bytes): {exc}') from None
    return m, stamp_ns(m.header.stamp)


def _slow_wrench(b: bytes):
    m, ns = _deserialize(b, WrenchStamped)
    f = m.wrench.force
    return ns, m.header.frame_id, (f.x, f.y, f.z)


def _slow_pose(b: bytes):
    m, ns = _deserialize(b, PoseStamped)
    q = m.pose.position
    return ns, m.header.frame_id, (q.x, q.y, q.z)


def _slow_joint_state(b: bytes):
    m, ns = _deserialize(b, JointState)
    return ns, m.header.frame_id, tuple(m.position), tuple(m.effort)
