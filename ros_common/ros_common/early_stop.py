"""Ctrl-C or SIGTERM at any moment of a node's life, its start-up included.

``ros2 launch`` sends SIGINT to every process of a launch on Ctrl-C (SIGTERM 5 s later, then
SIGKILL). A Python node spends its first second importing rclpy, PyBullet and the rest, and
then building itself: a signal in that time ended it with a KeyboardInterrupt traceback, or
killed it (exit -15), or shut rclpy's context down under the node being built ("rcl node's
context is invalid"). Here a signal only records that a stop was asked for, from the moment the
console script starts (``lazy_main``) to the end, and runs what the node registered to stop
(``on_stop``): the spin ends between two callbacks, never inside one.

This module imports nothing heavy: a package's ``__init__`` names its executables with it, and
the console script imports the node's module only once the handler is in place. (The
interpreter's own start, before any of the project's code runs, is not covered: a signal in its
first tenths of a second takes Python's default action.)
"""
from __future__ import annotations

import importlib
import signal
import threading
from typing import Any, Callable, List, Optional

_requested = threading.Event()
_actions: List[Callable[[], None]] = []


def _on_signal(_signum: int, _frame: Any) -> None:
    # The first stop only: a terminal's Ctrl-C reaches a launched node twice (from the
    # terminal, to its process group, and from ros2 launch), and SIGTERM may follow.
    if _requested.is_set():
        return
    _requested.set()
    for action in list(_actions):
        action()


def install() -> None:
    """From now on SIGINT and SIGTERM request a stop instead of ending the process."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _on_signal)


def requested() -> bool:
    """A stop was asked for."""
    return _requested.is_set()


def on_stop(action: Callable[[], None]) -> None:
    """Run ``action`` when a stop is asked for (at once if it was already). It runs in the
    signal handler: it must only set flags, or start a thread."""
    _actions.append(action)
    if _requested.is_set():
        action()


def ignore() -> None:
    """SIGINT and SIGTERM ignored from now on: the process is ending. (Python's finalization
    puts back the default action of a signal it handled, and a second Ctrl-C, or launch's SIGTERM
    after its grace, then killed a node that was tidily on its way out: exit code -2.)"""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)


def reset() -> None:
    """Forget a stop and the actions (a process that runs nodes one after another: tests)."""
    _requested.clear()
    _actions.clear()


def lazy_main(module: str, attr: str = 'main') -> Callable[[Optional[List[str]]], int]:
    """A console script's ``main``: the handler installed first, then ``module`` imported
    and its ``attr`` run (exit code 0 if a stop came while it was imported)."""
    def main(args: Optional[List[str]] = None) -> int:
        install()
        try:
            target = getattr(importlib.import_module(module), attr)
            if _requested.is_set():
                return 0
            return int(target() if args is None else target(args=args))
        finally:
            ignore()
    main.__doc__ = f'{module}.{attr}, with Ctrl-C and SIGTERM handled from the start'
    return main
