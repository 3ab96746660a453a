"""Start the package's nodes as separate processes (what ``ros2 launch`` would do; not available
here), with their scheduling: real-time priority and CPU pinning of a node graph, a session of
its own. Pure process management, no ROS imports: used by ``haptic-anfis launch``, the
multi-process loop benchmark and the cross-process tests.
"""
from __future__ import annotations

import ctypes
import functools
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import IO, Mapping, Sequence

from . import rtkit
from .scheduling import is_realtime, realtime_priority, realtime_refused, to_normal_scheduler

#: The nodes' console scripts sit next to the interpreter in a virtualenv (bin/); on a colcon
#: install they are in lib/haptic_anfis/ instead, and nodes are started as modules.
BIN = Path(sys.executable).parent
NODES_DIR = Path(__file__).resolve().parent.parent / 'nodes'  # haptic_anfis/nodes
#: Set by a session runner in its node processes' environment: the session checked the parameters
#: against every one of its nodes (a global key only another node declares is then no error in
#: the node's own check, ``haptic_anfis.nodes.runtime.check_node_arguments``).
SESSION_CHECKED = 'HAPTIC_ANFIS_SESSION_CHECKED'
#: Set by a session runner for a RESTARTED node when the session records: the name of the
#: recorder node; the node holds its output until the recorder has matched its publishers
#: (``haptic_anfis.nodes.runtime.hold_until_recorder_matched``), so the bag misses none of it.
HOLD_FOR_RECORDER = 'HAPTIC_ANFIS_HOLD_FOR_RECORDER'
#: Set beside :data:`HOLD_FOR_RECORDER`: the topics that recorder records, comma-separated.
RECORDED_TOPICS = 'HAPTIC_ANFIS_RECORDED_TOPICS'


@functools.lru_cache(maxsize=1)
def node_names() -> tuple[str, ...]:
    """The package's nodes: modules of haptic_anfis.nodes that run as ``python -m``."""
    return tuple(sorted(f.stem for f in NODES_DIR.glob('*.py')
                        if "__name__ == '__main__'" in f.read_text()))


def node_env(domain_id: int | None = None, localhost: bool = True,
             base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for a node process: this interpreter's prefix as the ament prefix (so the
    package's share/ files are found), unbuffered output, and optionally a ROS domain id and
    localhost-only discovery. The ROS wheels' bootstrap marker is dropped so that each child
    bootstraps its own environment."""
    env = {k: v for k, v in (os.environ if base is None else base).items()
           if k != '_ROS_WHEELS_BOOTSTRAP_COMPLETE'}
    env.update(AMENT_PREFIX_PATH=str(Path(sys.executable).parents[1]), PYTHONUNBUFFERED='1')
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(int(domain_id))
    if localhost:
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return env


def _stop_with_parent() -> None:
    """In the child before exec (Linux): SIGINT when the starting process dies, so a node is
    never left running (a recorder recording forever) after a launcher was killed with
    ``kill -9``; SIGINT, as Ctrl-C, lets it zero the force / close its bag."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGINT)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: nodes outlive a killed launcher
        pass


#: CPU priority of the side nodes (nice): they yield the cores to the loop's threads
SIDE_NICE = 10

#: Nodes drawn for a person, never on the haptic path: at :data:`SIDE_NICE` in every layout.
VIEW_NODES = ('visualizer', 'web_view')


#: SCHED_FIFO priority of the graph's nodes on the haptic path (every node but the view nodes;
#: in ``sim``, the loop's whole process), below the servo thread's (falcon_driver's
#: ``servo_priority``, 50): the local models come from them. Under the normal scheduler a busy
#: machine starves them even where the servo thread itself is real-time: beside 8 busy
#: processes and the browser view on 2 cores, ``sim`` with the servo at SCHED_FIFO 50 had its
#: models expire (dropouts to 0 N mid-press); with the graph at SCHED_FIFO 10 as well, none
#: (``bench/bench_servo_load.py --busy 8 --view --configs sim:50,sim:50:10``).
#: Event-driven nodes: they sleep between messages, and Linux keeps 5 % of each second for the
#: normal scheduler whatever real-time threads do (``/proc/sys/kernel/sched_rt_runtime_us``).
GRAPH_PRIORITY = 10


def _threads(pid: int | None = None) -> list[int]:
    try:
        return [int(t) for t in os.listdir(f'/proc/{pid or "self"}/task')]
    except FileNotFoundError:  # the process has ended
        return []
    except OSError:  # not Linux: the calling thread only
        return [0] if pid is None else []


def _thread_names(pid: int | None = None) -> dict[int, str]:
    """{tid: name} of every thread of process ``pid`` (None: this one), the names the system
    shows (``top -H``); a thread that ended meanwhile is left out."""
    names = {}
    for tid in _threads(pid):
        try:
            names[tid] = Path(f'/proc/{pid or "self"}/task/{tid}/comm').read_text().strip()
        except OSError:  # the thread has ended
            continue
    return names


def set_graph_priority(priority: int, pid: int | None = None) -> str:
    """Schedule every thread of process ``pid`` (None: this one) SCHED_FIFO at ``priority``
    (0: leave them as they are); the threads it starts later inherit it (the processes it
    starts with :func:`start_node` do not). A thread already real-time at ``priority`` or above
    keeps its own (the servo thread). Call it once the process is ready: a cold numba compile
    at real-time priority would hold a core for minutes. Returns what was done, in words, for
    the log.

    Refused (no CAP_SYS_NICE, no rtprio limit: a trainee's account), the threads that carry the
    haptic path (:func:`haptic_path_threads`) ask rtkit for SCHED_RR instead, as the servo's
    threads do (:func:`_graph_from_rtkit`); refused by rtkit too, every thread keeps the normal
    scheduler and the words say how to allow it."""
    if priority <= 0:
        return 'normal scheduler (graph priority 0)'
    done = []
    for tid in _threads(pid):
        try:
            if realtime_priority(tid) >= priority:
                continue
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(int(priority)))
            done.append(tid)
        except ProcessLookupError:  # the thread has ended
            continue
        except (OSError, AttributeError) as exc:  # EPERM without the right; not Linux
            for t in done:
                _normal(t)
            return _graph_from_rtkit(priority, pid, exc)
    return f'SCHED_FIFO priority {priority}'


