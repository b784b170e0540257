"""The recording nodes in-process: parameters, and failures that must end clearly."""
import errno

import pytest
import yaml
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from std_msgs.msg import String
from test_recording_core import damaged_mid_stream_bag

from recording.bag_writer import BagError
from recording.recorder import Recorder
from recording.replay import Replay


def make(context, tmp_path, **overrides):
    params = {'output_dir': str(tmp_path), 'bag_name': 'node', 'topics': ['/nothing']}
    params.update(overrides)
    return Recorder(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
@pytest.mark.parametrize('where', ['write', 'flush'])
def test_a_failing_write_closes_the_bag_at_its_last_flush_and_ends_the_run(context, tmp_path,
                                                                          storage, where):
    """Issue 15, finding 3, with an injected ENOSPC (a real full disk: the graph test). The
    recorder crashed with two tracebacks (MCAP), or reported 689 messages in metadata.yaml
    over a database holding 453 (SQLite). Now the bag is closed where its last flush left it,
    metadata.yaml counts exactly that, one error says so, and the run ends with exit code 1."""
    node = make(context, tmp_path, storage=storage)
    try:
        node._writer.add_topic('/t', 'std_msgs/msg/String')
        node._on_message('/t', serialize_message(String(data='kept')))
        node._flush()
        node._on_message('/t', serialize_message(String(data='written, not flushed')))

        def full_disk(*_):
            raise OSError(errno.ENOSPC, 'No space left on device')

        if where == 'write':
            node._writer._writer.storage.write = full_disk
            node._on_message('/t', serialize_message(String(data='refused')))
        else:
            node._writer._writer.storage.flush = full_disk
            node._flush()
        assert node.exit_request.is_set() and node.exit_code == 1
        node._on_message('/t', serialize_message(String(data='after the failure')))
        assert node.dropped == 1
        summary = node.finish()
        assert 'closed with 1 messages' in summary and 'No space left on device' in summary
        assert '1 messages arrived after it' in summary
    finally:
        node.destroy_node()
    bag = tmp_path / 'node'
    with AnyReader([bag]) as reader:
        assert [reader.deserialize(raw, c.msgtype).data
                for c, _, raw in reader.messages()] == ['kept']
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['message_count'] == 1
    assert info['topics_with_message_count'][0]['message_count'] == 1
    assert not (bag / '.close_reserve').exists()


def test_bad_storage_fails_at_start(context, tmp_path):
    with pytest.raises(BagError, match='storage must be one of'):
        make(context, tmp_path, storage='bag')


def test_compression_is_zstd_chunks_of_mcap_or_none(context, tmp_path):
    with pytest.raises(BagError, match='compression must be one of'):
        make(context, tmp_path, compression='gzip')
    with pytest.raises(BagError, match='sqlite3 bags are written uncompressed'):
        make(context, tmp_path, storage='sqlite3', compression='zstd')
    node = make(context, tmp_path, compression='zstd')
    try:
        node._writer.add_topic('/t', 'std_msgs/msg/String')
        node._on_message('/t', serialize_message(String(data='squeezed')))
        node.finish()
    finally:
        node.destroy_node()
    with AnyReader([tmp_path / 'node']) as reader:
        assert [reader.deserialize(raw, c.msgtype).data
                for c, _, raw in reader.messages()] == ['squeezed']
    # (As rosbag2's MCAP plugin, the compression is in the chunks; metadata.yaml leaves its
    # compression fields, which are for file and message compression, empty.)
    from mcap.reader import make_reader
    (path,) = (tmp_path / 'node').glob('*.mcap')
    with path.open('rb') as stream:
        chunks = make_reader(stream).get_summary().chunk_indexes
    assert chunks and {c.compression for c in chunks} == {'zstd'}


def test_replay_of_a_bag_damaged_mid_stream_stops_with_an_error(context, tmp_path):
    node = Replay(context=context, parameter_overrides=[
        Parameter('bag', value=str(damaged_mid_stream_bag(tmp_path))),
        Parameter('rate', value=100.0)])
    try:
        assert node.run() == 1
        assert node.published == 1000
    finally:
        node.destroy_node()


def test_the_ready_file_appears_once_every_ready_topic_is_recorded(context, tmp_path):
    """A launcher waits on this file, not on a log line's wording, before it starts what must
    be recorded from its first message (run_trials: the coordinator, after /clock)."""
    from rclpy.qos import QoSProfile
    from rosgraph_msgs.msg import Clock
    ready = tmp_path / 'recorder.ready'
    ready.write_text('stale\n')                           # (left by an earlier run)
    node = make(context, tmp_path, topics=['/clock', '/t'], ready_file=str(ready),
                ready_topics=['/clock', '/t'])
    try:
        assert not ready.exists()
        clock_pub = node.create_publisher(Clock, '/clock', QoSProfile(depth=10))
        node._subscribe('/clock', ['rosgraph_msgs/msg/Clock'], node.get_publishers_info_by_topic(
            '/clock'))
        assert not ready.exists()                         # /t is not recorded yet
        string_pub = node.create_publisher(String, '/t', QoSProfile(depth=10))
        node._subscribe('/t', ['std_msgs/msg/String'], node.get_publishers_info_by_topic('/t'))
        assert ready.read_text() == '/clock /t\n'
        del clock_pub, string_pub
    finally:
        node.finish()
        node.destroy_node()
