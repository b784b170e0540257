"""Publishes a bag's messages on their topics with the recorded timing (and /clock from it)."""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Dict

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import ReaderError
from rosgraph_msgs.msg import Clock

from recording.qos_profiles import replay_policies
from recording.replay_schedule import ReplaySchedule
from recording.types import TypeResolutionError, message_class
from ros_common.node_main import run_task
from ros_common.params import Param, declare_params
from ros_common.stamps import set_stamp

SUBSCRIBER_MATCH_SETTLE_S = 0.5


PARAMS = (
    Param('bag', '', 'Bag directory to replay'),
    Param('rate', 1.0, 'Replay speed factor', 0.01, 100.0),
    Param('loop', False, 'Start again at the end'),
    Param('topics', [''], 'Topics to replay; empty: all'),
    Param('start_offset', 0.0, 'Seconds of the bag to skip at the start', 0.0, 1e6),
    Param('publish_clock', False, 'Publish /clock from bag time (the recorded /clock is then '
          'not replayed)'),
    Param('clock_rate', 100.0, '/clock messages per wall second with publish_clock',
          1.0, 10000.0),
    Param('wait_for_subscribers', 0.0, 'Wall seconds to wait until every replayed topic has a '
          'subscriber', 0.0, 600.0),
    Param('delay', 0.0, 'Wall seconds to wait before the first message (as ros2 bag play '
          '--delay)', 0.0, 600.0),
)


class ReplayError(RuntimeError):
    """A bag that cannot be replayed."""


class BagDataError(RuntimeError):
    """The bag's reader failed on its data (truncated, corrupt)."""


