"""The ``main()`` of the project's nodes (``run_node``: spin until shutdown; ``run_task``: run
a job to its end): start-up errors as one fatal line and exit code 1,
and a shutdown by SIGINT or SIGTERM that always ends cleanly with exit code 0.

rclpy's signal handler shuts the context down from outside the executor. If that happens while
the executor is building its next wait set, rclpy raises ``RCLError`` ("the given context is not
valid") instead of ``ExternalShutdownException`` (ros2/rclpy#398, ros2/ros2cli#854). Both mean
the same thing, a requested shutdown, and are treated alike here.

The nodes spin on rclpy's EventsExecutor (``rclpy.experimental``): its queue of ready entities
is kept in C++, so taking a message costs about 80 µs of CPU instead of the 450-700 µs that the
SingleThreadedExecutor spends rebuilding its wait set in Python for every spin (measured with a
node of 12 subscriptions and 12 publishers). A lock-step trial's coordinator takes about 10,000
messages. Two limits of the Jazzy version shape its use here:

- its ``spin()`` busy-waits (a whole core with nothing to do), so it is spun with
  ``spin_once(timeout)`` in a loop, which sleeps;
- it cannot run coroutine callbacks (an ``async def`` service answers a coroutine object and
  rclpy raises TypeError), so no node of the project has one; a node that must passes
  ``events=False``;
- it has no guard conditions (``create_guard_condition`` fails at the first spin).

``ROBOT_SIM_EXECUTOR=single`` in the environment runs every node on the SingleThreadedExecutor
instead (the same behaviour, more CPU).
"""
from __future__ import annotations

import os
import threading
from typing import Callable, List, Optional, Tuple, Type, TypeVar

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ros_common import early_stop
from ros_common.memory import keep_large_blocks

try:
    from rclpy._rclpy_pybind11 import InvalidHandle, RCLError
except ImportError:  # pragma: no cover - a future rclpy may move them
    RCLError = InvalidHandle = RuntimeError
# What rclpy raises where a shutdown from another thread meets a wait: the context is invalid,
# or a guard condition was destroyed under it. Either means a requested shutdown when the
# context is no longer ok (and is raised again otherwise).
_SHUTDOWN_RACE = (RCLError, InvalidHandle)


# How long one spin_once of the EventsExecutor may sleep; a shutdown wakes it at once.
_SPIN_SLICE_S = 1.0


def make_executor(node: Node, events: bool = True) -> Executor:
    """The executor a node of the project spins on (see the module's docstring)."""
    if events and os.environ.get('ROBOT_SIM_EXECUTOR', 'events') != 'single':
        from rclpy.experimental import EventsExecutor
        return EventsExecutor(context=node.context)
    return SingleThreadedExecutor(context=node.context)


def spin_until_shutdown(executor: Executor, context,
                        stop: Optional[threading.Event] = None) -> None:
    """Run callbacks until the context is shut down, or ``stop`` is set and the executor woken
    (an EventsExecutor's ``spin()`` would busy-wait)."""
    while context.ok() and not (stop is not None and stop.is_set()):
        executor.spin_once(timeout_sec=_SPIN_SLICE_S)


