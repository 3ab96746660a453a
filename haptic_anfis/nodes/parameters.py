"""Node parameters without rclpy: declarations (:class:`Param`), their checks, and the check of
parameter files and ``-p name:=value`` overrides BEFORE any node starts.

A node module lists its parameters in ``PARAMS`` (a list of :class:`Param`; the case-aware nodes
also take :data:`CASE_PARAMS`); :func:`declare_parameters` declares them on a running node, and
:func:`check_parameter_sources` checks what a session was given against every node's declarations
(:func:`haptic_anfis.nodes.registry.declared_parameters`): YAML syntax (file:line), unknown keys
(the node and the nearest known parameter), types ("got 'lots' (a string), expected a double such
as 8.9") and values, each as one line.
"""
from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import yaml

from ..errors import HapticAnfisError
from ..yamlfile import yaml_error

__all__ = ['Param', 'ParameterError', 'CASE_PARAMS', 'CASE_KEYS', 'effective_case', 'ROS_BUILTIN', 'positive', 'non_negative',
           'one_of', 'finite_vector', 'declare_parameters', 'resolve_parameters', 'type_name',
           'value_type_name', 'check_value', 'read_parameter_file', 'parse_overrides',
           'check_parameter_sources', 'ros_args_sources', 'default_of']


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


def _example(p: Param) -> str:
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
        return f'got {v!r} ({value_type_name(v)}), expected {_example(p)}{hint}'
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
            errors.append(f'parameter {p.name!r}: ' + (why or f'expected {_example(p)}: {exc}'))
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


