"""Make the bag of a killed recorder readable again: ``bag_repair BAG`` writes ``BAG_repaired``.

A recorder killed with SIGKILL leaves no metadata.yaml and, for MCAP, no summary section. What
it flushed is intact: MCAP chunks that were written completely, SQLite rows that were
committed. Repair reads exactly those, from every file of the bag (a bag split by size or
duration has several), and writes them into a new, complete bag beside the original, which is
left untouched.

MCAP files are read record by record with the ``mcap`` library's stream reader, which needs no
summary; chunks are opened here, one at a time, so that a damaged chunk (flipped bytes, a bad
length, a failed decompression or checksum) costs its own messages and no more. The file's
outer framing must hold: where it breaks, the rest of that file is lost. SQLite rows are read
with a cursor, up to the first unreadable page. Nothing is held in memory but the schemas and
channels; a length read from the file is never trusted past the file's own size.
"""
from __future__ import annotations

import argparse
import re
import shutil
import sqlite3
import struct
import sys
import tempfile
import zlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Hashable, Iterator, List, Optional, Sequence, Tuple, Union

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.opcode import Opcode
from mcap.records import Channel as McapChannel
from mcap.records import Chunk, Message, Schema
from mcap.stream_reader import StreamReader, get_chunk_data_stream
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.writer import WriterError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.base import TypesysError

from recording.bag_writer import unique_bag_path
from recording.qos_profiles import parse_offered_qos
from recording.types import register_bag_definition

# A chunk that says it unpacks to more than this is damaged (rosbag2 writes chunks of about
# 1 MiB; a corrupt size field would otherwise be allocated).
MAX_CHUNK_BYTES = 1 << 30
# What a damaged record raises while it is read (the decompressors' own errors among them).
_DAMAGE = (McapError, EndOfFile, struct.error, UnicodeDecodeError, ValueError, KeyError,
           RuntimeError, MemoryError, OverflowError, zlib.error)


class RepairError(RuntimeError):
    """Nothing recoverable, or not a bag directory."""


@dataclass(frozen=True)
class Topic:
    """A recovered channel: its key in the scan, topic name, message type and definition,
    offered QoS (YAML)."""
    channel: Hashable
    topic: str
    msgtype: str
    msgdef: str
    qos: str


# What a scan yields, in file order: a topic before the messages on it.
Item = Union[Topic, Tuple[Hashable, int, bytes]]        # or (channel, log time [ns], data)


@dataclass
class Scan:
    """The recoverable records of one bag file, read lazily: ``truncated`` once the scan met
    the file's incomplete end, ``damage`` what it had to skip (why, for the report)."""

    path: Path
    items: Iterator[Item] = iter(())
    truncated: bool = False
    damage: List[str] = field(default_factory=list)

    def __iter__(self) -> Iterator[Item]:
        return self.items


def scan_mcap(path: Path, file_index: int = 0) -> Scan:
    """The schemas, channels and messages of an MCAP file, chunk by chunk."""
    scan = Scan(path)

    def items() -> Iterator[Item]:
        schemas: Dict[int, Schema] = {}

        def recovered(record: Any) -> Iterator[Item]:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, McapChannel):
                schema = schemas.get(record.schema_id)
                if schema is None:
                    scan.damage.append(f'channel {record.topic!r} without its schema')
                    return
                try:
                    msgdef = schema.data.decode()
                except UnicodeDecodeError:
                    scan.damage.append(f'the definition of {schema.name!r} is not text')
                    return
                yield Topic((file_index, record.id), record.topic, schema.name, msgdef,
                            record.metadata.get('offered_qos_profiles', ''))
            elif isinstance(record, Message):
                if record.log_time >= 2 ** 63:
                    scan.damage.append('a message with a damaged time skipped')
                    return
                yield (file_index, record.channel_id), record.log_time, record.data

        size = path.stat().st_size
        with open(path, 'rb') as stream:
            # (No record is longer than the file: a corrupt length is not allocated.)
            reader = StreamReader(stream, skip_magic=False, emit_chunks=True,
                                  record_size_limit=max(size, 1))
            try:
                for record in reader.records:
                    if isinstance(record, Chunk):
                        yield from _chunk(record, recovered, scan)
                    else:
                        yield from recovered(record)
            except InvalidMagic:
                raise RepairError(f'{path} is not an MCAP file') from None
            except (EndOfFile, struct.error):
                # (The reader raises struct.error when the file ends inside a record's
                # opcode and length.)
                scan.truncated = True
            except _DAMAGE as exc:
                scan.truncated = True
                scan.damage.append(f'the file is unreadable past a damaged record '
                                   f'({type(exc).__name__}: {str(exc)[:80]})')

    scan.items = items()
    return scan


