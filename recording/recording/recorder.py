"""Records topics to a rosbag2 bag as they appear, writing the serialized bytes as received."""
from __future__ import annotations

import functools
import os
import sys
import threading
from pathlib import Path
from typing import Dict, Sequence, Set

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import WriterError

from recording.bag_writer import STORAGES, BagError, BagWriter
from recording.qos_profiles import adapt_to_publishers, bag_qos
from recording.types import TypeResolutionError, message_class
from ros_common.node_main import run_node
from ros_common.params import Param, declare_params

PARAMS = (
    Param('topics', [''], 'Topics to record; empty: every topic, as it appears'),
    Param('exclude', [''], 'Topics never recorded'),
    Param('output_dir', 'bags', 'Directory that receives the bag directory'),
    Param('bag_name', '', 'Bag directory name; empty: rosbag2_<date>-<time>. An existing bag '
          'is never overwritten: _1, _2, ... is appended'),
    Param('storage', 'mcap', 'Storage plugin: mcap or sqlite3'),
    Param('compression', 'none', 'none, or zstd: MCAP chunks compressed with zstd (mcap '
          'storage only)'),
    Param('chunk_crc', False, 'MCAP chunks carry a CRC-32, so readers tell a damaged chunk '
          '(about 0.3 ms of CPU per MB)'),
    Param('flush_period', 0.5, 'Wall seconds between durable flushes: what a SIGKILL can lose',
          0.05, 10.0),
    # rosbag2's names and units. A file is closed complete when the next one starts.
    Param('max_bag_size', 0, 'Split the bag into a new file once the open one holds this many '
          'bytes of messages; 0: no limit', 0, 2**62),
    Param('max_bag_duration', 0.0, 'Split the bag into a new file once the open one spans this '
          'many seconds of message time; 0: no limit', 0.0, 1e9),
    Param('discovery_period', 0.1, 'Wall seconds between looks for new topics', 0.01, 10.0),
    Param('queue_depth', 1000, 'Subscription history depth, to absorb bursts', 1, 100000),
    Param('ready_file', '', 'Written once every topic of ready_topics is recorded: the signal '
          'that a launcher waits for before it starts what must be recorded from its first '
          'message; empty: none'),
    Param('ready_topics', ['/clock'], 'The topics whose recording ready_file signals'),
    Param('custom_data', [''], 'KEY=VALUE pairs kept in the bag\'s metadata (metadata.yaml\'s '
          'custom_data, as ros2 bag record --custom-data)'),
)


def parse_custom_data(items: Sequence[str]) -> Dict[str, str]:
    """``KEY=VALUE`` strings as a mapping (empty strings left out); BagError for one without
    a key or an ``=``."""
    out: Dict[str, str] = {}
    for item in items:
        if not item:
            continue
        key, sep, value = item.partition('=')
        if not sep or not key.strip():
            raise BagError(f'custom_data "{item[:60]}": give KEY=VALUE')
        out[key.strip()] = value
    return out


