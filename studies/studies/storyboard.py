"""A recorded trial's storyboard, like the pipeline paper's Figure 8: the cell seen from an
overview camera at its phases (start, first grasp, first load, the first material placed, the
youBot's departure, loading over, the first material unloaded, both robots home; and the first
trouble, a missed grasp or a stall, if any), one PNG.

``storyboard RUN [-o PNG]``: RUN is a recorded trial (its directory, its result.json, or a run
directory with one trial, as ``make demo`` leaves it). The phases' times come from the bag's
``/coordinator_node/events``; at each, the arms' joint states, the mobile bases' odometry and
the materials' ground truth (``/cell/materials``) recorded last before it pose a fresh PyBullet
world built from the world the trial ran in (its result keeps it), which the CPU renderer draws.
The world's perturbations are drawn again from the trial's seed, so that a robot is shown where
it was, not where its encoders or its odometry said it was.
"""
from __future__ import annotations

import argparse
import bisect
import math
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import cv2
import numpy as np
import pybullet

from recording.analysis import AnalysisError, open_reader, read_messages
from ros_common.outputs import OutputError, check_output_file, make_dir, write_file
from sim_bridge.world import SimWorld, WorldError
from studies.recorded import RecordError, is_bag, load_trial, trial_bag
from trial_record.result import TrialResult
from world_description.footprint import footprints
from world_description.robot_files import check_robot_files
from world_description.world_config import WorldConfig, WorldConfigError, parse_world

EVENTS_TOPIC = '/coordinator_node/events'
MATERIALS_TOPIC = '/cell/materials'
# The phases: (caption, the event kind whose first occurrence is the phase; '' for the run's
# first event). "{color}" takes the event's material colour.
PHASES: Tuple[Tuple[str, str], ...] = (
    ('start', ''), ('first grasp', 'picked'), ('first load', 'loaded'),
    ('{color} placed', 'placed'), ('youBot departs', 'departing'),
    ('loading over', 'loading_over'), ('first unloaded', 'delivered'),
    ('both home', 'finished'))
# What went wrong first, shown as a phase of its own (coordinator.pipeline.EventKind): where a
# perturbed cell starts to fail, the picture shows how.
TROUBLE = ('grasp_missed', 'grasp_failed', 'missed', 'failed', 'ik_failed', 'arm_stalled',
           'drive_stalled')
PANEL = (480, 360)                 # each phase's picture [px]
CAPTION = 46                       # the caption's band above it [px]
FONT = cv2.FONT_HERSHEY_SIMPLEX
# A state recorded at most this long after a phase's event still shows it [s]: an event and
# the states of the same control tick carry the same stamp, give or take rounding.
STAMP_SLACK = 1e-3


class StoryboardError(RuntimeError):
    """A run that cannot be drawn; the message says why."""


@dataclass(frozen=True)
class Event:
    time: float                    # simulated time [s], the bag's clock
    kind: str
    color: str
    detail: str


@dataclass(frozen=True)
class Phase:
    caption: str
    time: float                    # simulated time [s]
    since_start: float             # since the run's first event [s]
    detail: str


def phases(events: Sequence[Event]) -> List[Phase]:
    """The storyboard's phases found in a run's events (in time order): each phase at the first
    event of its kind, and the first trouble (a missed grasp, a stall, ...) if there was any; a
    kind that never happened (a cell with no transport, a run stopped early) gives no phase."""
    if not events:
        return []
    ordered = sorted(events, key=lambda e: e.time)
    t0 = ordered[0].time
    out = []
    for caption, kind in PHASES:
        e = ordered[0] if not kind else next((e for e in ordered if e.kind == kind), None)
        if e is None:
            continue
        out.append(Phase(caption.format(color=e.color or 'material'), e.time, e.time - t0,
                         e.detail if kind else ''))
    trouble = next((e for e in ordered if e.kind in TROUBLE), None)
    if trouble is not None:
        out.append(Phase(f'first trouble: {trouble.kind.replace("_", " ")}'
                         + (f' ({trouble.color})' if trouble.color else ''), trouble.time,
                         trouble.time - t0, trouble.detail))
    return sorted(out, key=lambda p: p.time)


@dataclass
class Material:
    key: Tuple[str, int]           # (colour, index): the marker's namespace and id
    position: Tuple[float, float, float]
    orientation: Tuple[float, float, float, float]
    size: Tuple[float, float, float]
    rgba: Tuple[float, float, float, float]


