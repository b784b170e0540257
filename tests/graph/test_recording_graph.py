"""Recorder and replay nodes with the simulator, over DDS."""
import signal
import time

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message
from rosbags.highlevel import AnyReader
from rosgraph_msgs.msg import Clock

from helpers import chunked_bag, flipped_copies, lying_bag, wait_for
from recording.repair import repair

DT_NS = round(1e9 / 240)
STATE_NS = 10_000_000          # 100 Hz
CAMERA_NS = round(1e9 / 15)


def _ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _bag_messages(path):
    with AnyReader([path]) as reader:
        out = {}
        for c, t, raw in reader.messages():
            out.setdefault(c.topic, []).append((t, bytes(raw), c.msgtype, reader))
        return {topic: [(t, raw, reader.deserialize(raw, msgtype)) for t, raw, msgtype, _ in m]
                for topic, m in out.items()}


def _start_recording(start_node, tmp_path, *args, name='run'):
    rec = start_node('recorder', '-p', f'output_dir:={tmp_path / "bags"}', '-p',
                     f'bag_name:={name}', *args, name=f'recorder_{name}')
    for topic in ('/clock', '/mini_robot/odom', '/mini_robot/camera/image_raw'):
        wait_for(lambda t=topic: f'receiving {t}\n' in rec.output(), 20.0,
                 what=f'the recorder to receive {topic}')
    return rec


def _assert_on_grid(stamps_ns, period_ns, what):
    """Every point of the period grid between the first and last stamp is present once."""
    stamps = np.array(stamps_ns, dtype=np.int64)
    assert len(stamps) > 10, what
    gaps = np.diff(stamps)
    # A stamp is the first step at/after its grid point: gaps differ from the period by less
    # than one physics step, so a missing message would show as a gap of about two periods.
    assert np.all(np.abs(gaps - period_ns) < DT_NS), (what, gaps.min(), gaps.max())


@pytest.mark.parametrize('storage, stop_signal', [('mcap', signal.SIGINT),
                                                  ('sqlite3', signal.SIGTERM)])
def test_recording_at_full_rates_loses_nothing_and_keeps_bytes(start_node, probe, tmp_path,
                                                               storage, stop_signal):
    start_node('sim_node')
    probe_odom = probe.collect(Odometry, '/mini_robot/odom', raw=True)
    # The probe receives before the recorder starts, so it saw everything the bag can hold.
    wait_for(lambda: len(probe_odom) > 5, 20.0, what='the probe receiving odometry')
    sim_odom = probe.collect(Odometry, '/mini_robot/odom')
    rec = _start_recording(start_node, tmp_path, '-p', f'storage:={storage}')
    # Three seconds of simulated time: on a loaded machine the simulator runs behind the
    # clock on the wall (three wall seconds gave 583 steps, not 720).
    wait_for(lambda: sim_odom, 20.0, what='odometry')
    t0 = _ns(sim_odom[-1][1].header.stamp)
    wait_for(lambda: _ns(sim_odom[-1][1].header.stamp) - t0 >= 3_000_000_000, 60.0,
             what='three simulated seconds')
    assert rec.stop(stop_signal) == 0
    assert 'closed with' in rec.output()
    bag = tmp_path / 'bags' / 'run'
    assert (bag / 'metadata.yaml').is_file()  # finalised: readable without repair
    msgs = _bag_messages(bag)
    # /clock: one per physics step, none missing between the first and the last recorded.
    clocks = [_ns(m.clock) for _, _, m in msgs['/clock']]
    assert np.all(np.diff(clocks) == DT_NS) and len(clocks) > 600
    _assert_on_grid([_ns(m.header.stamp) for _, _, m in msgs['/mini_robot/odom']], STATE_NS,
                    'odom')
    _assert_on_grid([_ns(m.header.stamp) for _, _, m in msgs['/mini_robot/joint_states']],
                    STATE_NS, 'joint_states')
    images = [_ns(m.header.stamp) for _, _, m in msgs['/mini_robot/camera/image_raw']]
    _assert_on_grid(images, CAMERA_NS, 'images')
    infos = [_ns(m.header.stamp) for _, _, m in msgs['/mini_robot/camera/camera_info']]
    assert set(images[:-1]) <= set(infos)  # the recorder may stop between an image and its info
    assert len(msgs['/mini_robot/camera/image_raw'][0][1]) > 320 * 240 * 3
    # Byte for byte: what an independent subscriber received in that interval is exactly what
    # the bag holds.
    recorded = {raw for _, raw, _ in msgs['/mini_robot/odom']}
    first, last = (_ns(msgs['/mini_robot/odom'][i][2].header.stamp) for i in (0, -1))
    overlap = [raw for _, raw in probe_odom
               if first <= _ns(deserialize_message(raw, Odometry).header.stamp) <= last]
    assert len(overlap) == len(recorded) and set(overlap) == recorded


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_sigkill_loses_at_most_the_last_second(start_node, probe, tmp_path, storage):
    start_node('sim_node')
    probe_odom = probe.collect(Odometry, '/mini_robot/odom', raw=True)
    wait_for(lambda: len(probe_odom) > 5, 20.0, what='the probe receiving odometry')
    rec = _start_recording(start_node, tmp_path, '-p', f'storage:={storage}', name='killed')
    # A few seconds of recording, counted in messages (a loaded machine runs the simulator
    # behind the wall clock): enough that more than 100 are older than the last second.
    n0 = len(probe_odom)
    wait_for(lambda: len(probe_odom) >= n0 + 150, 60.0, what='150 odometry messages')
    time.sleep(1.0)
    killed_at = time.monotonic()
    rec.stop(signal.SIGKILL)
    bag = tmp_path / 'bags' / 'killed'
    assert not (bag / 'metadata.yaml').exists()
    result = repair(bag)
    repaired, count = result.path, result.messages
    assert count > 0
    recorded = {raw for _, raw, _ in _bag_messages(repaired)['/mini_robot/odom']}
    first = min(_ns(deserialize_message(raw, Odometry).header.stamp) for raw in recorded)
    wanted = [raw for t, raw in probe_odom if t < killed_at - 1.0
              and _ns(deserialize_message(raw, Odometry).header.stamp) >= first]
    assert len(wanted) > 100
    missing = [raw for raw in wanted if raw not in recorded]
    assert missing == []


