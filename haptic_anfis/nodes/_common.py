"""What every node shares: typed, documented, validated parameters; stamps; the spin loop."""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import rclpy
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

#: QoS of the 1 kHz loop topics: reliable, keep only the newest sample (a late one is useless).
LOOP_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE)

_TYPE_NAMES = {bool: 'a bool (true/false)', int: 'an integer', float: 'a double (write 500.0, not 500)',
               str: 'a string'}


class ParameterError(ValueError):
    """One or more parameters have values the node cannot run with."""


@dataclass(frozen=True)
class Param:
    """A parameter: name, default (its type is the parameter's type), description, and a check
    returning an error message (or None) for a value."""
    name: str
    default: Any
    description: str
    check: Callable[[Any], str | None] | None = None


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


def declare_parameters(node, params: list[Param]) -> dict[str, Any]:
    """Declare ``params`` read-only with their descriptions; return {name: value}.

    Raises:
        ParameterError: naming every parameter with a wrong type or a value its check rejects.
    """
    values: dict[str, Any] = {}
    errors: list[str] = []
    for p in params:
        desc = ParameterDescriptor(description=p.description, read_only=True)
        try:
            node.declare_parameter(p.name, p.default, desc)
        except ParameterException as exc:
            kind = type(p.default[0] if isinstance(p.default, list) else p.default)
            what = _TYPE_NAMES.get(kind, kind.__name__)
            if isinstance(p.default, list):
                what = f'a list of {what.split(" ", 1)[1]}'
            errors.append(f'parameter {p.name!r}: expected {what}: {exc}')
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


def stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def set_stamp(stamp: Time, ns: int) -> None:
    stamp.sec, stamp.nanosec = divmod(ns, 1_000_000_000)


def config_file(name: str) -> Path:
    """A file shipped in ``config/``: the source tree's (an editable install or a checkout being
    worked on), else the installed share directory (colcon / pip), as scene files are found."""
    src = Path(__file__).resolve().parents[2] / 'config' / name
    if src.is_file():
        return src
    try:
        from ament_index_python.packages import get_package_share_directory
        p = Path(get_package_share_directory('haptic_anfis')) / 'config' / name
        if p.is_file():
            return p
    except Exception:  # no ament index: the source tree's path, for a clear 'not found' later
        pass
    return src


def make_executor():
    """The executor measured fastest here: rclpy's EventsExecutor (drive it with spin_once)."""
    from rclpy.experimental import EventsExecutor
    return EventsExecutor()


def interrupted(context=None) -> bool:
    """True once rclpy's context was shut down (Ctrl-C / SIGTERM handled by rclpy)."""
    return not rclpy.ok(context=context)


def settle_gc() -> None:
    """Collect once, then move every object alive now (modules, compiled kernels, the mesh, the
    model) into the permanent generation: later collections walk only what the running loop
    allocates (measured: longest gen-0 pause 0.26 ms frozen, 0.87 ms not; bench_soak.py)."""
    import gc
    gc.collect()
    gc.freeze()


def run_node(factory: Callable[[], Any], args=None) -> int:
    """Init rclpy, build the node, spin it until shut down or ``node.finished``; 1 on bad params.

    Uses EventsExecutor with a ``spin_once(timeout_sec=...)`` loop (its ``spin()`` runs no
    callbacks with the rclpy wheels here, see DESIGN.md). Calls ``node.close()`` (if defined)
    before destroying the node. Once built, the node announces its status on ``session/status``
    (:class:`~haptic_anfis.nodes.session.Readiness`). Interrupted while starting (Ctrl-C or SIGTERM
    during a long compile), the node exits with code 0 and a one-line message, no traceback.
    """
    from rclpy.executors import ExternalShutdownException

    from .session import Readiness
    rclpy.init(args=args)
    node = executor = None
    code = 0
    try:
        try:
            node = factory()
        except (ParameterError, ValueError, OSError) as exc:
            if interrupted():
                return _interrupted_while_starting()
            print(f'error: {exc}', file=sys.stderr, flush=True)
            return 1
        except (KeyboardInterrupt, ExternalShutdownException):
            return _interrupted_while_starting()
        except Exception:
            if interrupted():  # e.g. "rcl node's context is invalid" after Ctrl-C
                return _interrupted_while_starting()
            raise
        try:
            node.readiness = Readiness(node)
            executor = make_executor()
            executor.add_node(node)
            settle_gc()
            while rclpy.ok() and not getattr(node, 'finished', False):
                executor.spin_once(timeout_sec=0.05)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except Exception:
            if not interrupted():
                raise
        code = int(getattr(node, 'exit_code', 0) or 0)
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
    except KeyboardInterrupt:  # a second Ctrl-C while shutting down
        pass
    finally:
        if node is not None:
            if hasattr(node, 'close'):
                node.close()
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def _interrupted_while_starting() -> int:
    print('interrupted while starting: exiting', file=sys.stderr, flush=True)
    return 0


def resolve_parameters(params: list[Param], node_name: str, params_files=(),
                       overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The values a node named ``node_name`` would get, without rclpy: defaults, then each YAML
    ``params_files`` (sections ``node_name`` and ``/**``, key ``ros__parameters``), then
    ``overrides``; typed and checked like :func:`declare_parameters`.

    Raises:
        ParameterError: unknown file, unknown parameter name, wrong type or a rejected value.
    """
    import yaml
    known = {p.name: p for p in params}
    values = {p.name: p.default for p in params}
    given: dict[str, Any] = {}
    for f in params_files:
        try:
            doc = yaml.safe_load(Path(f).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ParameterError(f'{f}: cannot read the parameter file: {exc}') from None
        for section in ('/**', node_name, '/' + node_name):
            sec = doc.get(section) if isinstance(doc, dict) else None
            if isinstance(sec, dict):
                given.update(sec.get('ros__parameters') or {})
    given.update(overrides or {})
    errors = []
    for name, v in given.items():
        p = known.get(name)
        if p is None:
            continue  # like rclpy: parameters a node does not declare are ignored
        want = type(p.default[0] if isinstance(p.default, list) and p.default else p.default)
        items = v if isinstance(p.default, list) else [v]
        if isinstance(p.default, list) != isinstance(v, list) or not all(
                type(x) is want or (want is float and type(x) is float) for x in items):
            errors.append(f'parameter {name!r}: expected {_TYPE_NAMES.get(want, want.__name__)}'
                          f'{" list" if isinstance(p.default, list) else ""}, got {v!r}')
            continue
        msg = p.check(v) if p.check is not None else None
        if msg:
            errors.append(f'parameter {name!r} = {v!r}: {msg}')
        values[name] = list(v) if isinstance(v, list) else v
    if errors:
        raise ParameterError(f'{node_name}: bad parameters: ' + '; '.join(errors))
    return values


def message_class(type_name: str):
    """'geometry_msgs/msg/PoseStamped' (or 'geometry_msgs/PoseStamped') -> the rclpy message class.

    Raises:
        ValueError: malformed name, or no such installed message package / type.
    """
    import importlib
    parts = type_name.strip('/').split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f'message type {type_name!r}: expected package/msg/Name')
    try:
        cls = getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError):
        raise ValueError(f'message type {type_name!r}: not installed (no {parts[0]}.{parts[1]}.'
                         f'{parts[2]} importable)') from None
    return cls
