"""What the live view decides without ROS or a socket: the topics it streams, what it keeps
for a client that reads slowly, and the count of what that client missed."""
import logging
import struct

import pytest

from live_view.bridge import (
    ClientOutbox,
    GraphChange,
    SlowClients,
    TopicFilter,
    changes_per_look,
    graph_change,
    paced,
)


def data(channel: int, size: int) -> bytes:
    """A Foxglove message-data frame (opcode 1) of ``size`` bytes."""
    return struct.pack('<BIQ', 0x01, channel, 0) + bytes(size - 13)


def test_a_client_that_does_not_read_is_owed_at_most_the_limit():
    box = ClientOutbox(1000)
    advertise = '{"op": "advertise", "channels": []}'
    assert box.put(advertise)
    for k in range(100):
        assert box.put(data(k, 300))
        assert box.size <= 1000
    # The advertisement is kept (a client that misses it cannot read what follows), and the
    # newest data after it, in order; the oldest data went.
    frames = []
    while len(box):
        frames.append(box.take())
    assert frames[0] == advertise
    assert [struct.unpack_from('<I', f, 1)[0] for f in frames[1:]] == [97, 98, 99]
    assert box.dropped == 97 and box.size == 0 and box.take() is None


def test_a_frame_that_must_not_be_dropped_is_kept_and_a_client_too_slow_for_them_is_let_go():
    box = ClientOutbox(100)
    assert box.put(bytes([0x03]) + bytes(40))          # a service response: never dropped
    assert box.put(data(1, 50))
    assert box.put(data(2, 50))                        # (pushes out data 1)
    assert box.dropped == 1
    assert not box.put('{"op": "advertise"}' + ' ' * 80)   # over the limit, nothing to drop


def test_a_limit_below_one_byte_is_refused():
    with pytest.raises(ValueError):
        ClientOutbox(0)


def test_slow_clients_are_counted_from_the_gate_and_from_the_sdks_log():
    slow = SlowClients()
    slow.add('127.0.0.1:5000 #1', 7)
    slow.add('127.0.0.1:5000 #1', 0)
    slow.emit(logging.LogRecord('foxglove', logging.WARNING, '', 0,
                                'outbox for client 127.0.0.1:6000 full', (), None))
    assert slow.news() == [('127.0.0.1:5000 #1', 7, 7), ('gate connection 127.0.0.1:6000', 1, 1)]
    slow.add('127.0.0.1:5000 #1', 3)
    assert slow.news() == [('127.0.0.1:5000 #1', 3, 10)]
    assert slow.news() == []


def test_topics_are_advertised_while_they_have_a_publisher_and_one_type():
    wanted = TopicFilter([], ['/secret'])
    change = graph_change({'/gone': 'std_msgs/msg/String', '/odom': 'nav_msgs/msg/Odometry'},
                          [('/odom', ['nav_msgs/msg/Odometry'], 1),
                           ('/new', ['std_msgs/msg/String'], 1),
                           ('/two', ['a/msg/A', 'b/msg/B'], 2),
                           ('/secret', ['std_msgs/msg/String'], 1),
                           ('/gone', ['std_msgs/msg/String'], 0)], wanted)
    assert change.advertise == (('/new', 'std_msgs/msg/String'),)
    assert change.drop == ('/gone',)
    with pytest.raises(ValueError, match='absolute'):
        TopicFilter(['odom'])


def test_a_graph_that_appears_at_once_is_advertised_a_few_channels_per_look():
    """Each channel advertised or dropped is a control message to every client, queued by the
    SDK (message_backlog_size) faster than it sends them; past its queue, the SDK closes the
    client (a loaded suite's live-view client, at a backlog of 4, got nothing more). A look at
    the graph makes at most half the backlog of changes, drops first; the rest come at the next
    looks, and a topic whose type changed is advertised again only once it has been dropped."""
    assert [changes_per_look(b) for b in (2, 4, 16, 1024)] == [1, 2, 8, 512]
    advertised = {'/gone': 'std_msgs/msg/String', '/retyped': 'std_msgs/msg/String'}
    graph = [(f'/t{k:02d}', ['std_msgs/msg/Int32'], 1) for k in range(40)]
    graph.append(('/retyped', ['std_msgs/msg/Float64'], 1))
    looks = 0
    while True:
        change = paced(graph_change(advertised, graph, TopicFilter()), changes_per_look(4))
        if not change.advertise and not change.drop:
            break
        looks += 1
        assert len(change.advertise) + len(change.drop) <= 2
        assert not {t for t, _ in change.advertise} & set(advertised) - set(change.drop)
        for topic in change.drop:
            del advertised[topic]
        advertised.update(change.advertise)
    assert looks == 22 and len(advertised) == 41
    assert advertised['/retyped'] == 'std_msgs/msg/Float64' and '/gone' not in advertised
    # The drops go first, and a retyped topic is not advertised while its drop waits.
    first = paced(GraphChange((('/a', 'x'), ('/b', 'y')), ('/a', '/c')), 1)
    assert first == GraphChange((), ('/a',))
    second = paced(GraphChange((('/a', 'x'), ('/b', 'y')), ('/c', '/a')), 2)
    assert second == GraphChange((), ('/c', '/a'))
    third = paced(GraphChange((('/a', 'x'), ('/b', 'y')), ('/c', '/a')), 1)
    assert third == GraphChange((), ('/c',))