def test_two_recorders_never_share_a_bag(start_node, tmp_path):
    start_node('sim_node')
    a = _start_recording(start_node, tmp_path, name='same')
    b = start_node('recorder', '-p', f'output_dir:={tmp_path / "bags"}', '-p',
                   'bag_name:=same', name='recorder_b')
    wait_for(lambda: 'receiving /clock\n' in b.output(), 20.0, what='the second recorder')
    a.stop()
    b.stop()
    assert sorted(p.name for p in (tmp_path / 'bags').iterdir()) == ['same', 'same_1']
    for name in ('same', 'same_1'):
        assert _bag_messages(tmp_path / 'bags' / name)['/clock']


def _record_short_run(start_node, probe, tmp_path, name, topics, seconds, twist=None):
    """Run the simulator with a recorder on ``topics`` for ``seconds`` of wall time (driving with
    ``twist`` from the moment the robot is seen moving), stop both, and return the bag path:
    afterwards only a replay publishes those topics."""
    sim = start_node('sim_node')
    rec = start_node('recorder', '-p', f'output_dir:={tmp_path / "bags"}', '-p',
                     f'bag_name:={name}', '-p', f'topics:=[{", ".join(topics)}]',
                     name=f'recorder_{name}')
    for topic in topics:
        wait_for(lambda t=topic: f'receiving {t}\n' in rec.output(), 20.0,
                 what=f'the recorder to receive {topic}')
    if twist is not None:
        # Drive until the robot is seen moving, however long discovery and start-up take on a
        # busy machine, then keep driving for the recording's length.
        cmd = probe.node.create_publisher(Twist, '/mini_robot/cmd_vel', 10)
        odom = probe.collect(Odometry, '/mini_robot/odom')
        wait_for(lambda: cmd.get_subscription_count() > 0, 20.0, what='the simulator on cmd_vel')

        def moving():
            cmd.publish(twist)
            return any(abs(m.twist.twist.linear.x) > 0.5 * twist.linear.x for _, m in odom[-5:])
        wait_for(moving, 30.0, period=0.05, what='the robot moving')
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if twist is not None:
            cmd.publish(twist)
        time.sleep(0.05)
    rec.stop()
    sim.stop()
    return tmp_path / 'bags' / name


