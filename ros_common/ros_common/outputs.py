"""Where the tools that write files (the study tools, bag_analysis) write: checked before any
work starts, and written so that a run that fails leaves nothing half-written (a report's plots
without its report.md, half a PNG).

A directory of outputs is made in a staging directory beside it and its files moved in at the
end, the main file last (``report.md``, ``comparison.md``): a reader who finds the main file
finds every file it names. A single file is written beside its name and renamed over it.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Optional, Sequence


class OutputError(ValueError):
    """An output path that cannot be written; the message is the line to print."""


def _first_existing(path: Path) -> Path:
    for candidate in (path, *path.parents):
        if candidate.exists() or candidate.is_symlink():
            return candidate
    return Path('.')


def check_output_dir(path: Path, option: str) -> None:
    """``path`` is a directory, or one that can be made where nothing stands in its way
    (OutputError naming ``option``)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f'{option} {path}: exists and is not a directory')
    existing = _first_existing(path)
    if not existing.is_dir():
        raise OutputError(f'{option} {path}: {existing} is not a directory')
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f'{option} {path}: {existing} cannot be written')


def check_output_file(path: Path, option: str, suffixes: Sequence[str]) -> None:
    """``path`` names a file of one of ``suffixes`` that can be written (OutputError)."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f'{option} {path}: a directory; name the file ({suffixes[0]})')
    if path.suffix.lower() not in suffixes:
        raise OutputError(f'{option} {path}: the file\'s name must end in '
                          f'{" or ".join(suffixes)}')
    if path.exists() and not path.is_file():
        raise OutputError(f'{option} {path}: exists and is not a regular file')
    check_output_dir(path.parent, option)


def make_dir(path: Path, option: str) -> Path:
    """The directory ``path``, made if need be (OutputError if it cannot be)."""
    check_output_dir(path, option)
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f'{option} {path}: {exc.strerror or exc}') from None
    return Path(path)


@contextmanager
def staged_dir(out: Path, option: str, last: Optional[str] = None) -> Iterator[Path]:
    """A directory to write ``out``'s files into; they move into ``out`` only when the block
    ends without an exception (``last``, the main file, moved after the others). A failure
    leaves ``out`` as it was."""
    out = Path(out)
    make_dir(out.parent, option)
    check_output_dir(out, option)
    try:
        staging = Path(tempfile.mkdtemp(prefix=f'.{out.name}.partial-', dir=out.parent))
    except OSError as exc:
        raise OutputError(f'{option} {out}: {exc.strerror or exc}') from None
    try:
        yield staging
        out.mkdir(parents=True, exist_ok=True)
        names = sorted(p.name for p in staging.iterdir())
        if last in names:
            names.remove(last)
            names.append(last)
        for name in names:
            os.replace(staging / name, out / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def write_file(path: Path, data: bytes) -> None:
    """``data`` into ``path``, whole or not at all."""
    path = Path(path)
    scratch = path.with_name(f'.{path.name}.partial')
    try:
        scratch.write_bytes(data)
        os.replace(scratch, path)
    finally:
        scratch.unlink(missing_ok=True)
