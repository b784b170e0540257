"""Helpers for graph tests: node processes, a probe node, and condition waits."""
from __future__ import annotations

import contextlib
import math
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence

import rclpy
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

# Lines a test adds to the end of the run's report (tests/conftest.py prints them): the fuzz
# tests' counts.
REPORT: List[str] = []

ROOT = Path(__file__).resolve().parents[1]


def wait_for(condition: Callable[[], bool], timeout: float = 10.0, period: float = 0.01,
             what: str = 'condition') -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return
        time.sleep(period)
    raise TimeoutError(f'timed out after {timeout} s waiting for {what}')


def handshake_status(url: str, host: Optional[str], origins: Sequence[str] = (),
                     websocket: bool = True, extra: Sequence = ()) -> int:
    """The HTTP status a web server on loopback answers a request with these Host and Origin
    headers (a browser cannot choose them; a page of another site gets them from its own
    address): 101 for an accepted WebSocket (of the Foxglove protocol: the live view takes no
    other). ``url``: http:// or ws://, its path is asked."""
    import http.client
    import urllib.parse
    parts = urllib.parse.urlsplit(url)
    conn = http.client.HTTPConnection('127.0.0.1', parts.port, timeout=20)
    try:
        conn.putrequest('GET', parts.path or '/', skip_host=True,
                        skip_accept_encoding=True)
        if host is not None:
            conn.putheader('Host', host)
        for origin in origins:
            conn.putheader('Origin', origin)
        if websocket:
            for name, value in (('Upgrade', 'websocket'), ('Connection', 'Upgrade'),
                                ('Sec-WebSocket-Key', 'dGhlIHNhbXBsZSBub25jZQ=='),
                                ('Sec-WebSocket-Version', '13'),
                                ('Sec-WebSocket-Protocol', 'foxglove.sdk.v1')):
                conn.putheader(name, value)
        for name, value in extra:
            conn.putheader(name, value)
        conn.endheaders()
        return conn.getresponse().status
    finally:
        conn.close()


class NodeProcess:
    """A node executable run as its own process, its output kept in a log file."""

    def __init__(self, executable: str, ros_args: List[str], log_dir: Path,
                 name: Optional[str] = None, env: Optional[Dict[str, str]] = None,
                 stdin=subprocess.DEVNULL) -> None:
        path = shutil.which(executable)
        if path is None:
            raise FileNotFoundError(f'{executable} not on PATH (source scripts/env.sh)')
        self.name = name or executable
        self.log_path = log_dir / f'{self.name}.log'
        self._log = open(self.log_path, 'w')
        cmd = [path, '--ros-args'] + ros_args
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT,
                                     stdin=stdin, env={**os.environ, **(env or {})},
                                     start_new_session=True)

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def problems(self, also: Sequence[str] = (), limit: int = 40) -> List[str]:
        """The log's warnings, errors and tracebacks, and the lines that contain one of
        ``also`` (the last ``limit``), each named after this process: what a failing graph
        test prints, since its logs are gone after a CI run."""
        lines = [f'{self.name}: {line}' for line in self.output().splitlines()
                 if line.startswith(('[WARN]', '[ERROR]', '[FATAL]', 'Traceback'))
                 or 'Error' in line.split(':', 1)[0] or any(a in line for a in also)]
        return lines[-limit:]

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return self.proc.returncode


class Probe:
    """An rclpy node spun in a background thread, for subscribing and calling from tests."""

    def __init__(self, name: str = 'test_probe') -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._clients: Dict[str, object] = {}
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._running = True
        self._thread.start()

    def _spin(self) -> None:
        while self._running and self.context.ok():
            self.executor.spin_once(timeout_sec=0.02)

    def collect(self, msg_type, topic: str, qos=1000, raw: bool = False) -> List:
        """Subscribe and return a list that fills with (receive_monotonic, msg) pairs
        (the serialized bytes instead of the message with ``raw``). The default history is deep
        (1000) so that a test process busy elsewhere does not drop messages from its queue."""
        received: List = []
        self.node.create_subscription(msg_type, topic,
                                      lambda m: received.append((time.monotonic(), m)), qos,
                                      raw=raw)
        return received

    def service(self, srv_type, name: str, timeout: float = 10.0):
        """A client of the service, once the server is discovered (one per name: a test that
        must call at a given moment discovers the server before, not in that moment)."""
        client = self._clients.get(name)
        if client is None:
            client = self._clients[name] = self.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f'service {name} not available')
        return client

    def call(self, srv_type, name: str, request, timeout: float = 10.0):
        future = self.service(srv_type, name, timeout).call_async(request)
        wait_for(future.done, timeout, what=f'reply of {name}')
        return future.result()

    def close(self) -> None:
        self._running = False
        self._thread.join(2.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@contextlib.contextmanager
def cpu_load(processes: Optional[int] = None):
    """A busy process per core (by default) for as long as the block runs: what a test that
    must not depend on the machine's load runs under."""
    count = processes or os.cpu_count() or 1
    busy = [subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True) for _ in range(count)]
    try:
        yield busy
    finally:
        for proc in busy:
            proc.kill()
            proc.wait()