@dataclass
class Recording:
    """What a bag says the cell looked like: every recorded state, by its stamp [s]."""
    events: List[Event] = field(default_factory=list)
    # robot name: [(stamp, (joint names, positions))]
    joints: Dict[str, List[Tuple[float, Tuple[List[str], List[float]]]]] = field(
        default_factory=dict)
    # robot name: [(stamp, (position, orientation))] in its odom frame
    odometry: Dict[str, List[Tuple[float, Tuple[Tuple[float, ...], Tuple[float, ...]]]]] = (
        field(default_factory=dict))
    materials: List[Tuple[float, List[Material]]] = field(default_factory=list)

    @staticmethod
    def at(series: Sequence[Tuple[float, Any]], time: float) -> Any:
        """The last state recorded at or before ``time`` (the first one before any)."""
        if not series:
            return None
        i = bisect.bisect_right([s for s, _ in series], time + STAMP_SLACK)
        return series[max(0, i - 1)][1]


def _stamp(header: Any) -> float:
    return float(header.stamp.sec) + 1e-9 * float(header.stamp.nanosec)


def _topic(namespace: str, name: str) -> str:
    return f'/{namespace}/{name}' if namespace else f'/{name}'


def read_recording(bag: Path, world: WorldConfig) -> Recording:
    """One pass over a trial's bag: the events, and the states that pose the cell."""
    by_topic: Dict[str, Tuple[str, str]] = {EVENTS_TOPIC: ('events', ''),
                                            MATERIALS_TOPIC: ('materials', '')}
    for robot in world.robots:
        by_topic[_topic(robot.namespace, 'joint_states')] = ('joints', robot.name)
        if robot.drive is not None:
            by_topic[_topic(robot.namespace, 'odom')] = ('odometry', robot.name)
    out = Recording()
    reader = open_reader(bag)
    try:
        connections = [c for c in reader.connections if c.topic in by_topic]
        if not any(c.topic == EVENTS_TOPIC for c in connections):
            raise StoryboardError(f'{bag}: no {EVENTS_TOPIC} recorded (the phases come from '
                                  'the coordinator\'s events)')
        for connection, _, msg in read_messages(reader, bag, connections):
            what, name = by_topic[connection.topic]
            _take(out, what, name, msg)
    finally:
        reader.close()
    return out


def _take(out: Recording, what: str, robot: str, msg: Any) -> None:
    if what == 'events':
        out.events.append(Event(_stamp(msg.header), msg.kind, msg.color, msg.detail))
    elif what == 'joints':
        out.joints.setdefault(robot, []).append(
            (_stamp(msg.header), (list(msg.name), [float(v) for v in msg.position])))
    elif what == 'odometry':
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        out.odometry.setdefault(robot, []).append(
            (_stamp(msg.header), ((p.x, p.y, p.z), (o.x, o.y, o.z, o.w))))
    elif msg.markers:
        # (ADD markers with a finite pose: a material whose pose is not finite is left out.)
        markers = [m for m in msg.markers if m.action == 0 and all(math.isfinite(v) for v in (
            m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.w))]
        out.materials.append((_stamp(msg.markers[0].header), [Material(
            (m.ns, int(m.id)), (m.pose.position.x, m.pose.position.y, m.pose.position.z),
            (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
             m.pose.orientation.w), (m.scale.x, m.scale.y, m.scale.z),
            (m.color.r, m.color.g, m.color.b, m.color.a)) for m in markers]))


