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

A flush that fails (a full disk) raises OSError; what was flushed before stays readable.
"""
from __future__ import annotations

import sqlite3
from importlib.metadata import version
from pathlib import Path
from typing import Dict, Literal, Mapping

from mcap.writer import CompressionType
from mcap.writer import Writer as McapFileWriter
from rosbags.interfaces import Connection, ConnectionExtRosbag2, MessageDefinitionFormat
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.enums import CompressionMode

CHUNK_BYTES = 1 << 20  # rosbag2's MCAP default chunk size


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

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        if compression not in (CompressionMode.NONE, CompressionMode.STORAGE):
            raise WriterError(f'MCAP storage compresses chunks, not {compression.name} mode')
        self.path = path / f'{path.name}.mcap'
        self._file = self.path.open('xb')
        self._mcap = McapFileWriter(
            self._file, chunk_size=CHUNK_BYTES,
            compression=(CompressionType.ZSTD if compression == CompressionMode.STORAGE
                         else CompressionType.NONE),
            enable_crcs=self.chunk_crc)
        self._mcap.start(profile='ros2', library=f'robot_sim recording, mcap {version("mcap")}')
        self._schemas: Dict[str, int] = {}
        self._channels: Dict[int, int] = {}

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

    def close(self, version: int, metadata: str) -> None:
        del version  # (the metadata text carries it)
        try:
            self._mcap.add_metadata('rosbag2', {'serialized_metadata': metadata})
            self._mcap.finish()
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

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        if compression != CompressionMode.NONE:
            raise WriterError('SQLite bags are written uncompressed')
        self.path = path / f'{path.name}.db3'
        self._db = sqlite3.connect(f'file:{self.path}?mode=rwc', uri=True)
        self._db.executescript(self.SCHEMA)
        self._cursor = self._db.cursor()

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

    def abort(self) -> None:
        try:
            self._db.rollback()
        finally:
            self._db.close()


class DurableWriter(Writer):
    """rosbags' rosbag2 Writer on the storages above, with :meth:`flush`."""

    STORAGE_PLUGINS: Mapping = {StoragePlugin.MCAP: McapStorage,
                                StoragePlugin.SQLITE3: Sqlite3Storage}

    def __init__(self, path: Path, *, version: Literal[8, 9], storage_plugin: StoragePlugin,
                 chunk_crc: bool = False) -> None:
        super().__init__(path, version=version, storage_plugin=storage_plugin)
        if chunk_crc:
            # (rosbags builds the storage from the class it finds in STORAGE_PLUGINS.)
            self.STORAGE_PLUGINS = {**self.STORAGE_PLUGINS,
                                    StoragePlugin.MCAP: CheckedMcapStorage}

    def flush(self) -> None:
        """Make every message written so far survive a killed process."""
        storage = self.storage
        if storage is None:
            raise WriterError('the bag is not open')
        assert isinstance(storage, (McapStorage, Sqlite3Storage))
        storage.flush()
