"""Make the bag of a killed recorder readable again: ``bag_repair BAG`` writes ``BAG_repaired``.

A recorder killed with SIGKILL leaves no metadata.yaml and, for MCAP, no summary section. What
it flushed is intact: MCAP chunks that were written completely, SQLite rows that were
committed. Repair reads exactly those and writes them into a new, complete bag beside the
original, which is left untouched.

The MCAP file is read with the ``mcap`` library's stream reader, which needs no summary and
stops at the first incomplete record; SQLite rows are read with a cursor. Messages go to the
new bag as they are read: nothing is held in memory but the schemas and channels.
"""
from __future__ import annotations

import argparse
import shutil
import sqlite3
import struct
import sys
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Iterator, Optional, Tuple, Union

from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from recording.bag_writer import unique_bag_path
from recording.qos_profiles import parse_offered_qos
from recording.types import register_bag_definition


class RepairError(RuntimeError):
    """Nothing recoverable, or not a bag directory."""


@dataclass(frozen=True)
class Topic:
    """A recovered channel: topic name, message type and definition, offered QoS (YAML)."""
    channel: int
    topic: str
    msgtype: str
    msgdef: str
    qos: str


# What a scan yields, in file order: a topic before the messages on it.
Item = Union[Topic, Tuple[int, int, bytes]]        # or (channel, log time [ns], data)


class Scan:
    """The recoverable records of one bag file, read lazily; ``truncated`` is set once the
    scan met an incomplete record."""

    def __init__(self, items: Iterator[Item]) -> None:
        self._items = items
        self.truncated = False

    def __iter__(self) -> Iterator[Item]:
        return self._items


def scan_mcap(path: Path) -> Scan:
    scan = Scan(iter(()))

    def items() -> Iterator[Item]:
        schemas: Dict[int, Schema] = {}
        with open(path, 'rb') as stream:
            try:
                for record in StreamReader(stream, skip_magic=False).records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        schema = schemas.get(record.schema_id)
                        if schema is not None:
                            yield Topic(record.id, record.topic, schema.name,
                                        schema.data.decode(),
                                        record.metadata.get('offered_qos_profiles', ''))
                    elif isinstance(record, Message):
                        yield record.channel_id, record.log_time, record.data
            except InvalidMagic:
                raise RepairError(f'{path} is not an MCAP file') from None
            except (EndOfFile, struct.error):
                # (The reader raises struct.error when the file ends inside a record's
                # opcode and length.)
                scan.truncated = True
            except McapError as exc:
                # (A chunk cut short reads as a bad length or a failed decompression.)
                scan.truncated = True
                print(f'bag_repair: stopped at a damaged record: {exc}', file=sys.stderr)

    scan._items = items()
    return scan


def scan_sqlite(path: Path) -> Scan:
    """What a sqlite3 bag's database holds, as committed. A writer killed in a transaction
    leaves a hot journal (or a write-ahead log) beside it that SQLite must roll back (or check)
    before it reads, and it cannot in a read-only connection ("attempt to write a readonly
    database"): the database is read from a copy made with those files, so the bag is left as
    it was."""
    def items() -> Iterator[Item]:
        with _sqlite_copy(path) as copy:
            try:
                db = sqlite3.connect(copy)
                try:
                    defs = {row[0]: row[1] for row in db.execute(
                        'SELECT topic_type, encoded_message_definition FROM '
                        'message_definitions')}
                    for tid, name, msgtype, qos in db.execute(
                            'SELECT id, name, type, offered_qos_profiles FROM topics'):
                        yield Topic(tid, name, msgtype, defs.get(msgtype, ''), qos)
                    yield from db.execute(
                        'SELECT topic_id, timestamp, data FROM messages ORDER BY id')
                finally:
                    db.close()
            except (sqlite3.DatabaseError, sqlite3.OperationalError) as exc:
                raise RepairError(f'{path}: {exc}') from None

    return Scan(items())


@contextmanager
def _sqlite_copy(path: Path) -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix='repair_') as scratch:
        copy = Path(scratch) / path.name
        for suffix in ('', '-journal', '-wal', '-shm'):
            side = path.with_name(path.name + suffix)
            if side.exists():
                shutil.copyfile(side, copy.with_name(copy.name + suffix))
        yield copy


def repair(bag: Path, output: Optional[Path] = None) -> Tuple[Path, int, bool]:
    """Write the recoverable part of ``bag`` to a new bag; returns (path, messages, truncated)."""
    bag = Path(bag)
    if not bag.is_dir():
        raise RepairError(f'{bag} is not a bag directory')
    mcaps, dbs = sorted(bag.glob('*.mcap')), sorted(bag.glob('*.db3'))
    if mcaps:
        scan, plugin = scan_mcap(mcaps[0]), StoragePlugin.MCAP
    elif dbs:
        scan, plugin = scan_sqlite(dbs[0]), StoragePlugin.SQLITE3
    else:
        raise RepairError(f'{bag} holds no .mcap or .db3 file')
    typestore = get_typestore(Stores.EMPTY)
    out = output or unique_bag_path(bag.parent, bag.name + '_repaired')
    writer = Writer(out, version=9, storage_plugin=plugin)
    writer.open()
    connections = {}
    count = 0
    try:
        for item in scan:
            if isinstance(item, Topic):
                register_bag_definition(typestore, item.msgtype, item.msgdef)
                connections[item.channel] = writer.add_connection(
                    item.topic, item.msgtype, msgdef=item.msgdef,
                    rihs01=typestore.hash_rihs01(item.msgtype),
                    offered_qos_profiles=parse_offered_qos(item.qos))
            elif item[0] in connections:
                writer.write(connections[item[0]], item[1], bytes(item[2]))
                count += 1
    except RepairError:
        writer.close()
        shutil.rmtree(out, ignore_errors=True)
        raise
    writer.close()
    if not connections:
        shutil.rmtree(out, ignore_errors=True)
        raise RepairError(f'{bag}: no topic was flushed before the recorder stopped')
    return out, count, scan.truncated


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='bag_repair', description=__doc__.splitlines()[0])
    parser.add_argument('bag', type=Path, help='bag directory left by a killed recorder')
    parser.add_argument('-o', '--output', type=Path, help='new bag directory (must not exist)')
    args = parser.parse_args(argv)
    if args.output is not None and args.output.exists():
        print(f'bag_repair: error: {args.output} exists; a bag is never overwritten',
              file=sys.stderr)
        return 2
    try:
        out, count, truncated = repair(args.bag, args.output)
    except RepairError as exc:
        print(f'bag_repair: error: {exc}', file=sys.stderr)
        return 2
    print(f'bag_repair: recovered {count} messages into {out}'
          + (' (the last, incomplete record of the original was dropped)' if truncated else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