#: Threads that carry the haptic path, by the names their libraries give them: Fast DDS's
#: receive threads (``dds.udp.PORT``) and the driver's servo bridge; with the process's main
#: thread (its executor).
HAPTIC_PATH_THREADS = ('dds.udp.', 'servo-bridge')

#: rtkit's soft run-time limit for a graph node, as a share of its hard one: a thread that
#: computes this long at real-time priority without blocking gets SIGXCPU
#: (:func:`guard_realtime_time`) before the hard limit's SIGKILL.
RTTIME_SOFT_SHARE = 0.5


def haptic_path_threads(pid: int | None = None) -> list[int]:
    """The threads of process ``pid`` (None: this one) that carry the haptic path: its main
    thread (the executor: callbacks run there) and those named in :data:`HAPTIC_PATH_THREADS`.

    Why not every thread, as with SCHED_FIFO: rtkit serves at most 25 threads per user and 25
    requests per 20 s (its defaults), and a node has a dozen threads, most asleep for good
    (BLAS workers, discovery)."""
    main = pid or os.getpid()
    return [tid for tid, name in _thread_names(pid).items()
            if tid == main or name.startswith(HAPTIC_PATH_THREADS)]


def _graph_from_rtkit(priority: int, pid: int | None, refused: BaseException) -> str:
    """SCHED_FIFO ``priority`` was ``refused`` for process ``pid``: ask rtkit for SCHED_RR for
    its haptic-path threads, with the soft run-time limit below rtkit's; the words for the
    log."""
    tids = haptic_path_threads(pid)
    if not tids:  # the process has ended
        return realtime_refused(priority, refused)
    try:
        granted, failed = rtkit.make_threads_realtime(priority, tids, pid,
                                                      soft_share=RTTIME_SOFT_SHARE)
    except rtkit.RealtimeKitError as kit:
        return realtime_refused(priority, refused, kit)
    if len(failed) == len(tids):
        return realtime_refused(priority, refused,
                                rtkit.RealtimeKitError(next(iter(failed.values()))))
    words = (f'SCHED_RR priority {granted} from rtkit for {len(tids) - len(failed)} of its '
             f'threads (executor, DDS receive, servo bridge), in place of SCHED_FIFO {priority}')
    if failed:
        words += f'; {len(failed)} not raised ({next(iter(failed.values()))})'
    return words


