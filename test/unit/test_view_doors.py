"""The two doors: the trainee's page answers only its own origin and shows the exam alone; the
instructor's console needs its token too; a malformed message costs one log line; texts are
escaped. Spoken to with viser's own protocol (``_viser_client``) as a hostile page would."""
from __future__ import annotations

import logging
import urllib.error
import urllib.request

import numpy as np
import pytest

pytest.importorskip('viser', reason='the view extra (pip install .[view]) is not installed')

from websockets.exceptions import InvalidStatus  # noqa: E402

from haptic_anfis.record import store_session  # noqa: E402
from haptic_anfis.view.browser import free_port  # noqa: E402
from haptic_anfis.view.doors import (Door, DoorError, close_door, guarded_server,  # noqa: E402
                                     host_names, load_token)
from haptic_anfis.view.escape import md  # noqa: E402

from _viser_client import Client, texts, types  # noqa: E402

TOKEN = 'T0k3n-for-the-tests_0123456789'
REPORT = {'coverage_pct': {'light': 90.0, 'medium': 70.0, 'deep': 40.0}, 'hits': 1, 'misses': 0,
          'false_marks': 0, 'score': 55.0, 'verdict': 'needs practice', 'duration_s': 60.0,
          'lesions': []}


@pytest.fixture
def page():
    from haptic_anfis.view.app import ViewApp
    from haptic_anfis.view.build import case_view
    cv = case_view(None)
    app = ViewApp(cv.vertices, cv.faces, cv.region_faces, cv.config.thresholds,
                  port=free_port(), deformation=cv.deformation)
    yield app
    app.close()


@pytest.fixture
def console(tmp_path):
    from haptic_anfis.view.console import ConsoleApp
    db = tmp_path / 'record.sqlite'
    store_session(db, 'victim01', dict(REPORT, case='lib_l_dense_idc18_d25'))
    c = ConsoleApp(free_port(), TOKEN, ['default', 'normal'], db=db)
    yield c
    c.close()


def _get(port: int, path: str = '/', host: str | None = None) -> int:
    req = urllib.request.Request(f'http://127.0.0.1:{port}{path}')
    if host:
        req.add_header('Host', host)
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status
    except urllib.error.HTTPError as e:
        return e.code


def test_another_origin_is_refused_and_the_pages_own_gets_the_exam_alone(page):
    port = page.port
    for origin in ('http://evil.example', f'http://evil.example:{port}', None,
                   f'http://localhost:{port + 1}'):
        with pytest.raises(InvalidStatus, match='403'):
            Client(port, origin)
    with Client(port, f'http://127.0.0.1:{port}') as c:
        msgs = c.read(3.0)
    kinds = types(msgs)
    assert 'GuiMarkdownMessage' in kinds and 'GuiHtmlMessage' in kinds   # the gauge, the legend
    # no control of the session: no case choice, no start / stop, no trainee id
    assert not kinds & {'GuiButtonMessage', 'GuiDropdownMessage', 'GuiTextMessage'}
    assert 'trainee' not in texts(msgs).lower()
    assert page.door.refused == 4


def test_a_rebound_host_name_is_refused_even_from_its_own_origin(page):
    """DNS rebinding: evil.example re-pointed at 127.0.0.1 sends Host and Origin of its own."""
    host = f'evil.example:{page.port}'
    assert _get(page.port, host=host) == 403
    assert _get(page.port) == 200 and _get(page.port, host=f'localhost:{page.port}') == 200
    with pytest.raises(InvalidStatus, match='403'):
        Client(page.port, f'http://{host}', host='127.0.0.1')


def test_the_console_refuses_any_client_without_its_token(console):
    port = console.port
    own = f'http://127.0.0.1:{port}'
    for path in ('', '/', '/wrong-token-0123456789', f'/{TOKEN[:-1]}', f'/x/{TOKEN}'):
        with pytest.raises(InvalidStatus, match='403'):
            Client(port, own, path)
        assert _get(port, path or '/') == 403
    with pytest.raises(InvalidStatus, match='403'):
        Client(port, 'http://evil.example', f'/{TOKEN}')   # the token, another origin
    assert _get(port, f'/{TOKEN}/') == 200   # the page itself, with the token
    with Client(port, own, f'/{TOKEN}') as c:   # as viser's client opens it: the page's path
        msgs = c.read(3.0)
    kinds = types(msgs)
    assert {'GuiButtonMessage', 'GuiDropdownMessage', 'GuiTextMessage'} <= kinds
    assert 'victim01' in texts(msgs)   # the class overview
    assert console.url == f'http://127.0.0.1:{port}/{TOKEN}/'


def test_a_malformed_message_is_one_log_line_and_the_page_keeps_serving(page, caplog, capfd):
    own = f'http://127.0.0.1:{page.port}'
    caplog.set_level(logging.WARNING, logger='haptic_anfis.view')
    for bad in (b'\x93garbage', b'\xc1', b'{"type": "nothing"}'):
        c = Client(page.port, own)
        c.ws.send(bad)
        c.read(1.0)
        c.close()
    for msg in ({'type': 'NoSuchMessage', 'x': 1},   # fails decoding: the connection closes
                # decodes, then fails in viser's handler (a task of its event loop)
                {'type': 'GuiUpdateMessage', 'uuid': page.g_time._impl.uuid,
                 'updates': {'no_such_property': [1, 2]}},
                {'type': 'ViewerCameraMessage', 'wxyz': 'x'}):   # a field of the wrong type
        c = Client(page.port, own)
        c.send(msg)
        c.read(1.0)
        c.close()
    lines = [r for r in caplog.records if r.name == 'haptic_anfis.view']
    assert len(lines) == 1 and '\n' not in lines[0].getMessage()
    assert 'connection failed and was closed' in lines[0].getMessage()
    assert page.door.failed >= 5
    with Client(page.port, own) as c:   # still serving
        assert 'GuiMarkdownMessage' in types(c.read(2.0))
    err = capfd.readouterr().err   # no traceback, no warning printed besides the log
    assert 'Traceback' not in err and 'Warning' not in err, err


