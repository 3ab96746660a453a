"""bench/harness.py: a benchmark's printed output becomes its documentation page; the load
average read through a block (LoadSampler), its median after; the hypervisor's steal over it."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / 'bench'
sys.path.insert(0, str(BENCH))
import harness  # noqa: E402
from harness import LoadSampler, steal_pct  # noqa: E402


def test_printed_tables_stay_markdown_the_rest_is_text():
    out = harness.printed_to_markdown('load 3.2\nrate 999 Hz\n| a | b |\n|---|---|\n| 1 | 2 |\nend\n')
    assert out == ('```text\nload 3.2\nrate 999 Hz\n```\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n'
                   '```text\nend\n```\n')


def test_title_is_the_first_clause_and_the_docstring_stays():
    title, intro = harness._title_and_intro('Bag benchmark: recording overhead\non the loop.\n\nMore.')
    assert title == 'Bag benchmark'
    assert intro.startswith('Bag benchmark: recording overhead') and intro.endswith('More.')
    assert harness._title_and_intro('Start time of every node.') == ('Start time of every node', '')


def test_run_with_page_prints_and_writes_only_on_success(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys, 'argv', ['bench/bench_demo.py', '--quick'])

    def main():
        print('| x | y |\n|---|---|\n| 1 | 2 |')
        return 0
    assert harness.run_with_page(main, str(BENCH / 'bench_demo.py'), 'Demo bench: a test.',
                               pages_dir=tmp_path) == 0
    assert '| 1 | 2 |' in capsys.readouterr().out  # still printed
    text = (tmp_path / 'demo.md').read_text()
    assert text.startswith('# Demo bench\n') and '| 1 | 2 |' in text
    assert '```text\nDemo bench: a test.\n```' in text  # the docstring as plain text
    assert 'Reproduce: `.venv/bin/python bench/bench_demo.py --quick`' in text
    assert 'load ' in text  # the machine line with its load

    # a page of its own for another configuration of the same script (bench_soak --page)
    assert harness.run_with_page(main, str(BENCH / 'bench_demo.py'), 'Demo bench: a test.',
                               pages_dir=tmp_path, name='demo_other') == 0
    assert 'Reproduce: `.venv/bin/python bench/bench_demo.py --quick`' in (
        tmp_path / 'demo_other.md').read_text()

    assert harness.run_with_page(lambda: 1, 'bench/bench_fails.py', 'Fails.', pages_dir=tmp_path) == 1
    assert not (tmp_path / 'fails.md').exists()
    monkeypatch.setattr(sys, 'argv', ['bench/bench_child.py', '--stream-child', 'x'])
    assert harness.run_with_page(lambda: 0, 'bench/bench_child.py', 'Child.',
                               no_page_flags=('--stream-child',), pages_dir=tmp_path) == 0
    assert not (tmp_path / 'child.md').exists()
    with pytest.raises(SystemExit):  # --help: argparse exits, no page
        harness.run_with_page(lambda: sys.exit(0), 'bench/bench_help.py', 'Help.',
                            pages_dir=tmp_path)
    assert not (tmp_path / 'help.md').exists()


def test_a_page_written_without_a_command_says_how_to_reproduce_it(tmp_path, monkeypatch):
    """The default command names the interpreter: the scripts are not executable themselves
    (a page said `bench/bench_servo_load.py ...`, which a shell refuses)."""
    monkeypatch.setattr(sys, 'argv', [str(BENCH / 'bench_demo.py'), '--busy', '8'])
    text = harness.write_page('demo', 'Demo', '| a |', pages_dir=tmp_path).read_text()
    assert 'Reproduce: `.venv/bin/python bench/bench_demo.py --busy 8`' in text


def test_markdown_table_formats_every_cell_and_a_missing_key_as_none():
    rows = [{'a': 1.234, 'b': 'x'}, {'a': None}]

    def fmt(v) -> str:
        return 'n/a' if v is None else (f'{v:.1f}' if isinstance(v, float) else str(v))
    assert harness.markdown_table(rows, ('a', 'b'), fmt) == (
        '| a | b |\n|---|---|\n| 1.2 | x |\n| n/a | n/a |')
    assert harness.markdown_table([], ('a',)) == '| a |\n|---|'


def test_samples_through_the_block_and_stops_after_it():
    with LoadSampler(every=0.01) as s:
        deadline = time.monotonic() + 5.0
        while len(s.samples) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
    n = len(s.samples)
    assert n >= 3 and all(x >= 0.0 for x in s.samples)
    assert min(s.samples) <= s.median <= max(s.samples)
    time.sleep(0.05)
    assert len(s.samples) == n   # the thread ended with the block


def test_median_of_even_and_odd_counts_and_none_without_samples():
    s = LoadSampler()
    assert s.median is None
    s.samples = [3.0, 1.0, 2.0]
    assert s.median == 2.0
    s.samples = [4.0, 1.0, 2.0, 3.0]
    assert s.median == 2.5


def test_steal_is_the_eighth_counters_share_of_all_eight():
    """/proc/stat's cpu line: user nice system idle iowait irq softirq steal guest guest_nice;
    guest time is inside user already, so the total is the first eight."""
    before = [100, 0, 50, 800, 0, 0, 0, 50, 30, 0]
    after = [200, 0, 100, 1550, 0, 0, 0, 150, 90, 0]   # 1000 ticks, 100 of them stolen
    assert steal_pct(before, after) == 10.0
    assert steal_pct(before, before) is None   # no time passed
    assert steal_pct(None, after) is None and steal_pct([1, 2, 3], after) is None
    with LoadSampler(every=10.0) as s:
        sum(range(10 ** 6))
    assert s.steal is None or 0.0 <= s.steal <= 100.0
