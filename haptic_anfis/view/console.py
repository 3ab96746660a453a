"""The instructor's console: a page of its own (its own viser server and port), behind a secret
token, from which the instructor runs the class (no ROS).

- **The exam**: the case (or a blind random draw), the trainee id, start / stop, the session's
  messages (which case the loop runs, where the session was stored).
- **The class**: every trainee of the record with sessions, last score, mastered level, stalled
  / drifting (:mod:`haptic_anfis.record.overview`), exportable as CSV, and one trainee's curves
  (:mod:`.curves`, colour-blind safe, with a legend).

The server is bound to ``127.0.0.1`` unless told otherwise and answers only its own origin with
the token as the first path segment (:mod:`.doors`): ``http://127.0.0.1:PORT/<token>/``. The
trainee's page never carries the token. Every text shown is escaped (:func:`.escape.md`).
The controls call back ``on_start`` / ``on_stop`` / ``on_case`` (set by the owner; they run on
viser's threads).
"""
from __future__ import annotations

import threading
from typing import Callable

from ..record import RecordError
from ..record.mastery import DEFAULT
from ..record.overview import overview, overview_csv
from .app import BLIND, check_port
from .curves import curves_image
from .doors import close_door, guarded_server
from .escape import md

__all__ = ['BLIND', 'ConsoleApp', 'overview_markdown']

#: the trainee dropdown's entry before any trainee is stored
NOBODY = '(no trainee yet)'


