"""Report on a rosbag2 bag: topics, counts and rates, odometry paths, joint tracking errors.

``bag_analysis BAG [-o DIR]`` writes DIR/report.md, DIR/report.json and one PNG per odometry
topic (default DIR: BAG_report beside the bag).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import ReaderError

from controllers.transforms import yaw_from_quaternion
from recording.plot import plot_paths
from ros_common.outputs import OutputError, check_output_dir

ODOMETRY = 'nav_msgs/msg/Odometry'


class AnalysisError(RuntimeError):
    """A bag that cannot be read; the message says why and what to do."""


@dataclass
class TopicStats:
    topic: str
    msgtype: str
    count: int
    first_s: Optional[float]
    last_s: Optional[float]
    rate_hz: Optional[float]
    bytes: int


@dataclass
class PathStats:
    topic: str
    samples: int
    distance_m: float
    start: List[float]
    end: List[float]
    end_yaw_deg: float
    plot: str = ''


@dataclass
class TrackingStats:
    """Position tracking of one joint on a controller-state topic (reference - feedback)."""

    topic: str
    joint: str
    samples: int
    rms_error: float
    max_abs_error: float


@dataclass
class Report:
    bag: str
    storage: str
    duration_s: float
    message_count: int
    topics: List[TopicStats] = field(default_factory=list)
    paths: List[PathStats] = field(default_factory=list)
    tracking: List[TrackingStats] = field(default_factory=list)
    notes: List[str] = field(default_factory=list)


def open_reader(bag: Path) -> AnyReader:
    bag = Path(bag)
    if not bag.exists():
        raise AnalysisError(f'{bag} does not exist')
    try:
        reader = AnyReader([bag])
        reader.open()
        return reader
    except (AnyReaderError, ReaderError, OSError, ValueError, KeyError, IndexError) as exc:
        hint = ''
        if bag.is_dir() and not (bag / 'metadata.yaml').exists():
            hint = ' (no metadata.yaml: if its recorder was killed, run bag_repair on it)'
        raise AnalysisError(f'{bag} is not a readable rosbag2 bag: {exc}{hint}') from None


def read_messages(reader: AnyReader, bag: Path, connections: Sequence[Any] = ()
                  ) -> Iterator[Tuple[Any, int, Any]]:
    """The reader's messages (connection, time, message) of ``connections`` (all if none),
    deserialized. Whatever the libraries raise on damaged data (rosbags, the mcap and SQLite
    libraries raise many kinds: a zeroed block gave OverflowError, others struct.error,
    KeyError, CorruptError) is an AnalysisError that names the bag: a bag from elsewhere is
    data, and a tool that reads one ends with a line, not a traceback."""
    messages = reader.messages(connections=list(connections)) if connections else \
        reader.messages()
    while True:
        try:
            connection, stamp, raw = next(messages)
            msg = reader.deserialize(raw, connection.msgtype)
        except StopIteration:
            return
        except Exception as exc:
            raise AnalysisError(f'{bag}: unreadable data ({type(exc).__name__}: '
                                f'{str(exc)[:200]}); the bag is truncated or corrupt: '
                                'bag_repair recovers what is intact') from None
        yield connection, stamp, msg


@dataclass
class _Scan:
    """What one pass over a bag's messages gathers, per topic."""
    stamps: Dict[str, List[int]] = field(default_factory=dict)
    sizes: Dict[str, int] = field(default_factory=dict)
    types: Dict[str, str] = field(default_factory=dict)
    paths: Dict[str, List[Any]] = field(default_factory=dict)
    yaws: Dict[str, float] = field(default_factory=dict)
    tracking: Dict[str, Dict[str, List[Any]]] = field(default_factory=dict)


def analyse(bag: Path) -> Tuple['Report', Dict[str, Any]]:
    """Read every message once; returns the Report and the odometry paths (x, y arrays)."""
    reader = open_reader(bag)
    try:
        scan = _scan(reader, bag)
        report = _counts(reader, bag, scan)
        arrays = {t: np.asarray(p, float) for t, p in scan.paths.items()}
        for topic, p in arrays.items():
            report.paths.append(PathStats(
                topic, len(p), float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()),
                p[0].tolist(), p[-1].tolist(), math.degrees(scan.yaws[topic])))
        for topic, joints in sorted(scan.tracking.items()):
            for joint, errors in joints.items():
                e = np.asarray(errors, float)
                report.tracking.append(TrackingStats(
                    topic, joint, len(e), float(np.sqrt(np.mean(e * e))), float(np.abs(e).max())))
        return report, arrays
    finally:
        reader.close()


def _scan(reader: AnyReader, bag: Path) -> _Scan:
    scan = _Scan()
    for c in reader.connections:
        scan.stamps.setdefault(c.topic, [])
        scan.sizes.setdefault(c.topic, 0)
        scan.types[c.topic] = c.msgtype
    try:
        for c, t, raw in reader.messages():
            scan.stamps[c.topic].append(t)
            scan.sizes[c.topic] += len(raw)
            if _is_controller_state(c):
                _add_tracking(reader.deserialize(raw, c.msgtype), scan.tracking.setdefault(
                    c.topic, {}))
            elif c.msgtype == ODOMETRY:
                odometry: Any = reader.deserialize(raw, c.msgtype)    # (nav_msgs/Odometry)
                pose = odometry.pose.pose
                scan.paths.setdefault(c.topic, []).append((pose.position.x, pose.position.y))
                q = pose.orientation
                scan.yaws[c.topic] = yaw_from_quaternion((q.x, q.y, q.z, q.w))
    except Exception as exc:
        raise AnalysisError(f'{bag}: unreadable data ({type(exc).__name__}: {exc}); the '
                            'bag is truncated or corrupt') from None
    return scan


