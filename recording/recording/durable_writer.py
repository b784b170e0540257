"""rosbags' rosbag2 Writer on storages that can be made durable while the bag is open.

rosbags' Writer writes ``metadata.yaml``, serializes the QoS profiles and keeps the connections;
the bytes go to a storage object it takes from ``Writer.STORAGE_PLUGINS`` (its
``StorageWriter`` protocol). rosbags' own storages keep MCAP messages in a 1 MiB chunk in memory
and commit SQLite only at close, and give no way to flush. The two here implement the same
protocol and add :meth:`flush` (one per file, as rosbags keeps them):

- ``storage_mcap.McapStorage`` writes through the ``mcap`` library;
- ``storage_sqlite3.Sqlite3Storage`` writes rosbag2's SQLite schema (version 4).

A write or flush that fails (a full disk) raises OSError; what was flushed before stays
readable, and :meth:`DurableWriter.close_after_failure` closes the bag at that point: the MCAP
file is cut back to its last flush and ended there (its metadata record, DataEnd and a footer
with no summary section, which readers scan), the SQLite transaction is rolled back, and
metadata.yaml counts what the files hold. A reserve file, freed first, leaves room for that.

Bags split into several files by size or by duration, as rosbag2's ``max_bag_size`` and
``max_bag_duration`` do: every file but the last is closed complete when the next starts, and
metadata.yaml lists each with its own counts.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any, Dict, List, Literal, Mapping, Optional, Sequence, Type, Union

import yaml
from rosbags.interfaces import Connection, ConnectionExtRosbag2, Qos
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.metadata import dump_qos_v8, dump_qos_v9

from recording.storage_mcap import CheckedMcapStorage, McapStorage
from recording.storage_sqlite3 import Sqlite3Storage

# Room kept on the bag's file system for closing the bag after a write fails: at most this,
# and at most a quarter of what is free when the bag opens.
RESERVE_BYTES = 4 << 20
RESERVE_NAME = '.close_reserve'


class _Reserve:
    """A file that holds some free space of the bag's file system until it is released."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / RESERVE_NAME
        free = shutil.disk_usage(directory).free
        size = min(RESERVE_BYTES, free // 4)
        try:
            with self.path.open('xb') as f:
                if size:
                    os.posix_fallocate(f.fileno(), 0, size)
        except OSError:
            self.path.unlink(missing_ok=True)

    def release(self) -> None:
        self.path.unlink(missing_ok=True)


Storage = Union[McapStorage, Sqlite3Storage]


class DurableWriter(Writer):
    """rosbags' rosbag2 Writer on the storages above: :meth:`flush`, splitting into several
    files (``max_bag_size`` bytes of messages, ``max_bag_duration`` seconds of message time; 0:
    no limit), and :meth:`close_after_failure`. It writes metadata.yaml itself, with a line per
    file, as rosbag2 does for a split bag."""

    STORAGE_PLUGINS: Mapping[StoragePlugin, Type[Storage]] = {StoragePlugin.MCAP: McapStorage,
                                StoragePlugin.SQLITE3: Sqlite3Storage}

    def __init__(self, path: Path, *, version: Literal[8, 9], storage_plugin: StoragePlugin,
                 chunk_crc: bool = False, max_bag_size: int = 0,
                 max_bag_duration: float = 0.0) -> None:
        super().__init__(path, version=version, storage_plugin=storage_plugin)
        if max_bag_size < 0 or not max_bag_duration >= 0.0:
            raise WriterError('max_bag_size and max_bag_duration must be >= 0')
        self._storage_class = self.STORAGE_PLUGINS[storage_plugin]
        if chunk_crc and storage_plugin == StoragePlugin.MCAP:
            self._storage_class = CheckedMcapStorage
        self.max_bag_size = max_bag_size
        self.max_bag_duration_ns = round(max_bag_duration * 1e9)
        self._qos_text: Dict[int, str] = {}
        self.files: List[Dict[str, Any]] = []       # closed files, as metadata.yaml lists them
        self._file: Dict[str, Any] = {}             # the open file's name and counts
        self._durable: Dict[str, Any] = {}          # the counts at the last flush
        self._reserve: Optional[_Reserve] = None

    @property
    def current_file(self) -> str:
        return str(self._file.get('path', ''))

    @property
    def splitting(self) -> bool:
        return bool(self.max_bag_size or self.max_bag_duration_ns)

    def open(self) -> None:
        try:
            self.path.mkdir(mode=0o755, parents=True)
        except FileExistsError:
            raise WriterError(f'{self.path} exists already, not overwriting.') from None
        self._reserve = _Reserve(self.path)
        self._start_file()
        self._snapshot()

    def _start_file(self) -> None:
        index = len(self.files)
        suffix = self._storage_class.SUFFIX
        name = (f'{self.path.name}_{index}{suffix}' if self.splitting
                else f'{self.path.name}{suffix}')
        self.storage = self._storage_class(self.path, self.compression_mode, name)
        self._file = {'path': name, 'count': 0, 'bytes': 0, 'start': 2**63 - 1, 'end': 0}
        for msgtype in sorted(self.added_types):
            self.storage.add_msgtype(next(c for c in self.connections if c.msgtype == msgtype))
        for connection in self.connections:
            self.storage.add_connection(connection, self._qos_text[connection.id])

    def add_connection(self, topic: str, msgtype: str, **kwargs: Any) -> Connection:
        connection = super().add_connection(topic, msgtype, **kwargs)
        self._qos_text[connection.id] = _dump_qos(self.version,
                                                  kwargs.get('offered_qos_profiles', ()))
        return connection

    def write(self, connection: Connection, timestamp: int, data: Union[bytes, memoryview]
              ) -> None:
        f = self._file
        if (self.max_bag_duration_ns and f['count']
                and timestamp - f['start'] >= self.max_bag_duration_ns):
            self.split()
        super().write(connection, timestamp, data)
        f = self._file
        f['count'] += 1
        f['bytes'] += len(data)
        f['start'], f['end'] = min(f['start'], timestamp), max(f['end'], timestamp)
        if self.max_bag_size and f['bytes'] >= self.max_bag_size:
            self.split()

    def split(self) -> None:
        """Close the open file complete and go on in a new one."""
        storage = self._storage()
        self.flush()
        storage.close(self.version, self._metadata_text(self._file_entries(self._file)))
        self.files.append(self._file_entry(self._file))
        self._start_file()
        self._snapshot()

    def flush(self) -> None:
        """Make every message written so far survive a killed process."""
        self._storage().flush()
        self._snapshot()

    def close(self) -> None:
        """Close the bag complete: the open file's index and summary, and metadata.yaml."""
        storage = self._storage()
        entries = self._file_entries(self._file)
        storage.close(self.version, self._metadata_text(entries))
        self.storage = None
        self._write_metadata(entries)

    def close_after_failure(self) -> int:
        """Close the bag where its last flush left it, after a write or flush failed; returns
        the messages the bag holds. The reserve is freed first, to make room."""
        if self._reserve is not None:
            self._reserve.release()
        durable = self._durable
        self.counts = dict(durable['counts'])
        self.min_timestamp, self.max_timestamp = durable['min'], durable['max']
        self._file = dict(durable['file'])
        entries = self._file_entries(self._file)
        storage = self._storage()
        self.storage = None
        # metadata.yaml first, while the reserve's room is surely there.
        try:
            self._write_metadata(entries)
        finally:
            storage.close_at_durable(self._metadata_text(entries))
        return sum(self.counts.values())

    def _storage(self) -> Storage:
        storage = self.storage
        if storage is None:
            raise WriterError('the bag is not open')
        assert isinstance(storage, (McapStorage, Sqlite3Storage))
        return storage

    def _snapshot(self) -> None:
        self._durable = {'counts': dict(self.counts), 'min': self.min_timestamp,
                         'max': self.max_timestamp, 'file': dict(self._file)}

    @staticmethod
    def _file_entry(f: Dict[str, Any]) -> Dict[str, Any]:
        start = f['start'] if f['count'] else 0
        return {'path': f['path'], 'starting_time': {'nanoseconds_since_epoch': start},
                'duration': {'nanoseconds': max(0, f['end'] - start) if f['count'] else 0},
                'message_count': f['count']}

    def _file_entries(self, open_file: Dict[str, Any]) -> List[Dict[str, Any]]:
        return self.files + [self._file_entry(open_file)]

    def _information(self, files: Sequence[Dict[str, Any]]) -> Dict[str, Any]:
        count = sum(self.counts.values())
        start = self.min_timestamp if count else 0
        dump = dump_qos_v9 if self.version >= 9 else dump_qos_v8
        return {
            'version': self.version,
            'storage_identifier': self.storage_plugin.name.lower(),
            'relative_file_paths': [f['path'] for f in files],
            'duration': {'nanoseconds': max(0, self.max_timestamp - start) if count else 0},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': count,
            'topics_with_message_count': [
                {'topic_metadata': {
                    'name': c.topic, 'type': c.msgtype,
                    'serialization_format': c.ext.serialization_format,
                    'offered_qos_profiles': dump(c.ext.offered_qos_profiles),
                    'type_description_hash': c.digest},
                 'message_count': self.counts[c.id]}
                for c in self.connections if isinstance(c.ext, ConnectionExtRosbag2)],
            'compression_format': '',
            'compression_mode': '',
            'files': list(files),
            'custom_data': self.custom_data or None,
            'ros_distro': 'rosbags',
        }

    def _metadata_text(self, files: Sequence[Dict[str, Any]]) -> str:
        return _yaml(self._information(files)).strip()

    def _write_metadata(self, files: Sequence[Dict[str, Any]]) -> None:
        text = _yaml({'rosbag2_bagfile_information': self._information(files)})
        tmp = self.metapath.with_suffix('.yaml.tmp')
        tmp.write_text(text, 'utf8')
        tmp.replace(self.metapath)
        if self._reserve is not None:
            self._reserve.release()


def _yaml(data: Any) -> str:
    return str(yaml.safe_dump(data, default_flow_style=False, sort_keys=False))


def _dump_qos(bag_version: int, profiles: Sequence[Qos]) -> str:
    """The offered QoS profiles as rosbags' Writer hands them to its storage."""
    dumped = (dump_qos_v9 if bag_version >= 9 else dump_qos_v8)(list(profiles))
    return dumped if isinstance(dumped, str) else _yaml(dumped).strip()
