"""A subscription the servo thread reads itself, once per tick, instead of an executor callback.

The falcon driver's executor thread and its 1 kHz servo thread share one GIL. Every message the
executor hands to a Python callback is a GIL hand-over; on a loaded machine the thread holding it
can be preempted by the OS while the servo thread waits (measured: separate processes at load
~10, the local-model driver — two loop messages per pose — fell to 350-470 Hz while its process
used 21 % of a core, i.e. it waited, it did not compute). A haptic servo loop reads its newest
input at the start of each tick anyway, so the driver takes ``falcon/servo_cf`` and
``falcon/servo_cf_local`` from their DDS readers in the servo thread itself: with keep-last-1 QoS
the reader holds the newest sample, and one take is a short C call on the thread that already
holds the GIL.

The reader is an rcl subscription made through rclpy's implementation module (what
``Node.create_subscription`` makes) but not registered with the node, so no executor takes from
it; it is visible on the ROS graph as any subscription is.
"""
from __future__ import annotations

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.type_support import check_is_valid_msg_type


class PolledSubscription:
    """A raw (serialized bytes) subscription of ``node`` to ``topic`` that is never spun.

    Args:
        node: the rclpy node (its name / namespace / remappings resolve ``topic``).
        msg_type: the message class.
        topic: topic name (relative names resolve as for ``create_subscription``).
        qos: an rclpy QoSProfile (keep-last 1: the newest sample).
    """

    def __init__(self, node, msg_type, topic: str, qos) -> None:
        check_is_valid_msg_type(msg_type)  # imports the type support
        with node.handle:
            self._h = _rclpy.Subscription(node.handle, msg_type, topic, qos.get_c_qos_profile())
        self.msg_type = msg_type
        self.topic = topic

    def take(self, raw: bool = True):
        """The oldest sample not yet taken — serialized bytes, or with ``raw=False`` the message
        object — or None."""
        m = self.take_with_info(raw)
        return None if m is None else m[0]

    def take_with_info(self, raw: bool = True):
        """``(sample, message_info)`` of the oldest sample not yet taken, or None; the info dict
        has ``received_timestamp`` (system clock [ns], 0 if the middleware does not say)."""
        h = self._h
        if h is None:
            return None
        with h:
            return h.take_message(self.msg_type, raw)

    def take_newest(self, raw: bool = True):
        """The newest sample waiting (older ones dropped), or None when none is waiting."""
        newest = None
        while (m := self.take(raw)) is not None:
            newest = m
        return newest

    def destroy(self) -> None:
        """Release the reader (before the node is destroyed)."""
        if self._h is not None:
            self._h.destroy_when_not_in_use()
            self._h = None
