"""The live view's front door: it admits Foxglove clients by the Host and Origin rules of
``ros_common.web_access`` and a cap on their number, and relays each one to the Foxglove SDK's
server, frame by frame, through a bounded outbox (``bridge.ClientOutbox``).

The SDK checks neither Host nor Origin, so its own server must be out of a web page's reach:
it listens on loopback behind TLS, with a certificate made at start-up that only the gate
trusts. A browser refuses a WebSocket to a server whose certificate it does not trust (and
asks no one), so a page that finds the SDK's port cannot open it; the gate can.

The gate runs an asyncio loop in a thread of its own; ``start`` returns once it listens.
"""
from __future__ import annotations

import asyncio
import datetime
import http
import ipaddress
import itertools
import json
import logging
import re
import ssl
import threading
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID
from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed, InvalidHandshake
from websockets.http11 import Request, Response
from websockets.typing import Subprotocol

from live_view.bridge import ClientOutbox, SlowClients
from ros_common.web_access import WebAccess

# The subprotocols of the Foxglove WebSocket protocol, newest first (foxglove-sdk 0.30 speaks
# the first only; the gate offers its clients the one the SDK's server picks).
SUBPROTOCOLS = (Subprotocol('foxglove.sdk.v1'), Subprotocol('foxglove.websocket.v1'))
# The websockets package logs every connection at INFO: the gate logs its own lines.
_QUIET = logging.getLogger('live_view.gate.websockets')
_QUIET.setLevel(logging.WARNING)
# What a client may send in one frame (subscriptions, service calls; never data: the live view
# takes no client publishing).
MAX_CLIENT_FRAME = 1024 * 1024
UPSTREAM_HOST = '127.0.0.1'
# A subscription the SDK refuses as one to an unknown channel is sent again this often, this
# many times at most: the SDK advertises a new channel a moment before it takes subscriptions
# to it, and a client that subscribed as the advertisement came lost its subscription under
# load ("Client ... attempted to subscribe to unknown channel: 8"; no odometry in 30 s), told
# only by a status message that no client acts on [s].
RESUBSCRIBE_S, RESUBSCRIBE_TRIES = 0.1, 20
_UNKNOWN_CHANNEL = re.compile(r'Unknown channel ID: (\d+)')


class Resubscriber:
    """A client's subscriptions as it sent them, by channel, and the one to send again when the
    SDK says it does not know the channel yet."""

    def __init__(self) -> None:
        self._subscriptions: Dict[int, Dict[str, object]] = {}
        self._tries: Dict[int, int] = {}

    def sent(self, frame: object) -> None:
        """A frame the client sent the SDK."""
        msg = _json(frame)
        entries, ids = msg.get('subscriptions'), msg.get('subscriptionIds')
        if msg.get('op') == 'subscribe' and isinstance(entries, list):
            for entry in entries:
                if isinstance(entry, dict) and isinstance(entry.get('channelId'), int):
                    self._subscriptions[entry['channelId']] = entry
                    self._tries.pop(entry['channelId'], None)
        elif msg.get('op') == 'unsubscribe' and isinstance(ids, list):
            gone = {i for i in ids if isinstance(i, int)}
            for channel, entry in list(self._subscriptions.items()):
                if entry.get('id') in gone:
                    del self._subscriptions[channel]

    def again(self, frame: object) -> Optional[str]:
        """For a frame from the SDK: the subscribe to send again if it is the SDK's refusal of
        one of the client's subscriptions as to an unknown channel (and it has not been sent
        RESUBSCRIBE_TRIES times yet), else None."""
        if not (isinstance(frame, str) and 'Unknown channel' in frame):
            return None
        msg = _json(frame)
        found = _UNKNOWN_CHANNEL.search(str(msg.get('message', ''))) if msg.get(
            'op') == 'status' else None
        if found is None or int(found.group(1)) not in self._subscriptions:
            return None
        channel = int(found.group(1))
        tries = self._tries.get(channel, 0)
        if tries >= RESUBSCRIBE_TRIES:
            return None
        self._tries[channel] = tries + 1
        return json.dumps({'op': 'subscribe', 'subscriptions': [self._subscriptions[channel]]})


def _json(frame: object) -> Dict[str, object]:
    """A text frame's JSON object, or an empty one."""
    if not isinstance(frame, str):
        return {}
    try:
        msg = json.loads(frame)
    except ValueError:
        return {}
    return msg if isinstance(msg, dict) else {}


class GateError(RuntimeError):
    """The gate cannot serve (the port taken, the SDK's server out of reach)."""


