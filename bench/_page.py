"""Write a benchmark's figures as a documentation page: ``docs/measurements/<name>.md``.

Figures in the manual are never copied by hand: a benchmark script that measures them calls
:func:`write_page` with its Markdown table, and the page carries the date (UTC), the machine and the
load it was measured at, and the command that reproduces it. The documentation site links these
pages; re-running the script rewrites its page.

    from _page import write_page   # bench/ is sys.path[0] when a bench script runs
    write_page('loop', 'Haptic loop', table_md, command='.venv/bin/python bench/bench_loop.py')
"""
from __future__ import annotations

import datetime as _dt
import os
import platform
import sys
from pathlib import Path

__all__ = ['machine_line', 'write_page', 'PAGES_DIR']

PAGES_DIR = Path(__file__).resolve().parent.parent / 'docs' / 'measurements'


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


def write_page(name: str, title: str, body_md: str, command: str | None = None,
               pages_dir: Path | None = None) -> Path:
    """Write ``<pages_dir>/<name>.md`` (default ``docs/measurements``) and return its path.

    ``body_md`` is the benchmark's own Markdown (tables, notes); ``command`` the line that
    reproduces it (default: this interpreter's command line).
    """
    out_dir = Path(pages_dir) if pages_dir is not None else PAGES_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    cmd = command or ' '.join([os.path.relpath(sys.argv[0])] + sys.argv[1:])
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')
    text = (f'# {title}\n\n'
            f'*Written by the benchmark, not by hand: {stamp}; {machine_line()}.*\n\n'
            f'Reproduce: `{cmd}`\n\n{body_md.rstrip()}\n')
    path = out_dir / f'{name}.md'
    path.write_text(text, encoding='utf-8')
    return path