def graph_cores(names: Sequence[str], cpus: Sequence[int] | None = None) -> dict[str, int]:
    """{node: the one CPU its threads are kept on}, round robin over ``cpus`` (None: the CPUs
    this process may use) in the order of ``names``; {} with fewer than two CPUs (nothing to
    choose). Why one CPU per node (docs/sessions.md): with autogroups a node in a
    session of its own gets its session's share on a CPU in proportion to the load it has there,
    so a thread of it woken on the CPU where it has little load (a DDS receive thread, while
    the executor thread runs on the other) got almost no share beside busy processes and waited
    runnable longer than the driver's ``model_hold_time``; on one CPU the node's whole share is
    where its threads are."""
    if cpus is None:
        try:
            cpus = sorted(os.sched_getaffinity(0))
        except (AttributeError, OSError):  # not Linux
            return {}
    if len(cpus) < 2:
        return {}
    return {n: cpus[i % len(cpus)] for i, n in enumerate(names)}


def keep_on_cpu(pid: int, cpu: int) -> str:
    """Every thread of process ``pid`` onto CPU ``cpu`` only (the threads it starts later
    inherit it); returns what was done, in words. A process's own threads need no right; a
    refusal (or a process that ended) is said, not raised."""
    done = 0
    for tid in _threads(pid):
        try:
            os.sched_setaffinity(tid, {cpu})
            done += 1
        except ProcessLookupError:  # the thread has ended
            continue
        except (OSError, AttributeError) as exc:
            return f'threads not kept on CPU {cpu} ({exc.__class__.__name__}: {exc})'
    return f'threads kept on CPU {cpu}' if done else 'no thread to keep on a CPU'


#: Names of the servo loop's threads (``realtime.scheduling.name_thread``): the tick workers and the
#: real Falcon's device loop, on threads of the driver or in its servo process.
SERVO_THREADS = ('servo-tick', 'servo-device')


def servo_realtime(pid: int) -> bool | None:
    """Whether the servo loop of the falcon driver process ``pid`` runs real-time (SCHED_FIFO,
    or SCHED_RR from rtkit): any thread named as a servo thread (:data:`SERVO_THREADS`) in the
    process or in a process it started (the servo process); None where none is found (the loop
    not started yet, or not Linux)."""
    found = False
    for p in (pid, *_children(pid)):
        for tid, name in _thread_names(p).items():
            if name.startswith(SERVO_THREADS):
                if realtime_priority(tid) > 0:
                    return True
                found = True
    return False if found else None


def _children(pid: int) -> list[int]:
    """The processes that process ``pid``'s threads started (Linux's ``children`` files)."""
    out = []
    for tid in _threads(pid):
        try:
            out += map(int, Path(f'/proc/{pid}/task/{tid}/children').read_text().split())
        except OSError:
            continue
    return out


def _normal(tid: int) -> None:
    to_normal_scheduler(tid)


def leave_realtime() -> int:
    """Every real-time thread of this process but the servo's (:data:`SERVO_THREADS`) back to
    the normal scheduler; returns how many. For what computes long without blocking where a
    thread raised through rtkit would meet its run-time limit: a node's shutdown (the driver
    writes its tick trace), ``sim``'s stop (what :func:`set_graph_priority` raised) and
    :func:`guard_realtime_time`'s handler."""
    n = 0
    for tid, name in _thread_names().items():
        if not name.startswith(SERVO_THREADS) and realtime_priority(tid) > 0:
            _normal(tid)
            n += 1
    return n


def guard_realtime_time() -> None:
    """Catch SIGXCPU in this process (call it from the main thread): a thread of it ran at
    real-time priority for rtkit's soft run-time limit without blocking. Every real-time thread
    of the process but the servo's then goes back to the normal scheduler and standard error (the
    node's log) gets one line; without this handler SIGXCPU would end the node, and the hard
    limit's SIGKILL would come next. A node that never asked rtkit never gets the signal.

    Why: a graph node raised through rtkit (:func:`_graph_from_rtkit`) must never compute for
    long at real-time priority; a case switch steps off it (``realtime.scheduling.off_realtime``), and
    anything not foreseen is caught here instead of killing the node mid-session."""
    def demote(signum, frame) -> None:
        n = leave_realtime()
        ran = 'SIGXCPU'
        hard = resource.getrlimit(resource.RLIMIT_RTTIME)[1]
        if hard != resource.RLIM_INFINITY:  # the kernel raised the soft limit by 1 s: lower it
            soft = int(hard * RTTIME_SOFT_SHARE)
            resource.setrlimit(resource.RLIMIT_RTTIME, (soft, hard))
            ran = (f'a thread ran {soft / 1e3:g} ms at real-time priority without blocking '
                   '(RLIMIT_RTTIME)')
        print(f'warning: {ran}: {n} threads of this process back to the normal scheduler',
              file=sys.stderr, flush=True)
    try:
        signal.signal(signal.SIGXCPU, demote)
    except (AttributeError, ValueError, OSError):  # not POSIX; not the main thread
        pass


