"""The trials' report: a markdown summary beside the paper's Table 2, and PNG plots (OpenCV)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import cv2
import numpy as np

from recording.plot import plot_paths
from ros_common.outputs import staged_dir
from studies.recorded import trial_bag
from studies.sweep_report import sweep_lines
from trial_record.result import TrialResult
from trial_record.scoring import FAILURE_CAUSES, FIRST_STATE
from world_description.footprint import footprints
from world_description.resources import ResourceError, resolve_resource
from world_description.world_config import WorldConfigError, load_world, parse_world

# The paper's Table 2: trials, completion time [s], identification, grasp, handling [%].
PAPER_TABLE_2 = (('1-10', 85, 60, 70, 80), ('11-30', 76, 76, 75, 85), ('30-60', 69, 82, 82, 95),
                 ('60-100', 64, 90, 89, 100), ('100-110', 61, 99, 99, 10))
FONT = cv2.FONT_HERSHEY_SIMPLEX



def summary_rows(trials: Sequence[TrialResult]) -> Dict[str, float]:
    """Mean rates and median completion time over trials (for the report)."""
    if not trials:
        return {}
    times = [t.completion_time for t in trials]
    rates = {k: float(np.mean([getattr(t, k) for t in trials]))
             for k in ('identification_rate', 'grasp_success_rate', 'handling_success_rate',
                       'loader_grasp_rate', 'transport_grasp_rate', 'transport_rate')}
    return {
        'trials': len(trials),
        'completed': sum(1 for t in trials if t.status == 'completed'),
        'median_completion_time': float(np.median(times)),
        'p90_completion_time': float(np.percentile(times, 90)),
        **rates,
        # The largest over all trials: the limits hold only if they hold in every run.
        # (Per robot, by the name its world gives it.)
        **{f'peak_joint_speed_{robot}': max(
            (t.peak_joint_speed.get(robot, {}).get('fraction_of_limit', 0.0) for t in trials),
            default=0.0) for robot in sorted({r for t in trials for r in t.peak_joint_speed})},
        # Trials in which the world drove a joint past its speed limit (the simulator braked it
        # back), and the worst such joint's ratio.
        'trials_joints_driven_past': sum(1 for t in trials if t.joints_driven_past),
        'worst_driven_past': max((d['ratio'] for t in trials for d in t.joints_driven_past),
                                 default=0.0),
    }

def _canvas(title: str, size: Tuple[int, int] = (900, 500)) -> np.ndarray:
    img = np.full((size[1], size[0], 3), 255, np.uint8)
    cv2.putText(img, title, (70, 30), FONT, 0.6, (0, 0, 0), 1)
    return img


def histogram(values: Sequence[float], out: Path, title: str, xlabel: str,
              mark: Tuple[str, float] = ('', math.nan)) -> None:
    img = _canvas(title)
    left, top, w, h = 70, 50, 800, 380
    vals = np.asarray([v for v in values if math.isfinite(v)], float)
    if len(vals):
        lo = min(vals.min(), mark[1] if math.isfinite(mark[1]) else vals.min())
        hi = max(vals.max(), mark[1] if math.isfinite(mark[1]) else vals.max())
        lo, hi = math.floor(lo - 1), math.ceil(hi + 1)
        hi = max(hi, lo + 2)                # (never an empty span: values are finite, ranged)
        bins = max(5, min(30, int(hi - lo)))
        counts, edges = np.histogram(vals, bins=bins, range=(lo, hi))
        peak = max(1, counts.max())
        bw = w / bins
        for i, c in enumerate(counts):
            x0 = int(left + i * bw)
            y0 = int(top + h - h * c / peak)
            cv2.rectangle(img, (x0 + 1, y0), (int(x0 + bw) - 1, top + h), (180, 119, 31), -1)
        for i in range(0, bins + 1, max(1, bins // 8)):
            x = int(left + i * bw)
            cv2.putText(img, f'{edges[i]:.0f}', (x - 10, top + h + 20), FONT, 0.45, (0, 0, 0), 1)
        for k in range(0, peak + 1, max(1, peak // 5)):
            y = int(top + h - h * k / peak)
            cv2.putText(img, str(k), (left - 35, y + 5), FONT, 0.45, (0, 0, 0), 1)
        if math.isfinite(mark[1]):
            x = int(left + (mark[1] - lo) / (hi - lo) * w)
            cv2.line(img, (x, top), (x, top + h), (40, 39, 214), 2)
            cv2.putText(img, mark[0], (x + 5, top + 15), FONT, 0.5, (40, 39, 214), 1)
    cv2.rectangle(img, (left, top), (left + w, top + h), (0, 0, 0), 1)
    cv2.putText(img, xlabel, (left + w // 2 - 60, top + h + 45), FONT, 0.55, (0, 0, 0), 1)
    _write(img, out)


def bars(rows: Sequence[Tuple[str, float, float]], out: Path, title: str) -> None:
    """Pairs of bars (ours, the paper's best) in percent."""
    img = _canvas(title)
    left, top, w, h = 70, 50, 800, 380
    group = w / len(rows)
    for i, (name, ours, paper) in enumerate(rows):
        for j, (value, color) in enumerate(((ours, (180, 119, 31)), (paper, (160, 160, 160)))):
            x0 = int(left + i * group + 30 + j * (group - 60) / 2)
            x1 = int(x0 + (group - 60) / 2 - 6)
            if not math.isfinite(value):          # (no trial gave this rate)
                cv2.putText(img, 'n/a', (x0, top + h - 6), FONT, 0.45, (0, 0, 0), 1)
                continue
            y = int(top + h - h * value / 100.0)
            cv2.rectangle(img, (x0, y), (x1, top + h), color, -1)
            cv2.putText(img, f'{value:.1f}', (x0, y - 6), FONT, 0.45, (0, 0, 0), 1)
        cv2.putText(img, name, (int(left + i * group + 40), top + h + 22), FONT, 0.5,
                    (0, 0, 0), 1)
    cv2.putText(img, 'blue: these trials (mean)   grey: the paper, trials 100-110',
                (left, top + h + 45), FONT, 0.5, (0, 0, 0), 1)
    cv2.rectangle(img, (left, top), (left + w, top + h), (0, 0, 0), 1)
    _write(img, out)


# The timeline's colours per state (BGR) of the two machines (pipeline.LoaderState and
# TransportState), and the belt's.
STATE_COLORS = {
    'start': (220, 220, 220), 'wait': (200, 200, 200), 'wait_load': (200, 200, 200),
    'wait_bay': (200, 200, 200), 'leave': (200, 200, 200),
    'pick': (14, 127, 255), 'grasp': (14, 127, 255),
    'place': (180, 119, 31), 'carry': (180, 119, 31),
    'rise': (232, 199, 174), 'release': (232, 199, 174),
    'retreat': (40, 39, 214), 'drive': (44, 160, 44),
    'home': (189, 103, 148), 'fold': (189, 103, 148), 'running': (120, 120, 120)}
# The loader's machine and, with one youBot, the transport's; a fleet's youBots each have a
# machine of their own, by their robot names.
LOADER, TRANSPORT = 'loader', 'transport'


def lanes_of(trial: TrialResult) -> List[Tuple[str, str]]:
    """The timeline's lanes, (label, machine): the belt, the loader, and each youBot (one lane
    per robot of a fleet, named as the world names it)."""
    youbots = list(trial.transports or {}) or [TRANSPORT]
    loader = [r for r, g in (trial.robot_grasps or {}).items() if g['role'] == LOADER]
    return ([('belt', 'belt'), (loader[0] if loader else LOADER, LOADER)]
            + [('youBot' if m == TRANSPORT else m, m) for m in youbots])


def activity(trial: TrialResult) -> Dict[str, List[Tuple[float, float, str]]]:
    """Per lane of the timeline (the belt, the loader, each youBot): (start, end, state) from a
    trial's state changes and belt events, up to its completion time."""
    end = float(trial.completion_time)
    if not math.isfinite(end):             # (a run that did not end: up to its last record)
        end = max([float(s[0]) for s in trial.states] + [float(e[0]) for e in trial.events]
                  + [0.0])
    lanes: Dict[str, List[Tuple[float, float, str]]] = {}
    for label, machine in lanes_of(trial)[1:]:
        changes = [(float(t), state) for t, who, state in trial.states
                   if who == machine]
        if machine in (trial.transports or {}) and (not changes or changes[0][0] > 0.0):
            changes.insert(0, (0.0, FIRST_STATE))      # (a fleet's youBot waits at its park)
        lanes[label] = [(t0, t1, state) for (t0, state), (t1, _) in
                        zip(changes, changes[1:] + [(end, '')]) if t1 > t0 and state != 'done']
    belt = [float(e[0]) for e in trial.events if e[1] == 'belt_started']
    stop = [float(e[0]) for e in trial.events if e[1] == 'belt_stopped']
    lanes['belt'] = [(t0, min([t for t in stop if t >= t0] + [end]), 'running') for t0 in belt]
    return lanes


def timeline(trial: TrialResult, out: Path) -> None:
    """Each robot's activity over one run: a lane per robot (and the belt), a bar per state."""
    _write(timeline_image(trial), out)


def timeline_image(trial: TrialResult, end: Optional[float] = None,
                   title: str = '') -> np.ndarray:
    """The image of ``timeline``; ``end``: where its time axis ends [s] (two runs on one
    axis), else at the run's completion."""
    img = _canvas(title or (f'Activity over trial {trial.trial} (seed {trial.scenario_seed}, '
                            f'belt {trial.belt_speed:.3f} m/s): completed in '
                            f'{trial.completion_time:.1f} s'),
                  (900, 150 + 60 * len(lanes_of(trial))))
    left, top, w, lane_h = 90, 50, 780, 50
    if end is None:
        end = trial.completion_time if math.isfinite(trial.completion_time) else 1.0
    end = max(1.0, float(end))
    lanes = activity(trial)
    for i, (label, _) in enumerate(lanes_of(trial)):
        y0 = top + i * (lane_h + 10)
        cv2.putText(img, label[:11], (10, y0 + 30), FONT, 0.5, (0, 0, 0), 1)
        for t0, t1, state in lanes[label]:
            x0, x1 = (int(left + w * t / end) for t in (t0, t1))
            cv2.rectangle(img, (x0, y0), (max(x0, x1 - 1), y0 + lane_h),
                          STATE_COLORS.get(state, (0, 0, 0)), -1)
        cv2.rectangle(img, (left, y0), (left + w, y0 + lane_h), (0, 0, 0), 1)
    axis = top + len(lanes_of(trial)) * (lane_h + 10)
    for t in range(0, int(end) + 1, 10):
        x = int(left + w * t / end)
        cv2.line(img, (x, axis - 5), (x, axis), (0, 0, 0), 1)
        cv2.putText(img, f'{t}', (x - 8, axis + 15), FONT, 0.4, (0, 0, 0), 1)
    cv2.putText(img, 'simulated time [s]', (left + w // 2 - 70, axis + 35), FONT, 0.5,
                (0, 0, 0), 1)
    legend = (('wait', 'wait'), ('pick / grasp', 'pick'), ('place / carry', 'place'),
              ('rise / release', 'rise'), ('drive', 'drive'), ('home / fold', 'home'),
              ('retreat', 'retreat'))
    for k, (name, state) in enumerate(legend):
        x = left + k * 112
        cv2.rectangle(img, (x, axis + 50), (x + 14, axis + 64), STATE_COLORS[state], -1)
        cv2.putText(img, name, (x + 18, axis + 62), FONT, 0.38, (0, 0, 0), 1)
    return img


def write_png(img: np.ndarray, out: Path) -> None:
    """An image into a PNG file (OSError if it cannot be written)."""
    _write(img, out)


def _write(img: np.ndarray, out: Path) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), img):
        raise OSError(f'cannot write {out}')


