"""Node parameters: declarations (:class:`Param`) and their checks, without rclpy but for
:func:`declare_parameters`.

A node module lists its parameters in ``PARAMS`` (a list of :class:`Param`; the case-aware nodes
also take :data:`CASE_PARAMS`); :func:`declare_parameters` declares them on a running node
(rclpy, imported there: the rest of this module serves the ROS-free checks of
:mod:`.parameter_files` and the documentation). :func:`check_value` says why a value does not
fit a parameter ("got 'lots' (a string), expected a double such as 8.9").
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

from ..errors import HapticAnfisError

__all__ = ['Param', 'ParameterError', 'CASE_PARAMS', 'CASE_KEYS', 'effective_case', 'ROS_BUILTIN',
           'positive', 'non_negative', 'one_of', 'finite_vector', 'declare_parameters',
           'type_name', 'value_type_name', 'check_value', 'example', 'default_of']


class ParameterError(HapticAnfisError, ValueError):
    """One or more parameters have values the node cannot run with, or a parameter file is
    unreadable (the message names the file, the line, the node and the parameter)."""


@dataclass(frozen=True)
class Param:
    """A parameter: name, default (its type is the parameter's type), description, and a check
    returning an error message (or None) for a value."""
    name: str
    default: Any
    description: str
    check: Callable[[Any], str | None] | None = None

    @property
    def type(self) -> str:
        """The ROS parameter type: bool, integer, double, string, or ``<type>_array``."""
        return type_name(self.default)


_MISSING = object()


def default_of(params: Iterable[Param], name: str, fallback: Any = _MISSING) -> Any:
    """The default of the parameter ``name`` among ``params`` (a node's ``PARAMS``); ``fallback``
    where none is named so.

    Raises:
        KeyError: no parameter ``name`` and no ``fallback``.
    """
    for p in params:
        if p.name == name:
            return p.default
    if fallback is _MISSING:
        raise KeyError(f'no parameter {name!r} among {[p.name for p in params]}')
    return fallback


def positive(v) -> str | None:
    return None if math.isfinite(v) and v > 0 else 'expected a finite value > 0'


def non_negative(v) -> str | None:
    return None if math.isfinite(v) and v >= 0 else 'expected a finite value >= 0'


def one_of(*choices) -> Callable[[Any], str | None]:
    return lambda v: None if v in choices else f'expected one of {", ".join(map(repr, choices))}'


def finite_vector(n: int, positive: bool = False, nonzero: bool = False):
    """Check: ``n`` finite numbers; all > 0 if ``positive``; not all zero if ``nonzero``."""
    def check(v):
        if len(v) != n or not all(isinstance(c, (int, float)) and math.isfinite(c) for c in v):
            return f'expected {n} finite numbers'
        if positive and any(c <= 0 for c in v):
            return 'expected values > 0'
        if nonzero and all(c == 0 for c in v):
            return 'expected a non-zero vector'
        return None
    return check


#: Declared writable by the case-aware nodes (setting one on a running node switches the case;
#: ``nodes/_case.py``).
CASE_PARAMS = [
    Param('case', '', "case of the case library (haptic-anfis cases list; '' = the node's own "
          'mesh / model parameters, the default scene); writable: setting it on a running node '
          'switches the case'),
    Param('random_case_seed', -1, 'draw a ready case from the library with this seed (-1 = '
          'off); the case name is not logged; writable like case'),
]

#: the parameters that say a node's case
CASE_KEYS = tuple(p.name for p in CASE_PARAMS)


def effective_case(new: dict, current: tuple[str, int]) -> tuple[str, int]:
    """The ``(case, random_case_seed)`` a node runs after ``new`` ({name: value} of
    :data:`CASE_KEYS`) is set on it while it ran ``current``: a name set alone ends the random
    draw, a seed set alone replaces the name (the rule of
    :func:`haptic_anfis.nodes._case.declare_case`)."""
    n = new.get('case', current[0])
    s = new.get('random_case_seed', current[1])
    if 'case' in new and n and 'random_case_seed' not in new:
        s = -1
    if 'random_case_seed' in new and s >= 0 and 'case' not in new:
        n = ''
    return n, s


#: Parameters rclpy declares on every node itself.
ROS_BUILTIN = [
    Param('use_sim_time', False, 'take time from /clock (rclpy)'),
    Param('start_type_description_service', True, 'offer the type description service (rclpy)'),
]

_SCALAR = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
_ARTICLE = {'bool': 'a bool (true or false)', 'integer': 'an integer', 'double': 'a double',
            'string': 'a string'}


def type_name(value: Any) -> str:
    """The ROS parameter type of a Python value: 'double', 'string_array', ... ('' if none)."""
    if isinstance(value, (list, tuple)):
        kinds = {_SCALAR.get(type(v), '') for v in value}
        if len(kinds) == 1:
            return f'{kinds.pop()}_array'
        if kinds == {'integer', 'double'}:
            return 'mixed integer/double array'
        return 'array' if not value else 'mixed array'
    return _SCALAR.get(type(value), '')


def value_type_name(value: Any) -> str:
    """In words, with an article: 'a string', 'an integer', 'a list of doubles'..."""
    t = type_name(value)
    if t.endswith('_array'):
        return f'a list of {t[:-6]}s'
    if t in _ARTICLE:
        return _ARTICLE[t].split(' (')[0]
    return f'a {t or type(value).__name__}'


def example(p: Param) -> str:
    d = p.default
    if isinstance(d, float):
        return f'a double such as {d!r}'
    if isinstance(d, bool):
        return 'a bool (true or false)'
    if isinstance(d, int):
        return f'an integer such as {d}'
    if isinstance(d, str):
        return f'a string such as {d!r}' if d else 'a string'
    if isinstance(d, list):
        inner = type_name(d)[:-6] if d else 'value'
        return f'a list of {inner}s such as {list(d)!r}' if d else 'a list'
    return repr(d)


def check_value(p: Param, v: Any) -> str | None:
    """Why ``v`` cannot be ``p``'s value (type as rclpy would reject it, then ``p.check``), or
    None. The message says what was given and what is expected."""
    want = type_name(p.default)
    got = type_name(v)
    ok = got == want or (want.endswith('_array') and isinstance(v, list) and not v)
    if not ok and isinstance(p.default, list) and not p.default and isinstance(v, list):
        ok = got.endswith('_array')  # an empty default list takes any array
    if not ok:
        hint = ''
        if want == 'double' and got == 'integer':
            hint = f' (write {float(v)!r}: a double needs the decimal point)'
        elif want == 'double_array' and 'integer' in got:
            hint = ' (write every number with a decimal point, e.g. 1.0)'
        return f'got {v!r} ({value_type_name(v)}), expected {example(p)}{hint}'
    msg = p.check(list(v) if isinstance(v, (list, tuple)) else v) if p.check else None
    return f'{v!r}: {msg}' if msg else None


def declare_parameters(node, params: list[Param], writable: Sequence[str] = ()
                       ) -> dict[str, Any]:
    """Declare ``params`` read-only with their descriptions on an rclpy ``node`` (those named in
    ``writable`` writable: the node applies a set while it runs); return {name: value}.

    Raises:
        ParameterError: naming every parameter with a wrong type or a value its check rejects.
    """
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.exceptions import ParameterException
    values: dict[str, Any] = {}
    errors: list[str] = []
    for p in params:
        desc = ParameterDescriptor(description=p.description, read_only=p.name not in writable)
        try:
            node.declare_parameter(p.name, p.default, desc)
        except ParameterException as exc:
            given = _override_value(node, p.name)
            why = check_value(p, given) if given is not None else None
            errors.append(f'parameter {p.name!r}: ' + (why or f'expected {example(p)}: {exc}'))
            continue
        v = node.get_parameter(p.name).value
        if isinstance(v, (list, tuple)) or type(v).__name__ == 'array':
            v = list(v)
        msg = p.check(v) if p.check is not None else None
        if msg:
            errors.append(f'parameter {p.name!r} = {v!r}: {msg}')
        values[p.name] = v
    if errors:
        raise ParameterError(f'{node.get_name()}: bad parameters: ' + '; '.join(errors))
    return values


def _override_value(node, name: str):
    """The value the command line / parameter file gave ``name`` (rclpy's overrides), or None."""
    try:
        v = node._parameter_overrides[name].value  # noqa: SLF001 (rclpy keeps them here)
    except (AttributeError, KeyError):
        return None
    return list(v) if isinstance(v, (list, tuple)) or type(v).__name__ == 'array' else v
