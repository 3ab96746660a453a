"""Speed against error: our ANFIS models and their peers on one split (see haptic_anfis.report).

Run: ``make bench`` (writes ``out/report/``) or ``.venv/bin/python bench/bench_report.py [--quick]``.
"""
import sys

from haptic_anfis.cli import main
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

if __name__ == '__main__':
    sys.exit(run_with_page(lambda: main(['report', '--out', 'out/report', *sys.argv[1:]]), __file__, __doc__))