def test_texts_a_user_typed_are_shown_escaped(console, page):
    evil = '<img src=x onerror=alert(1)> [x](javascript:alert(1)) **b**'
    console.message(f'trainee id {evil!r}: refused')
    page.message(evil)
    for content in (console.g_msg.content, page.g_status.content):
        assert '<' not in content and '](' not in content and '**' not in content
    assert md('Zoë_1.b') == 'Zoë\\_1.b'


def test_a_viser_server_on_a_port_without_a_door_refuses_everything():
    import viser
    port = free_port()
    s = viser.ViserServer(host='127.0.0.1', port=port, verbose=False)
    try:
        assert _get(port) == 403
        with pytest.raises(InvalidStatus, match='403'):
            Client(port, f'http://127.0.0.1:{port}')
    finally:
        s.stop()


def test_host_names_and_tokens():
    names, any_ip = host_names('127.0.0.1')
    assert names == {'127.0.0.1', 'localhost', '::1'} and not any_ip
    d = Door(8081, names)
    assert d.check('/', {'Host': '127.0.0.1:8081'})[0] is None
    assert d.check('/', {'Host': '[::1]:8081'})[0] is None
    assert 'not this server' in d.check('/', {'Host': '127.0.0.1:8080'})[0]
    assert host_names('0.0.0.0')[1]
    with pytest.raises(DoorError, match='at least 16'):
        load_token_from('short')
    with pytest.raises(DoorError, match='letters'):
        load_token_from('a' * 20 + '/..')
    tok, where = load_token()
    assert len(tok) >= 16 and where == 'generated'
    close_door(d)   # not registered: nothing happens


def load_token_from(text: str):
    import os
    import tempfile
    with tempfile.NamedTemporaryFile('w', suffix='.token', delete=False) as f:
        f.write(text + '\n')
    try:
        return load_token(f.name)
    finally:
        os.unlink(f.name)


def test_the_console_shows_the_class_and_exports_it(console):
    for k in range(4):
        store_session(console.db, 'ann', dict(REPORT, score=50.0 - k,
                                              coverage_pct={'light': 90.0, 'medium': 70.0,
                                                            'deep': 60.0 - 15 * k}))
    console.refresh(select='ann')
    rows = {r['trainee']: r for r in console.rows}
    assert rows['ann']['sessions'] == 4 and rows['ann']['stalled']
    assert not rows['victim01']['stalled'] and not rows['victim01']['drifting']
    text = console.g_overview.content
    assert '| ann | 4 | 47 ' in text and 'stalled' in text
    csv = console.overview_csv().splitlines()
    assert csv[0].startswith('trainee,sessions,') and csv[1].startswith('ann,4,')
    assert console.g_pick.value == 'ann' and console.g_curves is not None
    img = console.g_curves.image
    assert img.ndim == 3 and img.shape[2] == 3 and np.ptp(img) > 0

    class Clicker:   # the client that pressed 'export CSV'
        sent = None

        def send_file_download(self, name, content):
            self.sent = (name, content)
    who = Clicker()
    console._export(who)
    assert who.sent == ('class_overview.csv', console.overview_csv().encode())


def test_guarded_server_closes_its_door(monkeypatch):
    port = free_port()
    server, door = guarded_server(port, '127.0.0.1', 'x')
    server.stop()
    close_door(door)
    from haptic_anfis.view import doors
    assert port not in doors._doors


def test_the_sessions_console_options_are_checked_before_any_node_starts(tmp_path):
    from haptic_anfis.session import SessionError, SessionSpec
    p = free_port()
    with pytest.raises(SessionError, match='--console-port .*the same as --view-port'):
        SessionSpec(command='sim', view=True, view_port=p, console_port=p).check(
            check_parameters=False)
    short = tmp_path / 'token'
    short.write_text('short\n')
    with pytest.raises(DoorError, match='at least 16'):
        SessionSpec(command='launch', view=True, view_port=p, console_port=free_port(),
                    console_token_file=str(short)).check(check_parameters=False)
    args = SessionSpec(command='sim', view=True, console_port=9001,
                       console_token_file=str(short)).view_arguments(controls=True)
    assert 'console_port:=9001' in args and f'console_token_file:={short}' in args
    assert not any('console' in a for a in SessionSpec(command='exam').view_arguments(False))


def test_a_launch_gives_its_web_view_one_token_for_every_restart(monkeypatch):
    import os

    from haptic_anfis.session import SessionSpec
    from haptic_anfis.session.launch_runner import ProcessSession
    from haptic_anfis.view.doors import TOKEN_ENV
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    spec = SessionSpec(command='launch', nodes=('falcon_driver', 'web_view'))
    ProcessSession(spec)
    token = os.environ[TOKEN_ENV]
    assert load_token() == (token, f'${TOKEN_ENV}')   # what the node (and a restart) reads
    ProcessSession(spec)
    assert os.environ[TOKEN_ENV] == token
