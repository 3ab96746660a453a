"""Speed against error: our ANFIS models and their peers on one split (see haptic_anfis.report).

Run: ``make bench`` (writes ``out/report/``) or ``.venv/bin/python bench/bench_report.py [--quick]``.
"""
import sys

from haptic_anfis.cli import main

if __name__ == '__main__':
    sys.exit(main(['report', '--out', 'out/report', *sys.argv[1:]]))
