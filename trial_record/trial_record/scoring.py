"""Scoring a run as the paper's Table 2 does, checked against the simulator's ground truth.

The coordinator acts on what its sensors tell it; the score does not trust that. At the end of
a run, every material's true resting place (``/cell/materials``) is checked against its
destination, and every identification against the true colour of the material it was made on.

Definitions (docs/pipeline.md repeats them):
- identification rate: materials whose vision track carried their true colour / materials in
  the batch;
- grasp success rate: successful grasps / grasp attempts, both arms (first-attempt and retried);
- handling success rate: materials resting at their destination at the end / materials in the
  batch (each class's destination by the world's rules: resting on the region's top face, not
  on another material);
- split as the paper's columns, by role: the loader's grasp rate (its picks; the paper's
  Zu 12) and the transports' grasp rate (their unloads; its youBot), and each robot's; the
  transport rate: materials loaded onto a plate that rest at their destination / materials
  loaded onto a plate;
- completion time: simulated seconds from the start until both robots are back at their start
  poses (or the run ended).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Dict, FrozenSet, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from cell_layout.layout import CellLayout
from cell_layout.world_layout import layout_from_world
from controllers.arrays import Vector
from trial_record.events import Event, EventKind, RunResult
from trial_record.result import MAX_DRIVEN_PAST, TrialResult

TruePose = Tuple[str, np.ndarray]            # (true colour, centre position)


@dataclass(frozen=True)
class Destinations:
    """Where each class's materials belong, by the world's rules: per class, the box its centre
    lies in when it rests on its destination's top face (x_min, x_max, y_min, y_max, z_min,
    z_max; not on another material, whose centre lies a size higher); and the carried
    classes (the youBot's transport rate counts them)."""
    boxes: Dict[str, Tuple[float, ...]]
    carried: FrozenSet[str]
    places: Dict[str, str]                    # per class: its destination's name


def destinations(layout: CellLayout) -> Destinations:
    return Destinations(
        {c: layout.region_of(c).box(layout.size_of(c)) for c in layout.rules},
        frozenset(c for c in layout.rules if layout.carried(c)),
        {c: layout.destination(c) for c in layout.rules})


def regions_from_world(world: Any) -> Destinations:
    """The destinations of a loaded world's classes."""
    return destinations(layout_from_world(world))


def at_destination(color: str, position: Vector, regions: Destinations) -> bool:
    """Whether a material of ``color`` resting at ``position`` is where its rule puts it."""
    box = regions.boxes.get(color)
    if box is None:
        return False
    x0, x1, y0, y1, z0, z1 = box
    x, y, z = (float(v) for v in position)
    return x0 <= x <= x1 and y0 <= y <= y1 and z0 <= z <= z1


def why_not_there(color: str, position: Vector, regions: Destinations) -> str:
    """Why a material of ``color`` resting at ``position`` is not at its destination ('' if it
    is), from where it lies."""
    box = regions.boxes.get(color)
    if box is None:
        return f'{color} is no class of this cell'
    x0, x1, y0, y1, z0, z1 = box
    x, y, z = (float(v) for v in position)
    where = regions.places[color]
    at = f'({x:.3f}, {y:.3f}, {z:.3f})'
    if x0 <= x <= x1 and y0 <= y <= y1:
        if z > z1:
            return f'on {where} but {z - z0:.3f} m over its face, on another material, at {at}'
        if z < z0:
            return f'under {where}\'s face at {at}'
        return ''
    return f'not on {where}: at {at}'


def not_at_destination(final_truth: Sequence[TruePose], regions: Destinations,
                       tracks: Optional[Dict[int, int]] = None) -> List[Dict[str, Any]]:
    """Each material (by its order of appearance, the simulator's id) not at its destination,
    and why; with ``tracks`` (simulator id: the coordinator's material id), the id the
    coordinator's log and the result's ``materials`` know it by (-1 if it never saw it)."""
    out = []
    for k, (color, p) in enumerate(final_truth):
        why = why_not_there(color, p, regions)
        if why:
            out.append({'id': k, 'color': color, 'destination': regions.places.get(color, ''),
                        'why': why, 'material': (tracks or {}).get(k, -1)})
    return out


# What went wrong with a material that is not at its destination, earliest cause first.
FAILURE_CAUSES = {
    'not_seen': 'the vision never reported it',
    'wrong_colour': 'the vision took it for another class',
    'missed': 'it went off the belt\'s end unpicked',
    'grasp_missed': 'a grasp of it failed, and was given up',
    'given_up': 'it was given up',
    'dropped': 'it was lifted off the belt and lost before it was set down',
    'left_on_plate': 'it was loaded onto a youBot\'s plate and not unloaded by the run\'s end',
    'on_another': 'it was set down on another material, not on its destination',
    'out_of_place': 'it was set down, but off its destination',
    'not_handled': 'the run ended before it was handled',
}


def failure_cause(sim_id: int, true_color: str, details: Sequence[Dict[str, Any]],
                  materials: Sequence[Dict[str, Any]], events: Sequence[Sequence[Any]],
                  where: str = '') -> Tuple[str, str]:
    """Why the simulator's material ``sim_id`` is not at its destination: a FAILURE_CAUSES key
    and what tells it, from what the vision reported (the identifications' ``details``), what
    the coordinator made of it (its ``materials``), the run's ``events`` and where the ground
    truth has it (``where``: why_not_there)."""
    seen = [d for d in details if d.get('truth_id') == sim_id]
    if not seen:
        return 'not_seen', FAILURE_CAUSES['not_seen']
    wrong = [d for d in seen if d.get('color') != true_color]
    if wrong:
        return 'wrong_colour', f'seen as {wrong[0].get("color")}, it is {true_color}'
    ids = {d['material'] for d in seen if d.get('material', -1) >= 0}
    mine = [m for m in materials if m.get('id') in ids]
    status = {m.get('status') for m in mine}
    kinds = {str(e[1]) for e in events if len(e) > 3 and e[3] in ids}
    failure = next((m.get('failure') for m in mine if m.get('failure')), '')
    lies = f' (it lies {where})' if where else ''
    if status & {'placed', 'delivered'}:
        if 'on another material' in where:
            return 'on_another', FAILURE_CAUSES['on_another'] + lies
        return 'out_of_place', FAILURE_CAUSES['out_of_place'] + lies
    if 'missed' in status:
        return 'missed', FAILURE_CAUSES['missed']
    if 'grasp_failed' in kinds:
        return 'grasp_missed', failure or FAILURE_CAUSES['grasp_missed']
    if 'on_plate' in status:
        tried = 'unload_grasped' in kinds or 'grasp_missed' in kinds
        return 'left_on_plate', (FAILURE_CAUSES['left_on_plate']
                                 + (', after an unload was tried' if tried
                                    else ': no unload of it was tried') + lies)
    if 'failed' in status:
        return 'given_up', failure or FAILURE_CAUSES['given_up']
    if 'picked' in kinds:
        return 'dropped', FAILURE_CAUSES['dropped'] + lies
    return 'not_handled', (f'the run ended with it {", ".join(sorted(map(str, status)))}'
                           if status else FAILURE_CAUSES['not_handled'])


def tracks_of(details: Sequence[Dict[str, Any]]) -> Dict[int, int]:
    """Simulator id: the coordinator's material id, from the identifications' details (each
    made on the material nearest its detection, in the snapshot of its moment)."""
    return {d['truth_id']: d['material'] for d in details
            if d.get('truth_id') is not None and d.get('material', -1) >= 0}


def nearest_material(position: Vector,
                     truth: Sequence[TruePose]) -> Tuple[Optional[str], float]:
    """The true colour of the material nearest ``position``, and its distance [m]."""
    _, color, distance = _nearest(position, truth)
    return color, distance


def _nearest(position: Vector,
             truth: Sequence[TruePose]) -> Tuple[Optional[int], Optional[str], float]:
    """The material nearest ``position``: its simulator id, true colour and distance [m]."""
    best, best_d = None, math.inf
    for k, (_, p) in enumerate(truth):
        d = float(np.linalg.norm(np.asarray(p, float) - np.asarray(position, float)))
        if d < best_d:
            best, best_d = k, d
    return best, (truth[best][0] if best is not None else None), best_d


def match_identification(position: Vector, truth: Sequence[TruePose],
                         tolerance: float = 0.04) -> Optional[str]:
    """The true colour of the material nearest ``position`` (within ``tolerance``), or None."""
    color, distance = nearest_material(position, truth)
    return color if distance <= tolerance else None


class IdentificationCheck:
    """Each identification checked against the ground truth of its own moment: the true
    colour of the material at the detection's position, in the ground-truth snapshot nearest
    the detection's stamp. A check waits until a snapshot at or after that stamp has come in
    (or the run ends): decided at once, under load it took an older snapshot, the material had
    ridden on 4 cm from where the truth showed it, and a correct identification counted as
    wrong. Which snapshot decides does not depend on when the messages arrive."""

    def __init__(self, keep: int = 50) -> None:
        self._snapshots: List[Tuple[int, Sequence[TruePose]]] = []
        self._pending: List[Tuple[int, np.ndarray, str, int]] = []
        self._keep = keep
        self.results: List[bool] = []
        # Per identification: its stamp [s], colour, the coordinator's material id, the nearest
        # true material's simulator id, colour and distance [m] in the snapshot that decided
        # it (None where there was none).
        self.details: List[Dict[str, Any]] = []

    def truth(self, stamp_ns: int, truth: Sequence[TruePose]) -> None:
        """A ground-truth snapshot, stamped."""
        self._snapshots.append((stamp_ns, truth))
        self._snapshots.sort(key=lambda item: item[0])
        del self._snapshots[:-self._keep]
        self._decide(final=False)

    def seen(self, stamp_ns: int, position: Vector, color: str, material: int = -1) -> None:
        """An identification: ``color`` for the material at ``position`` at ``stamp_ns`` (the
        coordinator's material ``material``)."""
        self._pending.append((stamp_ns, np.asarray(position, float).copy(), color, material))
        self._decide(final=False)

    def unknown(self) -> None:
        """An identification with nothing to check it on counts as wrong."""
        self.results.append(False)
        self.details.append({'stamp': None, 'color': None, 'material': -1, 'truth_id': None,
                             'true_color': None, 'distance': None})

    def finish(self) -> List[bool]:
        """Decide what is still pending with the snapshots there are; the results."""
        self._decide(final=True)
        return self.results

    def _decide(self, final: bool) -> None:
        waiting = []
        for item in self._pending:
            stamp_ns = item[0]
            if not self._snapshots:
                if final:
                    self._record(item, [])
                else:
                    waiting.append(item)
                continue
            if not final and self._snapshots[-1][0] < stamp_ns:
                waiting.append(item)
                continue
            _, truth = min(self._snapshots, key=lambda snap: abs(snap[0] - stamp_ns))
            self._record(item, truth)
        self._pending = waiting

    def _record(self, item: Tuple[int, np.ndarray, str, int],
                truth: Sequence[TruePose]) -> None:
        stamp_ns, position, color, material = item
        self.results.append(match_identification(position, truth) == color)
        k, true_color, distance = _nearest(position, truth)
        self.details.append({'stamp': round(stamp_ns * 1e-9, 4), 'color': color,
                             'material': material, 'truth_id': k, 'true_color': true_color,
                             'distance': round(distance, 4) if true_color else None})


def identified_materials(identifications: Sequence[bool],
                         details: Optional[Sequence[Dict[str, Any]]] = None) -> int:
    """The materials identified with their true colour: with each identification's ``details``
    (IdentificationCheck.details, in the same order), each true material once, when every
    identification made on it was right; without them, each identification as one material.
    A material seen again and again (held in the camera's view) is still one material."""
    if details is None or len(details) != len(identifications):
        return sum(1 for ok in identifications if ok)
    verdict: Dict[int, bool] = {}
    for ok, d in zip(identifications, details):
        k = d.get('truth_id')
        if k is not None:
            verdict[k] = verdict.get(k, True) and bool(ok)
    return sum(verdict.values())


def score(result: RunResult, final_truth: Sequence[TruePose], identifications: Sequence[bool],
          regions: Destinations, tracks: Optional[Dict[int, int]] = None,
          details: Optional[Sequence[Dict[str, Any]]] = None) -> TrialResult:
    """The run's figures: counts, the three rates and the completion time. The materials not at
    their destination are named by their simulator id, and with ``tracks`` (tracks_of) by the
    coordinator's too; identifications are counted by material (identified_materials)."""
    total = max(result.total, 1)
    handled = sum(1 for color, p in final_truth if at_destination(color, p, regions))
    correct = min(identified_materials(identifications, details), result.total)
    missing = not_at_destination(final_truth, regions, tracks)
    told = [f'material {m["id"]} ({m["color"]}'
            + (f', the coordinator\'s {m["material"]}' if m['material'] >= 0 else '')
            + f') {m["why"]}' for m in missing]
    if len(final_truth) < result.total:
        told.append(f'{result.total - len(final_truth)} of the {result.total} materials never '
                    'appeared')
    status, message = result.status, result.message
    if told:
        # (The coordinator may have believed every material delivered: the simulator's ground
        # truth says otherwise, and the run did not complete.)
        if status == 'completed':
            status = 'incomplete'
        message = '; '.join(([message] if message else []) + told)
    plate_bound = sum(1 for color, p in final_truth
                      if color in regions.carried and at_destination(color, p, regions))
    counts = {k: v for k, v in asdict(result).items()
              if k not in ('status', 'message', 'transports')}
    return TrialResult(
        status=status, message=message, **counts, not_at_destination=missing,
        # The paper's split by role: the loader's grasps, the transports' unloads and carrying.
        loader_grasp_rate=_rate(result.loader_grasp_successes, result.loader_grasp_attempts),
        transport_grasp_rate=_rate(result.transport_grasp_successes,
                                   result.transport_grasp_attempts),
        transport_rate=_rate(min(plate_bound, result.loaded), result.loaded),
        identified_correct=correct, handled_verified=handled,
        identification_rate=correct / total,
        grasp_success_rate=_rate(result.grasp_successes, result.grasp_attempts),
        handling_success_rate=handled / total)


@dataclass(frozen=True)
class RunTrace:
    """What a run went through, beside its counts: the scenario, the identifications'
    details, each arm's peak joint speed, the youBot's path, the events and state changes (times
    in simulated seconds, ``start`` the run's start)."""
    seed: Optional[int]
    belt_speed: float
    mode: str
    start: float
    identification_details: Sequence[Dict[str, Any]]
    peaks: Mapping[str, 'PeakJointSpeed']
    joint_names: Mapping[str, Sequence[str]]
    youbot_path: Sequence[Tuple[float, float]]
    events: Sequence[Event]
    # Several youBots: each one's path as its odometry saw it, at every decision ({} for one).
    paths: Mapping[str, Sequence[Tuple[float, float]]] = field(default_factory=dict)
    odometry_age: Optional[Dict[str, float]] = None
    # Several mobile bases: their closest approach (distance, time, robots), by the ground truth.
    closest_bases: Optional[Dict[str, Any]] = None
    # The joints the simulator found driven past their speed limits (cell_layout.joint_speeds).
    driven_past: Sequence[Dict[str, Any]] = ()


def build_result(result: RunResult, final_truth: Sequence[TruePose],
                 identifications: Sequence[bool], regions: Destinations,
                 trace: RunTrace) -> TrialResult:
    """A run's result record: its score (``score``), each material by both ids, where every
    material rests and why it is not at its destination, and what the run went through."""
    tracks = tracks_of(trace.identification_details)
    out = score(result, final_truth, identifications, regions, tracks,
                trace.identification_details)
    sim_id = {material: k for k, material in tracks.items()}
    materials = [{**m, 'sim_id': sim_id.get(m['id'], -1)} for m in out.materials]
    final = [{'id': k, 'material': tracks.get(k, -1), 'color': color,
              'position': [round(float(v), 4) for v in p],
              'at_destination': at_destination(color, p, regions),
              'why': why_not_there(color, p, regions)} for k, (color, p) in enumerate(final_truth)]
    start = trace.start
    # Each machine's state changes: the report's timeline.
    states = [[round(e.time - start, 4), e.robot, e.detail]
              for e in trace.events if e.kind is EventKind.STATE]
    events = [[round(e.time - start, 4), str(e.kind), e.robot, e.material, e.color, e.detail]
              for e in trace.events if e.kind is not EventKind.STATE]
    missing = []
    for m in out.not_at_destination:
        cause, why = failure_cause(m['id'], m['color'], trace.identification_details,
                                   materials, events, m.get('why', ''))
        missing.append({**m, 'cause': cause, 'cause_detail': why})
    peaks = {arm: {'fraction_of_limit': round(p.fraction, 4),
                   'joint': trace.joint_names[arm][p.joint] if p.joint >= 0 else '',
                   'time': round(p.time - start, 4) if math.isfinite(p.time) else None}
             for arm, p in trace.peaks.items()}
    return replace(
        out, materials=materials, identifications=list(trace.identification_details),
        final_materials=final, peak_joint_speed=peaks, odometry_age=trace.odometry_age,
        closest_bases=None if trace.closest_bases is None else {
            **trace.closest_bases, 'time': round(trace.closest_bases['time'] - start, 4)},
        joints_driven_past=[{**d, 'time': round(float(d['time']) - start, 4)}
                            for d in trace.driven_past][:MAX_DRIVEN_PAST],
        scenario_seed=trace.seed, belt_speed=trace.belt_speed, mode=trace.mode,
        youbot_path=[[round(x, 4), round(y, 4)] for x, y in trace.youbot_path[::3]],
        events=events, not_at_destination=missing, states=states,
        transports=fleet_shares(result.transports, states, trace.paths, out.completion_time))


# A youBot's states in which it waits for another robot (to be loaded, for the loading pose, to
# leave the pool); in the others it drives or unloads.
WAITING_STATES = frozenset(('wait_load', 'wait_bay', 'leave'))
FIRST_STATE = 'wait_bay'            # a fleet's youBot's state before its first change


def fleet_shares(counts: Mapping[str, Mapping[str, int]], states: Sequence[Sequence[Any]],
                 paths: Mapping[str, Sequence[Tuple[float, float]]], end: float
                 ) -> Optional[Dict[str, Dict[str, Any]]]:
    """Each youBot's share of a fleet's run (None for one youBot): its counts, the distance
    it drove (its odometry's path) [m], and its time busy (driving, unloading, folding) and
    waiting (``WAITING_STATES``) from the start to ``end`` [s], from its state changes."""
    if not counts:
        return None
    out = {}
    for robot, c in counts.items():
        changes = [(float(t), state) for t, who, state in states if who == robot]
        if not changes or changes[0][0] > 0.0:
            changes.insert(0, (0.0, FIRST_STATE))      # (it starts waiting at its park)
        busy = waiting = 0.0
        for (t0, state), t1 in zip(changes, [t for t, _ in changes[1:]] + [end]):
            span = max(0.0, min(t1, end) - t0) if math.isfinite(end) else max(0.0, t1 - t0)
            if state in WAITING_STATES:
                waiting += span
            elif state != 'done':
                busy += span
        xy = np.asarray(paths.get(robot, ()), float).reshape(-1, 2)
        distance = float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))) if len(xy) else 0.0
        out[robot] = {**c, 'distance': round(distance, 3), 'busy': round(busy, 3),
                      'waiting': round(waiting, 3),
                      'path': [[round(x, 4), round(y, 4)] for x, y in xy[::3].tolist()]}
    return out


class PeakJointSpeed:
    """The largest joint speed seen in an arm's joint states, as a fraction of each joint's
    published limit (1.0 = at the limit): the proof, from what the simulator reported, that the
    arms kept their limits."""

    def __init__(self, limits: Vector) -> None:
        self.limits = np.asarray(limits, float)
        self.fraction = 0.0
        self.joint = -1
        self.time = math.nan          # the sample's stamp [s]

    def update(self, velocities: Vector, time: float = math.nan) -> None:
        v = np.abs(np.asarray(velocities, float))
        if v.shape != self.limits.shape or not np.all(np.isfinite(v)):
            return
        ratios = v / self.limits
        k = int(np.argmax(ratios))
        if ratios[k] > self.fraction:
            self.fraction, self.joint, self.time = float(ratios[k]), k, float(time)


def _rate(part: int, whole: int) -> float:
    return part / whole if whole else 0.0
