"""Arm kinematics in a robot description's terms: joint positions as the description (and
/joint_states) gives them, poses of a tool frame in base_link (or another known frame).

A chain of DH frames, a conversion between its joint values and the description's, where the
chain's frame 0 sits in base_link, the tool frames on the last DH frame, and an IK solver for
the chain. The youBot and the Zu 12 fill these in (youbot_kinematics.py, zu12_kinematics.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from controllers.arrays import Vector
from controllers.dh_chain import DHChain, IKResult
from controllers.transforms import pose_distance

Solver = Callable[[np.ndarray, Optional[np.ndarray], DHChain], IKResult]
Convert = Callable[[Vector], np.ndarray]


@dataclass
class ArmSolution:
    success: bool
    positions: Optional[np.ndarray] = None     # description convention, joint_names order
    reason: str = ''
    position_error: float = math.inf
    rotation_error: float = math.inf


def _identity(q: Vector) -> np.ndarray:
    return np.asarray(q, float)


class FrameLookup:
    """Targets given in a robot's known frames (``reference_frames``: name -> transform from
    base_link)."""

    reference_frames: Dict[str, np.ndarray]

    def in_base_link(self, frame: str, pose: np.ndarray, prefix: str = '') -> np.ndarray:
        """A pose given in one of the reference frames (with the robot's frame prefix; empty
        means base_link) as a pose in base_link. Raises KeyError for other frames."""
        name = frame[len(prefix):] if prefix and frame.startswith(prefix) else frame
        name = name or 'base_link'
        if name not in self.reference_frames:
            known = [prefix + f if f != 'world' else f for f in self.reference_frames]
            raise KeyError(f'unknown frame "{frame}": targets must be given in {known} '
                           '(no tf2 lookup here)')
        in_base: np.ndarray = self.reference_frames[name] @ np.asarray(pose, float)
        return in_base


class ArmKinematics(FrameLookup):
    """FK and IK of one arm for one of its tool frames."""

    def __init__(self, chain: DHChain, solver: Solver, joint_names: Sequence[str],
                 velocity_limits: Vector, base: np.ndarray,
                 tool_frames: Dict[str, np.ndarray], tool_frame: str,
                 reference_frames: Dict[str, np.ndarray],
                 to_chain: Convert = _identity, from_chain: Convert = _identity,
                 min_frame_height: Optional[float] = None) -> None:
        if tool_frame not in tool_frames:
            raise ValueError(f'unknown tool frame "{tool_frame}"; known: {sorted(tool_frames)}')
        self.chain, self._solver = chain, solver
        self.joint_names = tuple(joint_names)
        self.velocity_limits = np.asarray(velocity_limits, float)
        self.tool_frame = tool_frame
        self.tool_frames = dict(tool_frames)
        self.reference_frames = dict(reference_frames)
        self._tool = tool_frames[tool_frame]
        self._tool_inv = np.linalg.inv(self._tool)
        self._base = np.asarray(base, float)
        self._base_inv = np.linalg.inv(self._base)
        self._to_chain, self._from_chain = to_chain, from_chain
        # Solutions that put a joint frame below this height in base_link are not used (the
        # floor: IK alone would happily fold an elbow through it).
        self.min_frame_height = min_frame_height
        lower, upper = chain.limits
        ends = np.sort(np.stack([from_chain(lower), from_chain(upper)]), 0)
        self.lower, self.upper = ends[0], ends[1]

    def fk(self, positions: Vector) -> np.ndarray:
        """4x4 pose of the tool frame in base_link."""
        pose: np.ndarray = self._base @ self.chain.fk(self._to_chain(positions)) @ self._tool
        return pose

    def ik(self, target: np.ndarray, seed: Optional[Vector] = None) -> ArmSolution:
        """Joint positions that put the tool frame at ``target`` (4x4 in base_link), nearest
        to ``seed``; a failure names why (out of reach, orientation, limits)."""
        target = np.asarray(target, float)
        # The sum is finite only if every element is (inf - inf and NaN give NaN).
        if target.shape != (4, 4) or not math.isfinite(float(target.sum())):
            return ArmSolution(False, reason='target must be a finite 4x4 pose')
        flange = self._base_inv @ target @ self._tool_inv
        seed_chain = None if seed is None else self._to_chain(seed)
        result = self._solver(flange, seed_chain, self.chain)
        if not result.success:
            return ArmSolution(False, reason=result.reason)
        answer = result.q
        if answer is None:
            return ArmSolution(False, reason='the solver reported success without a solution')
        q = answer
        if self.min_frame_height is not None:
            # The solver checked its answer; the others are checked here before use.
            ref = seed_chain if seed_chain is not None else np.zeros(self.chain.dof)
            order = sorted(result.candidates[1:], key=lambda c: float(np.abs(c - ref).sum()))
            chosen = next((c for c in [answer] + order if self.above_floor(c) and (
                c is answer or self._reaches(c, flange))), None)
            if chosen is None:
                return ArmSolution(False, reason='every solution puts the arm below '
                                                 f'{self.min_frame_height} m (the floor)')
            q = chosen
        rows = result.flange_rows
        if q is answer and rows is not None and not self.chain.has_tool:
            reached = np.array((rows[0:4], rows[4:8], rows[8:12], (0.0, 0.0, 0.0, 1.0)))
        else:
            reached = self.chain.fk(q)
        reached = self._base @ reached @ self._tool
        return ArmSolution(True, self._from_chain(q), '',
                           *pose_distance(reached.tolist(), target.tolist()))

    def _reaches(self, q_chain: np.ndarray, flange: np.ndarray, tol: float = 1e-6) -> bool:
        reached = self.chain.fk(q_chain)
        return bool(np.abs(reached - flange).max() < tol)

    def above_floor(self, q_chain: np.ndarray) -> bool:
        """Every joint frame above frame 1, and the tool frame, at least min_frame_height
        above base_link's floor (the tool's origin: the flange's, plus the chain's tool)."""
        points: Sequence[Tuple[float, ...]]
        if self.chain.has_tool:
            points = [tuple(f[:3, 3].tolist()) for f in self.chain.frames(q_chain)[1:]]
        else:
            origins: List[Tuple[float, float, float]] = []
            self.chain.fk_rows(q_chain, origins)
            points = origins[1:]
        b20, b21, b22, b23 = self._base[2].tolist()
        floor = -math.inf if self.min_frame_height is None else self.min_frame_height
        return bool(min(b20 * x + b21 * y + b22 * z for x, y, z in points) + b23 >= floor)

    def within_limits(self, positions: Vector, tol: float = 1e-9) -> bool:
        q = np.asarray(positions, float)
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))


def motion_duration(start: Vector, goal: Vector,
                    velocity_limits: Vector, scaling: float,
                    min_duration: float = 0.5) -> float:
    """Duration of a rest-to-rest cubic move whose peak joint speed (1.5x the average) stays
    within ``scaling`` times the velocity limits."""
    if not 0.0 < scaling <= 1.0:
        raise ValueError(f'velocity scaling must be within (0, 1], got {scaling}')
    step = np.abs(np.subtract(goal, start))
    return max(min_duration, float(np.max(1.5 * step / (np.asarray(velocity_limits) * scaling))))


# The longest motion an IK request may ask for [s] (a duration is sent as whole nanoseconds).
MAX_MOTION_S = 3600.0


@dataclass
class IKPlan:
    """What an IK request comes to: the joint positions and, to execute it, the duration of
    a rest-to-rest motion there that the joints' velocity limits allow; or why not."""
    success: bool
    message: str
    positions: Optional[np.ndarray] = None
    errors: Tuple[float, float] = (math.inf, math.inf)
    duration: Optional[float] = None