def resolve_parameters(params: list[Param], node_name: str, params_files=(),
                       overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The values a node named ``node_name`` would get, without rclpy: defaults, then each YAML
    ``params_files`` (sections ``node_name`` and ``/**``, key ``ros__parameters``), then
    ``overrides``; typed and checked like :func:`declare_parameters`. A key of the node's own
    section that neither ``params`` nor the case / rclpy parameters declare is an error (a
    misspelling would otherwise be silently ignored); ``/**`` keys may belong to other nodes.

    Raises:
        ParameterError: unreadable file, unknown parameter name, wrong type or a rejected value.
    """
    known = {p.name: p for p in params}
    allowed = set(known) | {p.name for p in CASE_PARAMS + ROS_BUILTIN}
    values = {p.name: p.default for p in params}
    given: dict[str, Any] = {}
    errors = []
    for f in params_files:
        for section, key, v, where in read_parameter_file(f):
            if section in ('/**', node_name, '/' + node_name):
                if section != '/**' and key not in allowed and not key.startswith('qos_overrides.'):
                    errors.append(f'{where}: unknown parameter {key!r}' + _nearest(key, allowed))
                given[key] = v
    given.update(overrides or {})
    for name, v in given.items():
        p = known.get(name)
        if p is None:
            continue
        why = check_value(p, v)
        if why:
            errors.append(f'parameter {name!r}: {why}')
            continue
        values[name] = list(v) if isinstance(v, list) else v
    if errors:
        raise ParameterError(f'{node_name}: bad parameters: ' + '; '.join(errors))
    return values


def _nearest(word: str, known: Iterable[str], what: str = '') -> str:
    close = difflib.get_close_matches(word, sorted(known), n=1, cutoff=0.6)
    return f' (did you mean {close[0]!r}?)' if close else (f'; known: {what}' if what else '')


# -- parameter files ----------------------------------------------------------------------------

def _loader():
    """PyYAML's SafeLoader reading numbers as rcl does: ``1e3`` (no decimal point) is a double
    there, a string for YAML 1.1."""
    class RclLoader(yaml.SafeLoader):
        pass
    RclLoader.add_implicit_resolver('tag:yaml.org,2002:float',
                                    re.compile(r'^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)[eE][-+]?[0-9]+$'),
                                    list('-+0123456789.'))
    return RclLoader

Entry = tuple[str, str, Any, str]  # (node section, parameter name, value, 'file:line')


def read_parameter_file(path: str | Path) -> list[Entry]:
    """Every parameter of a ROS 2 parameter file as ``(section, name, value, 'file:line')``;
    nested keys below ``ros__parameters`` become dotted names, as rcl reads them.

    Raises:
        ParameterError: missing / unreadable file, YAML syntax (with its line), or a layout that is
            not ``node: {ros__parameters: {name: value}}``.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ParameterError(f'{path}: cannot read the parameter file: '
                             f'{exc.strerror or exc}') from None
    try:
        root = yaml.compose(text, Loader=_loader())
    except yaml.YAMLError as exc:
        raise ParameterError(str(yaml_error(path, exc))) from None
    out: list[Entry] = []
    if root is None:
        return out

    def at(node) -> str:
        return f'{path}:{node.start_mark.line + 1}'

    if not isinstance(root, yaml.MappingNode):
        raise ParameterError(f'{at(root)}: expected node names at the top level '
                             '(node_name: {ros__parameters: {...}})')
    loader = _loader()('')
    for k, sec in root.value:
        section = str(loader.construct_object(k))
        if not isinstance(sec, yaml.MappingNode):
            raise ParameterError(f'{at(k)}: {section}: expected ros__parameters below the node '
                                 'name')
        for k2, body in sec.value:
            key2 = loader.construct_object(k2)
            if key2 != 'ros__parameters':
                raise ParameterError(f'{at(k2)}: {section}: expected ros__parameters, got '
                                     f'{key2!r}' + _nearest(str(key2), ['ros__parameters']))
            if isinstance(body, yaml.ScalarNode) and body.value in ('', 'null', '~'):
                continue
            if not isinstance(body, yaml.MappingNode):
                raise ParameterError(f'{at(body)}: {section}: ros__parameters must map names to '
                                     'values')
            _flatten(loader, body, '', section, at, out)
    return out


def _flatten(loader, body, prefix: str, section: str, at, out: list[Entry]) -> None:
    for k, v in body.value:
        name = prefix + str(loader.construct_object(k))
        if isinstance(v, yaml.MappingNode):
            _flatten(loader, v, name + '.', section, at, out)
        else:
            out.append((section, name, loader.construct_object(v, deep=True), at(k)))


def parse_overrides(args: Sequence[str]) -> list[tuple[str, Any, str]]:
    """``-p name:=value`` pairs of a ``--ros-args`` list as ``(name, value, '-p name:=value')``,
    the value read as YAML (as rcl does).

    Raises:
        ParameterError: ``-p`` without ``name:=value``.
    """
    out = []
    for i, a in enumerate(args):
        if a not in ('-p', '--param'):
            continue
        arg = args[i + 1] if i + 1 < len(args) else ''
        name, sep, text = arg.partition(':=')
        if not sep or not name:
            raise ParameterError(f'-p {arg}: expected -p name:=value')
        try:
            v = yaml.load(text, Loader=_loader()) if text.strip() else ''
        except yaml.YAMLError:
            v = text
        out.append((name, v, f'-p {arg}'))
    return out


def ros_args_sources(args: Sequence[str]) -> tuple[list[str], list[tuple[str, Any, str]], str]:
    """(parameter files, ``-p`` overrides, the ``__node`` remap or '') of an rclpy argument list
    (the part after ``--ros-args``; everything before it is ignored)."""
    args = list(args or [])
    if '--ros-args' in args:
        args = args[args.index('--ros-args') + 1:]
    files = [args[i + 1] for i, a in enumerate(args[:-1]) if a == '--params-file']
    node = ''
    for i, a in enumerate(args[:-1]):
        if a in ('-r', '--remap') and args[i + 1].startswith('__node:='):
            node = args[i + 1].split(':=', 1)[1]
    return files, parse_overrides(args), node


def check_parameter_sources(declared: Mapping[str, Sequence[Param]], params_files=(),
                            overrides: Sequence[tuple[str, Any, str]] = (),
                            nodes: Sequence[str] | None = None,
                            node_overrides: Mapping[str, Sequence[tuple[str, Any, str]]]
                            | None = None, whole_session: bool = True,
                            strict_globals: bool = True) -> list[str]:
    """Check parameter files and overrides against ``declared`` ({node: its parameters}) before
    any node starts; returns one line per problem (empty: all good).

    ``nodes``: the nodes of this session (default: all of ``declared``); a file's section for a
    known node outside the session is checked too (the shipped config files hold one each), an
    unknown section names the nearest node. A ``/**`` key or a global ``overrides`` key must be
    declared by at least one node of the session; its type and value are checked for each node
    that declares it. ``node_overrides``: {node: overrides given to that node alone}.
    ``whole_session`` False (one node checking its own arguments, ``run_node``): sections of
    nodes ``declared`` does not list are not checked; ``strict_globals`` False: neither are global
    keys no node of ``declared`` declares (a launcher checked them against its whole session).
    """
    session = list(nodes if nodes is not None else declared)
    full = {n: {p.name: p for p in (*ps, *ROS_BUILTIN)} for n, ps in declared.items()}
    errors: list[str] = []

    def value_errors(where: str, node_list: Sequence[str], key: str, v: Any) -> None:
        by_why: dict[str, list[str]] = {}  # nodes that reject the value alike: one line
        for n in node_list:
            p = full.get(n, {}).get(key)
            why = check_value(p, v) if p is not None else None
            if why:
                by_why.setdefault(why, []).append(n)
        for why, ns in by_why.items():
            errors.append(f'{where}: {", ".join(ns)}: {key}: {why}')

    def unknown(where: str, n: str, key: str) -> None:
        errors.append(f'{where}: {n}: unknown parameter {key!r}' + _nearest(key, full[n]))

    def global_key(where: str, key: str, v: Any) -> None:
        owners = [n for n in session if key in full.get(n, {})]
        if key.startswith('qos_overrides.'):
            return
        if not owners and not strict_globals:
            return
        if not owners:
            every = {k for n in session for k in full.get(n, {})}
            who = (f'{session[0]} declares no such parameter' if len(session) == 1 else
                   f'no node of this session ({", ".join(session)}) declares it')
            errors.append(f'{where}: unknown parameter {key!r}: {who}' + _nearest(key, every))
            return
        value_errors(where, owners, key, v)

    for f in params_files:
        try:
            entries = read_parameter_file(f)
        except ParameterError as exc:
            errors.append(str(exc))
            continue
        for section, key, v, where in entries:
            name = section.rsplit('/', 1)[-1] if section != '/**' else section
            if name == '/**':
                global_key(where, key, v)
            elif name not in full and not whole_session:
                continue
            elif name not in full:
                errors.append(f'{where}: unknown node {section!r}' + _nearest(
                    name, full, ', '.join(sorted(full))))
            elif key not in full[name]:
                if not key.startswith('qos_overrides.'):
                    unknown(where, name, key)
            else:
                value_errors(where, [name], key, v)
    for key, v, where in overrides:
        node, sep, own = key.partition(':')   # rcl's node-targeted form: -p node:name:=value
        if sep and node in full:
            if own not in full[node]:
                unknown(where, node, own)
            else:
                value_errors(where, [node], own, v)
        else:
            global_key(where, key, v)
    for n, ovs in (node_overrides or {}).items():
        for key, v, where in ovs:
            if n in full and key not in full[n]:
                unknown(where, n, key)
            else:
                value_errors(where, [n], key, v)
    return list(dict.fromkeys(errors))  # one line per problem, each once
