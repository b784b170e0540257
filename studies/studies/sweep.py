"""Sweeps: a campaign over the points of one parameter or a grid of two, each point a world
with its values set, run with the same scenario seeds at every point (so that two points differ
by the parameter, not by their draws); and what the points' trials say: each rate with its
Wilson interval, the completion time, and where the cell starts to fail.

A parameter is ``belt_speed`` (the trial's belt speed, m/s) or any number of the world file,
named by its path: ``perturbations.camera.pixel_noise``, ``materials.mass``,
``conveyor.length``."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import yaml

from ros_common.outputs import write_text
from trial_record.result import TrialResult
from world_description.resources import resolve_resource
from world_description.world_config import WorldConfigError, load_world

MAX_POINTS = 400
TRIAL_PARAMETERS = ('belt_speed',)            # set on the trial, not in its world
_NAME = re.compile(r'^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$')
WORLD_FILE = 'world.yaml'                      # a trial's own world, in its directory


class SweepError(ValueError):
    """A sweep that cannot be run; the message is the line to print."""


@dataclass(frozen=True)
class Axis:
    name: str
    values: Tuple[float, ...]


def parse_axis(spec: str) -> Axis:
    """``name=start:stop:step`` (stop included; ``start:stop`` steps by 1) or
    ``name=v1,v2,...``."""
    name, sep, values = spec.partition('=')
    name = name.strip()
    if not sep or not _NAME.match(name):
        raise SweepError(f'--sweep {spec!r}: give NAME=START:STOP:STEP or NAME=V1,V2,... '
                         '(NAME: belt_speed or a number of the world file, such as '
                         'perturbations.camera.pixel_noise)')
    try:
        if ':' in values:
            parts = values.split(':')
            # (START:STOP counts in ones: a fleet's size, a count of materials.)
            start, stop, step = (float(v) for v in (parts if len(parts) != 2 else parts + ['1']))
            if not (all(math.isfinite(v) for v in (start, stop, step)) and step > 0.0
                    and stop >= start):
                raise ValueError
            # (Counted before any point is made: 0:1e12:1 made a trillion of them.)
            span = (stop - start) / step
            if not math.isfinite(span) or span + 1 > MAX_POINTS:
                raise SweepError(f'--sweep {spec!r}: more than {MAX_POINTS} values')
            count = int(math.floor(span + 1e-9)) + 1
            points = tuple(round(start + k * step, 10) for k in range(count))
        else:
            items = values.split(',')
            if len(items) > MAX_POINTS:
                raise SweepError(f'--sweep {spec!r}: {len(items)} values (1..{MAX_POINTS})')
            points = tuple(float(v) for v in items)
            if not all(math.isfinite(v) for v in points):
                raise ValueError
    except SweepError:
        raise
    except (ValueError, OverflowError):
        raise SweepError(f'--sweep {spec!r}: the values must be finite numbers, START <= STOP '
                         'and STEP > 0') from None
    if not 1 <= len(points) <= MAX_POINTS:
        raise SweepError(f'--sweep {spec!r}: {len(points)} values (1..{MAX_POINTS})')
    return Axis(name, points)


def check_names(names: Sequence[str], what: str) -> None:
    """Parameters that can be set together: no name twice, and none inside another (``conveyor``
    and ``conveyor.length``: the first would replace what holds the second); SweepError
    naming ``what`` otherwise."""
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if a == b:
                raise SweepError(f'{what} name {a} twice')
            inner, outer = (a, b) if a.startswith(b + '.') else (b, a)
            if inner.startswith(outer + '.'):
                raise SweepError(f'{what} name {outer} and {inner}, which is a part of it: '
                                 'give one of them')


def grid(axes: Sequence[Axis]) -> List[Dict[str, float]]:
    """The points of one axis, or of two as a grid (the first axis the outer one)."""
    if not 1 <= len(axes) <= 2:
        raise SweepError(f'a sweep has one or two parameters, got {len(axes)}')
    check_names([a.name for a in axes], '--sweep')
    count = math.prod(len(a.values) for a in axes)
    if count > MAX_POINTS:
        raise SweepError(f'the grid has {count} points (at most {MAX_POINTS})')
    points: List[Dict[str, float]] = [{}]
    for axis in axes:
        points = [{**p, axis.name: v} for p in points for v in axis.values]
    if len(points) > MAX_POINTS:
        raise SweepError(f'the grid has {len(points)} points (at most {MAX_POINTS})')
    return points


def world_overrides(point: Dict[str, float]) -> Dict[str, Any]:
    """A point's world-file parameters as the nested mapping a world file gives them."""
    check_names(list(point), 'the point')
    out: Dict[str, Any] = {}
    for name, value in point.items():
        if name in TRIAL_PARAMETERS:
            continue
        *path, leaf = name.split('.')
        node = out
        for key in path:
            node = node.setdefault(key, {})
        node[leaf] = value
    return out


