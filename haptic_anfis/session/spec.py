"""A session description, built once from the command line, and the one argument helper that
builds it for ``sim``, ``launch`` and ``exam run``.

:class:`SessionSpec` says what runs (nodes, case, parameter files, recording, how long) and
nothing about how; the runners (:mod:`.one_process`, :mod:`.processes`) start it.
:data:`OPTIONS` is the one table of the session's command-line options: each row is a flag, its
argparse keywords, the commands that take it and the :class:`SessionSpec` field it fills (its
``dest``). Adding an option to every session command is one row here plus one field of
:class:`SessionSpec` (e.g. ``--view``: ``Option(('--view',), dict(action='store_true',
help=...))`` and ``view: bool = False``); the runners read the field.

ROS-free: the parameter check imports the node modules (for their declarations) only in
:meth:`SessionSpec.check`.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from ..cases.force_mapping import case_force_mapping
from ..cases.library import CASE_DIR_HELP, DEFAULT_CASE, case_node_arguments, library
from ..device.falcon import RATED_FORCE
from ..errors import HapticAnfisError
from ..nodes.parameter_files import (check_parameter_sources, parse_overrides,
                                     read_parameter_file, ros_args_sources)
from ..nodes.parameters import ParameterError, default_of
from ..nodes.registry import declared_parameters, node_parameters
from ..realtime.processes import GRAPH_PRIORITY, node_names
from ..resources import config_file
from ..view.app import check_port
from ..view.doors import load_token

__all__ = ['SessionSpec', 'SessionError', 'Option', 'OPTIONS', 'COMMANDS', 'ONE_PROCESS_NODES',
           'CASE_NODES', 'add_session_arguments', 'spec_from_args', 'recorder_settings']

#: the commands that run a session
COMMANDS = ('sim', 'launch', 'exam')
#: the nodes of the one-process graph (sim, exam run): the loop and its visualizer
ONE_PROCESS_NODES = ('falcon_driver', 'contact_detector', 'force_server', 'visualizer')
#: nodes that take the case parameters (--case / --random-case)
CASE_NODES = ('contact_detector', 'force_server', 'visualizer', 'examiner', 'web_view')
DEFAULT_LAUNCH_NODES = 'falcon_driver,contact_detector,force_server,visualizer'
#: parameters of the case nodes by which a session renders (or scores) another scene than its
#: case, or the default, when set to other than their defaults
SCENE_PARAMETERS = ('case', 'random_case_seed', 'mesh_path', 'mesh_unit', 'dome_radii',
                    'model_path', 'tumours', 'displacement_path', 'scene')


class SessionError(HapticAnfisError, ValueError):
    """The session's description is unusable (the message names the option and what was
    expected; one line per problem)."""


@dataclass(frozen=True)
class Option:
    """One command-line option of the session commands: ``flags`` and ``kwargs`` as given to
    ``argparse.add_argument``; ``commands`` that take it; per-command ``defaults`` / ``helps``
    replacing ``kwargs``' own; ``group``: the argparse group's title ('' = none)."""
    flags: tuple[str, ...]
    kwargs: Mapping[str, Any]
    commands: tuple[str, ...] = COMMANDS
    defaults: Mapping[str, Any] = field(default_factory=dict)
    helps: Mapping[str, str] = field(default_factory=dict)
    group: str = ''

    @property
    def dest(self) -> str:
        return self.kwargs.get('dest') or self.flags[0].lstrip('-').replace('-', '_')


_CASE = 'case (haptic-anfis cases list)'
_VIEW = "the trainee's screen in a browser (haptic-anfis view)"

#: The session commands' options, in help order.
OPTIONS: tuple[Option, ...] = (
    Option(('--nodes',), dict(default=DEFAULT_LAUNCH_NODES,
                              help=f'comma-separated nodes to start (default '
                                   f'{DEFAULT_LAUNCH_NODES})'), commands=('launch',)),
    Option(('--duration',), dict(type=float, default=None),
           defaults={'sim': 10.0, 'launch': 0.0},
           helps={'sim': 'seconds to run (default 10)',
                  'launch': 'stop the nodes this many seconds after the session is ready '
                            '(default 0 = at Ctrl-C)',
                  'exam': 'stop after this many seconds (default: when the trainee is done, at '
                          'most 300 s)'}),
    Option(('--params-file',), dict(action='append', default=[], metavar='YAML', dest='params_files',
                                    help='ROS 2 parameter file for the nodes (repeatable; keyed '
                                         'by node name, so the per-node YAMLs in config/ can all be '
                                         'given), e.g. config/falcon_driver.yaml; checked before '
                                         'any node starts'),
           helps={'exam': "ROS 2 parameter file for the nodes (repeatable; the exam sets the "
                          "driver's palpation_script and force_mode itself)"}),
    Option(('--record',), dict(metavar='BAG', default=None),
           helps={'sim': 'record every loop topic (pose, velocity, applied force, buttons, '
                         'contact, force command) to this new bag directory (rosbag2, MCAP)',
                  'launch': 'also start the recorder, writing this new bag directory (with the '
                            "session/status and session/events topics; a params file's recorder "
                            'topics are added, and what --record overrides is said)',
                  'exam': 'record the session (loop topics + marks) to this new bag directory'}),
    Option(('--no-viz',), dict(action='store_true', help='leave the visualizer out'),
           commands=('sim',)),
    Option(('--in-process',), dict(action='store_true',
                                   help="run the visualizer in the haptic loop's process too "
                                        "(default: in a process of its own, off the loop's "
                                        'interpreter lock)'), commands=('sim', 'exam'),
           helps={'exam': "the examiner in the loop's process (default: in a process of its "
                          "own, as sim's side nodes: off the servo thread's interpreter lock)"}),
    Option(('--recorder-process',), dict(action='store_true',
                                         help="with --record: the recorder in a process of its "
                                              "own (default: in the loop's process, which "
                                              'measured cheaper for the loop on 2 cores)'),
           commands=('sim',)),
    Option(('--case',), dict(default='', metavar='NAME',
                             help='run this case of the library (default: the default scene)'),
           helps={'exam': 'case of the library (haptic-anfis cases list: its model, surface and '
                          'lesions) or a scene file (its lesions, default model) (default: '
                          'default)'}, group=_CASE),
    Option(('--case-dir',), dict(default=None, metavar='DIR', help=CASE_DIR_HELP), group=_CASE),
    Option(('--random-case',), dict(action='store_true',
                                    help='draw a case with --seed; its name is not shown (for a '
                                         'blind session)'), commands=('sim', 'launch'),
           group=_CASE),
    Option(('--seed',), dict(type=int, default=None, help='seed of --random-case'),
           commands=('sim', 'launch'), group=_CASE),
    Option(('--domain-id',), dict(type=int, default=None,
                                  help='ROS_DOMAIN_ID for the nodes (default: inherited)'),
           commands=('launch',)),
    Option(('--localhost',), dict(action='store_true',
                                  help='discovery on this machine only '
                                       '(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)'),
           commands=('launch',)),
    Option(('--share-domain',), dict(action='store_true',
                                     help='start although another falcon driver, force server '
                                          'or examiner is already running on this ROS domain '
                                          '(default: refuse; two graphs on one domain corrupt '
                                          'each other)')),
    Option(('--log-dir',), dict(default=None,
                                help="write each node's output to DIR/<node>.log (default: this "
                                     'terminal)'), commands=('launch',)),
    Option(('--no-respawn',), dict(action='store_true',
                                   help='a node that exits on its own stops the launch (exit code '
                                        '1) instead of being restarted'), commands=('launch',)),
    Option(('--graph-pinning',),
           dict(choices=('auto', 'on', 'off'), default='auto',
                help='keep each node on the haptic path that runs under the normal scheduler on '
                     'one CPU, round robin: auto (default) where the servo loop is real-time, '
                     'so a busy machine cannot leave a node\'s thread runnable but unscheduled '
                     'for hundreds of ms; with the servo under the normal scheduler too the '
                     'pinned nodes cost it periods, so they are left free; on: always; off: '
                     'never'), commands=('launch',)),
    Option(('--node-sessions',),
           dict(choices=('each', 'one'), default='each',
                help='each (default): every node in a session of its own; one: the nodes share '
                     'one session of their own (the launcher re-runs itself in it), so where '
                     "the kernel shares the CPU between sessions (autogroups) the graph's share "
                     'is on every CPU its threads wake on. Measured once without real-time '
                     'priority beside 8 busy processes and the browser view, one left the '
                     'stretches without a model no shorter and cost the servo loop 14 %% of its '
                     'periods (docs/servo_loop.md). The servo process has a session of its own '
                     'either way'), commands=('launch',)),
    Option(('--max-restarts',), dict(type=int, default=3,
                                     help='restarts allowed per node before the launch gives up '
                                          '(default 3)'), commands=('launch',)),
    Option(('--enclave-root',), dict(default=None, metavar='ENCLAVE',
                                     help="SROS2: start each node with --enclave ENCLAVE/<node> "
                                          "(the launcher's own monitor with "
                                          'ENCLAVE/launch_monitor); security itself is switched '
                                          'on by ROS_SECURITY_KEYSTORE / ROS_SECURITY_ENABLE / '
                                          'ROS_SECURITY_STRATEGY'), commands=('launch',)),
    Option(('--view',), dict(action='store_true',
                             help="open the trainee's screen in a browser (the web_view node in "
                                  'a process of its own)'), group=_VIEW),
    Option(('--view-port',), dict(type=int, default=8080,
                                  help='TCP port of the page with --view (default 8080)'),
           group=_VIEW),
    Option(('--console-port',), dict(type=int, default=8081,
                                     help="TCP port of the instructor's console with --view "
                                          '(default 8081; bound to 127.0.0.1, behind a token '
                                          'printed at start)'),
           commands=('sim', 'launch'), group=_VIEW),
    Option(('--console-token-file',), dict(default='', metavar='FILE',
                                           help="with --view: the instructor console's token is "
                                                'the first line of FILE (default: '
                                                '$HAPTIC_ANFIS_CONSOLE_TOKEN, else a new random '
                                                'one)'),
           commands=('sim', 'launch'), group=_VIEW),
    Option(('--view-hold',), dict(type=float, default=None, metavar='S',
                                  help='with --view: serve the debrief this many seconds after '
                                       'the exam (default: until Ctrl-C)'),
           commands=('exam',), group=_VIEW),
    Option(('--graph-priority',), dict(type=int, default=GRAPH_PRIORITY, metavar='N',
                                       help='real-time priority (SCHED_FIFO 1-98) of the nodes '
                                            'that make the local models once they are ready '
                                            "(all but the view nodes; sim: the loop's process), "
                                            "below the driver's servo_priority (50), so a busy "
                                            'machine cannot starve them; 0 = the normal '
                                            'scheduler (use 0 with servo_priority 0). Needs '
                                            'CAP_SYS_NICE or an rtprio limit (ulimit -r); '
                                            'refused, they keep the normal scheduler and a line '
                                            f'says so (default {GRAPH_PRIORITY})')),
    Option(('--trace',), dict(default=None, metavar='NPZ',
                              help="keep the falcon driver's servo tick trace in this new file "
                                   '(every tick: time, probe, applied force, model status; '
                                   '`haptic-anfis loop NPZ` reports it again, --from S a window '
                                   'of it; a driver the launch restarts writes it again) '
                                   '(default: sim --json a temporary file, removed; launch: in '
                                   '--log-dir, else a temporary directory)'),
           commands=('sim', 'launch')),
    Option(('--ready-timeout',), dict(type=float, default=300.0,
                                      help='seconds to wait for the nodes to start and the first '
                                           'force command to reach the driver (default 300: a '
                                           'cold numba compile on a busy machine)'),
           commands=('sim', 'launch')),
)


@dataclass(frozen=True)
class SessionSpec:
    """What a session runs. Built by :func:`spec_from_args` (or directly, e.g. by a benchmark).

    Times in seconds. ``duration`` None: the command's own end (exam: the trainee is done).
    ``ros_args``: the user's extra rclpy arguments (``-p name:=value`` ...) for every node.
    ``scene``: a scene file whose lesions an exam scores (``--case FILE.yaml``).
    ``case_dir``: the user's own case folder (``--case-dir``; the command puts it in the
    environment before anything reads the library, so every node it starts sees it too).
    """
    command: str = 'sim'
    nodes: tuple[str, ...] = ONE_PROCESS_NODES
    case: str = ''
    case_dir: str | None = None
    random_case: bool = False
    seed: int | None = None
    scene: str = ''
    params_files: tuple[str, ...] = ()
    ros_args: tuple[str, ...] = ()
    record: str | None = None
    duration: float | None = None
    ready_timeout: float = 300.0
    no_viz: bool = False
    in_process: bool = False
    recorder_process: bool = False
    domain_id: int | None = None
    localhost: bool = False
    share_domain: bool = False
    log_dir: str | None = None
    no_respawn: bool = False
    graph_pinning: str = 'auto'
    node_sessions: str = 'each'
    max_restarts: int = 3
    enclave_root: str | None = None
    view: bool = False
    view_port: int = 8080
    console_port: int = 8081
    console_token_file: str = ''
    view_hold: float | None = None
    graph_priority: int = GRAPH_PRIORITY
    trace: str | None = None

    # -- derived ------------------------------------------------------------------------------
    @property
    def visualizer(self) -> bool:
        """The one-process graph draws (``visualizer`` in ``nodes`` and not ``--no-viz``)."""
        return 'visualizer' in self.nodes and not self.no_viz

    def case_arguments(self) -> list[str]:
        """``-p case:=NAME`` / ``-p random_case_seed:=N`` for the case-aware nodes ([] = none)."""
        if self.random_case:
            return ['-p', f'random_case_seed:={int(self.seed)}']
        return ['-p', f'case:={self.case}'] if self.case else []

    def user_parameter(self, node: str, key: str, default=None, shipped: bool = True):
        """The value the user gives ``key`` of ``node`` (the last of the parameter files' sections
        for it or for every node, then the ``-p`` overrides, as rcl applies them), else
        ``default``. ``shipped=False``: the package's own ``config/<node>.yaml`` does not count
        (its values are the defaults, written out)."""
        value = default
        own = Path(config_file(f'{node}.yaml')).resolve()
        for f in self.params_files:
            if not shipped and Path(f).resolve() == own:
                continue
            for section, k, v, _ in read_parameter_file(f):
                if k == key and section.rsplit('/', 1)[-1] in (node, '**'):
                    value = v
        _, overrides, _ = ros_args_sources(self.user_ros_args())
        for target, v, _ in overrides:
            n, _, k = target.rpartition(':')
            if k == key and n in ('', node):
                value = v
        return value

    def force_mapping(self):
        """The driver's :class:`~haptic_anfis.cases.force_mapping.ForceMapping` for the
        session's case (the drawn one for ``--random-case``; the default case without one or
        with a scene file, whose forces the default model renders), against the driver's
        ``max_force``; None without a driver in the session or when the user sets
        ``force_scale`` (on the command line or in a parameter file other than the shipped
        ``config/falcon_driver.yaml``, whose 1.0 is the node's default written out): that value
        is rendered."""
        if 'falcon_driver' not in self.nodes or self.user_parameter(
                'falcon_driver', 'force_scale', shipped=False) is not None:
            return None
        lib = library()
        case = (lib.random(int(self.seed)) if self.random_case
                else lib.get(self.case or DEFAULT_CASE))
        max_force = self.user_parameter('falcon_driver', 'max_force', RATED_FORCE)
        return case_force_mapping(case, float(max_force))

    def driver_arguments(self) -> list[str]:
        """``-p falcon_driver:force_scale:=S`` from :meth:`force_mapping` ([] = none)."""
        m = self.force_mapping()
        return [] if m is None else ['-p', f'falcon_driver:force_scale:={m.force_scale!r}']

    def recorder_case_arguments(self) -> list[str]:
        """The recorder's case parameter, which it writes into the bag: the nodes' (see
        :meth:`case_arguments`), or ``case:=default`` when nothing changed the default scene (no
        case, no scene file, no parameter file or ``-p`` override setting one of
        :data:`SCENE_PARAMETERS` of a case node to other than its default); else none (the bag
        then does not name its case: the nodes may render other files)."""
        if self.case or self.random_case:
            return self.case_arguments()
        return [] if self.scene or self._scene_parameters_set() else ['-p', 'case:=default']

    def _scene_parameters_set(self) -> bool:
        """A parameter file or ``-p`` override sets one of :data:`SCENE_PARAMETERS` of a case
        node (or of every node) to other than its default (or the overrides name a parameter
        file: not looked into)."""
        files, overrides, _ = ros_args_sources(self.user_ros_args())
        if files:
            return True
        entries = [(section.rsplit('/', 1)[-1], key, v) for f in self.params_files
                   for section, key, v, _ in read_parameter_file(f)]
        for target, v, _ in overrides:   # '-p [node:]name:=value', the value read as rcl does
            node, _, key = target.rpartition(':')
            entries.append((node or '**', key, v))
        return any(_changes_scene(node, key, v) for node, key, v in entries)

    def view_arguments(self, controls: bool) -> list[str]:
        """The web_view node's own ``-p`` arguments (its port; ``controls``: the instructor's
        console, on its port, with its token file; the driver's ``max_force`` and a
        ``force_scale`` the user set, which a case chosen on the console then leaves alone)."""
        args = ['-p', f'port:={int(self.view_port)}',
                '-p', f"controls:={'true' if controls else 'false'}"]
        if 'falcon_driver' in self.nodes:
            max_force = self.user_parameter('falcon_driver', 'max_force')
            if max_force is not None:
                args += ['-p', f'max_force:={float(max_force)!r}']
            scale = self.user_parameter('falcon_driver', 'force_scale', shipped=False)
            if scale is not None:
                args += ['-p', f'force_scale:={float(scale)!r}']
        if controls:
            args += ['-p', f'console_port:={int(self.console_port)}']
            if self.console_token_file:
                args += ['-p', f'console_token_file:={Path(self.console_token_file).resolve()}']
        return args

    def params_arguments(self) -> list[str]:
        """``--params-file ABS`` for every parameter file (absolute: a node may run elsewhere)."""
        return [a for f in self.params_files for a in ('--params-file', str(Path(f).resolve()))]

    def user_ros_args(self) -> list[str]:
        """The user's ``--ros-args`` tail, without ``--`` / ``--ros-args`` markers."""
        return [a for a in self.ros_args if a not in ('--', '--ros-args')]

    # -- checks -------------------------------------------------------------------------------
    def check(self, check_parameters: bool = True) -> 'SessionSpec':
        """Check everything that can be checked before a node starts; returns self.

        Raises:
            SessionError: bad duration / timeout / restarts, an existing ``record`` directory, a
                missing parameter file, an unknown node; CaseError: an unknown case;
            ParameterError: the parameter files / overrides (one line per problem:
                file:line, node, parameter, what was given and what is expected).
        """
        unknown = [n for n in self.nodes if n not in node_names()]
        if unknown or not self.nodes:
            raise SessionError(f'--nodes: unknown node(s) {unknown or list(self.nodes)!r}; '
                               f'known: {", ".join(node_names())}')
        if self.duration is not None and not (self.duration >= 0 and math.isfinite(self.duration)
                                              and (self.duration > 0 or self.command == 'launch')):
            raise SessionError(f'--duration: expected > 0 s, got {self.duration}')
        if not (self.ready_timeout >= 0 and math.isfinite(self.ready_timeout)):
            raise SessionError(f'--ready-timeout: expected >= 0 s, got {self.ready_timeout}')
        if self.max_restarts < 0:
            raise SessionError(f'--max-restarts: expected >= 0, got {self.max_restarts}')
        if not 0 <= self.graph_priority <= 98:
            raise SessionError(f'--graph-priority: expected 0 (the normal scheduler) to 98 '
                               f"(below the driver's servo thread), got {self.graph_priority}")
        for f in self.params_files:
            if not Path(f).is_file():
                raise SessionError(f'--params-file {f}: no such file')
        if self.record and Path(self.record).exists():
            raise SessionError(f'--record {self.record}: exists already; a recording needs a new '
                               'directory')
        if self.trace is not None:
            t = Path(self.trace)
            if t.suffix != '.npz' or t.exists() or not t.parent.is_dir():
                raise SessionError(f'--trace {self.trace}: expected a new .npz file in an '
                                   'existing directory')
            if 'falcon_driver' not in self.nodes:
                raise SessionError(f'--trace {self.trace}: the falcon driver writes it; '
                                   f'--nodes has none ({", ".join(self.nodes)})')
        self._check_case()
        if self.view:   # viser would move to the next free port and the URL shown be wrong
            check_port(self.view_port, flag='--view-port')
            if self.command != 'exam':   # the instructor's console (exam run has none)
                if self.console_port == self.view_port:
                    raise SessionError(f'--console-port {self.console_port}: the same as '
                                       "--view-port; the console needs a port of its own")
                check_port(self.console_port, flag='--console-port')
                if self.console_token_file:
                    load_token(self.console_token_file)   # DoorError: one line naming it
        if check_parameters:
            self.check_parameters()
        return self

    def _check_case(self) -> None:
        if self.command == 'exam':  # exam run resolves its --case (a case or a scene file)
            return
        case_node_arguments(self)  # the spec has the case options' fields: the same checks

    def check_parameters(self, nodes: Sequence[str] | None = None) -> None:
        """The parameter files and the user's ``-p`` overrides against the declarations of
        ``nodes`` (default: the session's, plus the recorder when recording).

        Raises:
            ParameterError: one line per problem.
        """
        names = list(nodes or self.nodes)
        if self.record and 'recorder' not in names:
            names.append('recorder')
        errors = check_parameter_sources(declared_parameters(), self.params_files,
                                         parse_overrides(self.user_ros_args()), nodes=names)
        if errors:
            raise ParameterError('\n'.join(errors))