def _chunk(chunk: Chunk, recovered: Callable[[Any], Iterator[Item]],
           scan: Scan) -> Iterator[Item]:
    """The records of one chunk, up to the first damaged one."""
    if chunk.uncompressed_size > MAX_CHUNK_BYTES:
        scan.damage.append(f'a chunk claims {chunk.uncompressed_size} bytes: skipped')
        return
    try:
        stream, length = get_chunk_data_stream(chunk, validate_crc=True)
    except _DAMAGE as exc:
        scan.damage.append(f'a chunk that does not unpack ({type(exc).__name__}): skipped')
        return
    records = _chunk_records(stream, length)
    while True:
        try:
            record = next(records)
        except StopIteration:
            return
        except _DAMAGE as exc:
            scan.damage.append(f'a chunk damaged inside ({type(exc).__name__}): the rest of it '
                               'skipped')
            return
        yield from recovered(record)


def _chunk_records(stream: ReadDataStream, length: int) -> Iterator[Union[Schema, McapChannel,
                                                                          Message]]:
    while stream.count < length:
        opcode = stream.read1()
        size = stream.read8()
        if size > length - stream.count:
            raise McapError(f'a record of {size} bytes in {length - stream.count} left')
        start = stream.count
        if opcode == Opcode.CHANNEL:
            yield McapChannel.read(stream)
        elif opcode == Opcode.MESSAGE:
            yield Message.read(stream, size)
        elif opcode == Opcode.SCHEMA:
            yield Schema.read(stream)
        if stream.count - start > size:
            raise McapError('a record read past its length')
        stream.read(size - (stream.count - start))


def scan_sqlite(path: Path, file_index: int = 0) -> Scan:
    """What a sqlite3 bag's database holds, as committed. A writer killed in a transaction
    leaves a hot journal (or a write-ahead log) beside it that SQLite must roll back (or check)
    before it reads, and it cannot in a read-only connection ("attempt to write a readonly
    database"): the database is read from a copy made with those files, so the bag is left as
    it was."""
    scan = Scan(path)

    def items() -> Iterator[Item]:
        with _sqlite_copy(path) as copy:
            db = sqlite3.connect(copy)
            # (Text is decoded here, row by row: a damaged row may not be UTF-8.)
            db.text_factory = bytes
            try:
                try:
                    defs = dict(_text_rows(db.execute(
                        'SELECT topic_type, encoded_message_definition FROM '
                        'message_definitions'), scan))
                    topics = list(_text_rows(db.execute(
                        'SELECT name, type, offered_qos_profiles, id FROM topics'), scan))
                except (sqlite3.Error, UnicodeDecodeError) as exc:
                    # (UnicodeDecodeError: the schema itself is damaged, its column names.)
                    raise RepairError(f'{path}: {exc}') from None
                for name, msgtype, qos, tid in topics:
                    yield Topic((file_index, tid), name, msgtype, defs.get(msgtype, ''),
                                qos or '')
                damaged = 0
                try:
                    for tid, stamp, data in db.execute(
                            'SELECT topic_id, timestamp, data FROM messages ORDER BY id'):
                        # (SQLite keeps any type in any column: a damaged row can hold text
                        # where a time was.)
                        if not (isinstance(tid, int) and isinstance(stamp, int)
                                and 0 <= stamp < 2 ** 63 and isinstance(data, bytes)):
                            damaged += 1
                            continue
                        yield (file_index, tid), stamp, data
                except (sqlite3.Error, UnicodeDecodeError) as exc:
                    scan.truncated = True
                    scan.damage.append(f'the messages are unreadable past a damaged page '
                                       f'({exc})')
                if damaged:
                    scan.damage.append(f'{damaged} damaged message rows skipped')
            finally:
                db.close()

    scan.items = items()
    return scan


def _text_rows(rows: Any, scan: Scan) -> Iterator[Tuple[Any, ...]]:
    """Rows whose text columns (bytes, as read) are UTF-8, decoded; the others are noted."""
    for row in rows:
        try:
            yield tuple(v.decode() if isinstance(v, bytes) else v for v in row)
        except UnicodeDecodeError:
            scan.damage.append('a damaged topic or definition row skipped')


@contextmanager
def _sqlite_copy(path: Path) -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix='repair_') as scratch:
        copy = Path(scratch) / path.name
        for suffix in ('', '-journal', '-wal', '-shm'):
            side = path.with_name(path.name + suffix)
            if side.is_file():
                shutil.copyfile(side, copy.with_name(copy.name + suffix))
        yield copy