def self_signed_certificate() -> Tuple[bytes, bytes]:
    """A certificate for 127.0.0.1 and its key (PEM, the key PKCS#8), made now: the SDK's
    server presents it, and only the gate, which made it, trusts it."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, 'robot-sim live_view')])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=3650))
            .add_extension(x509.SubjectAlternativeName(
                [x509.IPAddress(ipaddress.ip_address(UPSTREAM_HOST))]), critical=False)
            .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
            .sign(key, hashes.SHA256()))
    return (cert.public_bytes(serialization.Encoding.PEM),
            key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                              serialization.NoEncryption()))


@dataclass
class _Client:
    label: str
    outbox: ClientOutbox
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    reported: int = 0               # drops already handed to SlowClients
    subscriptions: Resubscriber = field(default_factory=Resubscriber)


class Gate:
    """Serves ``host:port`` for Foxglove clients and relays them to the SDK's server on
    ``upstream_port`` (TLS, trusting ``certificate`` only). ``log(level, text, kind)`` takes
    the gate's log lines from its thread (``kind``: lines of one kind may be rate-limited
    together; '' not)."""

    def __init__(self, access: WebAccess, host: str, port: int, upstream_port: int,
                 certificate: bytes, max_clients: int, send_buffer_limit: int,
                 slow: SlowClients, log: Callable[[str, str, str], None]) -> None:
        self._access, self._host, self._port = access, host, port
        self._upstream = f'wss://{UPSTREAM_HOST}:{upstream_port}'
        self._ssl = ssl.create_default_context(cadata=certificate.decode())
        self._max_clients, self._limit = max_clients, send_buffer_limit
        self._slow, self._log = slow, log
        self._clients: Dict[int, _Client] = {}
        self._ids = itertools.count(1)
        self._subprotocols: List[Subprotocol] = []
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: Optional[BaseException] = None
        self._server: Optional[Server] = None
        self._thread = threading.Thread(target=self._run, name='live_view_gate', daemon=True)

    # --- life --------------------------------------------------------------------------------
    def start(self, timeout: float = 10.0) -> int:
        """Serve; returns the port (raises GateError)."""
        self._thread.start()
        if not self._ready.wait(timeout) or self._error is not None:
            raise GateError(f'cannot serve on {self._host}:{self._port}: '
                            f'{self._error or "no answer"}')
        return self._port

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._start())
        except (OSError, GateError, InvalidHandshake, asyncio.TimeoutError) as exc:
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        self._loop.run_forever()

    async def _start(self) -> None:
        self._subprotocols = [await self._upstream_subprotocol()]
        self._server = await serve(
            self._relay, self._host, self._port, process_request=self._admit,
            subprotocols=self._subprotocols, max_size=MAX_CLIENT_FRAME, compression=None,
            ping_interval=5.0, ping_timeout=10.0, logger=_QUIET)
        if self._port == 0:
            self._port = self._server.sockets[0].getsockname()[1]

    async def _upstream_subprotocol(self) -> Subprotocol:
        """The subprotocol the SDK's server picks of those known (asked once, at start-up)."""
        try:
            async with connect(self._upstream, ssl=self._ssl, subprotocols=list(SUBPROTOCOLS),
                               open_timeout=10.0, logger=_QUIET) as probe:
                if probe.subprotocol:
                    return probe.subprotocol
        except InvalidHandshake as exc:
            raise GateError(f'the Foxglove server refused {list(SUBPROTOCOLS)}: {exc}') from None
        raise GateError(f'the Foxglove server speaks none of {list(SUBPROTOCOLS)}')

    def stop(self) -> None:
        if self._loop.is_closed() or not self._thread.is_alive():
            return

        async def close() -> None:
            if self._server is not None:
                self._server.close()
                await asyncio.wait_for(self._server.wait_closed(), 2.0)
        try:
            asyncio.run_coroutine_threadsafe(close(), self._loop).result(3.0)
        except (asyncio.TimeoutError, TimeoutError, RuntimeError):
            pass
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(2.0)

    def describe(self) -> str:
        return (f'{self._access.describe()}; at most {self._max_clients} clients, '
                f'{self._limit} bytes queued for each')

    def clients(self) -> int:
        return len(self._clients)

    def collect_drops(self) -> None:
        """Hand the drops of each client since the last call to SlowClients."""
        for client in list(self._clients.values()):
            self._report(client)

    def _report(self, client: _Client) -> None:
        new = client.outbox.dropped - client.reported
        client.reported = client.outbox.dropped
        self._slow.add(client.label, new)

    # --- a client's handshake ----------------------------------------------------------------
    def _admit(self, connection: ServerConnection, request: Request) -> Optional[Response]:
        refusal = self._access.check(request.headers.get_all('Host'),
                                     request.headers.get_all('Origin'), websocket=True)
        if refusal is not None:
            self._log('warn', f'refused a client from {_peer(connection)}: {refusal.reason}',
                      refusal.reason.split(' ', 1)[0])
            return connection.respond(http.HTTPStatus(refusal.status), refusal.reason + '\n')
        if len(self._clients) >= self._max_clients:
            self._log('warn', f'refused a client from {_peer(connection)}: '
                      f'{len(self._clients)} clients are connected (max_clients)', 'full')
            return connection.respond(http.HTTPStatus.SERVICE_UNAVAILABLE,
                                      f'{len(self._clients)} clients are connected\n')
        return None

    # --- a client's session ------------------------------------------------------------------
    async def _relay(self, connection: ServerConnection) -> None:
        number = next(self._ids)
        client = _Client(f'{_peer(connection)} #{number}', ClientOutbox(self._limit))
        try:
            upstream = await connect(
                self._upstream, ssl=self._ssl, open_timeout=10.0, max_size=None,
                compression=None, ping_interval=None, max_queue=2, logger=_QUIET,
                subprotocols=[connection.subprotocol] if connection.subprotocol else None)
        except (OSError, InvalidHandshake, asyncio.TimeoutError) as exc:
            self._log('error', f'client {client.label}: cannot reach the Foxglove server: '
                      f'{exc}', '')
            await connection.close(1011, 'the live view cannot reach its server')
            return
        self._clients[number] = client
        self._log('info', f'client {client.label} connected '
                  f'({connection.subprotocol}; {len(self._clients)} in all)', '')
        why = 'left'
        tasks = [asyncio.ensure_future(task) for task in (
            self._down(upstream, client), self._send(connection, client),
            self._up(connection, upstream, client))]
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                result = None if task.cancelled() else task.result()
                if isinstance(result, str):
                    why = result
        finally:
            for task in tasks:
                task.cancel()
            del self._clients[number]
            self._report(client)
            await upstream.close()
            if why != 'left':
                await connection.close(1008, why[:120])
            self._log('info', f'client {client.label} {why}', '')

    async def _down(self, upstream: ClientConnection, client: _Client) -> Optional[str]:
        """The SDK's frames into the client's outbox, as fast as they come."""
        try:
            async for frame in upstream:
                again = client.subscriptions.again(frame)
                if again is not None:       # (the SDK takes it once it knows the channel)
                    asyncio.get_running_loop().call_later(
                        RESUBSCRIBE_S, asyncio.ensure_future, _send_quietly(upstream, again))
                    continue
                if not client.outbox.put(frame):
                    return ('too slow: was disconnected (its outbox held '
                            f'{client.outbox.size} bytes of messages that cannot be dropped)')
                client.wake.set()
        except ConnectionClosed:
            pass
        return ('was disconnected: the Foxglove server closed its connection (it does when '
                'its queue of control messages for it, message_backlog_size, fills)')

    @staticmethod
    async def _send(connection: ServerConnection, client: _Client) -> None:
        """The outbox to the client, as fast as it reads."""
        try:
            while True:
                await client.wake.wait()
                client.wake.clear()
                while (frame := client.outbox.take()) is not None:
                    await connection.send(frame)
        except ConnectionClosed:
            pass

    @staticmethod
    async def _up(connection: ServerConnection, upstream: ClientConnection,
                  client: _Client) -> None:
        """The client's requests (subscriptions and the like) to the SDK."""
        try:
            async for frame in connection:
                client.subscriptions.sent(frame)
                await upstream.send(frame)
        except ConnectionClosed:
            pass


async def _send_quietly(upstream: ClientConnection, frame: str) -> None:
    try:
        await upstream.send(frame)
    except ConnectionClosed:
        pass


def _peer(connection: ServerConnection) -> str:
    address = connection.remote_address
    return f'{address[0]}:{address[1]}' if address else 'an unknown peer'


def default_origins() -> Sequence[str]:
    """The pages allowed by default: Foxglove's web app, and any page served from this
    machine's loopback (a Foxglove or Lichtblick served locally)."""
    return (r'https://app\.foxglove\.dev',
            r'https?://(localhost|127\.0\.0\.1|\[::1\])(:[0-9]{1,5})?')