class Replay(Node):

    def __init__(self, **kwargs) -> None:
        super().__init__('replay', **kwargs)
        p = declare_params(self, PARAMS)
        self.bag = Path(p['bag'])
        if not p['bag'] or not self.bag.is_dir():
            raise ReplayError(f'bag "{p["bag"]}" is not a bag directory')
        self.rate, self.loop = p['rate'], p['loop']
        self.start_offset = p['start_offset']
        self.publish_clock = p['publish_clock']
        self.clock_period = 1.0 / p['clock_rate']
        self.wait_for_subscribers = p['wait_for_subscribers']
        self.delay = p['delay']
        wanted = {t for t in p['topics'] if t}
        try:
            self.reader = AnyReader([self.bag])
            self.reader.open()
        except Exception as exc:    # (as _messages: the reader raises many kinds on bad data)
            raise ReplayError(f'{self.bag}: not a readable bag ({exc}); a bag left by a killed '
                              'recorder can be restored with bag_repair') from None
        self.connections = [c for c in self.reader.connections
                            if (not wanted or c.topic in wanted)
                            and not (self.publish_clock and c.topic == '/clock')]
        if not self.connections:
            raise ReplayError(f'{self.bag}: none of the topics {sorted(wanted)} is in the bag')
        self._topic_pubs: Dict[str, Publisher] = {}
        for c in self.connections:
            if c.topic in self._topic_pubs:
                continue
            try:
                msg_class = message_class(c.msgtype)
            except TypeResolutionError as exc:
                self.get_logger().warn(f'not replaying {c.topic}: {exc}')
                continue
            reliability, durability = replay_policies(
                getattr(c.ext, 'offered_qos_profiles', []), c.msgtype)
            qos = QoSProfile(depth=100, reliability=ReliabilityPolicy(reliability),
                             durability=DurabilityPolicy(durability))
            self._topic_pubs[c.topic] = self.create_publisher(msg_class, c.topic, qos)
        self.published = 0
        self._read_once = 0         # messages on the replayed topics, in one pass
        self.clock_pub = (self.create_publisher(Clock, '/clock', QoSProfile(depth=10))
                          if self.publish_clock else None)
        self.get_logger().info(
            f'replaying {len(self._topic_pubs)} topics of {self.bag} at rate {self.rate:g}'
            + (', looping' if self.loop else '') + (', publishing /clock' if self.publish_clock
                                                    else ''))

    def run(self) -> int:
        try:
            return self._play()
        except Exception:
            # SIGINT shuts the context down wherever the loop is: a publish or the final ack
            # wait then fails. That is a requested stop, not an error.
            if not self.context.ok():
                self.get_logger().info(f'stopped: {self.published} messages published')
                return 0
            raise

    def _play(self) -> int:
        try:
            return self._play_bag()
        except (BagDataError, AnyReaderError, ReaderError, OSError, ValueError, KeyError,
                IndexError) as exc:
            if not self.context.ok():
                raise
            # The index opened, but a chunk is damaged: say so instead of a traceback.
            self.get_logger().error(f'{self.bag}: unreadable data after {self.published} '
                                    f'messages ({exc}); the bag is truncated or corrupt')
            return 1

    def _play_bag(self) -> int:
        if self.wait_for_subscribers > 0.0:
            self._wait_for_subscribers()
        if self.delay > 0.0:
            time.sleep(self.delay)
        # The schedule starts at the bag's first message as read, not at metadata.yaml's start
        # time: metadata can be wrong (edited, or from another bag); the messages are played.
        first = next((stamp for _, stamp, _ in self._messages()), None)
        if first is None:
            self.get_logger().warn(f'{self.bag}: the bag holds no messages')
            return 0
        schedule = ReplaySchedule(first, self.rate, self.start_offset)
        first_pass = True
        while self.context.ok():
            schedule.restart(time.monotonic())
            next_clock = 0.0
            for connection, bag_ns, raw in self._messages(self.connections):
                self._read_once += first_pass
                if schedule.skip(bag_ns) or connection.topic not in self._topic_pubs:
                    continue
                due = schedule.due(bag_ns)
                while True:  # sleep until due, publishing /clock on the way
                    now = time.monotonic()
                    if self.clock_pub is not None and now >= next_clock:
                        self._publish_clock(min(schedule.bag_time_at(now), bag_ns))
                        next_clock = now + self.clock_period
                    if now >= due:
                        break
                    wake = due if self.clock_pub is None else min(due, next_clock)
                    time.sleep(max(0.0, wake - now))
                self._topic_pubs[connection.topic].publish(bytes(raw))
                self.published += 1
                if not self.context.ok():
                    break
            else:
                first_pass = False              # (a whole pass read)
            if not self.loop:
                break
        if self.context.ok():
            for pub in self._topic_pubs.values():
                pub.wait_for_all_acked(Duration(seconds=2.0))
        said = sum(c.msgcount for c in self.connections)
        if not first_pass and said != self._read_once:
            self.get_logger().warn(
                f'{self.bag}: metadata.yaml counts {said} messages on the replayed topics; '
                f'the bag holds {self._read_once}, which were replayed')
        self.get_logger().info(f'replay done: {self.published} messages published')
        return 0

    def _messages(self, connections=()):
        """The reader's messages; whatever the reader raises on damaged data (rosbags, the mcap
        and SQLite libraries raise many kinds: struct.error, OverflowError, CorruptError, ...)
        is a BagDataError."""
        messages = self.reader.messages(connections=connections)
        while True:
            try:
                item = next(messages)
            except StopIteration:
                return
            except Exception as exc:
                raise BagDataError(f'{type(exc).__name__}: {exc}') from None
            yield item

    def _wait_for_subscribers(self) -> None:
        end = time.monotonic() + self.wait_for_subscribers
        while time.monotonic() < end:
            if all(p.get_subscription_count() > 0 for p in self._topic_pubs.values()):
                # Our side has matched; the subscriber's side of discovery may finish a little
                # later, and a volatile reader misses what was sent before it did.
                time.sleep(SUBSCRIBER_MATCH_SETTLE_S)
                return
            rclpy.spin_once(self, timeout_sec=0.05)
        missing = sorted(t for t, p in self._topic_pubs.items() if p.get_subscription_count() == 0)
        self.get_logger().warn(f'starting without subscribers on {missing}')

    def _publish_clock(self, bag_ns: int) -> None:
        if self.clock_pub is None:
            return
        msg = Clock()
        set_stamp(msg.clock, bag_ns)
        self.clock_pub.publish(msg)

    def destroy_node(self) -> None:
        self.reader.close()
        super().destroy_node()


def main(args=None) -> int:
    return run_task(Replay, 'replay', lambda node: node.run(), (ReplayError,), args=args)


if __name__ == '__main__':
    sys.exit(main())
