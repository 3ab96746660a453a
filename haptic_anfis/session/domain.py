"""One session per ROS domain: look for another session's nodes before starting.

Two graphs on one domain corrupt each other silently (a second driver's poses reach the first
graph's detector; an examiner scores both hands). A session therefore looks at its domain first
and refuses to start if a falcon driver, force server or examiner is already there, unless told
to share (``--share-domain``).
"""
from __future__ import annotations

import os
import time

import rclpy
from rclpy.context import Context
from rclpy.signals import SignalHandlerOptions

from ..nodes.executor import make_executor
from .spec import SessionError, SessionSpec

__all__ = ['WATCHED_NODES', 'DISCOVERY_WAIT_S', 'others_on_domain', 'watched_nodes',
           'refuse_shared_domain']

#: nodes of which a domain holds at most one session's
WATCHED_NODES = ('falcon_driver', 'force_server', 'examiner')
#: [s] how long the graph is watched for other nodes (cross-process discovery on this machine:
#: 0.05-2.5 s; a session that was running for a while is found in well under a second)
DISCOVERY_WAIT_S = 1.0


def watched_nodes(names) -> list[str]:
    """The names of ``names`` that belong to another session's loop (:data:`WATCHED_NODES`)."""
    return sorted({n for n in names if n in WATCHED_NODES})


def others_on_domain(domain_id: int | None = None, wait: float = DISCOVERY_WAIT_S,
                     node=None) -> list[str]:
    """The :data:`WATCHED_NODES` running on ``domain_id`` (None: ROS_DOMAIN_ID), seen within
    ``wait`` s. ``node``: an rclpy node on that domain to look with (else a short-lived one)."""
    if node is not None:
        return _watch(node, None, wait)

    ctx = Context()
    rclpy.init(args=[], context=ctx, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    probe = None
    try:
        probe = rclpy.create_node('session_domain_probe', context=ctx,
                                  start_parameter_services=False, enable_rosout=False)
        return _watch(probe, make_executor(ctx), wait)
    finally:
        if probe is not None:
            probe.destroy_node()
        rclpy.try_shutdown(context=ctx)


def _watch(node, executor, wait: float) -> list[str]:
    end = time.monotonic() + wait
    while True:
        found = watched_nodes(node.get_node_names())
        if found or time.monotonic() >= end:
            return found
        if executor is not None:
            executor.spin_once(timeout_sec=0.05)
        else:
            time.sleep(0.05)


def refuse_shared_domain(spec: SessionSpec, node=None) -> None:
    """Raise if another session's loop nodes are on ``spec``'s domain (unless
    ``spec.share_domain``).

    Raises:
        SessionError: naming the domain, the nodes seen and the ways out.
    """
    if spec.share_domain:
        return
    found = others_on_domain(spec.domain_id, node=node)
    if found:
        dom = spec.domain_id if spec.domain_id is not None else os.environ.get('ROS_DOMAIN_ID',
                                                                                 '0')
        raise SessionError(f'ROS domain {dom} already has a running session ({", ".join(found)} '
                           'seen): two graphs on one domain corrupt each other; stop it, choose '
                           'another domain (ROS_DOMAIN_ID or --domain-id), or pass --share-domain')
