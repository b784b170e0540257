"""Bag writing, repair, replay schedule and analysis, without ROS nodes."""
import json
import math
import os
import signal
import struct
import subprocess
import sys
import textwrap

import cv2
import numpy as np
import pytest
import yaml
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from std_msgs.msg import String

from helpers import chunked_bag, flipped_copies, lying_bag
from recording.analysis import AnalysisError, analyse, write_report
from recording.analysis import main as analysis_main
from recording.bag_writer import BagError, BagWriter, unique_bag_path
from recording.qos_profiles import (
    BEST_EFFORT,
    RELIABLE,
    TRANSIENT_LOCAL,
    VOLATILE,
    adapt_to_publishers,
    bag_qos,
    parse_offered_qos,
    replay_policies,
)
from recording.repair import RepairError, repair
from recording.repair import main as repair_main
from recording.replay_schedule import ReplaySchedule
from recording.types import TypeResolutionError, TypeResolver

STORAGES = ['mcap', 'sqlite3']


def _odom(x, y, yaw):
    msg = Odometry()
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return serialize_message(msg)


def _read_all(path):
    with AnyReader([path]) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


@pytest.mark.parametrize('storage', STORAGES)
def test_round_trip_is_byte_for_byte(tmp_path, storage):
    rng = np.random.default_rng(1)
    writer = BagWriter(tmp_path, 'run', storage)
    writer.add_topic('/odom', 'nav_msgs/msg/Odometry', [bag_qos(RELIABLE, VOLATILE, 10)])
    writer.add_topic('/text', 'std_msgs/msg/String')
    written = []
    for i in range(500):
        topic, data = (('/odom', _odom(*rng.normal(size=3))) if i % 3 else
                       ('/text', serialize_message(String(data='x' * int(rng.integers(0, 99))))))
        writer.write(topic, 1_000_000 * i, data)
        written.append((topic, 1_000_000 * i, data))
        if i % 97 == 0:
            writer.flush()
    writer.close()
    assert _read_all(writer.path) == written
    with AnyReader([writer.path]) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == {'/odom': 333, '/text': 167}
        qos = reader.connections[0].ext.offered_qos_profiles
        assert qos and qos[0].reliability.name == 'RELIABLE'


@pytest.mark.parametrize('storage', STORAGES)
def test_a_bag_keeps_its_custom_data_in_its_metadata_and_its_mcap_file(tmp_path, storage):
    what = json.dumps({'world': {'b': 1, 'a': "it's \\ odd"}, 'seed': 5})
    writer = BagWriter(tmp_path, 'kept', storage, custom_data={'robot_sim.trial': what})
    writer.add_topic('/text', 'std_msgs/msg/String')
    writer.write('/text', 1, serialize_message(String(data='x')))
    writer.close()
    info = yaml.safe_load((writer.path / 'metadata.yaml').read_text())
    assert info['rosbag2_bagfile_information']['custom_data'] == {'robot_sim.trial': what}
    if storage == 'mcap':      # (the file's own rosbag2 record: a bag file alone keeps it)
        from mcap.reader import make_reader
        with open(next(writer.path.glob('*.mcap')), 'rb') as f:
            record = next(make_reader(f).iter_metadata())
        inner = yaml.safe_load(record.metadata['serialized_metadata'])
        assert inner['custom_data'] == {'robot_sim.trial': what}


def test_the_recorders_custom_data_parameter_is_checked():
    from recording.recorder import parse_custom_data
    assert parse_custom_data(['', 'a=1', 'b=x=y', 'c=']) == {'a': '1', 'b': 'x=y', 'c': ''}
    for bad in ('novalue', '=1'):
        with pytest.raises(BagError, match='give KEY=VALUE'):
            parse_custom_data([bad])


def test_a_bag_is_never_overwritten(tmp_path):
    first = BagWriter(tmp_path, 'run')
    first.add_topic('/t', 'std_msgs/msg/String')
    first.write('/t', 1, serialize_message(String(data='first')))
    first.close()
    second = BagWriter(tmp_path, 'run')
    second.close()
    assert (first.path.name, second.path.name) == ('run', 'run_1')
    assert unique_bag_path(tmp_path, 'run').name == 'run_2'
    assert len(_read_all(first.path)) == 1
    with pytest.raises(BagError):
        BagWriter(tmp_path, '../escape')
    with pytest.raises(BagError):
        BagWriter(tmp_path, 'x', storage='rosbag1')