def scenario(world: str) -> str:
    """The campaign's world, and its classes' rules (as far as the file can be read now)."""
    from cell_layout.layout import LayoutError
    from cell_layout.world_layout import layout_from_world
    try:
        layout = layout_from_world(load_world(resolve_resource(world)))
    except (WorldConfigError, LayoutError) as exc:
        return f'Scenario: `{world}` (cannot be read now: {exc}).'
    rules = ', '.join(f'{n} {c} to {layout.destination(c)} ({layout.rule(c).route}, '
                      f'{layout.size_of(c) * 1000:.0f} mm, {layout.rule(c).mass:g} kg)'
                      for c, n in layout.manifest.items())
    return f'Scenario: `{world}`: {layout.total} materials, {rules}.'


def write_report(trials: Sequence[TrialResult], out_dir: Path, setup: Dict[str, Any]) -> Path:
    """The campaign's report (``report.md``) and its plots, in ``out_dir``, all or none of
    them (outputs.staged_dir: report.md moves in last). ``setup``: how the trials were run
    (note, or seed0, belt_speed, parallel, wall_time; world)."""
    with staged_dir(out_dir, 'the report', last='report.md') as stage:
        _write_report(trials, out_dir, stage, setup)
    return out_dir / 'report.md'


def _write_report(trials: Sequence[TrialResult], out_dir: Path, stage: Path,
                  setup: Dict[str, Any]) -> None:
    """write_report's files into ``stage`` (the trials' own files are read in ``out_dir``)."""
    ok = [t for t in trials if t.status != 'error']
    s = summary_rows(ok)
    shown = _plots(ok, s, stage, setup.get('world'))
    swept = any(str(spec).partition('=')[0].strip() == 'belt_speed'
                for spec in setup.get('sweep') or ())
    belt = 'swept' if swept else f'{setup.get("belt_speed")} m/s'
    lines = ['# Pipeline trials', '', setup['note'] if 'note' in setup else (
        f'{len(trials)} trials (lock-step), plan seed {setup.get("seed0")}, belt speed '
        f'{belt}, {setup.get("parallel")} in parallel, wall time '
        f'{setup.get("wall_time", 0.0):.0f} s.'), '']
    if setup.get('world'):
        lines[-1:-1] = [scenario(str(setup['world'])), '']
    codes = sorted({t.run.code for t in trials})
    lines[-1:-1] = [f'Code: {", ".join(codes)}' + (
        ' (the trials were run by different code)' if len(codes) > 1 else '') + '.']
    if s:
        lines += _table(s)
    lines += _robot_lines(ok)
    lines += fleet_lines(ok)
    lines += sweep_lines(ok, stage, float(setup.get('break_below') or 0.9))
    bad = [t for t in trials if t.status != 'completed']
    lines += _causes(ok)
    if bad:
        lines += ['## Runs that did not complete', '']
        lines += [f'- trial {t.trial} (seed {t.scenario_seed}, belt {t.belt_speed:.3f}): '
                  f'{t.status} {t.message}; '
                  + ', '.join(f'{m["color"]} {m["id"]}: {m["status"]} ({m["failure"]})'
                              for m in t.materials if m.get('failure'))
                  for t in bad]
        lines.append('')
    lines += _definitions(sorted({t.total for t in trials if t.total}) or [8])
    if shown is not None:
        lines += ['The trial of median completion time, each robot\'s activity over it:', '',
                  '![timeline](timeline.png)', ''] + _storyboard(shown, out_dir, stage)
    (stage / 'report.md').write_text('\n'.join(lines))


