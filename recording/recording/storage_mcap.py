"""rosbag2's MCAP storage for rosbags' Writer, written through the ``mcap`` library (the
format's reference writer, with chunk CRCs) and made durable while the bag is open.

The ``ros2`` profile as rosbag2's MCAP plugin writes it: ``ros2msg`` schemas, ``cdr`` channels
carrying ``offered_qos_profiles`` and ``topic_type_hash``, and the bag's metadata as a
``rosbag2`` metadata record. :meth:`McapStorage.flush` ends the chunk in progress and hands it
to the OS; after a failed write, :meth:`McapStorage.close_at_durable` cuts the file back to its
last flush and ends it there (its metadata record, DataEnd and a footer with no summary
section, which readers scan).
"""
from __future__ import annotations

import os
from importlib.metadata import version
from pathlib import Path
from typing import BinaryIO, Dict, Optional, Union, cast

from mcap.data_stream import RecordBuilder
from mcap.records import DataEnd, Footer, Metadata
from mcap.writer import MCAP0_MAGIC, CompressionType
from mcap.writer import Writer as McapFileWriter
from rosbags.interfaces import Connection
from rosbags.rosbag2 import WriterError
from rosbags.rosbag2.enums import CompressionMode

from recording.storage_common import schema_encoding, serialization_format

CHUNK_BYTES = 1 << 20  # rosbag2's MCAP default chunk size


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
            connection.msgtype, schema_encoding(connection), connection.msgdef.data.encode())

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        self._channels[connection.id] = self._mcap.register_channel(
            connection.topic, serialization_format(connection),
            self._schemas[connection.msgtype],
            {'offered_qos_profiles': offered_qos_profiles, 'topic_type_hash': connection.digest})

    def write(self, connection: Connection, timestamp: int, data: bytes | memoryview) -> None:
        self._mcap.add_message(self._channels[connection.id], log_time=timestamp,
                               data=bytes(data), publish_time=timestamp)

    def flush(self) -> None:
        self._mcap.flush()  # type: ignore[no-untyped-call]
        self.durable_size = self._file.tell()

    def close(self, version: int, metadata: str) -> None:
        del version  # (the metadata text carries it)
        try:
            self._mcap.add_metadata('rosbag2', {'serialized_metadata': metadata})
            self._mcap.finish()  # type: ignore[no-untyped-call]
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
            self._file.write(out.end() + MCAP0_MAGIC)  # type: ignore[no-untyped-call]
        finally:
            self._file.close()

    def abort(self) -> None:
        self._file.close()


class CheckedMcapStorage(McapStorage):
    """:class:`McapStorage` whose chunks carry a CRC-32."""

    chunk_crc = True
