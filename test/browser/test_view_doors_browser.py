"""The two doors in a real browser (Debian's chromium, headless, driven over the DevTools protocol
with real mouse and key events): the trainee's page has no control, the console's button and
text field work, typed markup stays text, and a page of another site cannot connect to either.

Skipped, saying why, where chromium or viser is absent (.ci/run installs chromium)."""
from __future__ import annotations

import http.server
import threading
import time

import pytest

pytest.importorskip('viser', reason='the view extra (pip install .[view]) is not installed')

import viser  # noqa: E402

from haptic_anfis.view.browser import (Page, chromium, close_chromium, free_port,  # noqa: E402
                                       open_chromium)

pytestmark = pytest.mark.skipif(chromium() is None,
                                reason='chromium is not installed (apt-get install chromium)')

TOKEN = 'browser-test-token-0123456789'
SIZE = (1280, 800)


@pytest.fixture
def doors(tmp_path):
    from haptic_anfis.view.app import ViewApp
    from haptic_anfis.view.build import case_view
    from haptic_anfis.view.console import ConsoleApp
    cv = case_view(None)
    page = ViewApp(cv.vertices, cv.faces, cv.region_faces, cv.config.thresholds,
                   port=free_port(), deformation=cv.deformation)
    console = ConsoleApp(free_port(), TOKEN, ['default'], db=tmp_path / 'record.sqlite')
    try:
        yield page, console
    finally:
        console.close()
        page.close()


def wait_until(cond, seconds: float):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.1)
    return bool(cond())


class Browser:
    """One headless chromium on ``url`` and its DevTools page."""

    def __init__(self, url: str):
        self.proc = open_chromium(url, SIZE)
        self.page = Page(self.proc, SIZE, 60.0)

    def js(self, expr: str):
        r = self.page.call('Runtime.evaluate', expression=expr, returnByValue=True)
        return r.get('result', {}).get('value')

    def wait(self, expr: str, seconds: float = 60.0):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            v = self.js(expr)
            if v:
                return v
            time.sleep(0.25)
        raise AssertionError(f'not within {seconds:g} s: {expr}')

    def click(self, text: str) -> None:
        """A real mouse click (pressed, released) at the middle of the button saying ``text``."""
        rect = self.wait(f"""(() => {{ const b = [...document.querySelectorAll('button')]
            .find(e => e.innerText.trim() === {text!r});
            if (!b) return null; const r = b.getBoundingClientRect();
            return [r.x + r.width / 2, r.y + r.height / 2]; }})()""")
        for kind in ('mousePressed', 'mouseReleased'):
            self.page.call('Input.dispatchMouseEvent', type=kind, x=rect[0], y=rect[1],
                           button='left', clickCount=1)

    def type_into(self, label: str, text: str) -> None:
        """Click the text field labelled ``label`` and type ``text`` key by key."""
        rect = self.wait(f"""(() => {{ const l = [...document.querySelectorAll('label')]
            .find(e => e.innerText.trim() === {label!r});
            const i = l && [...document.querySelectorAll('input')].filter(
                x => x.type === 'text').find(
                x => l.compareDocumentPosition(x) & Node.DOCUMENT_POSITION_FOLLOWING);
            if (!i) return null; const r = i.getBoundingClientRect();
            return [r.x + r.width / 2, r.y + r.height / 2]; }})()""")
        for kind in ('mousePressed', 'mouseReleased'):
            self.page.call('Input.dispatchMouseEvent', type=kind, x=rect[0], y=rect[1],
                           button='left', clickCount=1)
        for ch in text:
            self.page.call('Input.dispatchKeyEvent', type='keyDown', text=ch)
            self.page.call('Input.dispatchKeyEvent', type='keyUp')
        self.page.call('Input.dispatchKeyEvent', type='keyDown', key='Tab', code='Tab',
                       windowsVirtualKeyCode=9)   # leave the field: viser sends the value

    def close(self) -> None:
        self.page.close()
        close_chromium(self.proc)


def test_the_trainee_page_has_no_control_and_the_console_works_with_real_input(doors):
    page, console = doors
    b = Browser(page.url)
    try:
        b.wait(f"document.body.innerText.includes('coverage')")
        text = b.js('document.body.innerText')
        assert 'start exam' not in text and 'trainee id' not in text and 'Class' not in text
        labels = b.js("[...document.querySelectorAll('label')].map(l => l.innerText.trim())")
        assert 'case' not in labels and 'trainee id' not in labels, labels
    finally:
        b.close()
    pressed = []
    console.on_start = lambda: pressed.append('start')
    b = Browser(console.url)
    try:
        b.wait("document.body.innerText.includes('start exam')")
        end = time.monotonic() + 30.0   # the client takes input once its replay is done
        while not pressed and time.monotonic() < end:
            b.click('start exam')
            wait_until(lambda: pressed, 3.0)
        assert pressed and set(pressed) == {'start'}
        evil = '<img src=x id=evil>'
        b.type_into('trainee id', evil)
        assert wait_until(lambda: console.trainee == evil, 20.0), console.trainee
        console.message(f'--trainee-id {console.trainee!r}: expected letters')   # as refused
        b.wait("document.body.innerText.includes('<img src=x id=evil>')")
        assert b.js("document.querySelectorAll('#evil, img[src=\"x\"]').length") == 0
    finally:
        b.close()


def test_a_page_of_another_site_cannot_connect_to_either_door(doors, tmp_path):
    page, console = doors
    protocol = f'viser-v{viser.__version__}'
    targets = [f'ws://127.0.0.1:{page.port}', f'ws://127.0.0.1:{console.port}/{TOKEN}']
    html = ('<html><body><script>document.title = "";' + ''.join(
        f"""(() => {{ const w = new WebSocket({t!r}, [{protocol!r}]);
            w.onopen = () => document.title += '|open{i}';
            w.onclose = () => document.title += '|refused{i}'; }})();"""
        for i, t in enumerate(targets)) + '</script></body></html>')
    (tmp_path / 'index.html').write_text(html)

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *a, **kw):
            super().__init__(*a, directory=str(tmp_path), **kw)

        def log_message(self, *a):
            pass
    evil = http.server.ThreadingHTTPServer(('127.0.0.1', free_port()), Quiet)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    before = (page.door.refused, console.door.refused)
    b = Browser(f'http://127.0.0.1:{evil.server_port}/')
    try:
        title = b.wait("document.title.split('|').filter(x => x).length >= 2 && "
                       "document.title", 60.0)
        assert set(title.strip('|').split('|')) == {'refused0', 'refused1'}, title
    finally:
        b.close()
        evil.shutdown()
    assert page.door.refused > before[0] and console.door.refused > before[1]
