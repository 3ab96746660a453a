"""The doors of the browser pages: which requests a viser server answers (no ROS).

viser 1.1.1 serves its page and its websocket on one port with ``websockets``' asyncio server
and checks nothing about who connects: no ``Origin`` check (``websockets.asyncio.server.serve``
takes ``origins=`` but viser does not pass it), no token, no hook of its own before a client
gets the whole scene and can press every control. Its ``process_request`` (the static files) is
a closure inside the server thread. So this module puts a :class:`Door` in front of it, in the
one place every viser server's connections pass: viser's module reference to ``websockets``
(:func:`install`) is replaced by a view of the same package whose ``asyncio.server.serve``
chains the door's check before viser's own ``process_request`` and wraps viser's connection
handler. A server whose port has no door refuses every request (fail closed), and
:func:`guarded` says whether a server's port went through it, so an app can refuse to run when
viser's internals change under it.

A door checks, for every HTTP request and websocket handshake:

- ``Host``: one of the server's own names (``127.0.0.1``, ``localhost``, ``[::1]``; bound to
  another address, that address, this machine's host names, or any IP literal): a page from
  another site whose name was re-pointed at this machine (DNS rebinding) is refused.
- ``Origin`` (websockets): present and the page's own, ``http://<Host>``: a page of another
  site open in the same browser cannot connect (browsers always send it on a websocket).
- a ``token`` (the instructor's console): the first path segment (``/<token>/``; viser's
  client opens its websocket on the page's path, so the websocket carries it too), compared in
  constant time; the page's own files are then served as from ``/``.

A websocket connection whose handler fails (a malformed message: viser's ``deserialize``
raises, or a text frame) is logged in ONE line (``haptic_anfis.view`` logger, at most one line
per ``LOG_EVERY`` seconds per door, with the count) and closed; the server keeps serving. A
message that decodes but fails in viser's handler (a GUI update of a property that does not
exist) fails in a task of the server's event loop: the loop's exception handler (asyncio's hook)
logs it the same way instead of asyncio's traceback; viser's warning for a field of the wrong
type is not printed (the message is then handled, or fails, as above). Refused requests are
counted and logged the same way.
"""
from __future__ import annotations

import hmac
import ipaddress
import logging
import os
import secrets
import socket
import threading
import time
import warnings
from dataclasses import dataclass, field
from http import HTTPStatus
from pathlib import Path
from types import ModuleType
from typing import Any, Callable

from ..errors import HapticAnfisError

__all__ = ['Door', 'DoorError', 'TOKEN_ENV', 'install', 'guarded', 'open_door', 'close_door',
           'load_token', 'LOG_EVERY']

LOG = logging.getLogger('haptic_anfis.view')
#: the environment variable holding the instructor console's token
TOKEN_ENV = 'HAPTIC_ANFIS_CONSOLE_TOKEN'
#: [s] at most one log line per door and kind (refused, malformed) this often
LOG_EVERY = 10.0
#: shortest token accepted from a file or the environment [characters]
MIN_TOKEN = 16
_LOOPBACK_NAMES = ('127.0.0.1', 'localhost', '::1')


class DoorError(HapticAnfisError, ValueError):
    """A door cannot be set up (a token too short, unreadable, viser's server not guarded)."""