def _in_child(stop_with_parent: bool, nice: int) -> None:
    if stop_with_parent:
        _stop_with_parent()
    if _realtime():
        _normal(0)  # not inherited from a real-time parent (sim's graph): raised when ready
    if nice:
        os.nice(nice)


def start_node(name: str, ros_args: Sequence[str] = (), env: Mapping[str, str] | None = None,
               log: IO | int | None = None, cwd: str | os.PathLike | None = None,
               own_session: bool = False, nice: int = 0,
               stop_with_parent: bool | None = None) -> subprocess.Popen:
    """Start node ``name`` with ``--ros-args ros_args``: its console script when it sits next to
    this interpreter, else ``python -m haptic_anfis.nodes.<name>``. Its stdout and stderr go to
    ``log`` (a file object, ``subprocess.DEVNULL``, or inherited). ``own_session``: in its own
    session, so a Ctrl-C at the terminal reaches only the launcher, which stops the nodes in
    order (the driver first) instead of all at once. ``stop_with_parent`` (default: as
    ``own_session``): the node gets SIGINT if the launcher dies (Linux), for a node that no
    terminal signal reaches (a session of its own, or a launcher's that has no terminal).
    ``nice`` > 0 lowers the node's CPU priority (a node off the haptic loop yields the cores to
    it). Where the kernel
    groups processes by session (autogroups, ``/proc/sys/kernel/sched_autogroup_enabled``) a nice
    value counts only between the processes of one session, so a node in a session of its own
    keeps its session's share; lowering the session's weight instead (``/proc/<pid>/autogroup``)
    was tried and made a 1 kHz loop in another session lose periods: not done.
    The node starts under the normal scheduler also when this process is real-time (sim's graph
    after :func:`set_graph_priority`); :meth:`Supervisor.raise_priority` raises it once ready."""
    if name not in node_names():
        raise ValueError(f'unknown node {name!r}; known: {", ".join(node_names())}')
    exe = BIN / name
    cmd = [str(exe)] if exe.exists() else [sys.executable, '-m', f'haptic_anfis.nodes.{name}']
    cmd += ['--ros-args', *ros_args] if ros_args else []
    stop = own_session if stop_with_parent is None else stop_with_parent
    return subprocess.Popen(cmd, env=dict(env) if env is not None else node_env(), cwd=cwd,
                            start_new_session=own_session,
                            preexec_fn=functools.partial(_in_child, stop, nice)
                            if stop or nice or _realtime() else None,
                            stdout=log, stderr=subprocess.STDOUT if log is not None else None)


def stop_node(p: subprocess.Popen, timeout: float = 10.0, sig: int = signal.SIGINT) -> int:
    """Ask a node to stop as Ctrl-C would (SIGINT: nodes zero the force and close their bags),
    kill it if it has not exited after ``timeout`` seconds; returns its exit code. ``sig``
    SIGTERM suits a node still importing (before rclpy handles signals SIGINT would print a
    KeyboardInterrupt traceback; SIGTERM ends it quietly, and once rclpy is up both are handled
    alike)."""
    if p.poll() is None:
        p.send_signal(sig)
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(5.0)
    return p.returncode


def _realtime() -> bool:
    return is_realtime()