def stamp_s(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def latest_stamp(messages: List) -> float:
    """The stamp [s] of the last of a ``Probe.collect`` list of stamped messages (-inf if
    none; a MarkerArray's is its first marker's)."""
    if not messages:
        return -math.inf
    msg = messages[-1][1]
    header = msg.markers[0].header if hasattr(msg, 'markers') and msg.markers else msg.header
    return stamp_s(header.stamp)


def wait_for_stamp(messages: List, t: float, timeout: float = 30.0, what: str = '') -> None:
    """Until ``messages`` holds one stamped at or after ``t`` [s of simulated time]: a test
    that lets simulated time pass waits for it to pass, not for wall time."""
    wait_for(lambda: latest_stamp(messages) >= t, timeout,
             what=what or f'a message stamped {t:.3f} s or later')


class PendingStep:
    """A step request and its latest call."""

    def __init__(self, client, request) -> None:
        self.client, self.request = client, request
        self.pending_replies = 0          # answers that the announced commands were not in yet
        self.send()

    def send(self) -> None:
        self.future = self.client.call_async(self.request)


class LockStepDriver:
    """Drives a lock-step (``synchronous:=true``) simulator as the coordinator does: a command
    is published, then announced in the next step request, so the simulator waits for it and
    every step runs with exactly the commands meant for it, whatever the machine's load."""

    def __init__(self, probe: Probe, robot: str = 'mini_robot', stamped: bool = False) -> None:
        from geometry_msgs.msg import Twist, TwistStamped
        from nav_msgs.msg import Odometry
        from sim_interfaces.srv import StepSimulation
        self._twist, self._request = Twist, StepSimulation.Request
        self._stamped = TwistStamped if stamped else None
        self.odom = probe.collect(Odometry, f'/{robot}/odom')
        self.pub = probe.node.create_publisher(TwistStamped if stamped else Twist,
                                               f'/{robot}/cmd_vel', 10)
        self.client = probe.node.create_client(StepSimulation, '/sim_node/step')
        assert self.client.wait_for_service(timeout_sec=15.0), 'no /sim_node/step'
        # A first round trip that steps nothing, sent again until answered (a reply right after
        # discovery can be lost; a step's must not be), as the coordinator does.
        from ros_common.services import call_and_wait
        call_and_wait(self.client, self._request(steps=0), 30.0, resend=0.5)
        wait_for(lambda: self.pub.get_subscription_count() > 0, 15.0, what='cmd_vel matched')

    def step(self, steps: int, commands: int = 0) -> 'PendingStep':
        """Send a step request; ``reply`` gets its answer."""
        return PendingStep(self.client, self._request(steps=steps, commands=commands))

    def reply(self, pending: 'PendingStep', timeout: float = 20.0):
        """The answer to a step request, asked again while the simulator still waits for the
        commands announced with it (``commands_pending``), as the coordinator does."""
        end = time.monotonic() + timeout
        while True:
            wait_for(pending.future.done, max(0.1, end - time.monotonic()),
                     what='the step reply')
            reply = pending.future.result()
            if not reply.commands_pending or time.monotonic() > end:
                return reply
            pending.pending_replies += 1
            time.sleep(0.001)
            pending.send()

    def ask_until(self, pending: 'PendingStep', answered: Callable[[object], bool],
                  timeout: float = 30.0):
        """The first answer to a step request that ``answered`` accepts (or that is not
        pending), asking again after each pending one: for a test that must see a given
        pending answer, however long the machine takes to deliver what it waits for."""
        end = time.monotonic() + timeout
        while True:
            wait_for(pending.future.done, max(0.1, end - time.monotonic()),
                     what='the step reply')
            reply = pending.future.result()
            if answered(reply) or not reply.commands_pending:
                return reply
            pending.pending_replies += 1
            pending.send()

    def send(self, vx: float, wz: float = 0.0, vy: float = 0.0) -> None:
        msg = self._twist()
        msg.linear.x, msg.linear.y, msg.angular.z = vx, vy, wz
        self.pub.publish(self._stamped(twist=msg) if self._stamped else msg)

    def odom_at(self, stamp):
        """The odometry published at ``stamp`` (a step's sim_time)."""
        def found():
            return any(m.header.stamp == stamp for _, m in self.odom)
        wait_for(found, 10.0, what='the odometry of the step')
        return next(m for _, m in self.odom if m.header.stamp == stamp)

    def hold(self, vx: float, wz: float, steps: int, batch: int = 24, vy: float = 0.0):
        """Command (vx, wz) (and ``vy``) for ``steps`` physics steps, re-sent every ``batch``
        steps (well inside the command timeout); returns the last reply."""
        reply = None
        while steps > 0:
            n = min(batch, steps)
            self.send(vx, wz, vy)
            reply = self.reply(self.step(n, commands=1))
            assert reply.success, reply.message
            steps -= n
        return reply


def moving(state) -> bool:
    """A control_msgs/JointTrajectoryControllerState whose reference moves: a trajectory is
    being followed (holding, the reference velocity is exactly zero)."""
    return any(v != 0.0 for v in state.reference.velocities)


class ActionUser:
    """An action client (FollowJointTrajectory unless ``action_type`` says otherwise) on a node
    of its own, spun only from the test's thread: rclpy 7's ActionClient loses a goal response
    that a spinning thread takes before send_goal_async has recorded the request ("Ignoring
    unexpected goal response", ros2/rclpy#1123). The handshake sends the action's empty goal,
    which the server must reject."""

    def __init__(self, action: str, action_type=FollowJointTrajectory):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('action_user', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.action_type = action_type
        self.client = ActionClient(self.node, action_type, action)

    def spin_until(self, condition, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > end:
                raise TimeoutError(f'timed out after {timeout} s waiting for {what}')
            self.executor.spin_once(timeout_sec=0.05)

    def handshake(self, timeout: float) -> None:
        """Wait until the server's answers reach this client. server_is_ready() says the client
        sees the server; the server may not see the client's response reader yet, and Fast DDS
        then drops the goal response after 100 ms ('client will not receive response'), which
        a loaded machine's discovery can take. An empty goal, which the server rejects, is sent
        until one answer arrives: the path works both ways from then on."""
        end = time.monotonic() + timeout
        while True:
            sent = self.client.send_goal_async(self.action_type.Goal())
            answered = time.monotonic() + 1.0
            while not sent.done() and time.monotonic() < min(answered, end):
                self.executor.spin_once(timeout_sec=0.05)
            if sent.done():
                assert not sent.result().accepted
                return
            if time.monotonic() > end:
                raise TimeoutError(f'no answer from the action server in {timeout} s')

    def ready(self, timeout: float) -> None:
        self.spin_until(self.client.server_is_ready, timeout, 'the action server')
        self.handshake(timeout)

    def send(self, goal, feedback=None):
        """The goal's handle, once the server has answered."""
        sent = self.client.send_goal_async(goal, feedback_callback=feedback)
        self.spin_until(sent.done, 20.0, 'the goal response')
        return sent.result()

    def result(self, handle, timeout: float = 60.0):
        future = handle.get_result_async()
        self.spin_until(future.done, timeout, 'the goal result')
        return future.result()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def lying_bag(directory, storage, variant):
    """A closed bag of 100 std_msgs/String on /t over 0.99 s whose metadata.yaml says
    otherwise: ``none`` (0 messages), ``many`` (999999999) or ``backwards`` (a negative
    duration)."""
    import yaml
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from recording.bag_writer import BagWriter
    writer = BagWriter(directory, f'{variant}_{storage}', storage)
    writer.add_topic('/t', 'std_msgs/msg/String')
    for i in range(100):
        writer.write('/t', 10_000_000 * i, serialize_message(String(data=str(i))))
    writer.close()
    meta = writer.path / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    info = doc['rosbag2_bagfile_information']
    if variant == 'none':
        info['message_count'] = 0
        for entry in info['topics_with_message_count'] + info['files']:
            entry['message_count'] = 0
    elif variant == 'many':
        info['message_count'] = 999999999
    elif variant == 'backwards':
        info['duration']['nanoseconds'] = -(2 ** 63) + 1
        info['starting_time']['nanoseconds_since_epoch'] = 0
    meta.write_text(yaml.safe_dump(doc))
    return writer.path


def chunked_bag(directory: Path, storage: str = 'mcap', name: str = 'flip',
                keep_metadata: bool = True) -> Path:
    """A closed bag of 600 std_msgs/String on /t, flushed every 100 (six MCAP chunks, six
    SQLite commits)."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from recording.bag_writer import BagWriter
    writer = BagWriter(directory, name, storage)
    writer.add_topic('/t', 'std_msgs/msg/String')
    for i in range(600):
        writer.write('/t', 1_000_000 * i, serialize_message(String(data=f'{i:04d}' + 'z' * 60)))
        if i % 100 == 99:
            writer.flush()
    writer.close()
    if not keep_metadata:
        (writer.path / 'metadata.yaml').unlink()
    return writer.path


def flipped_copies(bag: Path, directory: Path, count: int, seed: int):
    """``count`` copies of ``bag`` in ``directory``, each with a few of its data file's bytes
    set to 0, 255 or one bit flipped (a bad disk, a careless edit), seeded."""
    import random
    rng = random.Random(seed)
    data_file = next(p for p in bag.iterdir() if p.suffix in ('.mcap', '.db3'))
    data = data_file.read_bytes()
    for trial in range(count):
        damaged = bytearray(data)
        for _ in range(rng.choice([1, 1, 4, 16])):
            at = rng.randrange(len(damaged))
            damaged[at] = rng.choice([0x00, 0xff, damaged[at] ^ (1 << rng.randrange(8))])
        copy = directory / f'damaged_{bag.name}_{trial}'
        shutil.copytree(bag, copy)
        (copy / data_file.name).write_bytes(bytes(damaged))
        yield copy