@dataclass
class Door:
    """What one server (``port``) lets in: its ``hosts`` (names a browser may call it by; IP
    literals too when ``any_ip``), and a ``token`` ('' = none). Counts what it refused and the
    connections that failed."""
    port: int
    hosts: frozenset[str]
    any_ip: bool = False
    token: str = ''
    label: str = 'page'
    refused: int = 0
    failed: int = 0
    used: bool = False   # viser's server for this port was built through the door
    _last_log: dict = field(default_factory=dict)

    def check(self, path: str, headers) -> tuple[str | None, str]:
        """(why the request is refused or None, the path to serve): ``path`` is the request's,
        ``headers`` its headers (``.get``)."""
        host = (headers.get('Host') or '').strip()
        if not self._host_ok(host):
            return f'Host {host!r} is not this server', path
        websocket = (headers.get('Upgrade') or '').lower() == 'websocket'
        if websocket:
            origin = headers.get('Origin')
            if origin not in (f'http://{host}', f'https://{host}'):
                return f'Origin {origin!r} is not this page (http://{host})', path
        if self.token:
            first, _, rest = path.lstrip('/').partition('/')
            first = first.partition('?')[0]
            if not hmac.compare_digest(first.encode(), self.token.encode()):
                return 'no or wrong token', path
            path = '/' + rest
        return None, path

    def _host_ok(self, host: str) -> bool:
        name = host
        if name.startswith('['):   # [::1]:8080
            name = name[1:].partition(']')[0]
            port = host.rpartition(']:')[2] if ']:' in host else ''
        else:
            name, _, port = host.rpartition(':') if host.count(':') == 1 else (host, '', '')
        if port and port != str(self.port):
            return False
        if name.lower() in self.hosts:
            return True
        if self.any_ip:
            try:
                ipaddress.ip_address(name)
                return True
            except ValueError:
                return False
        return False

    def note(self, kind: str, text: str) -> None:
        """Count ``kind`` ('refused' / 'failed') and log ``text`` in one line, at most once per
        :data:`LOG_EVERY` per kind."""
        n = self.refused if kind == 'refused' else self.failed
        now = time.monotonic()
        if now - self._last_log.get(kind, -LOG_EVERY) >= LOG_EVERY:
            self._last_log[kind] = now
            LOG.warning('%s (port %d): %s (%d %s so far)', self.label, self.port,
                        text.replace('\n', ' ')[:300], n, kind)


_doors: dict[int, Door] = {}
_lock = threading.Lock()
_real: ModuleType | None = None


def host_names(host: str) -> tuple[frozenset[str], bool]:
    """(the names a browser may use for a server bound to ``host``, whether any IP literal may
    be used): loopback names always; a wildcard bind adds this machine's names and any IP
    literal, another address itself."""
    names = set(_LOOPBACK_NAMES)
    any_ip = False
    if host in ('', '0.0.0.0', '::'):
        any_ip = True
        names.update(n.lower() for n in (socket.gethostname(), socket.getfqdn()) if n)
    elif host.lower() not in names:
        names.add(host.lower())
    return frozenset(names), any_ip


def open_door(port: int, host: str, token: str = '', label: str = 'page') -> Door:
    """The door of the server about to start on ``port`` (bound to ``host``); :func:`install`
    must have run (it is run here)."""
    install()
    hosts, any_ip = host_names(host)
    door = Door(int(port), hosts, any_ip, token, label)
    with _lock:
        _doors[int(port)] = door
    return door


def close_door(door: Door) -> None:
    with _lock:
        if _doors.get(door.port) is door:
            del _doors[door.port]


def guarded(door: Door) -> bool:
    """Whether viser's server on the door's port was built through it."""
    return door.used


def _forbidden(connection, why: str):
    return connection.respond(HTTPStatus.FORBIDDEN, f'refused: {why}\n')


def _guarded_serve(handler: Callable, host: str, port: int, *args: Any,
                   process_request: Callable | None = None, **kwargs: Any):
    """``websockets.asyncio.server.serve`` as viser calls it, with the door of ``port`` first
    and viser's connection handler wrapped (one line for a connection that fails)."""
    assert _real is not None
    with _lock:
        door = _doors.get(int(port))
    if door is not None:
        door.used = True

    def check(connection, request):
        if door is None:   # a viser server on a port nobody opened a door for: closed
            return _forbidden(connection, 'no door for this port')
        why, path = door.check(request.path, request.headers)
        if why is not None:
            door.refused += 1
            door.note('refused', why)
            return _forbidden(connection, why)
        request.path = path
        return process_request(connection, request) if process_request is not None else None

    async def handle(connection) -> None:
        try:
            await handler(connection)
        except Exception as exc:   # a malformed message: one line, the server keeps serving
            if door is not None:
                door.failed += 1
                door.note('failed', f'a client connection failed and was closed: '
                                    f'{type(exc).__name__}: {exc}')
    return _real.asyncio.server.serve(handle, host, port, *args, process_request=check,
                                      **kwargs)