class Supervisor:
    """The launched node processes and their restarts (no ROS; ``haptic-anfis launch``).

    ``start(name, args)`` starts a node and remembers how; :meth:`dead` lists nodes that exited on
    their own; :meth:`restart` starts one again with the same arguments (``rename`` may adjust
    them, e.g. a new bag directory for the recorder) while at most ``max_restarts`` restarts per
    node are allowed. ``log_dir``: each node's output goes to ``DIR/<node>.log`` (appended to on a
    restart), else to ``stream`` (a file object; None = this terminal's standard output). ``nice``:
    as :func:`start_node`'s, for every node, or per node name ({name: nice}; others 0); by
    default the view nodes (:data:`VIEW_NODES`) at :data:`SIDE_NICE`, the others at 0.
    :meth:`raise_priority` puts the nodes on the haptic path (all but the view nodes) at a
    real-time priority once they are ready.
    """

    def __init__(self, env: Mapping[str, str], log_dir: Path | None = None,
                 max_restarts: int = 3, stream: IO | None = None,
                 nice: int | Mapping[str, int] | None = None):
        if max_restarts < 0:
            raise ValueError(f'max_restarts: expected >= 0, got {max_restarts}')
        self.env, self.log_dir, self.max_restarts = dict(env), log_dir, max_restarts
        self.stream = stream
        self.nice = {n: SIDE_NICE for n in VIEW_NODES} if nice is None else nice
        self.raised: dict[str, int] = {}  # node: the pid raised (a restart is raised again)
        #: {node: its CPU} for the nodes on the haptic path, when they run under the normal
        #: scheduler (:meth:`raise_priority`); set by the session from its node order
        self.cores: dict[str, int] = {}
        #: 'auto': keep a node on its CPU in :attr:`cores` where the servo loop is real-time (or
        #: its scheduling is not known); 'on': always (``launch --graph-pinning``)
        self.pinning = 'auto'
        #: every node in a session of its own (True), or in this launcher's (False: the
        #: launcher leads a session of its own; ``launch --node-sessions``)
        self.own_sessions = True
        self.procs: dict[str, subprocess.Popen] = {}
        self.args: dict[str, list[str]] = {}
        self.first_args: dict[str, list[str]] = {}
        self.started_at: dict[str, float] = {}
        self.restarts: dict[str, int] = {}
        self.logs: dict[str, IO] = {}

    def start(self, name: str, args: Sequence[str] = (), env: Mapping[str, str] | None = None
              ) -> subprocess.Popen:
        log = self.stream
        if self.log_dir is not None:
            log = self.logs.get(name) or (self.log_dir / f'{name}.log').open('w')
            self.logs[name] = log
        p = start_node(name, list(args), env={**self.env, **(env or {})}, log=log,
                       own_session=self.own_sessions, stop_with_parent=True,
                       nice=self.nice if isinstance(self.nice, int) else self.nice.get(name, 0))
        self.procs[name], self.args[name] = p, list(args)
        self.first_args.setdefault(name, list(args))
        self.started_at[name] = time.monotonic()
        self.restarts.setdefault(name, 0)
        return p

    def raise_priority(self, priority: int, names: Sequence[str]) -> dict[str, str]:
        """Every node of ``names`` not raised yet (since its last start), but the view nodes, at
        SCHED_FIFO ``priority`` (:func:`set_graph_priority`); where that leaves it under the
        normal scheduler (``priority`` 0, or refused), its threads kept on its CPU in
        :attr:`cores`, if it has one there (:func:`keep_on_cpu`) and the servo loop is
        real-time; {node: what was done}.

        Why only then: kept on one CPU, a node's whole share is where its threads are, which
        removed the models' long stalls beside busy processes with the servo real-time (rtkit);
        with the servo under the normal scheduler too, the pinned nodes took that share from the
        servo's tick workers on their CPU, and the loop lost more periods and had longer gaps
        than with the nodes free (interleaved runs, docs/sessions.md)."""
        servo_rt: list[bool | None] = []  # read once, and only when a node is to be pinned

        def pin(pid: int, cpu: int) -> str:
            if not servo_rt:
                driver = self.procs.get('falcon_driver')
                servo_rt.append(True if self.pinning == 'on' or driver is None
                                else servo_realtime(driver.pid))
            if servo_rt[0] is False:
                return 'threads left free: the servo loop is under the normal scheduler too'
            return keep_on_cpu(pid, cpu)
        done = {}
        for n in names:
            p = self.procs.get(n)
            if n in VIEW_NODES or p is None or self.raised.get(n) == p.pid \
                    or p.poll() is not None:
                continue
            what = set_graph_priority(priority, p.pid)
            self.raised[n] = p.pid
            if n in self.cores and not (priority > 0 and realtime_priority(p.pid) >= priority):
                what += '; ' + pin(p.pid, self.cores[n])
            if priority > 0 or '; threads' in what:
                done[n] = what
        return done

    def dead(self) -> list[tuple[str, int]]:
        """(name, exit code) of every node that has exited (and was not restarted since)."""
        return [(n, p.returncode) for n, p in self.procs.items() if p.poll() is not None]

    def may_restart(self, name: str) -> bool:
        return self.restarts.get(name, 0) < self.max_restarts

    def restart(self, name: str, rename=None, env: Mapping[str, str] | None = None
                ) -> subprocess.Popen:
        """Start ``name`` again (``rename(args, n) -> args`` for restart number ``n``, applied
        to the FIRST start's arguments: names do not nest, ``X.restart2`` follows
        ``X.restart1``); ``env``: variables added for this start."""
        self.restarts[name] = n = self.restarts.get(name, 0) + 1
        first = self.first_args.get(name, self.args[name])
        args = list(first) if rename is None else rename(first, n)
        if self.log_dir is not None:
            self.logs[name].write(f'\n--- restart {n} ---\n')
            self.logs[name].flush()
        return self.start(name, args, env=env)

    def stop_all(self, order: Sequence[str], starting: Sequence[str] = ()) -> dict[str, int]:
        """Stop every node, in ``order`` first (SIGINT, then kill after a timeout); nodes in
        ``starting`` (no status yet: maybe still importing) get SIGTERM, and their exit by that
        signal counts as a clean stop (code 0)."""
        names = [n for n in order if n in self.procs] + [n for n in self.procs if n not in order]
        codes = {}
        for n in names:
            sig = signal.SIGTERM if n in starting else signal.SIGINT
            code = stop_node(self.procs[n], sig=sig)
            codes[n] = 0 if (n in starting and code == -signal.SIGTERM) else code
        for f in self.logs.values():
            f.close()
        return codes


