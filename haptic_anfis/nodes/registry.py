"""Every node's declared parameters, read from the node modules without starting rclpy.

:func:`declared_parameters` -> ``{node name: [Param, ...]}`` (the module's ``PARAMS``, the case
parameters for the case-aware nodes, then the two rclpy declares on every node). The session
checks parameter files against it before any node starts; the documentation's parameter
reference is generated from it (each :class:`~haptic_anfis.nodes.parameters.Param` has ``name``,
``default``, ``type`` and ``description``).
"""
from __future__ import annotations

import functools
import importlib

from .parameters import CASE_PARAMS, ROS_BUILTIN, Param
from ..realtime.processes import node_names

__all__ = ['declared_parameters', 'node_parameters']


@functools.lru_cache(maxsize=None)
def node_parameters(node: str) -> tuple[Param, ...]:
    """The parameters node ``node`` (a module of :mod:`haptic_anfis.nodes`) declares, in order.

    Raises:
        ValueError: ``node`` is not one of the package's nodes.
    """
    if node not in node_names():
        raise ValueError(f'unknown node {node!r}; known: {", ".join(node_names())}')
    mod = importlib.import_module(f'{__package__}.{node}')
    params = list(getattr(mod, 'PARAMS', ()))
    if hasattr(mod, 'CASE_PARAMS'):
        params += CASE_PARAMS
    return tuple(params + ROS_BUILTIN)


def declared_parameters(nodes=None) -> dict[str, list[Param]]:
    """{node: its declared parameters} for ``nodes`` (default: every node of the package)."""
    return {n: list(node_parameters(n)) for n in (nodes or node_names())}
