"""Write a benchmark's figures as a documentation page: ``docs/measurements/<name>.md``.

Figures in the manual are never copied by hand: a benchmark script that measures them calls
:func:`write_page` with its Markdown table, and the page carries the date (UTC), the machine and the
load it was measured at, and the command that reproduces it. The documentation site links these
pages; re-running the script rewrites its page.

    from _page import write_page   # bench/ is sys.path[0] when a bench script runs
    write_page('loop', 'Haptic loop', table_md, command='.venv/bin/python bench/bench_loop.py')

A script that prints its tables can instead hand its ``main`` to :func:`run_with_page`: it prints
as before and, when ``main`` returns 0 (or None), the printed text becomes the page (lines that
start with ``|`` stay Markdown tables, the rest goes into text blocks)::

    if __name__ == '__main__':
        sys.exit(run_with_page(main, __file__, __doc__))
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import io
import os
import platform
import sys
from pathlib import Path
from typing import Callable, Iterable, Mapping, Sequence

__all__ = ['machine_line', 'reproduce_command', 'write_page', 'write_readme_block',
           'markdown_table', 'printed_to_markdown', 'run_with_page', 'PAGES_DIR', 'README']

PAGES_DIR = Path(__file__).resolve().parent.parent / 'docs' / 'measurements'
README = Path(__file__).resolve().parent.parent / 'README.md'


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
