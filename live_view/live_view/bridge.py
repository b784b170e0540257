"""What the live bridge decides without ROS: which topics it streams, what it keeps for a client
that reads slowly, and which clients fell behind.

Every client is relayed by the gate (gate.py), which keeps a bounded outbox per client
(``ClientOutbox``: ``send_buffer_limit`` bytes, as foxglove_bridge's): a client that does not
read fast enough never stalls the sender or costs more memory than that; when its outbox is
full its oldest message data is dropped. Behind the gate the Foxglove SDK keeps an outbox of its
own per connection (``message_backlog_size`` messages), which fills only if the gate itself
falls behind; the SDK then logs ``outbox for client <address> full`` (at most once a second).
``SlowClients`` counts both.
"""
from __future__ import annotations

import collections
import logging
import re
import threading
from dataclasses import dataclass, field
from typing import Deque, Dict, Iterable, List, Sequence, Set, Tuple, Union

# The SDK's logger and message for a client whose outbox is full (foxglove-sdk 0.30).
SEND_LOSSY_LOGGER = 'foxglove.websocket.connected_client.send_lossy'
_OUTBOX_FULL = re.compile(r'outbox for client (?P<client>\S+) full')
# Binary opcodes of the Foxglove WebSocket protocol that a client can do without: message data
# and the server's time (the next one replaces it). Everything else (advertisements, service
# responses, fetched assets) is kept.
DROPPABLE_OPCODES = (0x01, 0x02)

Frame = Union[str, bytes]


@dataclass
class TopicFilter:
    """Which topics are streamed: ``topics`` (empty: every topic), never ``exclude``."""

    topics: Sequence[str] = ()
    exclude: Sequence[str] = ()
    _wanted: Set[str] = field(init=False)
    _excluded: Set[str] = field(init=False)

    def __post_init__(self) -> None:
        self._wanted = {t for t in self.topics if t}
        self._excluded = {t for t in self.exclude if t}
        bad = [t for t in self._wanted | self._excluded if not t.startswith('/')]
        if bad:
            raise ValueError(f'topic names must be absolute (start with "/"): {sorted(bad)}')

    def wants(self, topic: str) -> bool:
        return topic not in self._excluded and (not self._wanted or topic in self._wanted)

    def describe(self) -> str:
        what = ', '.join(sorted(self._wanted)) if self._wanted else 'every topic'
        return what + (f' except {", ".join(sorted(self._excluded))}' if self._excluded else '')


@dataclass(frozen=True)
class GraphChange:
    """Topics to advertise (name, type) and topics to drop, from one look at the graph."""

    advertise: Tuple[Tuple[str, str], ...]
    drop: Tuple[str, ...]


def graph_change(advertised: Dict[str, str],
                 graph: Iterable[Tuple[str, Sequence[str], int]],
                 wanted: TopicFilter) -> GraphChange:
    """What changes, given the topics advertised now (name: type) and the graph as
    (name, types, publisher count). A topic is streamed while it has a publisher and one type;
    it is dropped when its last publisher goes, or its type changes (then advertised again)."""
    live: Dict[str, str] = {}
    for topic, types, publishers in graph:
        if publishers > 0 and len(types) == 1 and wanted.wants(topic):
            live[topic] = types[0]
    drop = tuple(sorted(t for t, kind in advertised.items() if live.get(t) != kind))
    add = tuple(sorted((t, kind) for t, kind in live.items()
                       if t not in advertised or t in drop))
    return GraphChange(add, drop)


def paced(change: GraphChange, limit: int) -> GraphChange:
    """At most ``limit`` of a change's drops and adverts, drops first; the rest wait for the
    next look at the graph (which finds them again). Each is a control message to every client,
    which the SDK queues (``message_backlog_size`` of them) faster than its sender sends them:
    a burst past its queue, such as the channels of a graph that appears at once, and the SDK
    closes the client's connection."""
    drop = change.drop[:limit]
    waiting = set(change.drop[limit:])
    add = tuple(item for item in change.advertise
                if item[0] not in waiting)[:max(0, limit - len(drop))]
    return GraphChange(add, drop)


def changes_per_look(backlog: int) -> int:
    """How many channel changes a look at the graph makes, for the SDK's ``backlog``: half of
    it, the rest of its control queue left for what else it sends (status, services)."""
    return max(1, backlog // 2)


class ClientOutbox:
    """The frames owed to one client, at most ``limit`` bytes: past it, the oldest message data
    is dropped. If only frames that must not be dropped are left over the limit, the client is
    too slow to serve (``put`` returns False: disconnect it)."""

    def __init__(self, limit: int) -> None:
        if limit < 1:
            raise ValueError(f'send_buffer_limit must be >= 1 byte, got {limit}')
        self.limit = limit
        self.size = 0
        self.dropped = 0                # frames of message data dropped
        self._frames: Deque[Frame] = collections.deque()

    def put(self, frame: Frame) -> bool:
        self._frames.append(frame)
        self.size += len(frame)
        while self.size > self.limit:
            if not self._drop_oldest_data():
                return False
        return True

    def _drop_oldest_data(self) -> bool:
        for k, frame in enumerate(self._frames):
            if isinstance(frame, bytes) and frame[:1] and frame[0] in DROPPABLE_OPCODES:
                del self._frames[k]
                self.size -= len(frame)
                self.dropped += 1
                return True
        return False

    def take(self) -> Union[Frame, None]:
        if not self._frames:
            return None
        frame = self._frames.popleft()
        self.size -= len(frame)
        return frame

    def __len__(self) -> int:
        return len(self._frames)


class SlowClients(logging.Handler):
    """Counts, per client, the messages dropped for it (``add``, from the gate's outboxes) and
    the times the SDK found its own outbox full (attached to the SDK's ``send_lossy`` logger)."""

    def __init__(self) -> None:
        super().__init__(level=logging.DEBUG)
        self._lock_counts = threading.Lock()
        self._counts: Dict[str, int] = {}
        self._reported: Dict[str, int] = {}

    def add(self, client: str, dropped: int) -> None:
        if dropped > 0:
            with self._lock_counts:
                self._counts[client] = self._counts.get(client, 0) + dropped

    def emit(self, record: logging.LogRecord) -> None:
        match = _OUTBOX_FULL.search(record.getMessage())
        if match:
            self.add(f'gate connection {match.group("client")}', 1)

    def counts(self) -> Dict[str, int]:
        with self._lock_counts:
            return dict(self._counts)

    def news(self) -> List[Tuple[str, int, int]]:
        """(client, drops since the last call, drops in all) for the clients that fell behind
        since the last call."""
        with self._lock_counts:
            out = [(c, n - self._reported.get(c, 0), n) for c, n in sorted(self._counts.items())
                   if n != self._reported.get(c, 0)]
            self._reported = dict(self._counts)
        return out