def fleet_lines(trials: Sequence[TrialResult]) -> List[str]:
    """Each youBot's share over the trials of a fleet (none for one youBot): means per trial
    of its trips, materials carried and delivered, distance driven, and time busy and
    waiting; and how near the bases came."""
    fleet = [t for t in trials if t.transports]
    if not fleet:
        return []
    robots = list(dict.fromkeys(r for t in fleet for r in t.transports or {}))
    lines = ['## Each youBot\'s share', '',
             f'Means per trial over the {len(fleet)} trials with several youBots.', '',
             '| youBot | trips | carried | delivered | distance (m) | busy (s) | waiting (s) |',
             '|---|---|---|---|---|---|---|']
    for robot in robots:
        shares = [(t.transports or {})[robot] for t in fleet if robot in (t.transports or {})]
        mean = {k: float(np.mean([sh[k] for sh in shares]))
                for k in ('trips', 'carried', 'delivered', 'distance', 'busy', 'waiting')}
        lines.append(f'| {robot} | {mean["trips"]:.1f} | {mean["carried"]:.1f} | '
                     f'{mean["delivered"]:.1f} | {mean["distance"]:.1f} | {mean["busy"]:.1f} | '
                     f'{mean["waiting"]:.1f} |')
    near = [t.closest_bases['distance'] for t in fleet if t.closest_bases]
    if near:
        lines += ['', f'The bases came no nearer than {min(near):.3f} m, footprint to footprint '
                  '(the simulator\'s ground truth, `closest_bases`).']
    return lines + ['', 'Busy: driving, unloading and folding; waiting: to be loaded, for '
                    'the loading pose, or to leave the pool (docs/writing-a-cell.md, "Several '
                    'youBots").', '']


