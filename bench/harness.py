"""The benchmarks' harness: what every ``bench/bench_*.py`` script shares (scripts import this
module only, never each other; a script puts ``bench/`` and the checkout on ``sys.path``).

- **Pages.** Figures in the manual are never copied by hand: a script that measures them calls
  :func:`write_page` with its Markdown table, and ``docs/measurements/<name>.md`` carries the date
  (UTC), the machine and the load it was measured at, and the command that reproduces it. A script
  that prints its tables hands its ``main`` to :func:`run_with_page` instead: it prints as usual
  and, when ``main`` returns 0 (or None), the printed text becomes the page (lines that start with
  ``|`` stay Markdown tables, the rest goes into text blocks)::

      from harness import run_with_page   # bench/ is sys.path[0] when a bench script runs
      if __name__ == '__main__':
          sys.exit(run_with_page(main, __file__, __doc__))

- **Load beside a run.** :func:`busy` starts processes spinning on the CPU (``sessions``: each in
  a session of its own; Linux's autogroup gives each session one fair share of the CPU, so 8
  spinners in 8 sessions load a process in another session far more than 8 spinners sharing one),
  :func:`paused` stops them for the script's own analysis, :class:`LoadSampler` reads the load
  average through a block; :class:`TestSuite` keeps the project's test suite running beside the
  runs; :func:`browser_when_up` keeps a headless chromium on the view's page (a trainee's browser).
- **Graphs.** :func:`loop_in_one_process` and :func:`loop_in_processes` run the haptic loop's
  graph (driver, contact detector, force server) for a while and write the servo tick trace;
  :func:`stop_launch` stops a ``haptic-anfis launch`` watched from a probe node; :func:`account`
  says who runs the benchmark and whether it may use real-time scheduling.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import io
import os
import platform
import signal
import statistics
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path
from typing import Callable, Iterable, Iterator, Mapping, Sequence

__all__ = ['PAGES_DIR', 'README', 'ROOT', 'LoadSampler', 'TestSuite', 'account', 'browser_when_up',
           'busy', 'close_browser', 'cpu_times', 'loop_in_one_process', 'loop_in_processes',
           'machine_line', 'markdown_table', 'open_browser', 'paused', 'printed_to_markdown',
           'reproduce_command', 'run_with_page', 'steal_pct', 'stop_launch', 'write_page',
           'write_readme_block']

#: the checkout's root (the scripts run from it: ``.venv/bin/python bench/bench_<name>.py``)
ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------------------ pages

PAGES_DIR = ROOT / 'docs' / 'measurements'
README = ROOT / 'README.md'


def machine_line() -> str:
    """One line: host kind, CPU model, cores, memory and the 1-minute load when measured."""
    cpu = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo', encoding='utf-8') as f:
            for line in f:
                if line.startswith('model name'):
                    cpu = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    mem = ''
    try:
        pages = os.sysconf('SC_PHYS_PAGES') * os.sysconf('SC_PAGE_SIZE')
        mem = f', {pages / 2**30:.0f} GiB'
    except (ValueError, OSError):
        pass
    load = os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan')
    return (f'{platform.system()} {platform.machine()}, {cpu}, {os.cpu_count()} cores{mem}, '
            f'Python {platform.python_version()}, load {load:.1f} at the start of the write')


def reproduce_command(script: str) -> str:
    """The command line that re-runs ``script`` with this run's arguments, from the checkout's
    root with the project's interpreter (the scripts are not executables of their own)."""
    rel = os.path.relpath(Path(script).resolve(), PAGES_DIR.parent.parent)
    return ' '.join(['.venv/bin/python', rel] + sys.argv[1:])


def write_page(name: str, title: str, body_md: str, command: str | None = None,
               pages_dir: Path | None = None) -> Path:
    """Write ``<pages_dir>/<name>.md`` (default ``docs/measurements``) and return its path.

    ``body_md`` is the benchmark's own Markdown (tables, notes); ``command`` the line that
    reproduces it (default: this interpreter's command line).
    """
    out_dir = Path(pages_dir) if pages_dir is not None else PAGES_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    cmd = command or reproduce_command(sys.argv[0])
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')
    text = (f'# {title}\n\n'
            f'*Written by the benchmark, not by hand: {stamp}; {machine_line()}.*\n\n'
            f'Reproduce: `{cmd}`\n\n{body_md.rstrip()}\n')
    path = out_dir / f'{name}.md'
    path.write_text(text, encoding='utf-8')
    return path


