"""The ``case`` / ``random_case_seed`` parameters the case-aware nodes share.

``case`` ('' = the node's own path parameters, i.e. the default scene) names a case of the
library (``haptic-anfis cases list``); ``random_case_seed`` (>= 0) draws one instead, for a
session where the trainee must not know the case (the node then logs no case name). Unlike the
nodes' other parameters these two are writable: setting either on a running node (``ros2 param
set /force_server case normal``, or ``Node.set_parameters``) switches the case. The node's
``switch(case)`` callback does the swap; a bad name is rejected (the parameter keeps its value,
the node keeps running on the old case) with the reason in the result. Setting one alone turns
the other off: a name ends the random draw, a seed replaces the name (``ros2 param set
/force_server random_case_seed 7`` on a node started with ``case:=NAME``); the browser page sets
both together, so that each node's parameters read back what it runs.
"""
from __future__ import annotations

from typing import Callable

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult

from ..cases import Case, CaseError, resolve_case
from ..realtime.scheduling import off_realtime
from ..tissue.displacement import displacement_path
from .parameters import CASE_KEYS, CASE_PARAMS, effective_case

__all__ = ['declare_case', 'declare_case_parameters', 'describe', 'apply_case',
           'requested_case']


def declare_case_parameters(node) -> None:
    """Declare ``case`` and ``random_case_seed`` (writable) on ``node`` in one call: one
    parameter event carries both, so a watcher (the browser page) never sees half a case."""
    node.declare_parameters('', [(p.name, p.default, ParameterDescriptor(description=p.description))
                                 for p in CASE_PARAMS])


def declare_case(node, switch: Callable[[Case | None], None]) -> Case | None:
    """Declare ``case`` and ``random_case_seed`` on ``node``, resolve them, and switch the case
    whenever either is set later. Returns the initial case (None = the node's own paths).

    Raises:
        CaseError (a ValueError): the initial parameters name no ready case.
    """
    declare_case_parameters(node)
    name = node.get_parameter('case').value
    seed = node.get_parameter('random_case_seed').value
    try:
        case = resolve_case(name, seed)
    except CaseError as exc:
        raise CaseError(f'{node.get_name()}: parameter case / random_case_seed: {exc}') from None
    node.get_logger().info(describe(case, seed))

    def on_set(params) -> SetParametersResult:
        try:
            asked = requested_case(node, params)
            if asked is None:
                return SetParametersResult(successful=True)
            n, s = asked
            target = resolve_case(n, s)
            with off_realtime():  # hundreds of ms of computing: never at real-time priority
                switch(target)
        except Exception as exc:  # keep running on the old case
            node.get_logger().error(f'case switch rejected: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        node.get_logger().info('switched: ' + describe(target, s))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    return case


def requested_case(node, params) -> tuple[str, int] | None:
    """``(case, random_case_seed)`` a parameter set on ``node`` asks for (None: it sets
    neither): the values set, the node's current ones for the other, except that a name set
    alone ends the random draw and a seed set alone replaces the name.

    Raises:
        CaseError: a value of the wrong type.
    """
    new = {p.name: p.value for p in params if p.name in CASE_KEYS}
    if not new:
        return None
    n, s = (new.get(k, node.get_parameter(k).value) for k in CASE_KEYS)
    if not isinstance(n, str) or not isinstance(s, int):
        raise CaseError(f'case must be a string and random_case_seed an integer, got {n!r}, '
                        f'{s!r}')
    # naming a case turns the random draw off; a draw replaces the name (the page's blind choice)
    return effective_case(new, (n, s))


def describe(case: Case | None, seed: int) -> str:
    if case is None:
        return 'no case: own mesh / model parameters (default scene)'
    if seed >= 0:
        return f'case drawn with seed {seed} (name hidden)'
    return f'case {case.name!r}: {case.description}'


def apply_case(p: dict, case: Case | None, own: dict | None = None) -> dict:
    """Parameter values ``p`` with the case's files in place of the path parameters the node has
    (``mesh_path`` + ``mesh_unit`` 'mm', ``model_path``, ``displacement_path``, ``tumours`` as flat x, y, z, r [m]);
    ``case`` None restores the node's own values from ``own``."""
    out = dict(p)
    if case is None:
        out.update({k: v for k, v in (own or {}).items()
                    if k in ('mesh_path', 'mesh_unit', 'model_path', 'displacement_path',
                             'tumours')})
        return out
    if 'mesh_path' in p:
        out['mesh_path'], out['mesh_unit'] = str(case.mesh_path), 'mm'
    if 'model_path' in p:
        out['model_path'] = str(case.model_path)
    if 'displacement_path' in p:  # the case's own skin displacements (the dent it draws)
        out['displacement_path'] = str(displacement_path(case.dataset_path))
    if 'tumours' in p:
        out['tumours'] = [float(v) for lesion in case.lesions_m() for v in lesion]
    return out
