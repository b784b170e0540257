"""``live_view``: a Foxglove live bridge. Serves the Foxglove WebSocket protocol (through the
foxglove-sdk package) on ``ws://127.0.0.1:8765`` and streams every topic of the graph, or a
chosen list, with its ``ros2msg`` schema and the CDR bytes as received.

Topics are advertised as they appear (a publisher and one type) and dropped as they go. A ROS
subscription is made only while a Foxglove client subscribes to the topic, so a camera nobody
watches is not rendered for the bridge. Clients come in through the gate (gate.py): only this
server's Host names and the allowed Origins (a web page of another site is refused), at most
``max_clients`` at once, each with an outbox of at most ``send_buffer_limit`` bytes. A slow
client never stalls the graph or another client: its oldest messages are dropped, and the node
counts and logs how many (bridge.py).
"""
from __future__ import annotations

import collections
import functools
import logging
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Deque, Dict, Optional, Set, Tuple

import foxglove
from foxglove.websocket import ChannelView, Client
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

from live_view.bridge import (
    SEND_LOSSY_LOGGER,
    SlowClients,
    TopicFilter,
    changes_per_look,
    graph_change,
    paced,
)
from live_view.gate import Gate, GateError, default_origins, self_signed_certificate
from recording.qos_profiles import adapt_to_publishers
from recording.types import TypeResolutionError, TypeResolver, message_class
from ros_common.log_limit import KeyedLimiter
from ros_common.node_main import run_node
from ros_common.params import Param, declare_params, declare_web_access
from ros_common.web_access import WebAccessError

PARAMS = (
    Param('host', '127.0.0.1', 'Address to serve on; the loopback interface unless told '
          'otherwise (0.0.0.0: every interface, so anyone who reaches it sees the graph)'),
    Param('port', 8765, 'TCP port of the Foxglove WebSocket server (0: any free port)',
          0, 65535),
    Param('topics', [''], 'Topics to stream; empty: every topic, as it appears'),
    Param('exclude', [''], 'Topics never streamed'),
    Param('discovery_period', 0.2, 'Wall seconds between looks for topics that appeared or '
          'went', 0.02, 10.0),
    Param('message_backlog_size', 16, "Messages the Foxglove SDK queues for the gate's "
          "connection of a client (the gate drains it at once into the client's outbox); "
          'past that its oldest are dropped. Its queue of control messages (channels '
          'advertised and gone) is as long, and a client is disconnected when that one fills: '
          'a look at the graph changes at most half this many channels', 2, 1024),
    Param('queue_depth', 10, 'History depth of the ROS subscriptions', 1, 10000),
    Param('report_period', 5.0, 'Wall seconds between reports of clients that fell behind',
          0.1, 3600.0),
    Param('send_buffer_limit', 10000000, 'Bytes queued for a client (as foxglove_bridge); past '
          'that its oldest messages are dropped', 1024, 2 ** 31 - 1),
)


class LiveViewError(RuntimeError):
    """The bridge cannot serve (a bad parameter, the port taken)."""


@dataclass
class _Topic:
    msgtype: str
    channel: foxglove.Channel
    clients: Set[int] = field(default_factory=set)
    subscription: Optional[Subscription] = None
    forwarded: int = 0


class _RosLog(logging.Handler):
    """The SDK's own log lines (clients connecting and leaving, errors) in the node's log."""

    def __init__(self, node: Node) -> None:
        super().__init__(level=logging.INFO)
        self._logger = node.get_logger()

    def emit(self, record: logging.LogRecord) -> None:
        text = f'foxglove: {record.getMessage()}'
        if record.levelno >= logging.ERROR:
            self._logger.error(text)
        elif record.levelno >= logging.WARNING:
            self._logger.warn(text)
        else:
            self._logger.info(text)


class _Listener(foxglove.ServerListener):
    """The SDK's server listener: called on the SDK's threads, it only queues what clients
    asked for; the node's timer acts on it (rclpy entities are made in the executor's thread)."""

    def __init__(self, requests: Deque[Tuple[str, int, int, str]]) -> None:
        self._requests = requests

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self._requests.append(('subscribe', client.id, channel.id, channel.topic))

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        self._requests.append(('unsubscribe', client.id, channel.id, channel.topic))