def test_replay_reproduces_the_recorded_odometry_with_its_timing(start_node, probe, tmp_path):
    twist = Twist()
    twist.linear.x, twist.angular.z = 0.15, 0.2
    bag = _record_short_run(start_node, probe, tmp_path, 'drive', ['/clock', '/mini_robot/odom'],
                            2.0, twist)
    recorded = _bag_messages(bag)['/mini_robot/odom']
    assert max(abs(m.twist.twist.linear.x) for _, _, m in recorded) > 0.1  # it drove

    replayed = probe.collect(Odometry, '/mini_robot/odom', raw=True)
    clock = probe.collect(Clock, '/clock')
    replay = start_node('replay', '-p', f'bag:={bag}', '-p', 'publish_clock:=true', '-p',
                        'wait_for_subscribers:=20.0')
    wait_for(lambda: not replay.alive(), 60.0, what='the replay to end')
    assert replay.proc.returncode == 0
    wait_for(lambda: len(replayed) >= len(recorded), 5.0, what='all replayed odometry')
    # Exactly the recorded messages, in order, byte for byte.
    assert [raw for _, raw in replayed] == [raw for _, raw, _ in recorded]
    # With the recorded timing: arrival intervals follow the recording's receive times.
    rec_span = (recorded[-1][0] - recorded[0][0]) * 1e-9
    rep_span = replayed[-1][0] - replayed[0][0]
    assert rep_span == pytest.approx(rec_span, rel=0.1)
    # /clock from bag time, not the recorded /clock (which was left out).
    bag_start, bag_end = recorded[0][0], recorded[-1][0]
    values = [_ns(m.clock) for _, m in clock]
    assert values and all(b >= a for a, b in zip(values, values[1:]))
    assert bag_start - 1e9 <= values[0] and values[-1] <= bag_end


def test_replay_rate_and_topic_filter(start_node, probe, tmp_path):
    bag = _record_short_run(start_node, probe, tmp_path, 'fast', ['/clock', '/mini_robot/odom'],
                            2.0)
    recorded = _bag_messages(bag)['/mini_robot/odom']
    replayed = probe.collect(Odometry, '/mini_robot/odom', raw=True)
    clock = probe.collect(Clock, '/clock')
    replay = start_node('replay', '-p', f'bag:={bag}', '-p', 'rate:=2.0', '-p',
                        'topics:=[/mini_robot/odom]', '-p', 'start_offset:=0.5', '-p',
                        'wait_for_subscribers:=20.0')
    wait_for(lambda: not replay.alive(), 60.0, what='the replay to end')
    with AnyReader([bag]) as reader:
        bag_start = reader.start_time  # the offset counts from the bag's first message
    kept = [r for r in recorded if r[0] >= bag_start + 500_000_000]
    wait_for(lambda: len(replayed) >= len(kept), 5.0, what='replayed odometry')
    assert [raw for _, raw in replayed] == [raw for _, raw, _ in kept]
    rec_span = (kept[-1][0] - kept[0][0]) * 1e-9
    assert replayed[-1][0] - replayed[0][0] == pytest.approx(rec_span / 2, rel=0.15)
    assert clock == []  # filtered out, and publish_clock is off


def test_replay_plays_the_messages_when_the_metadata_says_there_are_none(start_node, probe,
                                                                         tmp_path):
    """metadata.yaml edited to message_count: 0: replay said "0 messages published" and
    exited 0. The messages are what is played; the disagreement is logged."""
    from std_msgs.msg import String

    bag = lying_bag(tmp_path, 'mcap', 'none')
    received = probe.collect(String, '/t')
    replay = start_node('replay', '-p', f'bag:={bag}', '-p', 'rate:=4.0', '-p',
                        'wait_for_subscribers:=20.0')
    wait_for(lambda: not replay.alive(), 60.0, what='the replay to end')
    assert replay.proc.returncode == 0
    wait_for(lambda: len(received) >= 100, 10.0, what='every message replayed')
    assert [m.data for _, m in received] == [str(i) for i in range(100)]
    assert 'metadata.yaml counts 0 messages' in replay.output()
    assert 'replay done: 100 messages published' in replay.output()


def _damaged_bags(directory, wanted=4):
    """Copies of a closed bag with bytes flipped, chosen for the different errors they make
    rosbags raise while reading (struct.error and OverflowError were replay tracebacks)."""
    from rosbags.highlevel import AnyReader
    bags, seen = [], set()
    for storage in ('mcap', 'sqlite3'):
        for bag in flipped_copies(chunked_bag(directory / 'src', storage, f'src_{storage}'),
                                  directory, 200, seed=3):
            try:
                with AnyReader([bag]) as reader:
                    for _ in reader.messages():
                        pass
                continue
            except Exception as exc:  # (what kinds the reader raises is what is looked for)
                kind = (storage, type(exc).__name__)
            if kind not in seen:
                seen.add(kind)
                bags.append((bag, kind))
            if len(bags) >= wanted * 2:
                break
    return bags


def test_replay_of_damaged_bags_ends_with_one_error(start_node, tmp_path):
    bags = _damaged_bags(tmp_path)
    assert len(bags) >= 3, bags
    for k, (bag, kind) in enumerate(bags):
        proc = start_node('replay', '-p', f'bag:={bag}', '-p', 'rate:=100.0',
                          name=f'replay_{k}')
        wait_for(lambda p=proc: not p.alive(), 60.0, what='replay to exit')
        log = proc.output()
        assert proc.proc.returncode == 1, (kind, log)
        assert 'Traceback' not in log, (kind, log)
        assert 'not a readable bag' in log or 'unreadable data after' in log, (kind, log)


