"""The trainee record's hooks in ``haptic-anfis exam`` (kept here so exam.py gains three calls):
``--trainee-id`` / ``--db`` (and ``--next`` on ``exam run``), the blind draw of the next case,
and storing the scored report. A record that cannot be written costs one line on stderr naming
the file and exit status 1; the exam's report is printed all the same."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..bag.reader import bag_info
from ..cases import library
from ..record import (AlreadyStored, RecordError, check_trainee_id, level_of_case_name,
                      resolve_db_path, store_session, utc_iso)
from ..record.draw import next_case
from ..record.store import WALL_CLOCK_NS
from ..record.thresholds import latest_threshold

__all__ = ['add_record_arguments', 'case_parameter', 'prepare_record', 'store_report']


def add_record_arguments(p: argparse.ArgumentParser, run: bool = False) -> None:
    g = p.add_argument_group('trainee record (haptic-anfis trainees)')
    g.add_argument('--trainee-id', default=None, metavar='ID',
                   help='store the scored session in the trainee record under this id (a '
                        'pseudonym; created on its first session)')
    g.add_argument('--db', default=None, metavar='PATH',
                   help='the trainee record file (default $HAPTIC_ANFIS_DB, else '
                        '$XDG_DATA_HOME/haptic_anfis/trainees.sqlite)')
    if run:
        g.add_argument('--next', action='store_true',
                       help="with --trainee-id: a blind case of the level after the trainee's "
                            'mastered one (instead of --case)')


def prepare_record(args: argparse.Namespace) -> None:
    """Check ``--trainee-id`` before the exam; for ``--next``, choose the case (``args.case``)
    and mark the session blind (``args.blind``: the case is named only in the report).

    Raises:
        ValueError: a bad id, ``--next`` without ``--trainee-id`` or with ``--case``, no case of
        the next level, an unusable record file (for ``--next``, which reads it).
    """
    if args.trainee_id is not None:
        check_trainee_id(args.trainee_id)
    args.record_started_utc = utc_iso(time.time())
    if not getattr(args, 'next', False):
        return
    if args.trainee_id is None:
        raise ValueError('--next needs --trainee-id ID (the record says which level is next)')
    if args.case:
        raise ValueError(f'--next draws the case: give it or --case {args.case}, not both')
    own = latest_threshold(args.db, args.trainee_id)   # graded against the trainee's own
    case, level, m = next_case(args.db, args.trainee_id, exam_config=args.exam_config,
                               threshold_pct=own)
    args.case, args.blind = case.name, True
    print(f'record: trainee {args.trainee_id}, mastered level {m["mastered_level"] or "none"}: a '
          f'blind case of level {level}'
          + (f' (graded at the trainee\'s own threshold, {own:.1f} %)' if own else ''),
          flush=True)


def case_parameter(args: argparse.Namespace, case) -> tuple[str, str | int]:
    """The nodes' case parameter for ``case``: ``('case', name)``, or for a blind session
    (``--next``) ``('random_case_seed', seed)`` with a seed that draws this very case from the
    library, so that no node logs its name (the nodes' blind mode).

    Raises:
        ValueError: no seed below 10000 draws it (the library changed under the exam).
    """
    if not getattr(args, 'blind', False):
        return 'case', case.name
    lib = library()
    for seed in range(10000):
        if lib.random(seed).name == case.name:
            return 'random_case_seed', seed
    raise ValueError('--next: no random-case seed draws the case chosen for the session')


def _bag_folder(bag: str | Path) -> Path:
    """The bag a path names, as the record keeps it: absolute, and a bag's MCAP file named by
    its folder (``exam report BAG`` and ``exam report BAG/BAG.mcap`` are one recording)."""
    p = Path(bag).resolve()
    return p.parent if p.is_file() and (p.parent / 'metadata.yaml').is_file() else p


def _bag_start(bag: str | Path) -> tuple[str | None, int | None]:
    """The bag's first message: when (UTC, if its clock is wall time) and its time [ns]
    (which tells recordings made at the same path apart); None for what cannot be read."""
    try:
        info = bag_info(bag)
    except Exception:   # noqa: BLE001 (the report already read it; a time is optional)
        return None, None
    if not info.message_count:
        return None, None
    start = info.start_ns
    return (utc_iso(start * 1e-9) if start >= WALL_CLOCK_NS else None), int(start)


def store_report(args: argparse.Namespace, report: dict) -> int:
    """Store ``report`` for ``--trainee-id`` (nothing without it, nothing for an interrupted
    exam); returns the exit status: 0, or 1 after one line on stderr naming the record file."""
    if not getattr(args, 'trainee_id', None):
        return 0
    if report.get('interrupted') or report.get('time_limit_reached'):
        why = 'was interrupted' if report.get('interrupted') else (
            'stopped at its time limit before the trainee finished')
        print(f'record: the exam {why}: nothing stored for trainee {args.trainee_id}',
              file=sys.stderr)
        return 1
    bag = getattr(args, 'bag', None) or getattr(args, 'record', None)
    source = 'bag' if args.exam_command == 'report' else 'run'
    bag_utc, bag_ns = _bag_start(bag) if bag else (None, None)
    started = (bag_utc if source == 'bag' else None) or getattr(args, 'record_started_utc', None)
    try:
        sid = store_session(args.db, args.trainee_id, report, source=source, started_utc=started,
                            case_level=level_of_case_name(report.get('case')),
                            bag=str(_bag_folder(bag)) if bag else None, bag_start_ns=bag_ns)
    except AlreadyStored as exc:   # the report stands; the record keeps the bag's first one
        print(f'record         {exc}', flush=True)
        return 0
    except RecordError as exc:
        print(f'record: {exc}', file=sys.stderr)
        return 1
    except OSError as exc:   # e.g. the data directory cannot be created
        print(f'record: trainee record {str(resolve_db_path(args.db))!r}: {exc}',
              file=sys.stderr)
        return 1
    print(f'record         session {sid} of trainee {args.trainee_id} stored in '
          f'{resolve_db_path(args.db)}', flush=True)
    return 0
