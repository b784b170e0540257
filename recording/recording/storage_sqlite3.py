"""rosbag2's SQLite storage (schema version 4) for rosbags' Writer, one transaction per
flush: a bag killed or out of disk keeps what its last commit holds."""
from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Optional

from rosbags.interfaces import Connection
from rosbags.rosbag2 import WriterError
from rosbags.rosbag2.enums import CompressionMode

from recording.storage_common import schema_encoding, serialization_format


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
        """Bytes in the database file (with the journal in DELETE mode, all there is)."""
        return self.path.stat().st_size

    def add_msgtype(self, connection: Connection) -> None:
        self._cursor.execute(
            'INSERT INTO message_definitions (topic_type, encoding, encoded_message_definition, '
            'type_description_hash) VALUES (?, ?, ?, ?)',
            (connection.msgtype, schema_encoding(connection), connection.msgdef.data,
             connection.digest))

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        self._cursor.execute('INSERT INTO topics VALUES (?, ?, ?, ?, ?, ?)',
                             (connection.id, connection.topic, connection.msgtype,
                              serialization_format(connection), offered_qos_profiles,
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