def write_readme_block(name: str, body_md: str, command: str, readme: Path | None = None) -> Path:
    """Replace the README's text between ``<!-- measured:NAME -->`` and ``<!-- /measured:NAME -->``
    with ``body_md``, its date, machine and command (a figure the README states, written by the
    script that measures it). Raises ValueError when the markers are missing."""
    path = Path(readme) if readme is not None else README
    text = path.read_text(encoding='utf-8')
    start, end = f'<!-- measured:{name} -->', f'<!-- /measured:{name} -->'
    i, j = text.find(start), text.find(end)
    if i < 0 or j < i:
        raise ValueError(f'{path}: no {start} ... {end} block to write')
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')
    block = (f'{start}\n{body_md.strip()} *(Written by `{command}`, {stamp}; '
             f'{machine_line()}.)*\n')
    path.write_text(text[:i] + block + text[j:], encoding='utf-8')
    return path


def markdown_table(rows: Iterable[Mapping], cols: Sequence[str],
                   fmt: Callable[[object], str] = str) -> str:
    """A Markdown table of ``rows`` (mappings) in columns ``cols``, each cell ``fmt(value)``
    (a missing key: ``fmt(None)``)."""
    return '\n'.join(['| ' + ' | '.join(cols) + ' |', '|' + '---|' * len(cols)]
                     + ['| ' + ' | '.join(fmt(r.get(c)) for c in cols) + ' |' for r in rows])


def printed_to_markdown(text: str) -> str:
    """Markdown of a benchmark's printed output: runs of lines starting with ``|`` (Markdown
    tables the script prints) are kept as they are, everything else goes into ``text`` blocks."""
    out: list[str] = []
    block: list[str] = []
    table = False
    for line in text.rstrip().splitlines() + [None]:  # type: ignore[list-item]
        is_table = line is not None and line.lstrip().startswith('|')
        if line is None or is_table != table:
            if block and any(b.strip() for b in block):
                out.append('\n'.join(block).strip('\n') if table
                           else '```text\n' + '\n'.join(block).strip('\n') + '\n```')
            block, table = [], is_table
        if line is not None:
            block.append(line)
    return '\n\n'.join(out) + '\n'


class _Tee(io.TextIOBase):
    """Writes to ``stream`` and keeps a copy."""

    def __init__(self, stream) -> None:
        self.stream, self.copy = stream, io.StringIO()

    def write(self, s: str) -> int:
        self.copy.write(s)
        return self.stream.write(s)

    def flush(self) -> None:
        self.stream.flush()


def _title_and_intro(doc: str) -> tuple[str, str]:
    """(title, introduction) of a benchmark page from the script's docstring: the title is the
    first paragraph up to its first ': ' or '. ' (the whole docstring stays as the introduction,
    unless it is only that title)."""
    doc = doc.strip()
    first = ' '.join(doc.split('\n\n', 1)[0].split())
    cuts = [i for i in (first.find(': '), first.find('. ')) if i > 0]
    title = (first[:min(cuts)] if cuts else first).rstrip('.')
    return title, ('' if doc.rstrip('.') == title else doc)


def run_with_page(main: Callable[[], int | None], script: str, doc: str | None,
                  no_page_flags: Iterable[str] = (), pages_dir: Path | None = None,
                  name: str | None = None) -> int:
    """Run a benchmark's ``main`` printing as usual; if it returns 0 / None, write its printed
    output as ``docs/measurements/<name>.md`` (``name``: by default the script's file name
    without ``bench_``; title and introduction from ``doc``, see :func:`_title_and_intro`; the
    introduction goes in as plain text).
    No page for ``--help``, a failure, or when an argument in ``no_page_flags`` is given (a
    script's child-process mode). Returns ``main``'s exit code."""
    if any(a in no_page_flags for a in sys.argv[1:]):
        return int(main() or 0)
    tee = _Tee(sys.stdout)
    with contextlib.redirect_stdout(tee):
        rc = int(main() or 0)
    if rc == 0:
        name = name or Path(script).stem.removeprefix('bench_')
        title, intro = _title_and_intro(doc or name)
        # the docstring as written (plain text: its brackets and indentation are not Markdown)
        body = ((f'```text\n{intro}\n```\n\n' if intro else '') + '## Output\n\n'
                + printed_to_markdown(tee.copy.getvalue()))
        path = write_page(name, title, body, command=reproduce_command(script),
                          pages_dir=pages_dir)
        print(f'wrote {os.path.relpath(path)}', file=sys.stderr)
    return rc


# ------------------------------------------------------------------------- load beside a run

@contextlib.contextmanager
def busy(n: int, sessions: bool = False) -> Iterator[list[subprocess.Popen]]:
    """``n`` processes spinning on the CPU for the block (``sessions``: each in a session of
    its own); ended, and waited for, when it leaves, also on an error."""
    procs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                              start_new_session=sessions) for _ in range(n)]
    try:
        yield procs
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait()


