"""Writes a rosbag2 bag through rosbags: a new directory per run, and durable periodic flushes."""
from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from rosbags.interfaces import Connection, Qos
from rosbags.rosbag2 import StoragePlugin, WriterError
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

from recording.durable_writer import DurableWriter
from recording.types import TypeResolver

STORAGES = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
# 'zstd': MCAP chunks compressed with zstd (the storage-level compression of rosbag2's MCAP
# plugin, which every MCAP reader decodes).
COMPRESSIONS = ('none', 'zstd')
_NAME = re.compile(r'^[A-Za-z0-9][A-Za-z0-9_.-]*$')


class BagError(RuntimeError):
    """A bag that cannot be created or written."""


@dataclass
class TopicRecord:
    connection: Connection
    count: int = 0
    bytes: int = 0


def unique_bag_path(output_dir: Path, name: str) -> Path:
    """``output_dir/name``, or ``name_1``, ``name_2``, ... if taken: a bag is never overwritten."""
    if not _NAME.match(name):
        raise BagError(f'bag name "{name}" must be letters, digits, "_", "-" or "."')
    output_dir.mkdir(parents=True, exist_ok=True)
    candidate, n = output_dir / name, 0
    while candidate.exists():
        n += 1
        candidate = output_dir / f'{name}_{n}'
    return candidate


def default_bag_name() -> str:
    return time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S')


class BagWriter:
    """One open bag. Messages are written as the serialized bytes they arrived in.

    Messages wait in a 1 MiB chunk in memory (MCAP) or an open transaction (SQLite).
    :meth:`flush` ends the chunk and hands it to the operating system, or commits
    (``recording.durable_writer``): called every half second, a SIGKILL loses at most that
    much, and
    ``bag_repair`` restores the index.
    """

    def __init__(self, output_dir: Path, name: Optional[str] = None, storage: str = 'mcap',
                 resolver: Optional[TypeResolver] = None, compression: str = 'none',
                 chunk_crc: bool = False, max_bag_size: int = 0,
                 max_bag_duration: float = 0.0,
                 custom_data: Optional[Dict[str, str]] = None) -> None:
        if storage not in STORAGES:
            raise BagError(f'storage must be one of {sorted(STORAGES)}, got "{storage}"')
        if compression not in COMPRESSIONS:
            raise BagError(f'compression must be one of {list(COMPRESSIONS)}, got '
                           f'"{compression}"')
        if compression != 'none' and storage != 'mcap':
            raise BagError(f'compression {compression} compresses MCAP chunks; {storage} bags '
                           'are written uncompressed (compression:=none)')
        if chunk_crc and storage != 'mcap':
            raise BagError(f'chunk_crc applies to MCAP chunks; {storage} bags have none')
        self.compression = compression
        self.storage = storage
        self.resolver = resolver or TypeResolver()
        for _ in range(100):
            self.path = unique_bag_path(Path(output_dir), name or default_bag_name())
            self._writer = DurableWriter(self.path, version=9, storage_plugin=STORAGES[storage],
                                         chunk_crc=chunk_crc, max_bag_size=max_bag_size,
                                         max_bag_duration=max_bag_duration)
            if compression == 'zstd':
                self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            # (metadata.yaml's custom_data, and the MCAP's rosbag2 metadata record.)
            for key, value in (custom_data or {}).items():
                self._writer.set_custom_data(key, value)
            try:
                self._writer.open()
                break
            except (WriterError, FileExistsError):
                continue  # lost a race for the name with another recorder: take the next
        else:
            raise BagError(f'cannot create a bag directory in {output_dir}')
        self.topics: Dict[str, TopicRecord] = {}
        self._closed = False

    def add_topic(self, topic: str, msgtype: str, qos: Sequence[Qos] = ()) -> TopicRecord:
        if topic in self.topics:
            raise BagError(f'topic {topic} is already recorded')
        msgdef, rihs01 = self.resolver.definition(msgtype)
        connection = self._writer.add_connection(topic, msgtype, msgdef=msgdef, rihs01=rihs01,
                                                 offered_qos_profiles=list(qos))
        self.topics[topic] = TopicRecord(connection)
        return self.topics[topic]

    def write(self, topic: str, timestamp_ns: int, data: bytes) -> None:
        record = self.topics[topic]
        self._writer.write(record.connection, timestamp_ns, data)
        record.count += 1
        record.bytes += len(data)

    def flush(self) -> None:
        """Make everything written so far survive a killed process."""
        self._writer.flush()

    def close(self) -> None:
        """Finish the bag: index, summary and metadata.yaml."""
        if not self._closed:
            self._closed = True
            self._writer.close()

    def close_after_failure(self) -> int:
        """After a write or flush failed (a full disk): close the bag with what its last
        flush made durable, metadata.yaml counting exactly that; returns that many messages.
        The topics' counts are set to what the bag holds."""
        if self._closed:
            return self.message_count
        self._closed = True
        kept = self._writer.close_after_failure()
        for record in self.topics.values():
            record.count = self._writer.counts[record.connection.id]
        return kept

    @property
    def files(self) -> List[str]:
        """The bag's files so far (more than one once it split)."""
        return [f['path'] for f in self._writer.files] + [self._writer.current_file]

    @property
    def message_count(self) -> int:
        return sum(r.count for r in self.topics.values())
