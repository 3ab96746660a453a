"""``haptic-anfis trainees progress ID [--json] [--figure PNG]``: a trainee's sessions, mastery and
learning curve (matplotlib; see :mod:`haptic_anfis.commands.trainees`)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..record import history, load_mastery_config, mastery
from ..record.figure import plt, save_progress_figure
from .trainees import _mastery_lines, _table


def progress(args: argparse.Namespace, db: Path) -> int:
    cfg = load_mastery_config(args.exam_config)
    sessions = history(db, args.id, instructor=args.instructor)
    m = mastery(sessions, cfg)
    if args.figure:
        if plt is None:
            raise ValueError('--figure needs matplotlib (pip install matplotlib)')
        _figure_folder(args.figure)
        deep = {100 * lv.min_deep_coverage for lv in cfg.levels.values()}
        save_progress_figure(args.id, sessions, args.figure, m,
                             pass_deep_pct=deep.pop() if len(deep) == 1 else None)
    if args.json:
        print(json.dumps({'trainee': args.id, 'sessions': sessions, 'mastery': m}))
        return 0
    _table(sessions)
    _mastery_lines(m, cfg)
    if args.figure:
        print(f'figure {args.figure}')
    return 0


def _figure_folder(path: str) -> None:
    """Create the folder of ``--figure PATH`` (a new folder is said in one line); ValueError
    naming the path when it cannot be made or is a file."""
    folder = Path(path).expanduser().parent
    if folder.is_dir():
        return
    try:
        folder.mkdir(parents=True)
    except OSError as exc:
        raise ValueError(f'--figure {path}: cannot create its folder {str(folder)!r} '
                         f'({exc.strerror or exc})') from None
    print(f'created folder {folder}', file=sys.stderr)