@contextlib.contextmanager
def paused(procs: list[subprocess.Popen]) -> Iterator[None]:
    """The processes of :func:`busy` stopped (SIGSTOP) for the block, continued after it: the
    benchmark's own analysis between runs (an hour's trace: minutes of CPU) is not what they
    load."""
    for p in procs:
        p.send_signal(signal.SIGSTOP)
    try:
        yield
    finally:
        for p in procs:
            p.send_signal(signal.SIGCONT)


def cpu_times() -> list[int] | None:
    """The machine's CPU time counters (``/proc/stat``'s ``cpu`` line, in clock ticks: user nice
    system idle iowait irq softirq steal ...), or None where there is no such file."""
    try:
        with open('/proc/stat') as f:
            return [int(v) for v in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None


def steal_pct(before: list[int] | None, after: list[int] | None) -> float | None:
    """The share of CPU time [%] the hypervisor gave other guests between two
    :func:`cpu_times` readings ("steal", the 8th counter): a virtual machine's cores then run
    nobody's threads here, the servo thread's neither (None: no readings or no time passed)."""
    if not before or not after or len(before) < 8 or len(after) < 8:
        return None
    total = sum(after[:8]) - sum(before[:8])   # guest time is counted in user already
    return 100.0 * (after[7] - before[7]) / total if total > 0 else None


class LoadSampler:
    """The 1-minute load average read every ``every`` seconds while the block runs; ``median``
    afterwards. Read once at the start and once at the end (after the busy processes were
    stopped for the benchmark's own analysis) it said 3.9-4.7 of hours that stood at 14-17.
    ``steal``: the hypervisor's steal over the block [%] (:func:`steal_pct`): short runs that
    missed periods on a quiet machine ran under 0-27 % steal."""

    def __init__(self, every: float = 10.0) -> None:
        self.every, self.samples = every, []
        self.steal: float | None = None
        self._cpu0: list[int] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.every):
            self.samples.append(os.getloadavg()[0])

    def __enter__(self) -> LoadSampler:
        self._cpu0 = cpu_times()
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.steal = steal_pct(self._cpu0, cpu_times())

    @property
    def median(self) -> float | None:
        """The samples' median (None before the first: a block shorter than ``every``)."""
        return statistics.median(self.samples) if self.samples else None