def add_session_arguments(parser: argparse.ArgumentParser, command: str) -> None:
    """Add the session options of ``command`` ('sim', 'launch' or 'exam') to ``parser``."""
    if command not in COMMANDS:
        raise ValueError(f'command {command!r}: expected one of {", ".join(COMMANDS)}')
    groups: dict[str, Any] = {}
    for opt in OPTIONS:
        if command not in opt.commands:
            continue
        kw = dict(opt.kwargs)
        if command in opt.defaults:
            kw['default'] = opt.defaults[command]
        if command in opt.helps:
            kw['help'] = opt.helps[command]
        target = parser
        if opt.group:
            target = groups.get(opt.group) or groups.setdefault(
                opt.group, parser.add_argument_group(opt.group))
        target.add_argument(*opt.flags, **kw)


def spec_from_args(args: argparse.Namespace, command: str, **fields) -> SessionSpec:
    """The :class:`SessionSpec` of parsed ``args`` (every :data:`OPTIONS` dest that is a field),
    with ``fields`` on top (a command's own choices, e.g. ``nodes``)."""
    names = {f.name for f in dataclasses.fields(SessionSpec)}
    values: dict[str, Any] = {'command': command}
    for opt in OPTIONS:
        if command in opt.commands and opt.dest in names and hasattr(args, opt.dest):
            values[opt.dest] = getattr(args, opt.dest)
    if isinstance(values.get('nodes'), str):
        values['nodes'] = tuple(n.strip() for n in values['nodes'].split(',') if n.strip())
    if 'ros_args' in vars(args):
        values['ros_args'] = tuple(args.ros_args or ())
    values.update(fields)
    for k in ('params_files', 'ros_args', 'nodes'):
        if k in values:
            values[k] = tuple(values[k])
    return SessionSpec(**values)


