"""The shared node main(): a shutdown race is a clean exit, a real failure is not hidden."""
import pytest
from rclpy.node import Node

from ros_common import node_main
from ros_common.node_main import RCLError, run_node, spin


def _raising_spin(shutdown_first):
    def fake_spin(executor, context, stop=None):
        if shutdown_first:
            context.try_shutdown()   # as rclpy's signal handler does, from outside
        raise RCLError('failed to initialize wait set: the given context is not valid')
    return fake_spin


def test_the_wait_set_race_after_a_signal_is_a_clean_shutdown(context, monkeypatch):
    node = Node('racer', context=context)
    monkeypatch.setattr(node_main, 'spin_until_shutdown', _raising_spin(shutdown_first=True))
    spin(node)          # returns: the context was shut down, so this was the race
    node.destroy_node()


def test_an_rcl_error_with_the_context_alive_is_raised(context, monkeypatch):
    node = Node('failing', context=context)
    monkeypatch.setattr(node_main, 'spin_until_shutdown',
                        _raising_spin(shutdown_first=False))
    with pytest.raises(RCLError):
        spin(node)
    node.destroy_node()


class _Broken(Node):
    def __init__(self):
        raise ValueError('world file /x.yaml does not exist')


def test_a_start_up_error_is_one_fatal_line_and_exit_code_1(capfd):
    assert run_node(_Broken, 'broken', (ValueError,), args=[]) == 1
    assert 'cannot start: world file /x.yaml does not exist' in capfd.readouterr().err


def test_on_exit_runs_after_a_shutdown(monkeypatch):
    seen = []

    def fake_spin(executor, context, stop=None):
        context.try_shutdown()
        raise RCLError('the given context is not valid')
    monkeypatch.setattr(node_main, 'spin_until_shutdown', fake_spin)
    code = run_node(lambda: Node('finisher'), 'finisher',
                    on_exit=lambda node: seen.append(node.get_name()), args=[])
    assert code == 0
    assert seen == ['finisher']


def test_nodes_spin_on_the_events_executor_unless_told_otherwise(context, monkeypatch):
    from rclpy.executors import SingleThreadedExecutor
    node = Node('chooser', context=context)
    monkeypatch.delenv('ROBOT_SIM_EXECUTOR', raising=False)
    events = node_main.make_executor(node)
    assert type(events).__name__ == 'EventsExecutor'
    assert isinstance(node_main.make_executor(node, events=False), SingleThreadedExecutor)
    monkeypatch.setenv('ROBOT_SIM_EXECUTOR', 'single')
    assert isinstance(node_main.make_executor(node), SingleThreadedExecutor)
    node.destroy_node()


def test_an_idle_node_sleeps_while_it_spins(context):
    """The EventsExecutor's own spin() busy-waits; the project's spin loop must not."""
    import threading
    import time
    node = Node('sleeper', context=context)
    cpu = []

    def spin_for_a_second():
        timer = threading.Timer(1.0, context.try_shutdown)
        timer.start()
        start = time.thread_time()
        spin(node)
        cpu.append(time.thread_time() - start)
    thread = threading.Thread(target=spin_for_a_second)
    thread.start()
    thread.join(10.0)
    assert cpu and cpu[0] < 0.2, f'{cpu} s of CPU in one second of spinning with nothing to do'
    node.destroy_node()


def test_a_task_with_a_background_spin_gets_its_callbacks_and_ends():
    from std_msgs.msg import Int32
    got = []

    def task(node):
        import time
        node.create_subscription(Int32, 'node_main_test', got.append, 10)
        pub = node.create_publisher(Int32, 'node_main_test', 10)
        deadline = time.monotonic() + 20.0
        while len(got) < 5 and time.monotonic() < deadline:
            pub.publish(Int32(data=len(got)))
            time.sleep(0.02)
        return 3
    code = node_main.run_task(lambda: Node('tasker'), 'tasker', task, background_spin=True,
                              args=[])
    assert code == 3
    assert len(got) >= 5