class LiveView(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('live_view', **kwargs)
        p = declare_params(self, PARAMS)
        try:
            self._filter = TopicFilter(p['topics'], p['exclude'])
        except ValueError as exc:
            raise LiveViewError(str(exc)) from None
        self._depth = int(p['queue_depth'])
        self._changes_per_look = changes_per_look(int(p['message_backlog_size']))
        self._types = TypeResolver()
        self._topics: Dict[str, _Topic] = {}
        self._skipped: Dict[str, str] = {}          # topic: the type it could not be streamed as
        self._requests: Deque[Tuple[str, int, int, str]] = collections.deque()
        self.slow_clients = SlowClients()
        self._log_handlers = [(logging.getLogger(SEND_LOSSY_LOGGER), self.slow_clients),
                              (logging.getLogger('foxglove'), _RosLog(self))]
        for logger, handler in self._log_handlers:
            logger.addHandler(handler)
            logger.setLevel(logging.INFO)
        logging.getLogger('foxglove').propagate = False     # (the node's log only)
        foxglove.set_log_level(logging.INFO)
        self._serve(p)
        # Wall-clock timers: the bridge runs whether or not simulated time advances.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(p['discovery_period'], self._update, clock=steady)
        self.create_timer(p['report_period'], self._report, clock=steady)
        self.get_logger().info(
            f'serving the Foxglove WebSocket protocol on {self.url} ({self._filter.describe()}; '
            f'to {self._gate.describe()}); in Foxglove: Open connection > Foxglove WebSocket > '
            f'{self.url}')
        self._update()

    def _serve(self, p: Dict[str, Any]) -> None:
        """The SDK's server, on loopback behind TLS that only the gate trusts (gate.py), and the
        gate in front of it, at the parameters' host and port."""
        host, port = p['host'], int(p['port'])
        try:
            access, max_clients = declare_web_access(
                self, host, default_origins(), "clients that are not browsers send none and "
                "are let in. Default: Foxglove's web app and pages served on loopback",
                'max_clients', 'Clients')
        except WebAccessError as exc:
            self._detach_logs()
            raise LiveViewError(str(exc)) from None
        certificate, key = self_signed_certificate()
        try:
            self._server = foxglove.start_server(
                name='robot-sim live_view', host='127.0.0.1', port=0,
                server_listener=_Listener(self._requests), supported_encodings=['cdr'],
                message_backlog_size=int(p['message_backlog_size']),
                tls_cert=certificate, tls_key=key)
        except Exception as exc:    # (the SDK raises its own error types)
            self._detach_logs()
            raise LiveViewError(f'cannot start the Foxglove server: {exc}') from None
        self._gate_limiter = KeyedLimiter(1.0)
        self._gate_log_lock = threading.Lock()
        self._gate = Gate(access, host, port, self._server.port, certificate,
                          max_clients, int(p['send_buffer_limit']),
                          self.slow_clients, self._gate_log)
        try:
            served = self._gate.start()
        except GateError as exc:
            self._server.stop()
            self._detach_logs()
            raise LiveViewError(str(exc)) from None
        self.url = f'ws://{host}:{served}'
        self.get_logger().info(f'the Foxglove server behind the gate: wss://127.0.0.1:'
                               f'{self._server.port} (a certificate only the gate trusts)')

    # --- the graph --------------------------------------------------------------------------
    def _update(self) -> None:
        graph = [(topic, types, self.count_publishers(topic))
                 for topic, types in self.get_topic_names_and_types()]
        change = paced(graph_change({t: s.msgtype for t, s in self._topics.items()}, graph,
                                    self._filter), self._changes_per_look)
        for topic in change.drop:
            self._drop(topic)
        for topic, msgtype in change.advertise:
            if self._skipped.get(topic) != msgtype:
                self._advertise(topic, msgtype)
        while self._requests:
            op, client, channel_id, topic = self._requests.popleft()
            entry = self._topics.get(topic)
            if entry is None or entry.channel.id() != channel_id:
                continue                    # (a channel dropped since)
            if op == 'subscribe':
                entry.clients.add(client)
            else:
                entry.clients.discard(client)
            self._follow(topic, entry)

    def _advertise(self, topic: str, msgtype: str) -> None:
        try:
            message_class(msgtype)
            msgdef, _ = self._types.definition(msgtype)
        except (TypeResolutionError, OSError, ValueError) as exc:
            self._skipped[topic] = msgtype
            self.get_logger().warn(f'not streaming {topic}: {exc}')
            return
        schema = foxglove.Schema(name=msgtype, encoding='ros2msg', data=msgdef.encode())
        channel = foxglove.Channel(topic, schema=schema, message_encoding='cdr')
        self._topics[topic] = _Topic(msgtype, channel)
        self._skipped.pop(topic, None)
        self.get_logger().info(f'advertising {topic} [{msgtype}]')

    def _drop(self, topic: str) -> None:
        entry = self._topics.pop(topic)
        if entry.subscription is not None:
            self.destroy_subscription(entry.subscription)
        entry.channel.close()
        self.get_logger().info(f'{topic} is gone: no longer advertised '
                               f'({entry.forwarded} messages streamed)')

    def _follow(self, topic: str, entry: _Topic) -> None:
        """A ROS subscription while a client subscribes, none otherwise."""
        if entry.clients and entry.subscription is None:
            publishers = self.get_publishers_info_by_topic(topic)
            reliability, durability = adapt_to_publishers(
                [(int(p.qos_profile.reliability), int(p.qos_profile.durability))
                 for p in publishers])
            qos = QoSProfile(depth=self._depth, reliability=ReliabilityPolicy(reliability),
                             durability=DurabilityPolicy(durability))
            entry.subscription = self.create_subscription(
                message_class(entry.msgtype), topic,
                functools.partial(self._forward, entry), qos, raw=True)
            self.get_logger().info(f'streaming {topic} to {len(entry.clients)} client(s)')
        elif not entry.clients and entry.subscription is not None:
            self.destroy_subscription(entry.subscription)
            entry.subscription = None
            self.get_logger().info(f'{topic}: no client left, unsubscribed')

    def _forward(self, entry: _Topic, data: bytes) -> None:
        # The SDK copies the bytes into each subscribed client's outbox and returns at once.
        entry.channel.log(data, log_time=self.get_clock().now().nanoseconds)
        entry.forwarded += 1

    # --- reports ------------------------------------------------------------------------------
    def _report(self) -> None:
        self._gate.collect_drops()
        news = self.slow_clients.news()
        if news:
            shown = '; '.join(f'{client}: {new} ({total} in all)'
                              for client, new, total in news[:5])
            more = f'; and {len(news) - 5} more clients' if len(news) > 5 else ''
            self.get_logger().warn(
                f'{len(news)} client(s) fell behind, messages dropped since the last report, '
                f'the oldest first: {shown}{more}; the graph and the other clients were not '
                'held up')

    def _gate_log(self, level: str, text: str, kind: str) -> None:
        """The gate's log lines (from its thread); those of a kind at most once a second."""
        logger = self.get_logger()
        if kind:
            with self._gate_log_lock:
                line = self._gate_limiter.text(kind, time.monotonic(), text)
            if line is None:
                return
            text = line
        if level == 'warn':
            logger.warn(text)
        elif level == 'error':
            logger.error(text)
        else:
            logger.info(text)

    def streamed(self) -> Dict[str, int]:
        return {t: e.forwarded for t, e in self._topics.items()}

    def _detach_logs(self) -> None:
        for logger, handler in self._log_handlers:
            logger.removeHandler(handler)

    def finish(self) -> str:
        self._detach_logs()         # (the context may be shut down already: no ROS log now)
        self._gate.stop()
        self._server.stop()
        counts = self.slow_clients.counts()
        behind = (f'; clients that fell behind: {counts}' if counts else '')
        return f'served {self.url}; messages streamed per topic: {self.streamed()}{behind}'


def _finish(node: LiveView) -> None:
    print(f'[live_view] {node.finish()}', flush=True)


def main(args=None) -> int:
    return run_node(LiveView, 'live_view', (LiveViewError,), on_exit=_finish, args=args)


if __name__ == '__main__':
    sys.exit(main())
