"""The control panel's web server: its static page over HTTP and each page's WebSocket
(``/ws``), served by the ``websockets`` package on an asyncio loop in a thread of its own.

It knows nothing of ROS. What a page sends goes to the ``PanelHandler`` (the node), which
answers with a refusal or None; what the pages are shown is posted with :meth:`broadcast`
from any thread. Who may connect is ``ros_common.web_access``'s rule (pages of other sites,
DNS rebinding); at most ``max_pages`` pages at once, each with a bounded outbox
(``panel_core.Outbox``) that a page that never reads cannot grow.
"""
from __future__ import annotations

import asyncio
import http
import itertools
import json
import threading
import time
from pathlib import Path
from typing import Any, Dict, Optional, Protocol

from websockets.asyncio.server import ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from ros_common.log_limit import KeyedLimiter
from ros_common.web_access import WebAccess
from teleop.panel_core import Outbox

WEB = Path(__file__).resolve().parent / 'web'
STATIC = {'/': ('index.html', 'text/html; charset=utf-8'),
          '/index.html': ('index.html', 'text/html; charset=utf-8'),
          '/panel.js': ('panel.js', 'text/javascript; charset=utf-8'),
          '/panel.css': ('panel.css', 'text/css; charset=utf-8')}
MAX_FRAME = 64 * 1024           # what a page may send in one message
# Keepalive: a page whose pong has not come back PING_TIMEOUT s after a ping is dropped (its
# slot freed, page_gone). The pong queues behind everything the page sent before it and behind
# the server's own backlog on a busy machine, so the timeout is a liveness check, not a
# deadline: safety is the dead man's (deadman_timeout, 0.3 s), not this. (At 1 s / 2 s a page
# that sent a burst and then waited for its answer was cut off on a loaded machine.)
PING_INTERVAL, PING_TIMEOUT = 5.0, 20.0


class PanelServerError(RuntimeError):
    """The server cannot serve (the port taken, the page's files missing)."""


class PanelHandler(Protocol):
    """What the server asks of the panel."""

    def command(self, page: int, text: Any) -> Optional[str]:
        """A page's message; the reason it was refused, or None."""

    def page_gone(self, page: int) -> None: ...

    def hello(self) -> Dict[str, Any]:
        """The first message a page gets."""