class Stage:
    """A fresh world of the trial's cell, posed at recorded moments and drawn from above."""

    def __init__(self, world: WorldConfig, seed: Optional[int], time_step: float) -> None:
        # No materials from the world: the recorded ones are shown where they were.
        self.world = SimWorld(_without_materials(world), time_step, scenario_seed=seed)
        self._materials: Dict[Tuple[str, int], int] = {}
        self.view, self.projection = overview_camera(world, PANEL)

    def pose(self, recording: Recording, time: float) -> None:
        for name, robot in self.world.robots.items():
            joints = Recording.at(recording.joints.get(name, []), time)
            if joints is not None:
                robot.sensors.pose_as_reported(*joints)
            odom = Recording.at(recording.odometry.get(name, []), time)
            if odom is not None:
                robot.sensors.place_as_reported(*odom)
        shown = Recording.at(recording.materials, time) or []
        p = self.world.client
        for m in shown:
            body = self._materials.get(m.key)
            if body is None:
                shape = p.createVisualShape(pybullet.GEOM_BOX,
                                            halfExtents=[s / 2 for s in m.size], rgbaColor=m.rgba)
                body = self._materials[m.key] = p.createMultiBody(0.0, -1, shape)
            p.resetBasePositionAndOrientation(body, m.position, m.orientation)
        for key, body in self._materials.items():
            if key not in {m.key for m in shown}:            # not there yet, or gone
                p.resetBasePositionAndOrientation(body, (0.0, 0.0, -10.0), (0, 0, 0, 1))

    def draw(self) -> np.ndarray:
        """The cell now from the overview camera: an RGB image (height x width x 3)."""
        w, h = PANEL
        _, _, rgba, _, _ = self.world.client.getCameraImage(
            w, h, self.view, self.projection, shadow=1, lightDirection=(2.0, -1.0, 4.0),
            renderer=pybullet.ER_TINY_RENDERER, flags=pybullet.ER_NO_SEGMENTATION_MASK)
        return np.asarray(rgba, np.uint8).reshape(h, w, 4)[:, :, :3]

    def close(self) -> None:
        self.world.close()


def _without_materials(world: WorldConfig) -> WorldConfig:
    return replace(world, materials=None)


def overview_camera(world: WorldConfig, size: Tuple[int, int], fov: float = 40.0,
                    elevation: float = 65.0) -> Tuple[Tuple[float, ...], Tuple[float, ...]]:
    """View and projection matrices (PyBullet's) of a camera that sees the whole cell from
    above at ``elevation`` degrees, from the side of its longer extent: every footprint and
    everything on them up to half a metre high in the picture."""
    outlines = [f.outline for f in footprints(world)] or [np.zeros((1, 2))]
    xy = np.vstack(outlines)
    lo, hi = xy.min(axis=0) - 0.1, xy.max(axis=0) + 0.1
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.1])
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (0.0, 0.5)])
    # Looking across the longer side: from -y when the cell is wider in x, else from +x.
    across = np.array([0.0, -1.0]) if hi[0] - lo[0] >= hi[1] - lo[1] else np.array([1.0, 0.0])
    el = math.radians(elevation)
    direction = np.array([across[0] * math.cos(el), across[1] * math.cos(el), math.sin(el)])
    aspect = size[0] / size[1]
    projection = pybullet.computeProjectionMatrixFOV(fov, aspect, 0.05, 50.0)
    distance = 1.0
    for _ in range(200):            # back away until every corner is in the picture
        eye = centre + distance * direction
        view = pybullet.computeViewMatrix(eye.tolist(), centre.tolist(), [0.0, 0.0, 1.0])
        if _inside(corners, view, projection, 0.95):
            break
        distance *= 1.03
    return tuple(view), tuple(projection)


def _inside(points: np.ndarray, view: Sequence[float], projection: Sequence[float],
            margin: float) -> bool:
    """Whether every point projects within ``margin`` of the picture's edges (NDC)."""
    v = np.asarray(view, float).reshape(4, 4).T          # (PyBullet's matrices: column-major)
    p = np.asarray(projection, float).reshape(4, 4).T
    h = np.column_stack((points, np.ones(len(points)))) @ (p @ v).T
    if np.any(h[:, 3] <= 0.0):
        return False
    ndc = h[:, :2] / h[:, 3:4]
    return bool(np.all(np.abs(ndc) <= margin))


def storyboard(recording: Recording, world: WorldConfig, seed: Optional[int],
               time_step: float, title: str) -> np.ndarray:
    """The storyboard's image (BGR): one picture per phase, four or five to a row, captioned."""
    found = phases(recording.events)
    if not found:
        raise StoryboardError('the recording has no events: nothing to show')
    try:
        stage = Stage(world, seed, time_step)
    except (WorldError, pybullet.error) as exc:
        raise StoryboardError(f'cannot build the cell again: {exc}') from None
    try:
        panels = []
        for i, phase in enumerate(found):
            stage.pose(recording, phase.time)
            panels.append(_caption(cv2.cvtColor(stage.draw(), cv2.COLOR_RGB2BGR), i + 1, phase))
    finally:
        stage.close()
    return _grid(panels, title)