class TestSuite:
    """The project's test suite running beside the runs (``--beside-tests``): restarted when it
    ends, so every run has it beside it; its output is discarded."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None
        self.starts = 0

    def ensure(self) -> None:
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen(
                [sys.executable, '-m', 'pytest', 'test', '-q', '-p', 'no:cacheprovider'],
                cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                env=dict(os.environ, PYTHONPATH=str(ROOT)), start_new_session=True)
            self.starts += 1

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()


def browser_when_up(port: int, stop) -> threading.Thread:
    """A thread that waits until the page on ``port`` answers, then keeps a headless chromium
    on it (:func:`open_browser`: it stands for the trainee's browser) until ``stop`` is set."""
    def run() -> None:
        while not stop.is_set():
            # an HTTP request, as the browser's: a bare connect that closes unanswered leaves a
            # websocket handshake traceback in the view's log
            try:
                with urllib.request.urlopen(f'http://127.0.0.1:{port}/', timeout=2.0):
                    break
            except OSError:
                pass
            time.sleep(0.5)
        else:
            return
        t.started = time.monotonic()
        b = open_browser(f'http://127.0.0.1:{port}/')
        stop.wait()
        close_browser(b)

    t = threading.Thread(target=run, daemon=True)
    t.started = None   # when chromium was started (time.monotonic(): the trace's clock)
    t.start()
    return t


def open_browser(url: str) -> subprocess.Popen:
    """A headless chromium keeping ``url`` open (killed by the caller): it stands for a trainee's
    browser, another program in a session of its own, which draws on a GPU; this one draws in
    software on the loop's cores (a whole core of two at the view's 30 Hz). ``nice`` counts only
    inside its session where the kernel groups by session (autogroups), and run as root chromium
    sets some of its processes' priorities itself; putting it in the benchmark's session made it
    starve the `sim` graph there instead, and lowering its session's weight
    (``/proc/<pid>/autogroup``) made a 1 kHz loop in another session lose periods."""
    from haptic_anfis.view.browser import chromium, open_chromium
    if chromium() is None:   # a row "with the browser" measured without one would be a false figure
        raise SystemExit('no chromium on this machine: the browser view cannot be measured '
                         '(Debian: apt-get install chromium, as .ci/run does)')
    return open_chromium(url, nice=10)


def close_browser(browser: subprocess.Popen) -> None:
    """Kill the chromium of :func:`open_browser` with every process it started."""
    from haptic_anfis.view.browser import close_chromium
    close_chromium(browser)


# ------------------------------------------------------------------------------------ graphs

def stop_launch(launch: subprocess.Popen, executor, node, context) -> None:
    """Stop the launch as Ctrl-C does (its nodes stop in order; killed after 120 s), then the
    probe node, its executor and its rclpy context."""
    import rclpy
    launch.send_signal(signal.SIGINT)
    try:
        launch.wait(120)
    except subprocess.TimeoutExpired:
        launch.kill()
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def account() -> str:
    """Who runs the benchmark, for the page: the user, whether it may set SCHED_FIFO itself
    (root, CAP_SYS_NICE or an rtprio limit) and whether a RealtimeKit answers on the system bus."""
    import pwd
    import resource
    uid = os.geteuid()
    soft, _ = resource.getrlimit(resource.RLIMIT_RTPRIO)
    may = uid == 0 or soft != 0
    try:
        from haptic_anfis.realtime.rtkit import RealtimeKitError, max_realtime_priority
        kit = f'rtkit answers (max priority {max_realtime_priority()})'
    except RealtimeKitError as exc:
        kit = str(exc)
    return (f'run as {pwd.getpwuid(uid).pw_name} (uid {uid}); SCHED_FIFO '
            + ('allowed' if may else 'not allowed (no rtprio limit, not root)') + f'; {kit}')


def loop_in_one_process(seconds: float, mode: str, trace: Path,
                        driver_params: Mapping | None = None,
                        contact_params: Mapping | None = None) -> float:
    """``haptic-anfis sim``'s graph in this process (its own ROS domain, localhost discovery)
    with the driver's ``force_mode`` ``mode``, measured for ``seconds`` from the first force
    command (the servo loop's misses while the nodes load do not count); the driver writes its
    tick trace to ``trace`` at shutdown. ``driver_params`` / ``contact_params``: extra node
    parameters (name -> value). Returns the whole graph's CPU seconds over the window."""
    from rclpy.parameter import Parameter

    from haptic_anfis.session import open_graph
    # a domain of its own: another session's graph on the default domain would feed this driver
    # its commands (refused as unknown / future stamps, but taking this process's time)
    os.environ['ROS_DOMAIN_ID'] = str(100 + os.getpid() % 50)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    g = open_graph(program='bench', overrides={'falcon_driver': [
        Parameter('force_mode', value=mode), Parameter('trace_path', value=str(trace)),
        *(Parameter(k, value=v) for k, v in (driver_params or {}).items())],
        'contact_detector': [Parameter(k, value=v) for k, v in (contact_params or {}).items()]})
    try:
        if not g.spin_for(60.0, lambda: g.driver.first_command is not None):
            raise RuntimeError('no force command within 60 s')
        g.driver.servo.stats.reset()
        cpu0 = time.process_time()
        g.spin_for(seconds)
        return time.process_time() - cpu0
    finally:
        g.shutdown()  # the driver writes its trace


def loop_in_processes(seconds: float, mode: str, trace: Path, spinners: int = 0,
                      driver_params: Mapping | None = None,
                      contact_params: Mapping | None = None) -> None:
    """The driver, the contact detector and the force server as processes (a domain of their
    own), ``spinners`` processes spinning beside them (:func:`busy`); the driver runs
    ``seconds`` after its first command with ``force_mode`` ``mode`` and writes its tick trace
    to ``trace`` (RuntimeError with the end of its output when it wrote none)."""
    from haptic_anfis.realtime.processes import node_env, start_node, stop_node
    env = node_env(150 + os.getpid() % 50, localhost=True)
    with busy(spinners):
        cargs = [a for k, v in (contact_params or {}).items() for a in ('-p', f'{k}:={v}')]
        helpers = [start_node(n, cargs if n == 'contact_detector' else (), env=env,
                              log=subprocess.DEVNULL) for n in ('force_server', 'contact_detector')]
        try:
            time.sleep(3.0)
            driver = start_node('falcon_driver', ['-p', f'run_duration:={float(seconds)}',
                                                  '-p', f'force_mode:={mode}',
                                                  '-p', f'trace_path:={trace}',
                                                  *(a for k, v in (driver_params or {}).items()
                                                    for a in ('-p', f'{k}:={str(v).lower()}'))],
                                env=env, log=subprocess.PIPE)
            helpers.append(driver)  # stopped below if it outlives the timeout
            out = driver.communicate(timeout=seconds + 180)[0].decode(errors='replace')
            if not trace.is_file():
                raise RuntimeError(f'falcon_driver wrote no trace (rc {driver.returncode}):\n'
                                   f'{out[-2000:]}')
        finally:
            for h in helpers:
                stop_node(h)
