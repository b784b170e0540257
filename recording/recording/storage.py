"""rosbag2 storage for rosbags' Writer that can be made durable while the bag is open.

rosbags' Writer writes ``metadata.yaml``, serializes the QoS profiles and keeps the connections;
the bytes go to a storage object it takes from ``Writer.STORAGE_PLUGINS`` (its
``StorageWriter`` protocol). rosbags' own storages keep MCAP messages in a 1 MiB chunk in memory
and commit SQLite only at close, and give no way to flush. The two here implement the same
protocol and add :meth:`flush`:

- :class:`McapStorage` writes through the ``mcap`` library (the format's reference writer, with
  chunk CRCs), the ``ros2`` profile as rosbag2's MCAP plugin does: ``ros2msg`` schemas, ``cdr``
  channels carrying ``offered_qos_profiles`` and ``topic_type_hash``, and the bag's metadata as a
  ``rosbag2`` metadata record. ``flush`` ends the chunk in progress and hands it to the OS.
- :class:`Sqlite3Storage` writes rosbag2's SQLite schema (version 4), one transaction per flush.

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
import sqlite3
from importlib.metadata import version
from pathlib import Path
from typing import Any, BinaryIO, Dict, List, Literal, Mapping, Optional, Sequence, Union, cast

import yaml
from mcap.data_stream import RecordBuilder
from mcap.records import DataEnd, Footer, Metadata
from mcap.writer import MCAP0_MAGIC, CompressionType
from mcap.writer import Writer as McapFileWriter
from rosbags.interfaces import Connection, ConnectionExtRosbag2, MessageDefinitionFormat, Qos
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.metadata import dump_qos_v8, dump_qos_v9

CHUNK_BYTES = 1 << 20  # rosbag2's MCAP default chunk size
# Room kept on the bag's file system for closing the bag after a write fails: at most this,
# and at most a quarter of what is free when the bag opens.
RESERVE_BYTES = 4 << 20
RESERVE_NAME = '.close_reserve'


class _File:
    """An unbuffered file written whole: every write() lands completely or raises (a short
    write on a full disk, which a buffered or raw file object passes over, is retried until
    the OS refuses), and tell() is what the file holds."""

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._position = 0

    def write(self, data: Union[bytes, bytearray, memoryview]) -> int:
        view = memoryview(data).cast('B')
        while view:
            written = os.write(self._fd, view)
            self._position += written
            view = view[written:]
        return len(data)

    def tell(self) -> int:
        return self._position

    def flush(self) -> None:
        pass

    def cut(self, position: int) -> None:
        """Drop everything after ``position``."""
        os.ftruncate(self._fd, position)
        os.lseek(self._fd, position, os.SEEK_SET)
        self._position = position

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)


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


def _schema_encoding(connection: Connection) -> str:
    return 'ros2msg' if connection.msgdef.format == MessageDefinitionFormat.MSG else 'ros2idl'


def _serialization_format(connection: Connection) -> str:
    ext = connection.ext
    return ext.serialization_format if isinstance(ext, ConnectionExtRosbag2) else 'cdr'


class McapStorage:
    """One ``<bag>/<bag>.mcap`` file written with the mcap library.

    ``chunk_crc``: whether chunks carry a CRC-32 of their content, by which readers tell a
    damaged chunk. Off by default, as rosbags writes them: at about 0.3 ms per megabyte here
    it costs as much CPU as the rest of the write. :class:`DurableWriter` sets it per bag.
    """

    chunk_crc = False

    SUFFIX = '.mcap'

    def __init__(self, path: Path, compression: CompressionMode,
                 file_name: Optional[str] = None) -> None:
        if compression not in (CompressionMode.NONE, CompressionMode.STORAGE):
            raise WriterError(f'MCAP storage compresses chunks, not {compression.name} mode')
        self.path = path / (file_name or f'{path.name}.mcap')
        self._file = _File(self.path)
        self._mcap = McapFileWriter(
            cast(BinaryIO, self._file), chunk_size=CHUNK_BYTES,
            compression=(CompressionType.ZSTD if compression == CompressionMode.STORAGE
                         else CompressionType.NONE),
            enable_crcs=self.chunk_crc)
        self._mcap.start(profile='ros2', library=f'robot_sim recording, mcap {version("mcap")}')
        self._schemas: Dict[str, int] = {}
        self._channels: Dict[int, int] = {}
        self.durable_size = self._file.tell()     # what the last flush left complete

    @property
    def size(self) -> int:
        """Bytes in the file so far (not counting the chunk in progress)."""
        return self._file.tell()

    def add_msgtype(self, connection: Connection) -> None:
        self._schemas[connection.msgtype] = self._mcap.register_schema(
            connection.msgtype, _schema_encoding(connection), connection.msgdef.data.encode())

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        self._channels[connection.id] = self._mcap.register_channel(
            connection.topic, _serialization_format(connection),
            self._schemas[connection.msgtype],
            {'offered_qos_profiles': offered_qos_profiles, 'topic_type_hash': connection.digest})

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        self._mcap.add_message(self._channels[connection.id], log_time=timestamp,
                               data=bytes(data), publish_time=timestamp)

    def flush(self) -> None:
        self._mcap.flush()
        self.durable_size = self._file.tell()

    def close(self, version: int, metadata: str) -> None:
        del version  # (the metadata text carries it)
        try:
            self._mcap.add_metadata('rosbag2', {'serialized_metadata': metadata})
            self._mcap.finish()
        finally:
            self._file.close()

    def close_at_durable(self, metadata: str) -> None:
        """End the file where the last flush left it, whatever was written after: the bag's
        metadata record, DataEnd and a footer that declares no summary section (readers then
        scan the data section, as rosbags and rosbag2's MCAP plugin do)."""
        try:
            self._file.cut(self.durable_size)
            out = RecordBuilder()
            Metadata('rosbag2', {'serialized_metadata': metadata}).write(out)
            DataEnd(0).write(out)
            Footer(0, 0, 0).write(out)
            self._file.write(out.end() + MCAP0_MAGIC)
        finally:
            self._file.close()

    def abort(self) -> None:
        self._file.close()


class CheckedMcapStorage(McapStorage):
    """:class:`McapStorage` whose chunks carry a CRC-32."""

    chunk_crc = True


class Sqlite3Storage:
    """One ``<bag>/<bag>.db3`` database in rosbag2's schema version 4."""

    SCHEMA = """
    CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
    CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL,
                          metadata TEXT NOT NULL);
    CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
                        serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL,
                        type_description_hash TEXT NOT NULL);
    CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL,
                                     encoding TEXT NOT NULL,
                                     encoded_message_definition TEXT NOT NULL,
                                     type_description_hash TEXT NOT NULL);
    CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
                          timestamp INTEGER NOT NULL, data BLOB NOT NULL);
    CREATE INDEX timestamp_idx ON messages (timestamp ASC);
    INSERT INTO schema(schema_version, ros_distro) VALUES (4, 'jazzy');
    """

    SUFFIX = '.db3'

    def __init__(self, path: Path, compression: CompressionMode,
                 file_name: Optional[str] = None) -> None:
        if compression != CompressionMode.NONE:
            raise WriterError('SQLite bags are written uncompressed')
        self.path = path / (file_name or f'{path.name}.db3')
        self._db = sqlite3.connect(f'file:{self.path}?mode=rwc', uri=True)
        # Crash-safe: a rollback journal, synced at every commit (rosbag2 writes with the
        # journal in memory and no syncing unless told otherwise). A commit that fails, or a
        # process killed in one, leaves the database as the last commit left it, and between
        # commits the bag is the one .db3 file. (A write-ahead log was tried: a checkpoint cut
        # short by a full disk left the database readable only with its -wal file beside it,
        # which readers that open a bag read-only, as rosbags does, ignore: "database disk
        # image is malformed".)
        self._db.execute('PRAGMA journal_mode=DELETE')
        self._db.execute('PRAGMA synchronous=FULL')
        self._db.executescript(self.SCHEMA)
        self._cursor = self._db.cursor()

    @property
    def size(self) -> int:
        wal = self.path.with_name(self.path.name + '-wal')
        return self.path.stat().st_size + (wal.stat().st_size if wal.exists() else 0)

    def add_msgtype(self, connection: Connection) -> None:
        self._cursor.execute(
            'INSERT INTO message_definitions (topic_type, encoding, encoded_message_definition, '
            'type_description_hash) VALUES (?, ?, ?, ?)',
            (connection.msgtype, _schema_encoding(connection), connection.msgdef.data,
             connection.digest))

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        self._cursor.execute('INSERT INTO topics VALUES (?, ?, ?, ?, ?, ?)',
                             (connection.id, connection.topic, connection.msgtype,
                              _serialization_format(connection), offered_qos_profiles,
                              connection.digest))

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        self._cursor.execute('INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)',
                             (connection.id, timestamp, data))

    def flush(self) -> None:
        try:
            self._db.commit()
        except sqlite3.Error as exc:
            # The transaction is gone: its rows are not in the file, whatever comes next.
            self._db.rollback()
            raise OSError(f'{self.path}: commit failed ({exc})') from exc

    def close(self, version: int, metadata: str) -> None:
        try:
            self._cursor.execute(
                'INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)',
                (version, metadata))
            self.flush()
            self._db.execute('PRAGMA optimize')
        finally:
            self._db.close()

    def close_at_durable(self, metadata: str) -> None:
        """Close with what the last commit holds (and, space permitting, the metadata row)."""
        try:
            self._db.rollback()
            self._cursor.execute(
                'INSERT INTO metadata (metadata_version, metadata) VALUES (?, ?)',
                (9, metadata))
            self._db.commit()
        except sqlite3.Error:
            self._db.rollback()
        finally:
            self._db.close()

    def abort(self) -> None:
        try:
            self._db.rollback()
        finally:
            self._db.close()


Storage = Union[McapStorage, Sqlite3Storage]


class DurableWriter(Writer):
    """rosbags' rosbag2 Writer on the storages above: :meth:`flush`, splitting into several
    files (``max_bag_size`` bytes of messages, ``max_bag_duration`` seconds of message time; 0:
    no limit), and :meth:`close_after_failure`. It writes metadata.yaml itself, with a line per
    file, as rosbag2 does for a split bag."""

    STORAGE_PLUGINS: Mapping = {StoragePlugin.MCAP: McapStorage,
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
    return yaml.safe_dump(data, default_flow_style=False, sort_keys=False)


def _dump_qos(bag_version: int, profiles: Sequence[Qos]) -> str:
    """The offered QoS profiles as rosbags' Writer hands them to its storage."""
    dumped = (dump_qos_v9 if bag_version >= 9 else dump_qos_v8)(list(profiles))
    return dumped if isinstance(dumped, str) else _yaml(dumped).strip()