def point_world(base: str, point: Dict[str, float], directory: Path) -> str:
    """The world a trial at ``point`` runs in: ``base`` itself when the point sets only trial
    parameters, else a file in ``directory`` that extends it with the point's values (where a
    trial keeps its world as it ran). Raises SweepError when the result is no valid world."""
    overrides = world_overrides(point)
    if not overrides:
        return base
    try:
        base_path = resolve_resource(base)
    except (FileNotFoundError, ValueError) as exc:
        raise SweepError(f'world {base}: {exc}') from None
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / WORLD_FILE
    text = (f'# {base} with a sweep point\'s values\n'
            + yaml.safe_dump({'extends': str(base_path), **overrides}, sort_keys=False))
    write_text(path, text)
    try:
        load_world(path)
    except WorldConfigError as exc:
        why = str(exc).replace(f'{path}: ', '')
        raise SweepError(f'the sweep point {point} gives no valid world: {why}') from None
    return str(path)


def check_world_parameters(base: str, points: Sequence[Dict[str, float]],
                           scratch: Path) -> None:
    """Every point's world loads (SweepError naming the first that does not), and each world
    parameter names a number the base world file has or takes."""
    for point in points:
        point_world(base, point, scratch)


def wilson(successes: float, n: float, z: float = 1.96) -> Tuple[float, float]:
    """The Wilson score interval of a proportion (95 % by default); (nan, nan) for n = 0."""
    if n <= 0:
        return math.nan, math.nan
    p = min(1.0, max(0.0, successes / n))
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    # (The interval holds p; at p = 1, centre + half is 1 - 1e-16 in floating point.)
    return max(0.0, min(p, centre - half)), min(1.0, max(p, centre + half))


# The rates a sweep reports: a result's (successes, trials) of each, summed over a point.
RATES: Dict[str, Callable[[TrialResult], Tuple[int, int]]] = {
    'identification': lambda r: (r.identified_correct, r.total),
    'grasp': lambda r: (r.grasp_successes, r.grasp_attempts),
    'handling': lambda r: (r.handled_verified, r.total),
}


@dataclass(frozen=True)
class PointSummary:
    point: Tuple[Tuple[str, float], ...]
    trials: int
    completed: int
    rates: Dict[str, Tuple[float, float, float]]     # name: (rate, low, high)
    median_time: float                               # completed trials' [s]; nan: none


def summarise(results: Sequence[TrialResult]) -> List[PointSummary]:
    """Each point's trials (by their ``parameters``), in the order of their values."""
    by_point: Dict[Tuple[Tuple[str, float], ...], List[TrialResult]] = {}
    for r in results:
        if r.parameters and r.ran:
            by_point.setdefault(tuple(sorted(r.parameters.items())), []).append(r)
    out = []
    for point in sorted(by_point):
        rs = by_point[point]
        rates = {}
        for name, counts in RATES.items():
            s = sum(counts(r)[0] for r in rs)
            n = sum(counts(r)[1] for r in rs)
            rates[name] = ((s / n if n else math.nan), *wilson(s, n))
        times = sorted(r.completion_time for r in rs
                       if r.status == 'completed' and math.isfinite(r.completion_time))
        median = (times[len(times) // 2] if len(times) % 2 else
                  (times[len(times) // 2 - 1] + times[len(times) // 2]) / 2) if times else math.nan
        out.append(PointSummary(point, len(rs), sum(r.status == 'completed' for r in rs),
                                rates, median))
    return out


def breaking_point(rows: Sequence[PointSummary], rate: str, threshold: float
                   ) -> Optional[Tuple[Tuple[str, float], ...]]:
    """The first point (in the sweep's order) whose ``rate`` is below ``threshold``; None if
    none is."""
    for row in rows:
        value = row.rates[rate][0]
        if math.isfinite(value) and value < threshold:
            return row.point
    return None