def _changes_scene(node: str, key: str, value) -> bool:
    """Setting ``key`` to ``value`` on ``node`` ('**': every node) changes the scene a case
    node renders or scores: one of :data:`SCENE_PARAMETERS`, not its default."""
    if key not in SCENE_PARAMETERS:
        return False
    for n in (CASE_NODES if node == '**' else (node,) if node in CASE_NODES else ()):
        if value != default_of(node_parameters(n), key, value):
            return True
    return False


def recorder_settings(spec: SessionSpec, topics: Sequence[str]) -> tuple[list[str], list[str]]:
    """(topics, notes): what the session's recorder records. The session's ``topics``, plus any
    ``topics`` a parameter file gives the recorder (merged, not silently overridden); ``notes``
    say what the session's settings override (``--record`` over a file's ``output``)."""
    merged = list(topics)
    notes: list[str] = []
    for f in spec.params_files:
        for section, key, v, where in read_parameter_file(f):
            if section.rsplit('/', 1)[-1] not in ('recorder', '**'):
                continue
            if key == 'topics' and isinstance(v, list):
                added = [t for t in v if t not in merged and '/' + str(t).lstrip('/') not in
                         merged and str(t).lstrip('/') not in merged]
                merged += added
                if added:
                    notes.append(f'recording the topics of {where} too: {", ".join(added)}')
            elif key == 'output' and v:
                notes.append(f'--record {spec.record} overrides the recorder output {v!r} of '
                             f'{where}')
    return merged, notes