@pytest.mark.parametrize('executor', ['events', 'single'])
def test_a_background_spin_ends_with_its_task_not_at_the_end_of_its_wait(monkeypatch,
                                                                          executor):
    import threading
    monkeypatch.setenv('ROBOT_SIM_EXECUTOR', executor)
    # A spin slice far longer than the test: the spinner must be woken when the task ends,
    # before its executor is shut down, not left to wait out its slice.
    monkeypatch.setattr(node_main, '_SPIN_SLICE_S', 60.0)
    spinning_at_shutdown = []

    class Watched:
        def __init__(self, inner):
            self._inner = inner

        def __getattr__(self, name):
            return getattr(self._inner, name)

        def shutdown(self, *args, **kwargs):
            spinning_at_shutdown.append([t.name for t in threading.enumerate()
                                         if '_spin_in_thread' in t.name])
            return self._inner.shutdown(*args, **kwargs)

    make = node_main.make_executor
    monkeypatch.setattr(node_main, 'make_executor',
                        lambda node, events=True: Watched(make(node, events)))
    assert node_main.run_task(lambda: Node('woken'), 'woken', lambda node: 0,
                              background_spin=True, args=[]) == 0
    assert spinning_at_shutdown == [[]]


NODE_THAT_ENDS_ITSELF = '''
import os, signal, sys, threading
from rclpy.node import Node
from ros_common.node_main import run_node

class Ending(Node):
    def __init__(self):
        super().__init__('ending')
        self.exit_request = threading.Event()
        self.exit_code = int(sys.argv[1])
        if sys.argv[2] == 'signal':      # SIGINT while the node is still being made
            os.kill(os.getpid(), signal.SIGINT)
        else:                            # the node ends its own run from a callback
            self.create_timer(0.05, self.exit_request.set)

sys.exit(run_node(Ending, 'ending'))
'''


@pytest.mark.parametrize('how, code, expected', [('signal', 3, 0), ('itself', 1, 1)])
def test_a_node_ends_its_own_run_and_a_signal_while_it_is_made_is_not_lost(how, code,
                                                                          expected):
    """run_node: a node that sets its exit_request ends the spin with its exit_code; a SIGINT
    that came while the node was being made (before its event was known) still ends it, as a
    stop (exit 0: the recorder once missed it and hung until killed)."""
    import subprocess
    import sys
    out = subprocess.run([sys.executable, '-c', NODE_THAT_ENDS_ITSELF, str(code), how],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == expected, out.stdout + out.stderr


TASK_STOPPED_WHILE_MADE = '''
import os, signal, sys, time
import rclpy
from rclpy.node import Node
from ros_common import early_stop
from ros_common.node_main import run_task

class Late(Node):
    def __init__(self):
        # A SIGINT between rclpy.init and the node's creation (as ros2 launch sent one 0.92 s
        # into the pipeline's start): the stop shuts the task's context down in a thread.
        os.kill(os.getpid(), signal.SIGINT)
        deadline = time.monotonic() + 20.0
        while rclpy.ok() and time.monotonic() < deadline:
            time.sleep(0.01)
        super().__init__('late')         # NotInitializedException: the context is gone

early_stop.install()
sys.exit(run_task(Late, 'late', lambda node: 5, interrupted_code=int(sys.argv[1])))
'''


@pytest.mark.parametrize('interrupted_code', [0, 1])
def test_a_task_stopped_before_its_node_exists_ends_as_a_stop(interrupted_code):
    """run_task: a stop that shut the context down before the node was made ends the task
    as a stop (its interrupted code), with no traceback."""
    import subprocess
    import sys
    out = subprocess.run([sys.executable, '-c', TASK_STOPPED_WHILE_MADE, str(interrupted_code)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == interrupted_code, out.stdout + out.stderr
    assert 'Traceback' not in out.stderr and 'Exception' not in out.stderr, out.stderr