KILLED_WRITER = textwrap.dedent('''
    import os, signal, sys
    from pathlib import Path
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String
    from recording.bag_writer import BagWriter
    out, storage = Path(sys.argv[1]), sys.argv[2]
    w = BagWriter(out, 'killed', storage)
    w.add_topic('/t', 'std_msgs/msg/String')
    for i in range(1000):
        w.write('/t', i * 1000, serialize_message(String(data=f'm{i}')))
        if i == 599:
            w.flush()
    os.kill(os.getpid(), signal.SIGKILL)
''')


@pytest.mark.parametrize('storage', STORAGES)
def test_sigkill_loses_only_what_was_not_flushed_and_repair_restores_it(tmp_path, storage):
    proc = subprocess.run([sys.executable, '-c', KILLED_WRITER, str(tmp_path), storage],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL
    bag = tmp_path / 'killed'
    assert not (bag / 'metadata.yaml').exists()
    with pytest.raises(AnalysisError, match='bag_repair'):
        analyse(bag)
    result = repair(bag)
    out, count = result.path, result.messages
    assert out.name == 'killed_repaired' and count == 600
    messages = _read_all(out)
    assert [raw for _, _, raw in messages] == [
        serialize_message(String(data=f'm{i}')) for i in range(600)]
    assert [t for _, t, _ in messages] == [i * 1000 for i in range(600)]
    assert repair_main([str(bag)]) == 0 and (tmp_path / 'killed_repaired_1').is_dir()


KILLED_IN_A_BIG_TRANSACTION = textwrap.dedent('''
    import os, signal, sys
    from pathlib import Path
    from recording.bag_writer import BagWriter
    w = BagWriter(Path(sys.argv[1]), 'big', 'sqlite3')
    w.add_topic('/t', 'std_msgs/msg/String')
    for i in range(100):
        w.write('/t', i, bytes(100))
    w.flush()
    # 30 MB uncommitted: more than SQLite's page cache, so it spills into the database file
    # and keeps a hot journal beside it to roll back.
    for i in range(300):
        w.write('/t', 100 + i, bytes(100_000))
    side = [p.name for p in w.path.iterdir() if p.name.endswith(('-journal', '-wal'))]
    print(side, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
''')


def test_repair_of_a_sqlite_bag_killed_in_a_transaction_reads_what_was_committed(tmp_path):
    """A writer killed mid-transaction leaves a hot journal: a read-only connection cannot
    roll it back ('attempt to write a readonly database', seen under load); repair reads a
    copy, gets the committed messages, and leaves the bag as it was."""
    proc = subprocess.run([sys.executable, '-c', KILLED_IN_A_BIG_TRANSACTION, str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL
    assert 'journal' in proc.stdout or 'wal' in proc.stdout, proc.stdout
    bag = tmp_path / 'big'
    before = {p.name: p.read_bytes() for p in bag.iterdir()}
    result = repair(bag)
    out, count = result.path, result.messages
    assert count == 100 and [t for _, t, _ in _read_all(out)] == list(range(100))
    assert {p.name: p.read_bytes() for p in bag.iterdir()} == before


def _cut_mcap(tmp_path, name, compression='none'):
    """A bag of 300 messages flushed every 100, its metadata gone and its file cut at 55 %."""
    writer = BagWriter(tmp_path, name, 'mcap', compression=compression)
    writer.add_topic('/t', 'std_msgs/msg/String')
    for i in range(300):
        writer.write('/t', i, serialize_message(String(data=f'{i:04d}' * 50)))
        if i % 100 == 99:
            writer.flush()
    writer.close()
    mcap = next(writer.path.glob('*.mcap'))
    data = mcap.read_bytes()
    (writer.path / 'metadata.yaml').unlink()
    mcap.write_bytes(data[:int(len(data) * 0.55)])
    return writer.path


def test_repair_of_a_truncated_mcap_keeps_the_complete_chunks(tmp_path):
    result = repair(_cut_mcap(tmp_path, 'cut'))          # cut in the second chunk
    out, count, truncated = result.path, result.messages, result.truncated
    assert truncated and count == 100
    assert len(_read_all(out)) == 100


def test_repair_of_a_cut_zstd_bag_keeps_its_complete_chunks(tmp_path):
    result = repair(_cut_mcap(tmp_path, 'cutz', compression='zstd'))
    out, count, truncated = result.path, result.messages, result.truncated
    assert truncated and count in (100, 200)        # whole chunks only
    assert [raw for _, _, raw in _read_all(out)] == [
        serialize_message(String(data=f'{i:04d}' * 50)) for i in range(count)]


def test_mcap_bag_follows_the_ros2_profile_and_checks_chunks_when_asked(tmp_path):
    from mcap.reader import make_reader
    from mcap.stream_reader import CRCValidationError
    writer = BagWriter(tmp_path, 'crc', 'mcap', chunk_crc=True)
    writer.add_topic('/t', 'std_msgs/msg/String', [bag_qos(RELIABLE, TRANSIENT_LOCAL, 1)])
    payloads = [serialize_message(String(data=f'message {i:03d}')) for i in range(50)]
    for i, data in enumerate(payloads):
        writer.write('/t', i, data)
    writer.close()
    mcap = next(writer.path.glob('*.mcap'))
    with open(mcap, 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        assert reader.get_header().profile == 'ros2'
        assert [m.data for _, _, m in reader.iter_messages()] == payloads
        summary = reader.get_summary()
        schema, = summary.schemas.values()
        channel, = summary.channels.values()
        assert (schema.name, schema.encoding) == ('std_msgs/msg/String', 'ros2msg')
        assert channel.message_encoding == 'cdr'
        assert 'transient_local' in channel.metadata['offered_qos_profiles']
        assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
        rosbag2, = reader.iter_metadata()
        assert 'message_count: 50' in rosbag2.metadata['serialized_metadata']
    data = bytearray(mcap.read_bytes())
    at = data.index(b'message 025')
    data[at + 8] ^= 0x01                       # one bit of one message
    mcap.write_bytes(bytes(data))
    with open(mcap, 'rb') as stream, pytest.raises(CRCValidationError):
        list(make_reader(stream, validate_crcs=True).iter_messages())
    with pytest.raises(BagError, match='chunk_crc'):
        BagWriter(tmp_path, 'db', 'sqlite3', chunk_crc=True)


def test_repair_errors(tmp_path):
    with pytest.raises(RepairError, match='not a bag directory'):
        repair(tmp_path / 'missing')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(RepairError, match='no .mcap or .db3'):
        repair(tmp_path / 'empty')
    (tmp_path / 'junk').mkdir()
    (tmp_path / 'junk' / 'junk.mcap').write_bytes(b'not an mcap file at all')
    with pytest.raises(RepairError, match='not an MCAP file'):
        repair(tmp_path / 'junk')
    assert repair_main([str(tmp_path / 'junk')]) == 2


KILLED_SPLITTING_WRITER = textwrap.dedent('''
    import os, signal, sys
    from pathlib import Path
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String
    from recording.bag_writer import BagWriter
    out, storage = Path(sys.argv[1]), sys.argv[2]
    w = BagWriter(out, 'split', storage, max_bag_size=40_000)
    w.add_topic('/clock', 'std_msgs/msg/String')
    w.add_topic('/t', 'std_msgs/msg/String')
    for i in range(1000):
        w.write('/t', i * 1000, serialize_message(String(data=f'{i:04d}' + 'x' * 200)))
        w.write('/clock', i * 1000, serialize_message(String(data=str(i))))
        if i == 799:
            w.flush()
            print(len(w.files), flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
''')


@pytest.mark.parametrize('storage', STORAGES)
def test_repair_of_a_killed_split_bag_reads_every_file(tmp_path, storage):
    """A recorder killed with max_bag_size set leaves several files, each with its own copy
    of the channels: repair crashed ('Connection can only be added once: ... /clock') and left
    a 43-byte *_repaired/."""
    proc = subprocess.run([sys.executable, '-c', KILLED_SPLITTING_WRITER, str(tmp_path),
                           storage], capture_output=True, text=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL
    assert int(proc.stdout) >= 3                   # (files so far)
    bag = tmp_path / 'split'
    result = repair(bag)
    messages = _read_all(result.path)
    text = [raw for topic, _, raw in messages if topic == '/t']
    # What was flushed: the first 800, and what a later split closed.
    assert len(text) >= 800
    assert text == [serialize_message(String(data=f'{i:04d}' + 'x' * 200))
                    for i in range(len(text))]
    assert sorted({topic for topic, _, _ in messages}) == ['/clock', '/t']
    assert result.messages == len(messages) >= 1600


@pytest.mark.parametrize('storage', STORAGES)
def test_repair_of_a_closed_bag_without_its_metadata_counts_each_message_once(tmp_path,
                                                                             storage):
    """A closed MCAP file repeats its schemas and channels in its summary: repair took them
    for new connections and crashed."""
    writer = BagWriter(tmp_path, 'closed', storage, max_bag_size=20_000)
    writer.add_topic('/t', 'std_msgs/msg/String')
    payloads = [serialize_message(String(data=f'{i:04d}' + 'y' * 100)) for i in range(500)]
    for i, data in enumerate(payloads):
        writer.write('/t', i, data)
    writer.close()
    (writer.path / 'metadata.yaml').unlink()
    result = repair(writer.path)
    assert [raw for _, _, raw in _read_all(result.path)] == payloads
    assert not result.truncated and not result.notes


@pytest.mark.slow
@pytest.mark.parametrize('storage', STORAGES)
def test_repair_of_flipped_bytes_recovers_what_is_intact_or_says_why(tmp_path, storage):
    """Bytes flipped anywhere in the file (a bad disk, a careless edit): a UnicodeDecodeError
    or a MemoryError traceback before. Now the repair keeps what reads back, or ends with one
    line, and never leaves a partial bag behind."""
    original = chunked_bag(tmp_path / 'src', storage, keep_metadata=False)
    outcomes = {'repaired': 0, 'refused': 0}
    for bag in flipped_copies(original, tmp_path, 60, seed=7):
        try:
            result = repair(bag)
        except RepairError as exc:
            outcomes['refused'] += 1
            assert str(exc)
            assert not bag.with_name(bag.name + '_repaired').exists()
            continue
        outcomes['repaired'] += 1
        assert result.messages <= 600
        assert len(_read_all(result.path)) == result.messages
    assert outcomes['repaired'] > 30, outcomes


def test_repair_says_which_files_it_could_not_read(tmp_path, capsys):
    bag = chunked_bag(tmp_path, keep_metadata=False)
    (bag / 'extra_1.mcap').mkdir()                  # a data file replaced by a directory
    result = repair(bag)
    assert result.messages == 600 and 'extra_1.mcap is not a file' in result.notes
    only = tmp_path / 'only'
    only.mkdir()
    (only / 'only_0.mcap').mkdir()
    assert repair_main([str(only)]) == 2
    err = capsys.readouterr().err
    assert 'only_0.mcap is not a file' in err and 'Traceback' not in err
    assert not (tmp_path / 'only_repaired').exists()


@pytest.mark.parametrize('storage', STORAGES)
@pytest.mark.parametrize('variant', ['none', 'many', 'backwards'])
def test_analysis_counts_the_data_when_the_metadata_lies(tmp_path, storage, variant):
    """An edited metadata.yaml headed the report's tables with "999999999 messages" or "0
    messages over -9223372036.85 s" above the real counts."""
    report, _ = analyse(lying_bag(tmp_path, storage, variant))
    assert report.message_count == 100 and report.topics[0].count == 100
    assert report.duration_s == pytest.approx(0.99)
    if variant != 'backwards':
        assert report.notes and 'the bag holds 100' in report.notes[0]
    from recording.analysis import to_markdown
    assert '100 messages over 0.99 s' in to_markdown(report)


def test_analysis_reports_counts_rates_and_paths(tmp_path):
    writer = BagWriter(tmp_path, 'circle', 'mcap')
    writer.add_topic('/robot/odom', 'nav_msgs/msg/Odometry')
    writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
    from rosgraph_msgs.msg import Clock
    radius, n = 0.5, 201   # a half circle, 20 Hz for 10 s
    for i in range(n):
        a = math.pi * i / (n - 1)
        t = 50_000_000 * i
        writer.write('/robot/odom', t, _odom(radius * math.sin(a), radius * (1 - math.cos(a)),
                                             a))
        writer.write('/clock', t, serialize_message(Clock()))
    writer.close()
    report = write_report(writer.path, tmp_path / 'report')
    topics = {t.topic: t for t in report.topics}
    assert topics['/robot/odom'].count == n and topics['/robot/odom'].rate_hz == pytest.approx(20)
    path = report.paths[0]
    assert path.distance_m == pytest.approx(math.pi * radius, rel=1e-3)
    assert path.end == pytest.approx([0.0, 1.0], abs=1e-9)
    assert path.end_yaw_deg == pytest.approx(180.0, abs=1e-6) or path.end_yaw_deg == \
        pytest.approx(-180.0, abs=1e-6)
    saved = json.loads((tmp_path / 'report' / 'report.json').read_text())
    assert saved['paths'][0]['samples'] == n
    assert '| /robot/odom | nav_msgs/msg/Odometry | 201 | 20.00 |' in \
        (tmp_path / 'report' / 'report.md').read_text()
    img = cv2.imread(str(tmp_path / 'report' / 'paths.png'))
    blue = (img[:, :, 0] > 150) & (img[:, :, 2] < 100)   # the path colour (BGR)
    assert blue.sum() > 500


def test_analysis_errors_are_clear(tmp_path, capsys):
    assert analysis_main([str(tmp_path / 'nope')]) == 2
    assert 'does not exist' in capsys.readouterr().err
    good = BagWriter(tmp_path, 'good', 'mcap')
    good.add_topic('/t', 'std_msgs/msg/String')
    for i in range(2000):
        good.write('/t', i, serialize_message(String(data='y' * 100)))
    good.close()
    mcap = next(good.path.glob('*.mcap'))
    data = mcap.read_bytes()
    # Truncated (a copy cut short, the metadata.yaml still there): the summary is gone.
    mcap.write_bytes(data[:len(data) // 2])
    with pytest.raises(AnalysisError, match='not a readable'):
        analyse(good.path)
    # Garbage where the storage file should be.
    mcap.write_bytes(os.urandom(len(data)))
    with pytest.raises(AnalysisError, match='not a readable'):
        analyse(good.path)
    db_bag = BagWriter(tmp_path, 'db', 'sqlite3')
    db_bag.add_topic('/t', 'std_msgs/msg/String')
    db_bag.close()
    next(db_bag.path.glob('*.db3')).write_bytes(b'SQLite format 3\x00' + os.urandom(5000))
    with pytest.raises(AnalysisError, match='not a readable|unreadable'):
        analyse(db_bag.path)
    assert analysis_main([str(db_bag.path)]) == 2


def damaged_mid_stream_bag(directory):
    """An MCAP bag whose index is intact but whose second chunk holds a broken record: it
    opens, and fails after the first chunk's 1000 messages."""
    writer = BagWriter(directory, 'damaged', 'mcap')
    writer.add_topic('/t', 'std_msgs/msg/String')
    for i in range(3000):
        writer.write('/t', i * 1000, serialize_message(String(data='z' * 100)))
        if i % 1000 == 999:
            writer.flush()
    writer.close()
    mcap = next(writer.path.glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    pos, chunks = 8, 0
    while pos < len(data):
        op, length = data[pos], struct.unpack('<Q', data[pos + 1:pos + 9])[0]
        if op == 0x06:
            chunks += 1
            if chunks == 2:
                record = pos + 9 + 8 + 8 + 8 + 4 + 4 + 8   # first record inside the chunk
                data[record + 1:record + 9] = struct.pack('<Q', 10**12)
                break
        pos += 9 + length
    mcap.write_bytes(bytes(data))
    return writer.path


def test_analysis_of_a_bag_damaged_mid_stream_fails_clearly(tmp_path):
    with pytest.raises(AnalysisError, match='unreadable data.*truncated or corrupt'):
        analyse(damaged_mid_stream_bag(tmp_path))


def test_type_resolver_reads_installed_msg_files(tmp_path, monkeypatch):
    prefix = tmp_path / 'prefix'
    share = prefix / 'share' / 'fake_msgs' / 'msg'
    share.mkdir(parents=True)
    (share / 'Inner.msg').write_text('float64 value\n')
    (share / 'Thing.msg').write_text('std_msgs/Header header\nfake_msgs/Inner[] inner\n'
                                     'geometry_msgs/Point where\n')
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'fake_msgs').write_text('')
    monkeypatch.setenv('AMENT_PREFIX_PATH',
                       f'{prefix}{os.pathsep}{os.environ.get("AMENT_PREFIX_PATH", "")}')
    resolver = TypeResolver()
    msgdef, rihs01 = resolver.definition('fake_msgs/msg/Thing')
    assert rihs01.startswith('RIHS01_') and 'MSG: fake_msgs/Inner' in msgdef
    with pytest.raises(TypeResolutionError):
        resolver.definition('nothere_msgs/msg/Missing')
    with pytest.raises(TypeResolutionError):
        resolver.definition('not a type')
    assert resolver.definition('geometry_msgs/msg/Point')[1].startswith('RIHS01_')


def test_replay_schedule():
    s = ReplaySchedule(bag_first_ns=10_000_000_000, rate=2.0, start_offset_s=1.0,
                       wall_start=100.0)
    assert s.skip(10_500_000_000) and not s.skip(11_000_000_000)
    assert s.due(11_000_000_000) == pytest.approx(100.0)
    assert s.due(13_000_000_000) == pytest.approx(101.0)
    assert s.bag_time_at(101.0) == 13_000_000_000
    s.restart(200.0)
    assert s.due(11_000_000_000) == pytest.approx(200.0)
    with pytest.raises(ValueError):
        ReplaySchedule(0, rate=0.0)
    with pytest.raises(ValueError):
        ReplaySchedule(0, start_offset_s=-1.0)


def test_qos_choices():
    assert adapt_to_publishers([(RELIABLE, VOLATILE), (BEST_EFFORT, VOLATILE)]) == \
        (BEST_EFFORT, VOLATILE)
    assert adapt_to_publishers([(RELIABLE, TRANSIENT_LOCAL)]) == (RELIABLE, TRANSIENT_LOCAL)
    assert adapt_to_publishers([]) == (RELIABLE, VOLATILE)
    assert replay_policies([], 'sensor_msgs/msg/Image') == (BEST_EFFORT, VOLATILE)
    assert replay_policies([bag_qos(RELIABLE, TRANSIENT_LOCAL, 1)], 'std_msgs/msg/String') == \
        (RELIABLE, TRANSIENT_LOCAL)
    assert parse_offered_qos('') == [] and parse_offered_qos('{not yaml') == []


CONTROLLER_STATE = '''std_msgs/Header header
string[] joint_names
trajectory_msgs/JointTrajectoryPoint reference
trajectory_msgs/JointTrajectoryPoint feedback
trajectory_msgs/JointTrajectoryPoint error
trajectory_msgs/JointTrajectoryPoint output
'''


def test_analysis_reports_joint_tracking_of_controller_states(tmp_path, monkeypatch):
    # control_msgs is not installable here: its definition comes from a .msg file, as any
    # package's would, and the analysis reads the definition stored in the bag.
    prefix = tmp_path / 'prefix'
    (prefix / 'share' / 'control_msgs' / 'msg').mkdir(parents=True)
    (prefix / 'share' / 'control_msgs' / 'msg' / 'JointTrajectoryControllerState.msg'
     ).write_text(CONTROLLER_STATE)
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'control_msgs').write_text('')
    monkeypatch.setenv('AMENT_PREFIX_PATH',
                       f'{prefix}{os.pathsep}{os.environ.get("AMENT_PREFIX_PATH", "")}')
    msgtype = 'control_msgs/msg/JointTrajectoryControllerState'
    writer = BagWriter(tmp_path, 'arm', 'sqlite3')
    writer.add_topic('/arm/controller_state', msgtype)
    store = writer.resolver.typestore
    State = store.types[msgtype]
    Point = store.types['trajectory_msgs/msg/JointTrajectoryPoint']
    Header, Time = store.types['std_msgs/msg/Header'], store.types['builtin_interfaces/msg/Time']
    Duration = store.types['builtin_interfaces/msg/Duration']
    empty = np.array([], float)

    def point(pos):
        return Point(np.array(pos, float), empty, empty, empty, Duration(0, 0))

    errors = np.array([[0.01, -0.02], [-0.01, 0.04], [0.0, 0.0], [0.02, 0.0]])
    for i, e in enumerate(errors):
        ref = np.array([0.5, -0.3]) + i
        msg = State(Header(Time(i, 0), ''), ['joint_1', 'joint_2'], point(ref),
                    point(ref - e), point(e), point([]))
        writer.write('/arm/controller_state', i * 10**9, bytes(store.serialize_cdr(msg,
                                                                                  msgtype)))
    writer.close()
    report, _ = analyse(writer.path)
    by_joint = {t.joint: t for t in report.tracking}
    assert set(by_joint) == {'joint_1', 'joint_2'}
    assert by_joint['joint_1'].rms_error == pytest.approx(np.sqrt(np.mean(errors[:, 0] ** 2)))
    assert by_joint['joint_2'].max_abs_error == pytest.approx(0.04)
    assert by_joint['joint_1'].samples == 4


@pytest.mark.parametrize('storage', STORAGES)
@pytest.mark.parametrize('split', ['size', 'duration'])
def test_a_bag_splits_by_size_or_duration_into_complete_files(tmp_path, storage, split):
    """rosbag2's max_bag_size and max_bag_duration: every file but the last is closed
    complete when the next starts (an MCAP one with its summary), metadata.yaml lists each
    with its own counts, and the bag reads back whole, in order."""
    from mcap.reader import make_reader
    kwargs = {'max_bag_size': 40_000} if split == 'size' else {'max_bag_duration': 0.25}
    writer = BagWriter(tmp_path, 'split', storage, **kwargs)
    writer.add_topic('/text', 'std_msgs/msg/String')
    written = []
    for i in range(400):                    # 400 x ~220 bytes, 1 s of message time
        data = serialize_message(String(data=f'{i:04d}' + 'x' * 200))
        writer.write('/text', 2_500_000 * i, data)
        written.append(('/text', 2_500_000 * i, data))
    files = writer.files
    writer.close()
    assert len(files) >= 3 and files[0] == f'split_0.{"mcap" if storage == "mcap" else "db3"}'
    info = yaml.safe_load((writer.path / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert info['relative_file_paths'] == files
    assert [f['path'] for f in info['files']] == files
    assert sum(f['message_count'] for f in info['files']) == info['message_count'] == 400
    for entry in info['files'][:-1]:
        if split == 'duration':
            assert entry['duration']['nanoseconds'] < 250_000_000
        if storage == 'mcap':
            with open(writer.path / entry['path'], 'rb') as stream:
                summary = make_reader(stream).get_summary()
            assert summary is not None
            assert summary.statistics.message_count == entry['message_count']
    assert _read_all(writer.path) == written
    assert not (writer.path / '.close_reserve').exists()


@pytest.mark.parametrize('storage', STORAGES)
def test_a_bag_closed_after_a_failure_holds_what_its_metadata_says(tmp_path, storage):
    """close_after_failure: the MCAP file is cut back to its last flush and ended there, the
    SQLite transaction rolled back; metadata.yaml counts exactly what the file holds."""
    writer = BagWriter(tmp_path, 'cut', storage)
    writer.add_topic('/text', 'std_msgs/msg/String')
    for i in range(300):
        writer.write('/text', i, serialize_message(String(data=f'{i}' + 'y' * 3000)))
        if i == 199:
            writer.flush()
    assert writer.close_after_failure() == 200
    info = yaml.safe_load((writer.path / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert info['message_count'] == 200 and info['files'][0]['message_count'] == 200
    assert [t for _, t, _ in _read_all(writer.path)] == list(range(200))