class ConsoleApp:
    """The console on ``host:port`` with ``token`` (see the module docstring).

    Args:
        cases: the case names of the dropdown (besides the blind draw).
        db: the trainee record (None: its default file).
        mastery_config: the mastery thresholds (None: the record's default).
    """

    def __init__(self, port: int, token: str, cases: list[str], host: str = '127.0.0.1',
                 db=None, mastery_config=None, title: str = 'haptic_anfis instructor') -> None:
        check_port(port, host, flag='console_port')
        self.port, self.host, self.token = int(port), host, token
        self.db = db
        self.mastery_config = mastery_config
        self.on_start: Callable[[], None] | None = None
        self.on_stop: Callable[[], None] | None = None
        self.on_case: Callable[[str], None] | None = None
        self._lock = threading.RLock()
        self.rows: list[dict] = []
        self.last_message = ''
        self.server, self.door = guarded_server(self.port, host, title, token)
        g = self.server.gui
        with g.add_folder('Exam'):
            self.g_case = g.add_dropdown('case', [BLIND, *cases],
                                         initial_value=cases[0] if cases else BLIND)
            self.g_trainee = g.add_text('trainee id', '')
            self.g_start = g.add_button('start exam', color='green')
            self.g_stop = g.add_button('stop exam', color='red', disabled=True)
            self.g_msg = g.add_markdown('')
            #: the haptic loop's health as the falcon driver reports it ('' while it keeps up):
            #: the instructor's to judge (a session whose loop fell behind is void), not the
            #: trainee's to read while palpating
            self.g_loop = g.add_markdown('')
        with g.add_folder('Class'):
            self.g_refresh = g.add_button('refresh')
            self.g_csv = g.add_button('export CSV')
            self.g_overview = g.add_markdown('')
            self.g_pick = g.add_dropdown('curves of', [NOBODY], initial_value=NOBODY)
            self.g_curves = None
        self.g_start.on_click(lambda _: self._call(self.on_start))
        self.g_stop.on_click(lambda _: self._call(self.on_stop))
        # only the instructor's choices: a value set here (show_case_choice) is not one
        # (a client may send a value the dropdown does not list: not a choice either)
        self.g_case.on_update(lambda ev: ev.client is None or self.g_case.value not in
                              self.g_case.options or self._call(self.on_case, self.g_case.value))
        self.g_refresh.on_click(lambda _: self.refresh())
        self.g_csv.on_click(lambda ev: self._export(ev.client))
        self.g_pick.on_update(lambda _: self._show_curves(str(self.g_pick.value)))
        self.refresh()

    @property
    def url(self) -> str:
        """The console's address, token included (say it to the instructor only)."""
        return f'http://{self.host}:{self.port}/{self.token}/'

    @property
    def trainee(self) -> str:
        """The trainee id typed (stripped; '' = none)."""
        return (self.g_trainee.value or '').strip()

    def _call(self, fn, *a) -> None:
        if fn is None:
            return
        try:
            fn(*a)
        except Exception as exc:  # a control must not kill viser's thread: say it here
            self.message(f'error: {exc}')

    # -- the exam ---------------------------------------------------------------------------

    def message(self, text: str) -> None:
        """A line under the exam's controls (escaped; ``last_message`` keeps it as given)."""
        self.last_message = text
        self.g_msg.content = md(text)

    def show_loop_health(self, text: str) -> None:
        """A line under the exam's messages that the haptic loop fell behind (``text``:
        :func:`~haptic_anfis.device.loop_health.behind_text`), or none (``''``)."""
        content = f'**haptic loop behind**: {md(text)}' if text else ''
        if content != self.g_loop.content:   # every update redraws the page for a while
            self.g_loop.content = content

    def show_case_choice(self, name: str) -> None:
        """Show ``name`` (a case or :data:`BLIND`) in the dropdown without choosing it; a name
        the dropdown does not list (a case not ready) leaves it as it is."""
        if name in self.g_case.options:
            self.g_case.value = name

    def set_running(self, running: bool) -> None:
        """Start / stop buttons for an exam running or not."""
        self.g_start.disabled, self.g_stop.disabled = running, not running

    # -- the class --------------------------------------------------------------------------

    def refresh(self, select: str | None = None) -> None:
        """Read the record again: the overview table, the trainee list, the curves of
        ``select`` (None: the ones shown). A record that cannot be read is said, not raised."""
        with self._lock:
            try:
                self.rows = overview(self.db, self.mastery_config or DEFAULT)
            except (RecordError, OSError) as exc:
                self.rows = []
                self.g_overview.content = f'trainee record: {md(exc)}'
                return
            self.g_overview.content = overview_markdown(self.rows)
            ids = [r['trainee'] for r in self.rows] or [NOBODY]
            pick = select if select in ids else (self.g_pick.value if self.g_pick.value in ids
                                                 else ids[0])
            self.g_pick.options = ids
            self.g_pick.value = pick
            self._show_curves(pick)

    def _show_curves(self, trainee: str) -> None:
        with self._lock:
            row = next((r for r in self.rows if r['trainee'] == trainee), None)
            if row is None:
                return
            img = curves_image(trainee, row['sessions_list'])
            if self.g_curves is None:
                with self.server.gui.add_folder('Curves'):
                    self.g_curves = self.server.gui.add_image(img, label='learning curves',
                                                              format='png')
            else:
                self.g_curves.image = img

    def overview_csv(self) -> str:
        """The overview as CSV text (:func:`~haptic_anfis.record.overview.overview_csv`)."""
        return overview_csv(self.rows)

    def _export(self, client) -> None:
        if client is not None:
            client.send_file_download('class_overview.csv', self.overview_csv().encode())

    def close(self) -> None:
        self.server.stop()
        close_door(self.door)


def overview_markdown(rows: list[dict]) -> str:
    """The class overview as a Markdown table, every text escaped."""
    if not rows:
        return 'no trainee in the record yet'
    head = ('| trainee | sessions | last score | mastered level | best | deep % last | flags |\n'
            '|---|---|---|---|---|---|---|')
    lines = []
    for r in rows:
        flags = ', '.join(f for f, on in (('stalled', r['stalled']),
                                          ('drifting', r['drifting'])) if on) or '-'
        f = lambda v, d=0: '-' if v is None else f'{v:.{d}f}'  # noqa: E731
        lines.append(f"| {md(r['trainee'])} | {r['sessions']} | {f(r['last_score'])} "
                     f"({md(r['last_verdict'] or '-')}) | {r['mastered_level'] or 'none'} | "
                     f"{f(r['best_score'])} | {f(r['deep_coverage_last_pct'])} | {flags} |")
    return head + '\n' + '\n'.join(lines)
