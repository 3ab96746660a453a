"""The trainee record (no ROS): every scored exam session kept in one SQLite file, progress across
sessions, mastery by case level.

- :mod:`.db`: the file (default ``$XDG_DATA_HOME/haptic_anfis/trainees.sqlite``,
  ``$HAPTIC_ANFIS_DB`` or ``--db``), WAL, busy timeout + retries, schema version and
  migrations, :class:`RecordError`.
- :mod:`.store`: :func:`store_session` (one transaction per session), :func:`history` (the browser
  view's call), :func:`trainees`, :func:`delete_trainee`, :func:`export_csv`.
- :mod:`.levels`: :func:`case_level` (the graded library's ``level``, else lesion count and size).
- :mod:`.mastery`: thresholds per level from ``config/exam.yaml``, :func:`mastery`.
- :mod:`.figure`: the learning-curve PNG.
- :mod:`.overview`: the class at a glance (stalled, drifting), as rows and CSV.
"""
from .db import RecordError, default_db_path, resolve_db_path
from .levels import case_level, level_of_case_name
from .mastery import MasteryConfig, MasteryLevel, load_mastery_config, mastery, meets
from .store import (AlreadyStored, UnknownTrainee, check_trainee_id, delete_trainee,
                    export_csv, history, session_report, store_session, trainees, utc_iso)

__all__ = ['AlreadyStored', 'MasteryConfig', 'MasteryLevel', 'RecordError', 'UnknownTrainee',
           'case_level', 'check_trainee_id', 'default_db_path', 'delete_trainee', 'export_csv',
           'history', 'level_of_case_name', 'load_mastery_config', 'mastery', 'meets',
           'resolve_db_path', 'session_report', 'store_session', 'trainees', 'utc_iso']
