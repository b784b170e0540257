"""The shared node main(): a shutdown race is a clean exit, a real failure is not hidden."""
import pytest
from rclpy.node import Node

from ros_common import node_main
from ros_common.node_main import RCLError, run_node, spin


def _raising_spin(shutdown_first):
    def fake_spin(node, executor=None):
        if shutdown_first:
            node.context.try_shutdown()   # as rclpy's signal handler does, from outside
        raise RCLError('failed to initialize wait set: the given context is not valid')
    return fake_spin


def test_the_wait_set_race_after_a_signal_is_a_clean_shutdown(context, monkeypatch):
    node = Node('racer', context=context)
    monkeypatch.setattr(node_main.rclpy, 'spin', _raising_spin(shutdown_first=True))
    spin(node)          # returns: the context was shut down, so this was the race
    node.destroy_node()


def test_an_rcl_error_with_the_context_alive_is_raised(context, monkeypatch):
    node = Node('failing', context=context)
    monkeypatch.setattr(node_main.rclpy, 'spin', _raising_spin(shutdown_first=False))
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

    def fake_spin(node, executor=None):
        node.context.try_shutdown()
        raise RCLError('the given context is not valid')
    monkeypatch.setattr(node_main.rclpy, 'spin', fake_spin)
    code = run_node(lambda: Node('finisher'), 'finisher',
                    on_exit=lambda node: seen.append(node.get_name()), args=[])
    assert code == 0
    assert seen == ['finisher']
