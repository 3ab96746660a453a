"""The session room: one description of a session, built once from the command line, and two
runners behind it.

- :class:`SessionSpec` (:mod:`.spec`): nodes, case, parameter files, recording, duration, domain;
  :func:`add_session_arguments` / :func:`spec_from_args`: the one argument helper of ``sim``,
  ``launch`` and ``exam run`` (:data:`OPTIONS` is its table: a new option is one row there and one
  field of :class:`SessionSpec`).
- :class:`OneProcessSession` (:mod:`.one_process`): the haptic graph in one process, side nodes in
  processes of their own (``sim``, ``exam run``); :func:`open_graph` for benchmarks and tests.
- :class:`ProcessSession` (:mod:`.launch_runner`): one process per node under the supervisor, with
  restarts (``launch``).
- :mod:`.case_choice`, :mod:`.case_switch`, :mod:`.case_watch`: the browser page's case against the
  loop nodes' (a case chosen live, with the falcon driver's force scale).
- :mod:`.domain`: a session refuses a ROS domain another session's loop already runs on.

Before any node starts, :meth:`SessionSpec.check` checks the options, the case and every parameter
file and ``-p`` override against the nodes' declarations (one line per problem).
"""
from __future__ import annotations

from .spec import (COMMANDS, OPTIONS, Option, SessionError, SessionSpec, add_session_arguments,
                   recorder_settings, spec_from_args)
from .one_process import OneProcessSession, open_graph
from .launch_runner import ProcessSession

__all__ = ['COMMANDS', 'OPTIONS', 'Option', 'SessionError', 'SessionSpec', 'add_session_arguments',
           'recorder_settings', 'spec_from_args', 'OneProcessSession', 'open_graph',
           'ProcessSession']

