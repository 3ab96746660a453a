"""Parameter files and ``-p name:=value`` overrides, read and checked without rclpy BEFORE any
node starts.

:func:`check_parameter_sources` checks what a session was given against every node's
declarations (:func:`haptic_anfis.nodes.registry.declared_parameters`): YAML syntax (file:line),
unknown keys (the node and the nearest known parameter), types ("got 'lots' (a string),
expected a double such as 8.9") and values, each as one line. :func:`resolve_parameters` gives
the values a node would take from them (the ROS-free pipeline's nodes, ``haptic-anfis loop``).
"""
from __future__ import annotations

import difflib
import re
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import yaml

from ..yamlfile import yaml_error
from .parameters import (CASE_PARAMS, ROS_BUILTIN, Param, ParameterError, check_value, example,
                         type_name)

__all__ = ['resolve_parameters', 'read_parameter_file', 'parse_overrides', 'ros_args_sources',
           'check_parameter_sources']


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