class PanelServer:
    """Serves the panel's page until :meth:`close`."""

    def __init__(self, handler: PanelHandler, logger: Any, host: str, port: int,
                 access: WebAccess, max_pages: int, web: Path = WEB) -> None:
        for name, _kind in STATIC.values():
            if not (web / name).is_file():
                raise PanelServerError(f'the page is missing: {web / name}')
        self._handler, self._log, self._web = handler, logger, web
        self._host, self.port = host, port
        self._lines = KeyedLimiter(1.0)          # (one line a second of each kind)
        self._access, self._max_pages = access, max_pages
        self._pages: Dict[int, _Page] = {}        # (the loop owns them)
        self._page_ids = itertools.count(1)
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: Optional[BaseException] = None
        self._thread = threading.Thread(target=self._serve, name='control_panel_http',
                                        daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._error is not None or not self._ready.is_set():
            raise PanelServerError(f'cannot serve on {host}:{port}: {self._error or "no answer"}')
        self.url = f'http://{host}:{self.port}/'

    @property
    def pages(self) -> int:
        """Pages connected now."""
        return len(self._pages)

    def broadcast(self, kind: str, message: Any) -> None:
        """Post the latest ``kind`` of news to every page (from any thread): bytes as they
        are, anything else as JSON."""
        data = message if isinstance(message, bytes) else json.dumps(message)
        if self._pages and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._post_all, kind, data)

    def close(self) -> None:
        if not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(2.0)

    # --- the loop's side ----------------------------------------------------------------------
    def _serve(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._start())
        except OSError as exc:
            self._error = exc
            return
        self._ready.set()
        self._loop.run_forever()

    async def _start(self) -> None:
        self._server = await serve(self._page, self._host, self.port,
                                   process_request=self._http, max_size=MAX_FRAME,
                                   ping_interval=PING_INTERVAL, ping_timeout=PING_TIMEOUT)
        if self.port == 0:
            self.port = self._server.sockets[0].getsockname()[1]

    def _http(self, connection: ServerConnection, request: Request) -> Optional[Response]:
        path = request.path.split('?', 1)[0]
        websocket = path == '/ws'
        # Only this server's own names, and a browser's WebSocket only from the panel's own
        # page (ros_common/web_access.py: pages of other sites, DNS rebinding).
        refusal = self._access.check(request.headers.get_all('Host'),
                                     request.headers.get_all('Origin'), websocket)
        if refusal is not None:
            self._warn('refused', f'refused a request for {path[:100]!r} from '
                       f'{_peer(connection)}: {refusal.reason}')
            return connection.respond(http.HTTPStatus(refusal.status), refusal.reason + '\n')
        if websocket:
            if len(self._pages) >= self._max_pages:
                self._warn('full', f'refused a page: {len(self._pages)} pages are connected '
                           '(max_pages)')
                return connection.respond(http.HTTPStatus.SERVICE_UNAVAILABLE,
                                          f'{len(self._pages)} pages are connected\n')
            return None                         # the page's WebSocket
        if path not in STATIC:
            return connection.respond(http.HTTPStatus.NOT_FOUND, 'not found\n')
        name, kind = STATIC[path]
        body = (self._web / name).read_bytes()
        return Response(200, 'OK', Headers([('Content-Type', kind),
                                            ('Content-Length', str(len(body))),
                                            ('Cache-Control', 'no-store')]), body)

    async def _page(self, connection: ServerConnection) -> None:
        page = _Page(next(self._page_ids), connection)
        self._pages[page.id] = page
        self._log.info(f'page {page.id} connected from {_peer(connection)}')
        sender = asyncio.ensure_future(page.send_loop())
        page.post('hello', json.dumps(self._handler.hello()))
        try:
            async for text in connection:
                refused = self._command(page.id, text)
                if refused is not None:
                    page.outbox.refuse(refused)
                    page.wake.set()
        except ConnectionClosed:
            pass
        finally:
            sender.cancel()
            del self._pages[page.id]
            self._handler.page_gone(page.id)
            self._log.info(f'page {page.id} left')

    def _command(self, page: int, text: Any) -> Optional[str]:
        try:
            return self._handler.command(page, text)
        except Exception as exc:    # (a bug must not cut the page off)
            line = self._lines.text('failed', time.monotonic(), f'page {page}: a message '
                                    f'failed: {type(exc).__name__}: {exc}')
            if line is not None:
                self._log.error(line)
            return f'internal error: {type(exc).__name__}'

    def _warn(self, kind: str, text: str) -> None:
        line = self._lines.text(kind, time.monotonic(), text)
        if line is not None:
            self._log.warn(line)

    def _post_all(self, kind: str, data: Any) -> None:
        for page in self._pages.values():
            page.post(kind, data)


class _Page:
    """A connected page: its connection, what it is owed (``Outbox``), and the task that
    sends it, one message at a time, as fast as the page reads."""

    def __init__(self, page_id: int, connection: ServerConnection) -> None:
        self.id, self.connection = page_id, connection
        self.outbox = Outbox()
        self.wake = asyncio.Event()

    def post(self, kind: str, data: Any) -> None:
        self.outbox.put(kind, data)
        self.wake.set()

    async def send_loop(self) -> None:
        try:
            while True:
                await self.wake.wait()
                self.wake.clear()
                while (data := self.outbox.take()) is not None:
                    await self.connection.send(data)
        except ConnectionClosed:
            pass


def _peer(connection: ServerConnection) -> str:
    address = connection.remote_address
    return str(address[0]) if address else 'an unknown peer'
