"""What the live bridge decides without ROS: which topics it streams, and which clients fell
behind.

The Foxglove SDK keeps a bounded outbox per client (``message_backlog_size`` messages). A client
that does not read fast enough never stalls the sender: when its outbox is full the SDK drops
that client's oldest data messages, and logs ``outbox for client <address> full`` (at most once a
second, for all clients together). It does not report how many it dropped, so what is counted
here is how often each client's outbox was found full: ``SlowClients`` reads the SDK's log
records.
"""
from __future__ import annotations

import logging
import re
import threading
from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Sequence, Set, Tuple

# The SDK's logger and message for a client whose outbox is full (foxglove-sdk 0.30).
SEND_LOSSY_LOGGER = 'foxglove.websocket.connected_client.send_lossy'
_OUTBOX_FULL = re.compile(r'outbox for client (?P<client>\S+) full')


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


class SlowClients(logging.Handler):
    """Counts, per client, how often the SDK found its outbox full (and dropped its oldest
    messages). Attach it to the SDK's ``send_lossy`` logger."""

    def __init__(self) -> None:
        super().__init__(level=logging.DEBUG)
        self._lock_counts = threading.Lock()
        self._counts: Dict[str, int] = {}
        self._reported: Dict[str, int] = {}

    def emit(self, record: logging.LogRecord) -> None:
        match = _OUTBOX_FULL.search(record.getMessage())
        if match:
            with self._lock_counts:
                client = match.group('client')
                self._counts[client] = self._counts.get(client, 0) + 1

    def counts(self) -> Dict[str, int]:
        with self._lock_counts:
            return dict(self._counts)

    def news(self) -> List[Tuple[str, int, int]]:
        """(client, episodes since the last call, episodes in all) for the clients that fell
        behind since the last call."""
        with self._lock_counts:
            out = [(c, n - self._reported.get(c, 0), n) for c, n in sorted(self._counts.items())
                   if n != self._reported.get(c, 0)]
            self._reported = dict(self._counts)
        return out
