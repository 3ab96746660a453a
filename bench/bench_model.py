"""Speed against error of the ANFIS force model on the shipped dataset (see haptic_anfis.report.model_bench).

Run: ``make bench`` or ``.venv/bin/python bench/bench_model.py [--structures 3-3-3-2 ...]``.
"""
import sys

from haptic_anfis.cli import main
from harness import run_with_page  # noqa: E402  (bench/ is sys.path[0])

if __name__ == '__main__':
    sys.exit(run_with_page(lambda: main(['bench', 'model', *sys.argv[1:]]), __file__, __doc__))