def _rerun_child() -> None:
    _stop_with_parent()
    # SIGINT is how this process stops it: a SIGINT ignored here (a shell's background job)
    # must not be ignored there
    signal.signal(signal.SIGINT, signal.SIG_DFL)


#: Set in the environment of a command re-run by :func:`rerun_in_own_session`.
OWN_SESSION = 'HAPTIC_ANFIS_OWN_SESSION'


def rerun_in_own_session(argv: Sequence[str]) -> int | None:
    """Run ``haptic-anfis ARGV`` again in a session of its own and return its exit code; None
    (nothing done) in that re-run itself, or when this process leads a session already.

    Why (``sim``): where the kernel groups processes by session (autogroups), the
    CPU is shared between sessions first, and the one-process graph shared its terminal's
    session with whatever else runs there: beside 8 busy processes of that session and the
    browser view, without real-time priority, ``sim`` lost periods, the force error grew and
    the force rippled; in a session of its own far less (docs/servo_loop.md). This process stays in the terminal's session and
    waits: Ctrl-C, SIGTERM and SIGHUP reach it and are passed on as SIGINT (the re-run stops
    the device at zero force first and closes its bag); killed, the re-run gets SIGINT all the
    same (PR_SET_PDEATHSIG)."""
    if os.environ.get(OWN_SESSION) or os.getsid(0) == os.getpid():
        return None
    p = subprocess.Popen([sys.executable, '-m', 'haptic_anfis.cli', *argv],
                         env={**os.environ, OWN_SESSION: '1'}, start_new_session=True,
                         preexec_fn=_rerun_child)

    def forward(signum, frame) -> None:
        try:
            p.send_signal(signal.SIGINT)
        except ProcessLookupError:
            pass
    previous = on_stop_signals(forward)
    try:
        code = p.wait()
    finally:
        restore_signals(previous)
    return code if code >= 0 else 128 - code


def rerun_command_in_own_session(args) -> int | None:
    """:func:`rerun_in_own_session` of this program's command line when ``args`` were parsed
    from it (``args._program``, set by :mod:`haptic_anfis.cli`); None when called from Python
    (a test, a benchmark: those run where they are called) or in the re-run itself."""
    if not getattr(args, '_program', False):
        return None
    return rerun_in_own_session(sys.argv[1:])


#: The signals that stop a session: Ctrl-C, a kill, the terminal closed.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def on_stop_signals(handler) -> dict:
    """Handle every one of :data:`STOP_SIGNALS` with ``handler``; returns the handlers they had,
    for :func:`restore_signals`."""
    return {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}


def restore_signals(previous: dict) -> None:
    """Give the signals back the handlers :func:`on_stop_signals` returned."""
    for sig, h in previous.items():
        signal.signal(sig, h)


def recorder_arguments(output: str | os.PathLike, topics: Sequence[str]) -> list[str]:
    """The recorder's ``--ros-args`` for a bag at ``output`` (made absolute: the node may run in
    another working directory) holding ``topics``."""
    return ['-p', f'output:={Path(output).resolve()}', '-p', f'topics:=[{",".join(topics)}]']


def renamed_output(args: Sequence[str], n: int) -> list[str]:
    """The recorder's arguments for restart ``n``: ``output:=X`` becomes ``output:=X.restartN``
    (a bag directory is never reused; the killed one is salvaged by ``haptic-anfis bag recover``).
    """
    return [f'{a}.restart{n}' if a.startswith('output:=') else a for a in args]