def _causes(trials: Sequence[TrialResult]) -> List[str]:
    """The materials not at their destination, counted by what went wrong (results.
    FAILURE_CAUSES); none: no lines."""
    counts: Dict[str, int] = {}
    for t in trials:
        for m in t.not_at_destination:
            cause = str(m.get('cause', 'unknown'))
            counts[cause] = counts.get(cause, 0) + 1
    if not counts:
        return []
    order = list(FAILURE_CAUSES) + sorted(set(counts) - set(FAILURE_CAUSES))
    return ['Materials not at their destination, by cause: ' + ', '.join(
        f'{cause.replace("_", " ")} {counts[cause]}' for cause in order if cause in counts)
        + f' (of {sum(t.total for t in trials)} in {len(trials)} trials).', '']


def cell_shapes(world: Optional[str] = None, data: Optional[Dict[str, Any]] = None
                ) -> List[Tuple[str, np.ndarray, Sequence[float], bool]]:
    """The cell's footprints (world_description.footprint) to draw under paths, from its world
    file or a result's copy of it (``data``: scenario.world_data); none when neither is known
    or can be read."""
    try:
        if data:
            config = parse_world(data, 'the run\'s world')
        elif world:
            config = load_world(resolve_resource(world))
        else:
            return []
    except (WorldConfigError, ResourceError, OSError):
        return []
    return [(f.name, f.outline, f.rgba, f.label) for f in footprints(config)]


