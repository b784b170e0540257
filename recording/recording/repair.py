"""Make the bag of a killed recorder readable again: ``bag_repair BAG`` writes ``BAG_repaired``.

A recorder killed with SIGKILL leaves no metadata.yaml and, for MCAP, no summary section. What
it flushed is intact: MCAP chunks that were written completely, SQLite rows that were
committed. Repair reads exactly those and writes them into a new, complete bag beside the
original, which is left untouched.
"""
from __future__ import annotations

import argparse
import io
import shutil
import sqlite3
import struct
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Tuple

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from recording.bag_writer import unique_bag_path
from recording.qos_profiles import parse_offered_qos
from recording.types import register_bag_definition

MCAP_MAGIC = b'\x89MCAP0\r\n'
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_FOOTER = 0x03, 0x04, 0x05, 0x06, 0x02


class RepairError(RuntimeError):
    """Nothing recoverable, or not a bag directory."""


@dataclass
class Recovered:
    schemas: Dict[int, Tuple[str, str]] = field(default_factory=dict)   # id -> (type, msgdef)
    channels: Dict[int, Tuple[str, int, str]] = field(default_factory=dict)  # id -> (topic,
    #                                                                 schema id, qos yaml)
    messages: List[Tuple[int, int, bytes]] = field(default_factory=list)  # (channel, t, data)
    truncated: bool = False


def _string(buf: io.BytesIO) -> str:
    (n,) = struct.unpack('<I', _exact(buf, 4))
    return _exact(buf, n).decode()


def _exact(buf, n: int) -> bytes:
    data = buf.read(n)
    if len(data) != n:
        raise EOFError
    return data


def _records(stream) -> Iterator[Tuple[int, bytes]]:
    """(opcode, content) of each complete record; stops at the first incomplete one."""
    while True:
        head = stream.read(9)
        if len(head) < 9:
            return
        op, length = head[0], struct.unpack('<Q', head[1:])[0]
        content = stream.read(length)
        if len(content) != length:
            raise EOFError
        yield op, content


def scan_mcap(path: Path) -> Recovered:
    found = Recovered()
    with open(path, 'rb') as f:
        if f.read(8) != MCAP_MAGIC:
            raise RepairError(f'{path} is not an MCAP file')
        try:
            for op, content in _records(f):
                if op == OP_CHUNK:
                    _scan_chunk(content, found)
                elif op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
                    _scan_record(op, content, found)
                elif op == OP_FOOTER:
                    break
        except EOFError:
            found.truncated = True
    return found


def _scan_chunk(content: bytes, found: Recovered) -> None:
    buf = io.BytesIO(content)
    _exact(buf, 8 + 8 + 8 + 4)  # start, end, uncompressed size, crc
    compression = _string(buf)
    (size,) = struct.unpack('<Q', _exact(buf, 8))
    data = _exact(buf, size)
    if compression == 'zstd':
        try:
            from compression import zstd  # Python >= 3.14
        except ImportError:
            from backports import zstd  # what rosbags itself uses before 3.14
        data = zstd.decompress(data)
    elif compression:
        raise RepairError(f'unsupported chunk compression "{compression}"')
    for op, rec in _records(io.BytesIO(data)):
        _scan_record(op, rec, found)


def _scan_record(op: int, content: bytes, found: Recovered) -> None:
    buf = io.BytesIO(content)
    if op == OP_SCHEMA:
        (sid,) = struct.unpack('<H', _exact(buf, 2))
        name, _encoding, data = _string(buf), _string(buf), _string(buf)
        found.schemas[sid] = (name, data)
    elif op == OP_CHANNEL:
        cid, sid = struct.unpack('<HH', _exact(buf, 4))
        topic, _encoding = _string(buf), _string(buf)
        (meta_len,) = struct.unpack('<I', _exact(buf, 4))
        meta = io.BytesIO(_exact(buf, meta_len))
        entries = {}
        while meta.tell() < meta_len:
            key = _string(meta)
            entries[key] = _string(meta)
        found.channels[cid] = (topic, sid, entries.get('offered_qos_profiles', ''))
    elif op == OP_MESSAGE:
        cid, _seq, log_time, _pub_time = struct.unpack('<HIQQ', _exact(buf, 22))
        found.messages.append((cid, log_time, content[22:]))


def scan_sqlite(path: Path) -> Recovered:
    """What a sqlite3 bag's database holds, as committed. A writer killed in a transaction
    leaves a hot journal (or a write-ahead log) beside it that SQLite must roll back (or check)
    before it reads, and it cannot in a read-only connection ("attempt to write a readonly
    database"): the database is read from a copy made with those files, so the bag is left as
    it was."""
    found = Recovered()
    with tempfile.TemporaryDirectory(prefix='repair_') as scratch:
        copy = Path(scratch) / path.name
        for suffix in ('', '-journal', '-wal', '-shm'):
            side = path.with_name(path.name + suffix)
            if side.exists():
                shutil.copyfile(side, copy.with_name(copy.name + suffix))
        _scan_sqlite_copy(copy, path, found)
    return found


def _scan_sqlite_copy(copy: Path, path: Path, found: Recovered) -> None:
    try:
        db = sqlite3.connect(copy)
        defs = {row[0]: row[1] for row in db.execute(
            'SELECT topic_type, encoded_message_definition FROM message_definitions')}
        for tid, name, msgtype, qos in db.execute(
                'SELECT id, name, type, offered_qos_profiles FROM topics'):
            sid = len(found.schemas) + 1
            found.schemas[sid] = (msgtype, defs.get(msgtype, ''))
            found.channels[tid] = (name, sid, qos)
        found.messages = list(db.execute(
            'SELECT topic_id, timestamp, data FROM messages ORDER BY id'))
        db.close()
    except (sqlite3.DatabaseError, sqlite3.OperationalError) as exc:
        raise RepairError(f'{path}: {exc}') from None


def repair(bag: Path, output: Optional[Path] = None) -> Tuple[Path, int, bool]:
    """Write the recoverable part of ``bag`` to a new bag; returns (path, messages, truncated)."""
    bag = Path(bag)
    if not bag.is_dir():
        raise RepairError(f'{bag} is not a bag directory')
    mcaps, dbs = sorted(bag.glob('*.mcap')), sorted(bag.glob('*.db3'))
    if mcaps:
        found, plugin = scan_mcap(mcaps[0]), StoragePlugin.MCAP
    elif dbs:
        found, plugin = scan_sqlite(dbs[0]), StoragePlugin.SQLITE3
    else:
        raise RepairError(f'{bag} holds no .mcap or .db3 file')
    if not found.channels:
        raise RepairError(f'{bag}: no topic was flushed before the recorder stopped')
    typestore = get_typestore(Stores.EMPTY)
    out = output or unique_bag_path(bag.parent, bag.name + '_repaired')
    writer = Writer(out, version=9, storage_plugin=plugin)
    writer.open()
    connections = {}
    for cid, (topic, sid, qos) in sorted(found.channels.items()):
        msgtype, msgdef = found.schemas[sid]
        register_bag_definition(typestore, msgtype, msgdef)
        connections[cid] = writer.add_connection(
            topic, msgtype, msgdef=msgdef, rihs01=typestore.hash_rihs01(msgtype),
            offered_qos_profiles=parse_offered_qos(qos))
    count = 0
    for cid, timestamp, data in found.messages:
        if cid in connections:
            writer.write(connections[cid], timestamp, bytes(data))
            count += 1
    writer.close()
    return out, count, found.truncated


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