def plan_ik(kin: ArmKinematics, pose: np.ndarray, execute: bool, duration: float,
            scaling: float, current: Optional[Vector], seed: Optional[Sequence[float]] = None,
            default_scaling: float = 0.5, min_duration: float = 0.5) -> IKPlan:
    """Check an IK request (``pose``: 4x4 in base_link; ``duration`` 0: from ``scaling``, or
    ``default_scaling`` for 0; ``seed``: where to start the search, else ``current``) and
    solve it. Whatever the numbers, it answers: no request raises, and a motion it plans is
    one the simulator takes (never faster than the velocity limits, at most MAX_MOTION_S)."""
    def fail(message: str) -> IKPlan:
        return IKPlan(False, message)
    pose = np.asarray(pose, float)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        return fail('bad target: non-finite pose')
    if not (math.isfinite(duration) and 0.0 <= duration <= MAX_MOTION_S):
        return fail(f'bad duration {duration}: must be within [0, {MAX_MOTION_S:g}] s')
    if not (math.isfinite(scaling) and 0.0 <= scaling <= 1.0):
        return fail(f'bad velocity_scaling {scaling}: must be within [0, 1]')
    if execute and current is None:
        return fail('no joint_states received yet: cannot plan a motion from the current '
                    'position')
    start = None if current is None else np.asarray(current, float)
    if seed:
        if len(seed) != len(kin.joint_names) or not np.all(np.isfinite(seed)):
            return fail(f'bad seed {list(seed)}: needs {len(kin.joint_names)} finite values')
        start = np.asarray(seed, float)
    solution = kin.ik(pose, seed=start)
    if not solution.success or solution.positions is None:
        xyz = ', '.join(f'{v:.3f}' for v in pose[:3, 3])
        return fail(f'no IK solution for ({xyz}) in base_link: {solution.reason}')
    errors = (solution.position_error, solution.rotation_error)
    if not execute or current is None:
        return IKPlan(True, 'solved', solution.positions, errors)
    scaling = scaling or default_scaling
    # The fastest the joints allow (the simulator refuses a motion faster than that).
    fastest = motion_duration(current, solution.positions, kin.velocity_limits, 1.0, 0.0)
    if duration == 0.0:
        duration = motion_duration(current, solution.positions, kin.velocity_limits, scaling,
                                   min_duration)
        if duration > MAX_MOTION_S:
            return fail(f'the motion would take {duration:.3g} s at velocity_scaling '
                        f'{scaling:g} (at most {MAX_MOTION_S:g} s)')
    elif duration < fastest:
        return fail(f'duration {duration:g} s is too short: the joints\' velocity limits need '
                    f'at least {fastest:.3f} s for this motion')
    return IKPlan(True, f'solved; moving there in {duration:.2f} s', solution.positions,
                  errors, duration)