def _caption(img: np.ndarray, number: int, phase: Phase) -> np.ndarray:
    band = np.full((CAPTION, img.shape[1], 3), 255, np.uint8)
    cv2.putText(band, f'{number}. {phase.caption}  (t = {phase.since_start:.1f} s)', (8, 20),
                FONT, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    if phase.detail:
        cv2.putText(band, phase.detail[:60], (8, 40), FONT, 0.45, (90, 90, 90), 1, cv2.LINE_AA)
    return np.vstack((band, img))


def _grid(panels: Sequence[np.ndarray], title: str) -> np.ndarray:
    h, w = panels[0].shape[:2]
    columns = 5 if len(panels) > 8 else 4         # (two rows for the phases and a trouble)
    rows = -(-len(panels) // columns)
    cols = min(columns, len(panels))
    out = np.full((40 + rows * (h + 6), cols * (w + 6), 3), 255, np.uint8)
    cv2.putText(out, title, (8, 27), FONT, 0.7, (0, 0, 0), 1, cv2.LINE_AA)
    for i, panel in enumerate(panels):
        y, x = 40 + (i // columns) * (h + 6), (i % columns) * (w + 6)
        out[y:y + h, x:x + w] = panel
    return out


@dataclass(frozen=True)
class RecordedTrial:
    result: TrialResult
    source: Path                   # its result file
    bag: Path
    world: WorldConfig


def recorded_trial(run: Path) -> RecordedTrial:
    """A recorded trial's result, bag and world (StoryboardError saying what is missing)."""
    try:
        result, source = load_trial(run)
    except RecordError as exc:
        raise StoryboardError(str(exc)) from None
    bag = source if is_bag(source) else trial_bag(source.parent)
    if bag is None:
        raise StoryboardError(f'{source.parent}: no bag (record the trial: run_trials '
                              '--record, or make demo)')
    data = result.scenario.get('world_data')
    if not isinstance(data, dict):
        raise StoryboardError(f'{source}: the result does not keep the world it ran in '
                              '(results before the re-run feature)')
    try:
        world = parse_world(data, str(source))
        check_robot_files(world)            # (the robots' files, before the cell is built)
    except WorldConfigError as exc:
        raise StoryboardError(f'{source}: its world: {exc}') from None
    return RecordedTrial(result, source, bag, world)


def write_storyboard(run: Path, out: Optional[Path] = None) -> Path:
    """Draw a recorded trial's storyboard into ``out`` (default: storyboard.png in its
    directory); the file written, whole (StoryboardError, and nothing written, otherwise)."""
    if out is not None:
        _check_out(out)                      # (before any work)
    trial = recorded_trial(run)
    try:
        recording = read_recording(trial.bag, trial.world)
    except AnalysisError as exc:
        raise StoryboardError(str(exc)) from None
    r = trial.result
    title = (f'Trial {r.trial} (seed {r.scenario_seed}, belt {r.belt_speed:.3f} m/s): '
             f'{r.status}' + (f' in {r.completion_time:.1f} s' if
                              math.isfinite(r.completion_time) else ''))
    img = storyboard(recording, trial.world, r.scenario_seed,
                     float(r.scenario.get('time_step') or 1.0 / 240.0), title)
    # (Beside a bag given alone, not in it.)
    path = out or (trial.source.parent / f'{trial.source.name}_storyboard.png'
                   if is_bag(trial.source) else trial.source.parent / 'storyboard.png')
    _check_out(path)
    ok, png = cv2.imencode('.png', img)
    if not ok:
        raise StoryboardError(f'cannot encode the picture for {path}')
    try:
        make_dir(path.parent, '-o')
        write_file(path, png.tobytes())
    except (OutputError, OSError) as exc:
        raise StoryboardError(f'cannot write {path}: {exc}') from None
    return path


def _check_out(path: Path) -> None:
    try:
        check_output_file(path, '-o', ('.png',))
    except OutputError as exc:
        raise StoryboardError(str(exc)) from None


def main(args: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog='storyboard', description=__doc__.split('\n\n')[0])
    parser.add_argument('run', type=Path, help='a recorded trial: its directory, its '
                        'result.json, a run directory with one trial, or its bag')
    parser.add_argument('-o', '--out', type=Path, help='the PNG (default: storyboard.png in '
                        'the trial\'s directory; BAG_storyboard.png beside a bag)')
    options = parser.parse_args(args)
    try:
        path = write_storyboard(options.run, options.out)
    except StoryboardError as exc:
        print(f'storyboard: {exc}', file=sys.stderr)
        return 2
    print(f'storyboard: {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
