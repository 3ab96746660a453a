"""A live session's page: the trainee's page and the instructor's console around one exam
session, fed samples by the ``web_view`` node (no ROS).

:class:`LivePage` holds the case shown (:class:`~.build.CaseView`), the exam session collecting
the samples while it runs, its clock, and both doors: the trainee's page (:class:`~.app.ViewApp`:
the exam live, then its debrief) and the instructor's console (:class:`~.console.ConsoleApp`: a
case, the trainee id, start / stop, the class's record; its controls queue requests the owner
handles on its own thread). Stopping scores the session as ``exam report`` does, stores it for
the trainee and shows the debrief on the trainee's page. Tissue frame, metres, newtons, seconds.
"""
from __future__ import annotations

import time
from collections import deque
from typing import Callable

import numpy as np

from ..cases.force_mapping import tissue_clamp
from ..cases.library import Case
from ..exam.session import ExamSession
from ..record import level_of_case_name, store_session, utc_iso
from .app import BLIND, ViewApp
from .build import case_view
from .console import ConsoleApp
from .debrief import Debrief
from .doors import load_token
from .feel_again import feel_commands

__all__ = ['LivePage', 'ConsoleSettings']


class ConsoleSettings:
    """The instructor's console: ``port``, ``host``, ``token_file`` ('' = the environment's
    token, else a new one), the ``trainee`` id preset, the record ``db`` ('' = the default)."""

    def __init__(self, port: int, host: str, token_file: str = '', trainee: str = '',
                 db: str = '') -> None:
        self.port, self.host, self.token_file = port, host, token_file
        self.trainee, self.db = trainee, db