def _split_index(path: Path) -> Tuple[int, str]:
    """A split bag's files in their order: ``run_0.mcap``, ``run_1.mcap``, ... ``run_10``."""
    match = re.search(r'_(\d+)\.[^.]+$', path.name)
    return (int(match.group(1)) if match else -1, path.name)


def data_files(bag: Path) -> Tuple[StoragePlugin, List[Path], List[str]]:
    """The storage of a bag directory and its data files in order, and why any were left out."""
    if not bag.is_dir():
        raise RepairError(f'{bag} is not a bag directory')
    skipped = []
    found: Dict[str, List[Path]] = {'.mcap': [], '.db3': []}
    for path in bag.iterdir():
        if path.suffix in found:
            if path.is_file():
                found[path.suffix].append(path)
            else:
                skipped.append(f'{path.name} is not a file')
    if found['.mcap']:
        plugin, files = StoragePlugin.MCAP, found['.mcap']
        if found['.db3']:
            skipped.append(f'{len(found[".db3"])} .db3 file(s) beside the MCAP files')
    elif found['.db3']:
        plugin, files = StoragePlugin.SQLITE3, found['.db3']
    else:
        raise RepairError(f'{bag} holds no .mcap or .db3 file'
                          + (f' ({"; ".join(skipped)})' if skipped else ''))
    return plugin, sorted(files, key=_split_index), skipped


@dataclass
class Repaired:
    """What a repair recovered."""
    path: Path
    messages: int
    truncated: bool
    notes: List[str]


def repair(bag: Path, output: Optional[Path] = None) -> Repaired:
    """Write the recoverable part of ``bag`` to a new bag."""
    bag = Path(bag)
    plugin, files, notes = data_files(bag)
    scanner = scan_mcap if plugin == StoragePlugin.MCAP else scan_sqlite
    typestore = get_typestore(Stores.EMPTY)
    out = output or unique_bag_path(bag.parent, bag.name + '_repaired')
    writer = Writer(out, version=9, storage_plugin=plugin)
    writer.open()
    # One connection per (topic, type, definition): a channel recorded again (in each file of
    # a split bag, and in a closed MCAP's summary) is the same connection.
    by_topic: Dict[Tuple[str, str, str], Connection] = {}
    connections: Dict[Hashable, Connection] = {}
    count, truncated, written = 0, False, False
    try:
        for k, path in enumerate(files):
            scan = scanner(path, k)
            for item in scan:
                if isinstance(item, Topic):
                    key = (item.topic, item.msgtype, item.msgdef)
                    if key not in by_topic:
                        try:
                            register_bag_definition(typestore, item.msgtype, item.msgdef)
                            by_topic[key] = writer.add_connection(
                                item.topic, item.msgtype, msgdef=item.msgdef,
                                rihs01=typestore.hash_rihs01(item.msgtype),
                                offered_qos_profiles=parse_offered_qos(item.qos))
                        except (TypesysError, WriterError, KeyError, ValueError) as exc:
                            scan.damage.append(f'topic {item.topic} of type {item.msgtype!r} '
                                               f'cannot be written ({exc}): its messages skipped')
                            continue
                    connections[item.channel] = by_topic[key]
                elif item[0] in connections:
                    writer.write(connections[item[0]], item[1], bytes(item[2]))
                    count += 1
            truncated = truncated or scan.truncated
            notes.extend(f'{path.name}: {why}' for why in scan.damage)
        writer.close()
        written = True
    finally:
        if not written:
            try:
                writer.close()
            except (WriterError, OSError, sqlite3.Error):
                pass
            shutil.rmtree(out, ignore_errors=True)
    if not by_topic:
        shutil.rmtree(out, ignore_errors=True)
        raise RepairError(f'{bag}: no topic was flushed before the recorder stopped'
                          + (f' ({"; ".join(notes[:3])})' if notes else ''))
    return Repaired(out, count, truncated, notes)


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog='bag_repair', description=__doc__.splitlines()[0])
    parser.add_argument('bag', type=Path, help='bag directory left by a killed recorder')
    parser.add_argument('-o', '--output', type=Path, help='new bag directory (must not exist)')
    args = parser.parse_args(argv)
    if args.output is not None and args.output.exists():
        print(f'bag_repair: error: {args.output} exists; a bag is never overwritten',
              file=sys.stderr)
        return 2
    try:
        result = repair(args.bag, args.output)
    except RepairError as exc:
        print(f'bag_repair: error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:          # (a full disk, a file that cannot be read)
        print(f'bag_repair: error: {exc}; nothing was written', file=sys.stderr)
        return 2
    for note in result.notes:
        print(f'bag_repair: {note}', file=sys.stderr)
    print(f'bag_repair: recovered {result.messages} messages into {result.path}'
          + (' (the last, incomplete record of the original was dropped)'
             if result.truncated else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
