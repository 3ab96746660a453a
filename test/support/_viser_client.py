"""A websocket client speaking viser's protocol (for tests): the ``viser-v<version>`` subprotocol,
frames of zstd-compressed msgpack (``viser.infra._infra._message_producer``'s layout) in,
msgpack messages out, with any ``Origin`` and path a hostile page or process would use."""
from __future__ import annotations

import time

import msgspec
import viser
import zstandard
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

PROTOCOL = f'viser-v{viser.__version__}'


def decode(frame: bytes) -> list[dict]:
    """The messages of one server frame."""
    n = int.from_bytes(frame[:8], 'little')
    m = int.from_bytes(frame[8:16], 'little')
    inner = zstandard.ZstdDecompressor().decompress(frame[16:16 + m], max_output_size=n)
    return list(msgspec.msgpack.decode(inner)['messages'])


class Client:
    """One connection to ``ws://127.0.0.1:<port><path>`` from ``origin`` (None: no header).

    Raises (on open): ``websockets.exceptions.InvalidStatus`` when the server refuses."""

    def __init__(self, port: int, origin: str | None, path: str = '',
                 host: str = '127.0.0.1'):
        self.ws = connect(f'ws://{host}:{port}{path}', subprotocols=[PROTOCOL], origin=origin,
                          open_timeout=10)
        self.messages: list[dict] = []
        self.received = 0   # bytes

    def read(self, seconds: float = 2.0) -> list[dict]:
        """Every message that arrives within ``seconds`` (appended to ``messages``)."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                frame = self.ws.recv(timeout=left)
            except (TimeoutError, ConnectionClosed):
                break
            self.received += len(frame)
            self.messages += decode(frame)
        return self.messages

    def send(self, message: dict) -> None:
        self.ws.send(msgspec.msgpack.encode(message))

    def close(self) -> None:
        self.ws.close()

    def __enter__(self) -> 'Client':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def types(messages: list[dict]) -> set[str]:
    return {m.get('type') for m in messages}


def texts(messages: list[dict]) -> str:
    """Every string the messages carry, joined (what a client could read)."""
    out: list[str] = []

    def walk(v):
        if isinstance(v, str):
            out.append(v)
        elif isinstance(v, dict):
            for x in v.values():
                walk(x)
        elif isinstance(v, (list, tuple)):
            for x in v:
                walk(x)
    walk(messages)
    return '\n'.join(out)