def _plots(ok: Sequence[TrialResult], s: Dict[str, float], out_dir: Path,
           world: Optional[str] = None) -> Optional[TrialResult]:
    """The report's plots; the trial its timeline shows, if any."""
    histogram([t.completion_time for t in ok], out_dir / 'completion_times.png',
              'Completion time per trial (simulated seconds)', 'completion time [s]',
              ('paper best 61 s', 61.0))
    if s:
        bars([('identification', 100 * s['identification_rate'], 99.0),
              ('grasp', 100 * s['grasp_success_rate'], 99.0),
              ('handling', 100 * s['handling_success_rate'], 100.0)],
             out_dir / 'success_rates.png', 'Success rates [%]')
    paths = youbot_paths(sorted(ok, key=lambda t: t.trial or 0))
    if paths:
        plot_paths(paths, out_dir / 'youbot_paths.png', "The youBots' paths over the cell"
                   if any(t.transports for t in ok) else "The youBot's paths over the cell",
                   shapes=cell_shapes(world))
    shown = sorted((t for t in ok if t.states), key=lambda t: t.completion_time)
    if not shown:
        return None
    median = shown[len(shown) // 2]       # the trial of median completion time
    timeline(median, out_dir / 'timeline.png')
    return median


def youbot_paths(trials: Sequence[TrialResult], most: int = 6) -> Dict[str, np.ndarray]:
    """The paths the paths map draws: each youBot's (every robot of a fleet) of the first
    trials, at most ``most`` paths, a trial's robots all or none."""
    out: Dict[str, np.ndarray] = {}
    for t in trials:
        robots = {f'trial {t.trial} {name}': share['path']
                  for name, share in (t.transports or {}).items()} or {
                      f'trial {t.trial}': t.youbot_path}
        if out and len(out) + len(robots) > most:
            break
        out.update({k: np.asarray(p or np.zeros((0, 2)), float).reshape(-1, 2)
                    for k, p in robots.items()})
    return out


def _storyboard(trial: TrialResult, out_dir: Path, stage: Path) -> List[str]:
    """The storyboard of a recorded trial and its lines; none for a trial not recorded here.
    (Drawn here: the storyboard poses the cell in the simulator again, which this package
    sits above.)"""
    from studies.storyboard import StoryboardError, write_storyboard
    trial_dir = out_dir / f'trial_{trial.trial or 0:03d}'
    if trial.trial is None or trial_bag(trial_dir) is None:
        return []
    try:
        write_storyboard(trial_dir, stage / 'storyboard.png')
    except StoryboardError as exc:
        return [f'(No storyboard of trial {trial.trial}: {exc})', '']
    return [f'Trial {trial.trial} seen from above at its phases (its bag\'s states, posed in the '
            'simulator again: `storyboard RUN` draws any recorded trial):', '',
            '![storyboard](storyboard.png)', '']


def _table(s: Dict[str, float]) -> List[str]:
    """The trials' figures beside the paper's Table 2."""
    lines = ['| | trials | completion time (s, median) | identification (%) | grasp (%) | '
             'handling (%) |', '|---|---|---|---|---|---|',
             f'| **these trials** | {s["trials"]:.0f} | {s["median_completion_time"]:.1f} '
             f'(p90 {s["p90_completion_time"]:.1f}) | {100 * s["identification_rate"]:.1f}'
             f' | {100 * s["grasp_success_rate"]:.1f} | '
             f'{100 * s["handling_success_rate"]:.1f} |',
             f'| these trials, split as the paper: grasp = the loader\'s (the paper\'s Zu 12), '
             f'handling = the transports\' (its youBot) | | | '
             f'{100 * s["identification_rate"]:.1f} | {100 * s["loader_grasp_rate"]:.1f} '
             f'(transports {100 * s["transport_grasp_rate"]:.1f}) | '
             f'{100 * s["transport_rate"]:.1f} |']
    lines += [f'| paper, trials {r[0]} | | {r[1]} | {r[2]} | {r[3]} | {r[4]} |'
              for r in PAPER_TABLE_2]
    return lines + [
        '', f'Completed runs (every material at its destination): {s["completed"]:.0f} of '
        f'{s["trials"]:.0f}.', '',
        'Peak joint speed in the joint states the simulator published (all trials, as a '
        'fraction of each joint\'s published limit): '
        + ', '.join(f'{k[len("peak_joint_speed_"):]} {v:.3f}' for k, v in s.items()
                    if k.startswith('peak_joint_speed_'))
        + '; every joint with a limit, arms, fingers and wheels' + (
            f'. The world drove a joint past its limit (braked back to it) in '
            f'{s["trials_joints_driven_past"]:.0f} trials, at worst '
            f'{s["worst_driven_past"]:.2f} times its limit (each trial\'s '
            '`joints_driven_past`).' if s.get('trials_joints_driven_past') else '.'), '']


def _robot_lines(trials: Sequence[TrialResult]) -> List[str]:
    """Each robot's grasps over the trials, by its name and role."""
    totals: Dict[Tuple[str, str], List[int]] = {}
    for t in trials:
        for robot, g in (t.robot_grasps or {}).items():
            tally = totals.setdefault((robot, g['role']), [0, 0])
            tally[0] += g['attempts']
            tally[1] += g['successes']
    if not totals:
        return []
    return ['Grasps by robot (all trials; a loader\'s picks off the belt, a transport\'s '
            'unloads of its plate): ' + '; '.join(
                f'{robot} ({role}) {won} of {tried}'
                + (f' ({100 * won / tried:.1f} %)' if tried else '')
                for (robot, role), (tried, won) in totals.items()) + '.', '']


def _definitions(totals: Sequence[int]) -> List[str]:
    per = '/'.join(map(str, totals))
    return [f'Definitions: identification = materials whose track had their true colour / '
            f'{per} (the materials of a trial); grasp = successful grasps / attempts (both '
            'arms); handling = materials resting at their destination at the end (checked '
            f'against the simulator\'s ground truth) / {per}. Split: the loader\'s grasp = '
            'its successful picks / pick attempts; the transports\' handling = materials '
            'loaded onto a plate that rest at their destination / materials loaded onto '
            'a plate; completion time = simulated seconds until every robot is back '
            'home. The '
            "paper's last row prints 10 % handling (a typo for 100 %, by the rows before it).",
            '', '![completion times](completion_times.png) ![success rates](success_rates.png)'
            ' ![youBot paths](youbot_paths.png)', '']
