"""Where the tools that write files (the study tools, bag_analysis) write: checked before any
work starts, and written so that a run that fails leaves nothing half-written (a report's plots
without its report.md, half a PNG).

A directory of outputs is made in a staging directory (in it, or beside a new one) and its
files moved in at the end, the main file last (``report.md``, ``comparison.md``): a reader who
finds the main file finds every file it names. A single file is written beside its name and
renamed over it.

An output directory may hold what someone else put there (a campaign's directory is shared
with a user, who may plant links in it): nothing here follows a link standing where it writes.
A file is written to a new scratch file (``O_EXCL``) and renamed over its name, which replaces
a link there instead of writing through it; a directory that is a link is refused.
"""
from __future__ import annotations

import io
import os
import shutil
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, Iterator, Optional, Sequence

FILE_MODE = 0o644


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
    # (Inside ``out`` when it is there, so that nothing is written outside it.)
    where = out if out.is_dir() else out.parent
    try:
        staging = Path(tempfile.mkdtemp(prefix=f'.{out.name}.partial-', dir=where))
    except OSError as exc:
        raise OutputError(f'{option} {out}: {exc.strerror or exc}') from None
    try:
        yield staging
        if where is not out:
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
    """``data`` into ``path``, whole or not at all; a link standing at ``path`` is replaced,
    not written through."""
    path = Path(path)
    fd, scratch = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            os.fchmod(f.fileno(), FILE_MODE)
            f.write(data)
        os.replace(scratch, path)
    except BaseException:
        Path(scratch).unlink(missing_ok=True)
        raise


def save_figure(figure: Any, path: Path, dpi: int = 110) -> None:
    """A matplotlib figure into ``path`` (its format by the suffix), as ``write_file``."""
    data = io.BytesIO()
    figure.savefig(data, dpi=dpi, format=Path(path).suffix.lstrip('.') or 'png')
    write_file(path, data.getvalue())


def write_text(path: Path, text: str) -> None:
    """``text`` (UTF-8) into ``path``, as ``write_file``."""
    write_file(path, text.encode('utf-8'))


def open_new(path: Path) -> IO[str]:
    """``path`` as a new, empty text file to write (a log): what stood there (a file, or a
    link, which is not followed) is removed first."""
    path = Path(path)
    if path.is_symlink() or path.exists():
        if path.is_dir() and not path.is_symlink():
            raise IsADirectoryError(21, 'Is a directory', str(path))
        path.unlink()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, FILE_MODE)
    return os.fdopen(fd, 'w')


def inner_dir(path: Path, what: str) -> Path:
    """The directory ``path`` (made if need be, its parent must be there): a link or a file
    standing at its name is refused (OutputError), so that what is written in it stays in
    its parent."""
    path = Path(path)
    try:
        os.mkdir(path)
    except FileExistsError:
        pass
    except OSError as exc:
        raise OutputError(f'{what} {path}: {exc.strerror or exc}') from None
    mode = os.lstat(path).st_mode
    if stat.S_ISLNK(mode):
        raise OutputError(f'{what} {path} is a symbolic link: it would write where the link '
                          'points; remove it')
    if not stat.S_ISDIR(mode):
        raise OutputError(f'{what} {path} exists and is not a directory')
    return path


def open_lock(path: Path, what: str) -> IO[str]:
    """``path`` opened to read and write, made if need be, as a lock file: a link there is
    not followed, and a file that is not a plain file of its own (a hard link to another)
    is refused (OutputError)."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, FILE_MODE)
    except OSError as exc:
        why = ('is a symbolic link' if Path(path).is_symlink()
               else f'cannot be written ({exc.strerror or exc})')
        raise OutputError(f'{what} {path} {why}') from None
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode) or info.st_nlink != 1:
        os.close(fd)
        raise OutputError(f'{what} {path} is not a plain file of its own (a hard link, or '
                          'a device): remove it')
    return os.fdopen(fd, 'r+')