def _spin_in_thread(executor: Executor, context, stop: threading.Event) -> None:
    """``spin_until_shutdown`` as a thread's target: a shutdown by a signal (rclpy raises
    ExternalShutdownException, or RCLError in its race) ends the thread quietly."""
    try:
        spin_until_shutdown(executor, context, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _SHUTDOWN_RACE:
        if context.ok():
            raise           # a real failure, not the shutdown race


def _nothing() -> None:
    pass


def wake(executor: Executor) -> None:
    """End a ``spin_once`` that waits in another thread, now. (Jazzy's EventsExecutor.wake()
    does not end a waiting ``spin_once``: a task queued does, so a task that does nothing is
    queued; without it, a run_task's exit waited out the spin slice, up to a second.)"""
    executor.create_task(_nothing)
    executor.wake()


def spin(node: Node, executor: Optional[Executor] = None, events: bool = True,
         stop: Optional[threading.Event] = None) -> None:
    """Spin ``node`` until the context is shut down, by a signal or by the node itself (or
    ``stop`` is set)."""
    if executor is None:
        executor = make_executor(node, events)
    try:
        executor.add_node(node)
        spin_until_shutdown(executor, node.context, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _SHUTDOWN_RACE:
        if node.context.ok():
            raise           # a real failure, not the shutdown race


N = TypeVar('N', bound=Node)


class _Stopped(Exception):
    """Ctrl-C or SIGTERM while the node was being built."""


def _create(factory: Callable[[], N], name: str,
            startup_errors: Tuple[Type[BaseException], ...]) -> Optional[N]:
    """The node, or None after one fatal line for a configuration error (the context is then
    shut down); _Stopped if a stop was asked for while it was being built."""
    try:
        node = factory()
    except ParameterException as exc:
        rclpy.logging.get_logger(name).fatal(f'bad parameter: {exc}')
    except tuple(startup_errors) as exc:
        rclpy.logging.get_logger(name).fatal(f'cannot start: {exc}')
    except (ExternalShutdownException, KeyboardInterrupt):
        if not early_stop.requested():
            raise
        rclpy.try_shutdown()
        raise _Stopped() from None
    except Exception:
        # A stop shuts a task's context down from a thread of its own (run_task): a node
        # being built then fails in whatever rclpy call comes next (Node.__init__ raised
        # NotInitializedException, "rclpy.init() has not been called", 0.92 s into a launch).
        # With the context gone by a stop, that is the stop; anything else is raised.
        for thread in _SHUTTING_DOWN:          # (a stop's shutdown under way)
            thread.join(2.0)
        if not (early_stop.requested() and not rclpy.ok()):
            raise
        rclpy.try_shutdown()
        raise _Stopped() from None
    else:
        if early_stop.requested():
            node.destroy_node()
            rclpy.try_shutdown()
            raise _Stopped()
        return node
    rclpy.try_shutdown()
    return None


def run_node(factory: Callable[[], N], name: str,
             startup_errors: Tuple[Type[BaseException], ...] = (),
             on_exit: Optional[Callable[[N], None]] = None, args=None,
             events: bool = True) -> int:
    """Create the node, spin it until shutdown, and return the process exit code.

    A configuration error raised by ``factory`` (one of ``startup_errors``, or a bad parameter)
    is logged as one fatal line and returns 1. ``on_exit`` runs whatever ended the spin, before
    the node is destroyed (a recorder closes its bag there). ``events=False``: the node has
    coroutine callbacks, and spins on the SingleThreadedExecutor.

    A node may end its own run: it sets ``node.exit_request`` (a ``threading.Event`` it
    creates) and ``node.exit_code``, and the spin ends after the callback (a recorder that
    could not write closes its bag and exits 1).

    SIGINT and SIGTERM (early_stop.py) end the spin between two callbacks, never inside one,
    and the process exits 0. rclpy's handler raised KeyboardInterrupt wherever the main thread
    was: a recorder interrupted inside the mcap library's add_message closed its bag with half a
    message record in the last chunk (rosbags' reader then failed on it: "unpack requires a
    buffer of 22 bytes"), and a simulator interrupted inside a step logged a FATAL line. The
    node's timers bound how long the spin takes to notice (a recorder's: 0.1 s); at most
    ``_SPIN_SLICE_S``.
    """
    keep_large_blocks()     # (ros_common/memory.py: large messages without page faults)
    early_stop.install()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    early_stop.on_stop(stop.set)
    try:
        node = _create(factory, name, startup_errors)
    except _Stopped:
        return 0
    if node is None:
        return 1
    own: Optional[threading.Event] = getattr(node, 'exit_request', None)
    if own is not None:
        early_stop.on_stop(own.set)
        stop = own
    try:
        spin(node, events=events, stop=stop)
    finally:
        if on_exit is not None:
            on_exit(node)
        node.destroy_node()
        rclpy.try_shutdown()
    return int(getattr(node, 'exit_code', 0))


_SHUTTING_DOWN: List[threading.Thread] = []


def _shut_down_soon() -> None:
    """What a stop does to a task's node: rclpy's context shut down (from a thread of its own:
    the signal handler may have interrupted this thread inside the context's lock). run_task
    waits for it before the process ends (a daemon thread inside rclpy at the interpreter's
    finalization can hang it)."""
    thread = threading.Thread(target=rclpy.try_shutdown, daemon=True)
    _SHUTTING_DOWN.append(thread)
    thread.start()


def run_task(factory: Callable[[], N], name: str, task: Callable[[N], int],
             startup_errors: Tuple[Type[BaseException], ...] = (),
             on_exit: Optional[Callable[[N], None]] = None, background_spin: bool = False,
             interrupted_code: int = 0, args=None) -> int:
    """Create the node and run ``task(node)`` to its end: a node that does a job and exits
    with the task's code (a trial's coordinator, a replay, a check).

    Start-up errors as ``run_node``'s (exit code 1). With ``background_spin`` an executor
    spins the node in a thread while the task runs in this one (a task that blocks on what
    its callbacks deliver); otherwise the task spins the node itself. A shutdown by SIGINT or
    SIGTERM ends the task with ``interrupted_code`` (0: stopping is how a replay ends; 1: a
    check or a run that did not finish). ``on_exit`` runs however the task ended, before the
    node is destroyed (a coordinator stops its robots there).
    """
    keep_large_blocks()     # (ros_common/memory.py: large messages without page faults)
    early_stop.install()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    early_stop.on_stop(_shut_down_soon)
    try:
        node = _create(factory, name, startup_errors)
    except _Stopped:
        return interrupted_code
    if node is None:
        return 1
    executor: Optional[Executor] = None
    spinner: Optional[threading.Thread] = None
    stop = threading.Event()
    if background_spin:
        executor = make_executor(node)
        executor.add_node(node)
        spinner = threading.Thread(target=_spin_in_thread,
                                   args=(executor, node.context, stop), daemon=True)
        spinner.start()
    code = interrupted_code
    try:
        code = task(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # Once a stop shut the context down, rclpy's calls fail in many ways (an invalid
        # context or handle, the global executor gone: "'NoneType' object has no attribute
        # 'handle'"): a stop, not a failure. Anything else is raised.
        if node.context.ok() or not early_stop.requested():
            raise
    finally:
        if on_exit is not None:
            on_exit(node)
        if executor is not None and spinner is not None:
            stop.set()
            wake(executor)
            spinner.join(2.0)
            executor.shutdown(timeout_sec=2.0)
        for thread in _SHUTTING_DOWN:
            thread.join(2.0)
        node.destroy_node()
        rclpy.try_shutdown()
    return code