def test_bad_bags_fail_clearly(start_node, tmp_path):
    (tmp_path / 'empty').mkdir()
    for bag, fragment in ((tmp_path / 'missing', 'not a bag directory'),
                          (tmp_path / 'empty', 'not a readable bag')):
        proc = start_node('replay', '-p', f'bag:={bag}', name=f'replay_{bag.name}')
        wait_for(lambda p=proc: not p.alive(), 15.0, what='replay to exit')
        assert proc.proc.returncode == 1 and fragment in proc.output()
    proc = start_node('recorder', '-p', 'storage:=rosbag1', '-p',
                      f'output_dir:={tmp_path}', name='recorder_bad')
    wait_for(lambda: not proc.alive(), 15.0, what='recorder to exit')
    assert proc.proc.returncode == 1 and 'storage must be one of' in proc.output()


def test_replay_loops_until_stopped(start_node, probe, tmp_path):
    bag = _record_short_run(start_node, probe, tmp_path, 'short', ['/mini_robot/odom'], 0.5)
    recorded = _bag_messages(bag)['/mini_robot/odom']
    replayed = probe.collect(Odometry, '/mini_robot/odom', raw=True)
    replay = start_node('replay', '-p', f'bag:={bag}', '-p', 'loop:=true', '-p',
                        'rate:=4.0', '-p', 'wait_for_subscribers:=20.0')
    wait_for(lambda: len(replayed) >= 3 * len(recorded), 30.0, what='three passes')
    assert replay.alive()
    assert replay.stop() == 0
    first_pass = [raw for _, raw in replayed[:len(recorded)]]
    second_pass = [raw for _, raw in replayed[len(recorded):2 * len(recorded)]]
    assert first_pass == second_pass == [raw for _, raw, _ in recorded]


@pytest.fixture
def small_disk(tmp_path):
    """A 5 MiB tmpfs: a real full disk (ENOSPC), where the tests run as root."""
    import os
    import subprocess
    mount = tmp_path / 'small_disk'
    mount.mkdir()
    if os.geteuid() != 0 or subprocess.run(
            ['mount', '-t', 'tmpfs', '-o', 'size=5m', 'tmpfs', str(mount)],
            capture_output=True).returncode != 0:
        pytest.skip('mounting a small tmpfs needs root (the injected-ENOSPC unit tests cover '
                    'the same path)')
    yield mount
    subprocess.run(['umount', '-l', str(mount)], check=False)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_full_disk_closes_the_bag_with_what_is_on_disk_and_one_clear_error(
        start_node, probe, small_disk, storage):
    """Issue 15, finding 3, as reported: a 5 MiB tmpfs as output_dir. MCAP: the recorder
    exited 1 after two tracebacks and wrote no metadata.yaml. SQLite: metadata.yaml said 689
    messages over a database holding 453. Now: one error line, the bag closed at its last
    flush, metadata.yaml counting exactly what the bag holds, exit code 1."""
    from std_msgs.msg import String
    rec = start_node('recorder', '-p', f'output_dir:={small_disk}', '-p', 'bag_name:=full',
                     '-p', f'storage:={storage}', '-p', "topics:=['/bulk']",
                     '-p', 'flush_period:=0.1', name=f'recorder_full_{storage}')
    pub = probe.node.create_publisher(String, '/bulk', 100)
    wait_for(lambda: pub.get_subscription_count() > 0, 20.0, what='the recorder subscribed')
    payload = 'z' * 100_000                          # 5 MiB is about 50 of them
    deadline = time.monotonic() + 60.0
    sent = 0
    while rec.proc.poll() is None and time.monotonic() < deadline:
        pub.publish(String(data=f'{sent:06d}' + payload))
        sent += 1
        time.sleep(0.01)
    assert rec.proc.wait(30.0) == 1, rec.output()
    log = rec.output()
    errors = [line for line in log.splitlines() if line.startswith('[ERROR]')]
    assert len(errors) == 1, log
    assert ('No space left on device' in errors[0] or 'disk is full' in errors[0]), errors
    assert 'the recorder stops' in errors[0] and 'Traceback' not in log
    bag = small_disk / 'full'
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    with AnyReader([bag]) as reader:
        held = [reader.deserialize(raw, c.msgtype).data[:6] for c, _, raw in reader.messages()]
    assert info['message_count'] == len(held) > 5
    assert held == [f'{i:06d}' for i in range(len(held))]       # in order, none missing
    assert not (bag / '.close_reserve').exists()
