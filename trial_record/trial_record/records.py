"""Reading back what was written to disk or carried in a bag, checked: JSON of bounded size and
depth, and typed, ranged fields, each failure one line that names the record and the field.

Every record the study tools read (a trial's result, the trial record a bag keeps, a campaign's
plan) may have been cut by a crash, edited by hand, written by another version or made to
harm: nothing in it is used before it has passed these checks, so that what reads it on
(a report, a plot, a re-run) cannot fail on it, loop on it or write where it should not.
"""
from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence

MAX_RECORD_BYTES = 64 * 1024 * 1024   # a trial's result is 50-300 kB
MAX_TEXT = 10_000                     # characters of a string field
MAX_ITEMS = 1_000_000                 # entries of a list or a mapping
MAX_SIM_TIME_S = 1e5                  # simulated seconds (a day and more; a trial is minutes)
MAX_COUNT = 1_000_000                 # a count of materials, attempts, trips, ...


class RecordError(ValueError):
    """A record that cannot be used; the message is the line to print."""


def read_text(path: Path, what: str, limit: int = MAX_RECORD_BYTES) -> str:
    """A record file's text, read no further than ``limit`` bytes (RecordError: missing, not a
    file, too large, not UTF-8)."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):   # (a FIFO would block the reader)
            raise RecordError(f'{path} is not a regular file: not {what}')
        with open(path, 'rb') as f:
            data = f.read(limit + 1)
    except FileNotFoundError:
        raise RecordError(f'{path} does not exist') from None
    except OSError as exc:
        raise RecordError(f'{path} cannot be read ({exc.strerror or exc})') from None
    if len(data) > limit:
        raise RecordError(f'{path} has more than {limit} bytes: not {what}')
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise RecordError(f'{path} is not UTF-8 text (byte {exc.start}): not {what}') from None


def parse_json(text: str, what: str, limit: int = MAX_RECORD_BYTES) -> Any:
    """JSON of at most ``limit`` characters; nested too deeply or malformed: RecordError."""
    if len(text) > limit:
        raise RecordError(f'{what}: more than {limit} characters')
    try:
        return json.loads(text)
    except RecursionError:
        raise RecordError(f'{what}: nested too deeply') from None
    except ValueError as exc:
        raise RecordError(f'{what}: not JSON ({str(exc)[:80]})') from None


_MISSING: Any = object()
MAX_SHALLOW_LIST = 64                 # a list inside an entry of a record's list


class Fields:
    """Typed, ranged access to a mapping read back: each method returns the value or raises
    RecordError naming ``what`` and the field. A field that is absent takes ``default``;
    without one it is missing (RecordError)."""

    def __init__(self, data: Any, what: str) -> None:
        if not isinstance(data, Mapping):
            raise RecordError(f'{what}: a JSON object was expected, not {_shown(data)}')
        if len(data) > MAX_ITEMS or not all(isinstance(k, str) for k in data):
            raise RecordError(f'{what}: not a record of named fields')
        self.data, self.what = data, what

    def fail(self, key: str, message: str) -> RecordError:
        return RecordError(f'{self.what}: {key} {message}')

    def only(self, allowed: Sequence[str]) -> None:
        """Refuse the fields not in ``allowed`` (a record of another kind or version)."""
        unknown = sorted(k for k in self.data if k not in allowed)
        if unknown:
            shown = ', '.join(repr(k[:40]) for k in unknown[:5])
            raise RecordError(f'{self.what}: unknown fields {shown}')

    def has(self, key: str) -> bool:
        return key in self.data

    def _get(self, key: str, default: Any) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.fail(key, 'is missing')
        return default

    def integer(self, key: str, lo: int, hi: int, default: Any = _MISSING,
                none: bool = False) -> Optional[int]:
        """An integer within lo..hi (``none``: or null)."""
        value = self._get(key, default)
        if value is None and none:
            return None
        if not is_int(value) or not lo <= value <= hi:
            raise self.fail(key, f'is {_shown(value)}, not an integer within {lo}..{hi}')
        return int(value)

    def number(self, key: str, lo: float, hi: float, default: Any = _MISSING,
               nan: bool = False) -> float:
        """A number within lo..hi (``nan``: or NaN, what a record writes for "none")."""
        value = self._get(key, default)
        if not is_number(value) or not (lo <= value <= hi or nan and math.isnan(value)):
            allowed = f'within {lo:g}..{hi:g}' + (' (or NaN)' if nan else '')
            raise self.fail(key, f'is {_shown(value)}, not a number {allowed}')
        return float(value)

    def text(self, key: str, default: Any = _MISSING, limit: int = MAX_TEXT,
             choices: Sequence[str] = ()) -> str:
        value = self._get(key, default)
        if not isinstance(value, str):
            raise self.fail(key, f'is {_shown(value)}, not a string')
        if len(value) > limit:
            raise self.fail(key, f'has {len(value)} characters (at most {limit})')
        if choices and value not in choices:
            raise self.fail(key, f'is {_shown(value)}, none of {", ".join(choices)}')
        return value

    def record(self, key: str, default: Any = _MISSING) -> 'Fields':
        """A mapping nested in this one, as Fields."""
        return Fields(self._get(key, default), f'{self.what}: {key}')

    def items(self, key: str, default: Any = _MISSING, limit: int = MAX_ITEMS) -> List[Any]:
        value = self._get(key, default)
        if not isinstance(value, list):
            raise self.fail(key, f'is {_shown(value)}, not a list')
        if len(value) > limit:
            raise self.fail(key, f'has {len(value)} entries (at most {limit})')
        return value

    def numbers(self, key: str, lo: float, hi: float, default: Any = _MISSING
                ) -> Dict[str, float]:
        """A mapping of names to numbers within lo..hi."""
        fields = self.record(key, default)
        return {name: fields.number(name, lo, hi) for name in fields.data}

    def entries(self, key: str, default: Any = _MISSING) -> List[Dict[str, Any]]:
        """A list of flat mappings (scalars, or short lists of scalars): what a record keeps
        of each material or identification, whose fields only a person reads."""
        out = []
        for k, entry in enumerate(self.items(key, default)):
            if not isinstance(entry, Mapping) or not all(
                    isinstance(name, str) and len(name) <= MAX_TEXT and _flat(value)
                    for name, value in entry.items()):
                raise self.fail(f'{key}[{k}]', 'is not a mapping of plain values')
            out.append(dict(entry))
        return out


def _scalar(value: Any) -> bool:
    return (value is None or isinstance(value, (bool, int, float))
            or isinstance(value, str) and len(value) <= MAX_TEXT)


def _flat(value: Any) -> bool:
    return _scalar(value) or isinstance(value, list) and len(value) <= MAX_SHALLOW_LIST and all(
        _scalar(v) for v in value)


def is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _shown(value: Any) -> str:
    """A value in a message: its type and a short head (a 100,000-deep list is not printed)."""
    if isinstance(value, (dict, list)):
        return f'a {"mapping" if isinstance(value, dict) else "list"} of {len(value)}'
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + '...'
