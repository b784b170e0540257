"""A scratch directory that a process owns for its life and that outlives no process: removed
when it is closed, and removed by the next process that makes one after its owner died without
closing it (SIGKILL, a crash).

Ownership is an advisory lock (``flock``) on a file inside the directory, held while the owner
runs: the kernel lets it go however the process ends, so a directory whose lock can be taken is
a dead run's. (A process id would not do: ids are reused.)
"""
from __future__ import annotations

import fcntl
import os
import shutil
import tempfile
from pathlib import Path
from typing import IO, List, Optional

LOCK_NAME = '.owner.lock'


class ScratchDir:
    """A new directory ``<tmp>/<prefix><random>``; ``path`` while open."""

    def __init__(self, prefix: str, parent: Optional[Path] = None) -> None:
        self.removed_stale = remove_stale(prefix, parent)
        self.path = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
        # Locked before it takes its name: another process's remove_stale never finds the
        # lock file free while this one runs.
        self._lock: Optional[IO[str]] = open(self.path / (LOCK_NAME + '.new'), 'w')
        fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        self._lock.write(f'pid {os.getpid()}\n')
        self._lock.flush()
        os.rename(self.path / (LOCK_NAME + '.new'), self.path / LOCK_NAME)

    def close(self) -> None:
        """Remove the directory and everything in it (again: nothing)."""
        if self._lock is None:
            return
        shutil.rmtree(self.path, ignore_errors=True)
        self._lock.close()
        self._lock = None


def remove_stale(prefix: str, parent: Optional[Path] = None) -> List[Path]:
    """Remove the scratch directories of ``prefix`` whose owner is gone; those removed."""
    root = Path(parent or tempfile.gettempdir())
    removed: List[Path] = []
    try:
        candidates = [p for p in root.iterdir() if p.name.startswith(prefix)]
    except OSError:
        return removed
    for path in candidates:
        try:
            # (Never created here: a directory without its lock file is left alone.)
            handle = open(os.open(path / LOCK_NAME, os.O_RDWR), 'r+')
        except OSError:
            continue            # not one of ours, or not ours to remove
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()      # its owner runs
            continue
        shutil.rmtree(path, ignore_errors=True)
        handle.close()
        removed.append(path)
    return removed