class LivePage:
    """The page of a live session on ``case`` (None: the default scene).

    Args:
        case: the case shown first.
        blind: the case is a blind random draw (the trainee's page never names it).
        exam_config: scoring settings ('' = config/exam.yaml); ``dent``: draw the dent.
        port, host: the trainee's page.
        console: the instructor's console (None: the trainee's page alone).
        cases: the case names the console offers.
        requests: where the console's controls queue ``('start' | 'stop' | 'case', arg)``.
        max_force: the device's clamp [N]; ``force_scale(case)``: the tissue -> device scale
            rendered for a case (None: each case's own mapping): the gauge marks the tissue
            force at the clamp.
        log: ``log(level, msg)`` into the owner's log ('info', 'warning', 'error').
    """

    def __init__(self, case: Case | None, blind: bool, exam_config: str, dent: bool, port: int,
                 host: str, console: ConsoleSettings | None, cases: list[str], requests: deque,
                 max_force: float, force_scale: float = 0.0,
                 log: Callable[[str, str], None] = lambda level, msg: None) -> None:
        self.blind, self.exam_config, self.dent = blind, exam_config or None, dent
        self.max_force, self.force_scale, self.log = max_force, force_scale, log
        self.cv = case_view(case.name if case else None, self.exam_config, dent)
        self.app = ViewApp(self.cv.vertices, self.cv.faces, self.cv.region_faces,
                           self.cv.config.thresholds, port=port, host=host,
                           title='haptic_anfis', deformation=self.cv.deformation,
                           max_force=self._clamp(case))
        self.console: ConsoleApp | None = None
        self.token_from = ''
        if console is not None:
            token, self.token_from = load_token(console.token_file)
            self.console = ConsoleApp(console.port, token, cases, host=console.host,
                                      db=console.db or None)
            self.console.g_trainee.value = console.trainee
            if case is not None:
                self.console.show_case_choice(BLIND if blind else case.name)
            self.console.on_start = lambda: requests.append(('start', None))
            self.console.on_stop = lambda: requests.append(('stop', None))
            self.console.on_case = lambda name: requests.append(('case', name))
        self.db = console.db if console is not None else ''
        self.t_start = time.monotonic()
        self.running = True   # the session collects from the start; "start" begins afresh
        self.loop_text = ''   # the haptic loop's health ('' while it keeps up)
        self.show_running(True)

    @property
    def name(self) -> str:
        """The case shown ('' for the default scene)."""
        return self.cv.name or ''

    @property
    def session(self) -> ExamSession:
        return self.cv.session

    def _clamp(self, case: Case | None) -> float:
        """The tissue force [N] at which the device clamps on ``case``."""
        if self.force_scale > 0:
            return self.max_force / self.force_scale
        return tissue_clamp(case, self.max_force)

    # -- what the page says -----------------------------------------------------------------

    def tell(self, msg: str, page: str | None = None) -> None:
        """``msg`` to the instructor (the console; without one, nowhere: the owner logs what
        matters), ``page`` (if given) on the trainee's page: what a trainee may read (no
        trainee id, no case a blind exam hides, no record)."""
        if self.console is not None:
            self.console.message(msg)
        if page is not None:
            self.app.message(page)

    def show_case_choice(self, entry: str) -> None:
        """The console's dropdown on ``entry`` (a case name or the blind entry)."""
        if self.console is not None:
            self.console.show_case_choice(entry)

    def show_running(self, running: bool) -> None:
        """The trainee's page and the console's buttons for an exam running or not."""
        self.app.set_exam_running(running, self.blind, self.name)
        if self.console is not None:
            self.console.set_running(running)

    def show_loop_health(self, text: str) -> None:
        """The driver's servo loop fell behind (``text``; '' once it keeps up): the console and
        the log say so; the trainee's page does not (a machine's health is not the trainee's
        to act on)."""
        if text and text != self.loop_text:
            self.log('warning', f'haptic loop behind: {text}')
        self.loop_text = text
        if self.console is not None:
            self.console.show_loop_health(text)

    # -- the exam ---------------------------------------------------------------------------

    def load_case(self, case: Case | None) -> None:
        """Show ``case`` and start the exam afresh on it."""
        self.cv = case_view(case.name if case else None, self.exam_config, self.dent)
        self.app.deformation = self.cv.deformation
        self.app.max_force = self._clamp(case)
        self.app.set_surface(self.cv.vertices, self.cv.faces, self.cv.region_faces)
        self.restart()
        self.show_running(True)

    def restart(self) -> None:
        """A fresh exam session on the case shown, the clock from zero."""
        s = self.cv.session
        self.cv.session = ExamSession(s.surface, s.subject, s.config)
        self.t_start = time.monotonic()
        self.running = True
        self.app.set_coverage(self.cv.session.grid.level_per_face(),
                              self.cv.session.grid.fraction())

    def start(self) -> None:
        """The instructor's start: a fresh session."""
        self.restart()
        self.show_running(True)
        self.tell('exam started')

    def stop(self) -> None:
        """The instructor's stop: score the session, store it for the trainee named on the
        console, show the debrief on the trainee's page."""
        self.running = False
        self.app.show_over()   # before the scoring: the page says so at once
        self.show_running(False)
        report = self.cv.session.report()
        report['case'] = 'blind case' if self.blind else (self.cv.name or 'default')
        trainee = self.console.trainee if self.console is not None else ''
        stored = self._store(trainee, report) if trainee else ''
        self.app.show_debrief(Debrief(report, self.cv.session))   # no record here
        self.tell("exam stopped: the debrief is on the trainee's page" + stored
                  + self._feel_again(report))
        if self.console is not None:
            self.console.refresh(select=trainee or None)

    def stop_exam(self, msg: str) -> None:
        """Stop collecting without a debrief (the loop may be on another case): ``msg`` to the
        instructor, the trainee's page says a case is to be chosen again."""
        self.running = False
        self.show_running(False)
        self.tell(msg, page='the exam is stopped: the instructor chooses a case again')

    def _feel_again(self, report: dict) -> str:
        """The instructor's "feel it again" commands of the stopped exam's lesions (a blind
        case's too: the console may name it), as a sentence ('' for none)."""
        cmds = feel_commands(self.cv.name or 'default', report['lesions'],
                             self.cv.config.thresholds)
        return ''.join(f'; feel lesion {k} again: {v}' for k, v in cmds.items())

    def _store(self, trainee: str, report: dict) -> str:
        """Store the stopped exam in the trainee record under ``trainee``, with the case's real
        name (a blind case is named in the record, not on the page); returns what to say on
        the page. A record that cannot be written is said, never raised."""
        name = self.cv.name or 'default'
        started = time.time() - (time.monotonic() - self.t_start)   # wall clock at the start
        try:
            sid = store_session(self.db or None, trainee, dict(report, case=name),
                                source='run', case_level=level_of_case_name(name),
                                started_utc=utc_iso(started))
        except (ValueError, OSError) as exc:   # RecordError is a ValueError
            self.log('error', f'trainee record: {exc}')
            return f'; NOT stored in the trainee record: {exc}'
        return f'; stored as session {sid} of trainee {trainee}'

    # -- samples and frames -----------------------------------------------------------------

    def add_mark(self, stamp: float, point: tuple[float, float, float]) -> None:
        """The trainee marked ``point`` [m] at ``stamp`` [s]: scored, and on the page at once."""
        self.cv.session.add_mark(stamp, point)
        self.app.show_mark(point)

    def draw(self, pose, contact, force) -> None:
        """One live frame: the probe at ``pose`` (3,) [m], the ``contact`` state, the commanded
        ``force`` (3,) [N] (each None while unknown), the exam clock.

        Raises:
            ValueError: a bad sample (the frame is not drawn).
        """
        if self.app.mode == 'live':
            self.app.show_live(None if pose is None else np.asarray(pose),
                               contact, None if force is None else np.asarray(force),
                               time.monotonic() - self.t_start if self.running else None)

    def draw_coverage(self) -> None:
        """Repaint the coverage map (while the exam runs)."""
        if self.running and self.app.mode == 'live':
            s = self.cv.session
            s.update_coverage()
            self.app.set_coverage(s.grid.level_per_face(), s.grid.fraction())

    def close(self, flush: float) -> None:
        """Close both doors; a live page first says the session is over and gets ``flush`` [s]
        to send it (viser sends from a thread of its own: a server stopped at once drops it)."""
        if self.app.mode == 'live':   # the session ends (exam run --view): its debrief follows
            self.app.show_over()
            time.sleep(flush)
        self.app.close()
        if self.console is not None:
            self.console.close()