def _counts(reader: AnyReader, bag: Path, scan: _Scan) -> 'Report':
    """The report's counts, span and topics, as the data has them (metadata.yaml may say
    otherwise, edited or copied from another bag: where it does, the report says so)."""
    stamps = scan.stamps
    storage = 'mcap' if list(Path(bag).glob('*.mcap')) else 'sqlite3'
    count = sum(len(ts) for ts in stamps.values())
    firsts = [ts[0] for ts in stamps.values() if ts]
    lasts = [ts[-1] for ts in stamps.values() if ts]
    duration = (max(lasts) - min(firsts)) * 1e-9 if firsts else 0.0
    report = Report(str(bag), storage, duration, count)
    said = reader.message_count
    if said != count:
        report.notes.append(f'metadata.yaml says {said} messages; the bag holds {count}, '
                            'which this report counts')
    said_by_topic = {t: info.msgcount for t, info in reader.topics.items()}
    wrong = [t for t in sorted(stamps) if said_by_topic.get(t, 0) != len(stamps[t])]
    if wrong and said == count:
        report.notes.append(f'metadata.yaml miscounts the messages of {", ".join(wrong)}')
    for topic in sorted(stamps):
        ts = stamps[topic]
        span = (ts[-1] - ts[0]) * 1e-9 if len(ts) > 1 else 0.0
        report.topics.append(TopicStats(
            topic, scan.types[topic], len(ts), ts[0] * 1e-9 if ts else None,
            ts[-1] * 1e-9 if ts else None,
            (len(ts) - 1) / span if span > 0 else None, scan.sizes[topic]))
    return report


def _is_controller_state(connection: Any) -> bool:
    """A joint trajectory controller's state: control_msgs/JointTrajectoryControllerState or any
    type with its fields (joint_names, reference or desired, feedback or actual)."""
    msgdef = connection.msgdef.data
    return ('string[] joint_names' in msgdef
            and ('JointTrajectoryPoint reference' in msgdef
                 or 'JointTrajectoryPoint desired' in msgdef)
            and ('JointTrajectoryPoint feedback' in msgdef
                 or 'JointTrajectoryPoint actual' in msgdef))


def _add_tracking(msg: Any, joints: Dict[str, List[Any]]) -> None:
    reference = getattr(msg, 'reference', None)
    if reference is None or not len(reference.positions):
        reference = getattr(msg, 'desired', None)
    feedback = getattr(msg, 'feedback', None)
    if feedback is None or not len(feedback.positions):
        feedback = getattr(msg, 'actual', None)
    if reference is None or feedback is None:
        return
    n = min(len(msg.joint_names), len(reference.positions), len(feedback.positions))
    for i in range(n):
        joints.setdefault(msg.joint_names[i], []).append(
            float(reference.positions[i]) - float(feedback.positions[i]))


def write_report(bag: Path, out_dir: Path) -> Report:
    report, arrays = analyse(bag)
    out_dir.mkdir(parents=True, exist_ok=True)
    if arrays:
        png = out_dir / 'paths.png'
        plot_paths(arrays, png, f'odometry paths: {Path(bag).name}')
        for p in report.paths:
            p.plot = png.name
    (out_dir / 'report.json').write_text(json.dumps(asdict(report), indent=2))
    (out_dir / 'report.md').write_text(to_markdown(report))
    return report


def to_markdown(report: Report) -> str:
    lines = [f'# Bag report: {report.bag}', '',
             f'{report.storage}, {report.message_count} messages over '
             f'{report.duration_s:.2f} s', '']
    lines += [f'> Note: {note}' for note in report.notes] + ([''] if report.notes else [])
    lines += ['| topic | type | count | rate [Hz] | MB |', '|---|---|---|---|---|']
    for t in report.topics:
        rate = f'{t.rate_hz:.2f}' if t.rate_hz else '-'
        lines.append(f'| {t.topic} | {t.msgtype} | {t.count} | {rate} | '
                     f'{t.bytes / 1e6:.3f} |')
    if report.paths:
        lines += ['', '## Odometry paths', '', '![paths](paths.png)', '',
                  '| topic | samples | distance [m] | start (x, y) | end (x, y) | end yaw [deg] |',
                  '|---|---|---|---|---|---|']
        for p in report.paths:
            lines.append(f'| {p.topic} | {p.samples} | {p.distance_m:.3f} | '
                         f'({p.start[0]:+.3f}, {p.start[1]:+.3f}) | '
                         f'({p.end[0]:+.3f}, {p.end[1]:+.3f}) | {p.end_yaw_deg:+.2f} |')
    if report.tracking:
        lines += ['', '## Joint tracking (reference - feedback position)', '',
                  '| topic | joint | samples | RMS error | max abs error |',
                  '|---|---|---|---|---|']
        for tr in report.tracking:
            lines.append(f'| {tr.topic} | {tr.joint} | {tr.samples} | {tr.rms_error:.6f} | '
                         f'{tr.max_abs_error:.6f} |')
    return '\n'.join(lines) + '\n'


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog='bag_analysis', description=__doc__.splitlines()[0])
    parser.add_argument('bag', type=Path, help='rosbag2 bag directory (mcap or sqlite3)')
    parser.add_argument('-o', '--output', type=Path, help='report directory')
    args = parser.parse_args(argv)
    out = args.output or args.bag.parent / f'{args.bag.name}_report'
    try:
        check_output_dir(out, '-o')                    # (before the bag is read)
        report = write_report(args.bag, out)
    except (AnalysisError, OutputError) as exc:
        print(f'bag_analysis: error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:                             # (a full disk)
        print(f'bag_analysis: error: {exc}', file=sys.stderr)
        return 2
    print(to_markdown(report))
    print(f'bag_analysis: report written to {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