class Recorder(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('recorder', **kwargs)
        p = declare_params(self, PARAMS)
        self._wanted: Set[str] = {t for t in p['topics'] if t}
        self._excluded: Set[str] = {t for t in p['exclude'] if t}
        storage = p['storage']
        if storage not in STORAGES:
            raise BagError(f'storage must be one of {sorted(STORAGES)}, got "{storage}"')
        self._depth = p['queue_depth']
        self._ready_file = Path(p['ready_file']) if p['ready_file'] else None
        self._ready_topics: Set[str] = {t for t in p['ready_topics'] if t}
        if self._ready_file is not None:
            self._ready_file.unlink(missing_ok=True)
        self._writer = BagWriter(Path(p['output_dir']), p['bag_name'] or None, storage,
                                 compression=p['compression'], chunk_crc=p['chunk_crc'],
                                 max_bag_size=p['max_bag_size'],
                                 max_bag_duration=p['max_bag_duration'],
                                 custom_data=parse_custom_data(p['custom_data']))
        # A write that fails (a full disk) closes the bag at its last flush and ends the run
        # with exit code 1 (ros_common.node_main.run_node).
        self.exit_request = threading.Event()
        self.exit_code = 0
        self._failure = ''
        self._skipped: Set[str] = set()
        self._receiving: Set[str] = set()  # topics with a message written (or tried)
        self.dropped = 0
        # Wall-clock timers: they must run whether or not simulated time advances.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(p['discovery_period'], self._discover, clock=steady)
        self.create_timer(p['flush_period'], self._flush, clock=steady)
        self.get_logger().info(
            f'recording {sorted(self._wanted) if self._wanted else "all topics"} to '
            f'{self._writer.path} ({storage}'
            + (f', {self._writer.compression} compression)' if self._writer.compression != 'none'
               else ')'))
        self._discover()

    @property
    def bag_path(self) -> Path:
        return self._writer.path

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if (topic in self._writer.topics or topic in self._skipped or topic in self._excluded
                    or (self._wanted and topic not in self._wanted)):
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # only subscribers so far: nothing to record, QoS unknown
            self._subscribe(topic, types, publishers)

    def _subscribe(self, topic: str, types, publishers) -> None:
        if len(types) != 1:
            self._skip(topic, f'has several types {types}')
            return
        try:
            msg_class = message_class(types[0])
            policies = [(int(p.qos_profile.reliability), int(p.qos_profile.durability))
                        for p in publishers]
            self._writer.add_topic(topic, types[0], [
                bag_qos(r, d, p.qos_profile.depth) for (r, d), p in zip(policies, publishers)])
        except (TypeResolutionError, BagError) as exc:
            self._skip(topic, str(exc))
            return
        reliability, durability = adapt_to_publishers(policies)
        qos = QoSProfile(depth=self._depth, reliability=ReliabilityPolicy(reliability),
                         durability=DurabilityPolicy(durability))
        self.create_subscription(msg_class, topic, functools.partial(self._on_message, topic),
                                 qos, raw=True)
        self.get_logger().info(f'recording {topic} [{types[0]}]')
        if self._ready_file is not None and self._ready_topics <= set(self._writer.topics):
            _write_atomically(self._ready_file, ' '.join(sorted(self._ready_topics)) + '\n')
            self._ready_file = None

    def _on_message(self, topic: str, data: bytes) -> None:
        if self._failure:
            self.dropped += 1          # (between the failure and the end of the spin)
            return
        if topic not in self._receiving:
            self._receiving.add(topic)
            self.get_logger().info(f'receiving {topic}')
        try:
            self._writer.write(topic, self.get_clock().now().nanoseconds, data)
        except (OSError, WriterError) as exc:
            self._fail(f'writing {topic}', exc)

    def _flush(self) -> None:
        if self._failure:
            return
        try:
            self._writer.flush()
        except (OSError, WriterError) as exc:
            self._fail('flushing', exc)

    def _fail(self, doing: str, exc: BaseException) -> None:
        """A write failed: close the bag where its last flush left it, say so once, and end
        the run. (A full disk does not empty itself: going on would only drop messages.)"""
        written = self._writer.message_count
        try:
            kept = self._writer.close_after_failure()
            closed = (f'the bag is closed with the {kept} messages flushed before '
                      f'(metadata.yaml counts them; {written - kept} written since the last '
                      'flush are not in it)')
        except (OSError, WriterError) as second:
            closed = f'the bag could not be closed either ({second}): run bag_repair on it'
        self._failure = f'{doing} {self._writer.path} failed: {exc}'
        self.get_logger().error(f'{self._failure}; {closed}; the recorder stops')
        self.exit_code = 1
        self.exit_request.set()

    def _skip(self, topic: str, why: str) -> None:
        self._skipped.add(topic)
        self.get_logger().warn(f'not recording {topic}: {why}')

    def finish(self) -> str:
        if not self._failure:
            try:
                self._writer.close()
            except (OSError, WriterError) as exc:
                self._fail('closing', exc)
        counts = ', '.join(f'{t}: {r.count}' for t, r in sorted(self._writer.topics.items()))
        lost = ''
        if self._failure:
            lost = f'; recording ended early: {self._failure}' + (
                f'; {self.dropped} messages arrived after it' if self.dropped else '')
        return (f'bag {self._writer.path} closed with {self._writer.message_count} messages '
                f'({counts}){lost}')


def _finish(node: Recorder) -> None:
    # SIGINT and SIGTERM end up here: the bag is finalised and readable.
    print(f'[recorder] {node.finish()}', flush=True)



def _write_atomically(path: Path, text: str) -> None:
    """``path`` appears whole or not at all (written beside it, then renamed)."""
    part = path.with_name(path.name + '.part')
    part.write_text(text)
    os.replace(part, path)

def main(args=None) -> int:
    return run_node(Recorder, 'recorder', (BagError, OSError), on_exit=_finish, args=args)


if __name__ == '__main__':
    sys.exit(main())
