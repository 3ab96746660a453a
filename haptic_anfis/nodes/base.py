"""The base class of the package's nodes: a node whose constructor fails leaves nothing behind.

A node whose ``__init__`` raises (a bad parameter, a model file that does not load) is never
destroyed by its caller, who gets no object to destroy. Its name then stays on the ROS graph
until the garbage collector happens to free it (its callbacks make reference cycles), even
after its context is shut down, and a session started later in the same process (``sim``'s
graph, a test) would take it for another session's node on the domain and refuse to start.
Every node of the package derives from :class:`HapticNode`, which destroys such a node before
the error leaves its constructor.
"""
from __future__ import annotations

import functools

from rclpy.node import Node

__all__ = ['HapticNode']


class HapticNode(Node):
    """An rclpy :class:`~rclpy.node.Node` destroyed when its subclass's ``__init__`` raises (the
    error is re-raised unchanged)."""

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        init = cls.__dict__.get('__init__')
        if init is None:
            return

        @functools.wraps(init)
        def __init__(self, *args, **kw) -> None:
            try:
                init(self, *args, **kw)
            except BaseException:
                self._destroy_unbuilt()
                raise

        cls.__init__ = __init__

    def _destroy_unbuilt(self) -> None:
        """Destroy a node whose construction failed; never raises. The subclass's
        ``destroy_node`` first (it may release what the constructor had opened); if that fails
        on the half-built object, rclpy's own (``Node.__init__`` itself may have failed,
        leaving no handle: nothing to do then)."""
        for destroy in (type(self).destroy_node, Node.destroy_node):
            try:
                destroy(self)
                return
            except Exception:
                pass