class _QuietHandshakes(logging.Filter):
    """Drops websockets' records of handshakes that failed or were refused (viser drops the same
    two, but only once a request reached its own handler)."""

    def filter(self, record: logging.LogRecord) -> bool:
        msg = record.getMessage()
        return not (msg == 'opening handshake failed' or msg.startswith('connection rejected'))


class _Namespace:
    """A read-through view of a module with some attributes replaced."""

    def __init__(self, real: ModuleType, **replaced: Any):
        self._real = real
        self.__dict__.update(replaced)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._real, name)


def install() -> None:
    """Replace viser's module reference to ``websockets`` by one whose ``asyncio.server.serve``
    is :func:`_guarded_serve` (idempotent); viser's warning for a message field of the wrong
    type is not printed (a client's message: the door counts what fails).

    Raises:
        DoorError: viser's server module does not reach ``websockets`` where expected.
    """
    global _real
    from viser.infra import _infra
    with _lock:
        if isinstance(_infra.websockets, _Namespace):
            return
        real = _infra.websockets
        if not hasattr(getattr(getattr(real, 'asyncio', None), 'server', None), 'serve'):
            raise DoorError("viser's server module does not use websockets.asyncio.server.serve:"
                            ' the pages cannot be guarded with this viser version')
        _real = real
        # a browser's speculative connection that closes before its request, and every refusal
        # of ours, would be a traceback / a line of websockets' own each: the door counts them
        logging.getLogger('websockets.server').addFilter(_QuietHandshakes())
        warnings.filterwarnings('ignore', message=r'\[viser\] .* does not match annotation')
        server = _Namespace(real.asyncio.server, serve=_guarded_serve)
        _infra.websockets = _Namespace(real, asyncio=_Namespace(real.asyncio, server=server))


def load_token(path: str = '') -> tuple[str, str]:
    """(the console token, where it came from): the file ``path`` (its first line), else
    :data:`TOKEN_ENV`, else a new random one ('generated').

    Raises:
        DoorError: an unreadable file, or a token shorter than :data:`MIN_TOKEN` characters or
            with characters other than letters, digits, ``-`` and ``_`` (it is a URL path).
    """
    if path:
        try:
            token, where = Path(path).read_text().splitlines()[0].strip(), path
        except (OSError, IndexError) as exc:
            raise DoorError(f'console token file {path}: cannot read a token '
                            f'({getattr(exc, "strerror", None) or "empty file"})') from None
    elif os.environ.get(TOKEN_ENV):
        token, where = os.environ[TOKEN_ENV].strip(), f'${TOKEN_ENV}'
    else:
        return secrets.token_urlsafe(24), 'generated'
    if len(token) < MIN_TOKEN or not all(c.isascii() and (c.isalnum() or c in '-_')
                                         for c in token):
        raise DoorError(f'console token from {where}: expected at least {MIN_TOKEN} letters, '
                        'digits, - or _')
    return token, where


def guarded_server(port: int, host: str, label: str, token: str = ''):
    """(a viser server on ``host:port`` behind a :class:`Door`, the door). ``label``: the page's
    title and the door's name in log lines.

    Raises:
        DoorError: viser's server was not built through the door (its internals changed): the
            server is stopped, nothing is served unguarded.
    """
    import viser
    door = open_door(port, host, token, label)
    server = viser.ViserServer(host=host, port=int(port), label=label, verbose=False)
    if not guarded(door) or server.get_port() != int(port):
        server.stop()
        close_door(door)
        raise DoorError(f'{label}: viser did not serve port {port} through its door; refusing to '
                        'serve it unguarded')

    def failed_task(loop, context) -> None:   # a client's message failed in viser's handler
        exc = context.get('exception')
        door.failed += 1
        door.note('failed', f"a client's message failed: {type(exc).__name__}: {exc}"
                  if exc is not None else str(context.get('message')))
    server.get_event_loop().set_exception_handler(failed_task)
    return server, door
