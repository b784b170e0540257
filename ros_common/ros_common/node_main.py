"""One ``main()`` for the project's nodes: start-up errors as one fatal line and exit code 1,
and a shutdown by SIGINT or SIGTERM that always ends cleanly with exit code 0.

rclpy's signal handler shuts the context down from outside the executor. If that happens while
the executor is building its next wait set, rclpy raises ``RCLError`` ("the given context is not
valid") instead of ``ExternalShutdownException`` (ros2/rclpy#398, ros2/ros2cli#854). Both mean
the same thing, a requested shutdown, and are treated alike here.
"""
from __future__ import annotations

from typing import Callable, Optional, Tuple, Type

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.node import Node

try:
    from rclpy._rclpy_pybind11 import RCLError
except ImportError:  # pragma: no cover - a future rclpy may move it
    RCLError = RuntimeError


def spin(node: Node, executor: Optional[Executor] = None) -> None:
    """Spin ``node`` until the context is shut down, by a signal or by the node itself."""
    try:
        rclpy.spin(node, executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        if node.context.ok():
            raise           # a real failure, not the shutdown race


def run_node(factory: Callable[[], Node], name: str,
             startup_errors: Tuple[Type[BaseException], ...] = (),
             on_exit: Optional[Callable[[Node], None]] = None, args=None) -> int:
    """Create the node, spin it until shutdown, and return the process exit code.

    A configuration error raised by ``factory`` (one of ``startup_errors``, or a bad parameter)
    is logged as one fatal line and returns 1. ``on_exit`` runs whatever ended the spin, before
    the node is destroyed (a recorder closes its bag there).
    """
    rclpy.init(args=args)
    try:
        node = factory()
    except ParameterException as exc:
        rclpy.logging.get_logger(name).fatal(f'bad parameter: {exc}')
        rclpy.try_shutdown()
        return 1
    except tuple(startup_errors) as exc:
        rclpy.logging.get_logger(name).fatal(f'cannot start: {exc}')
        rclpy.try_shutdown()
        return 1
    try:
        spin(node)
    finally:
        if on_exit is not None:
            on_exit(node)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
