"""An arm's kinematics from its URDF, for any serial arm (no ROS): pinocchio's model of the
chain from the URDF's root link (the robot's base_link) to a tool frame (a link and an offset
in it), the joints an arm controller drives (every other joint held at its zero), their limits
as the URDF gives them.

Forward kinematics is pinocchio's. Inverse kinematics is damped least squares (Levenberg-
Marquardt on the pose error's SE(3) log, steps clipped to the joint limits), seeded from the
given posture; an arm with more joints than the task needs (a 7-joint arm; a 6-joint arm whose
tool is free to turn about its axis, as a suction cup is) then moves in the task's null space
to the posture nearest a preferred one (its home) on the branch the seed leads to, so that
successive solutions along a motion stay on one branch and do not wander. Where the seed does
not converge, the search starts again from the preferred posture, then from postures drawn
from a generator seeded by the target, so the same request always gives the same answer.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import eigenpy
import numpy as np
import pinocchio as pin

from controllers.arm_model import ArmSolution, FrameLookup
from controllers.arrays import Vector

# Converged: the tool within these of the target [m, rad] (promised: 1e-6 of each).
POSITION_TOLERANCE = 1e-9
ROTATION_TOLERANCE = 1e-9
# Iterations per start, and starts after the seed's (the preferred posture, then postures
# drawn within the limits).
MAX_ITERATIONS = 100
# A start is given up once its error has not halved in STALL_ITERATIONS iterations of the
# task alone in a row.
STALL_ITERATIONS = 5
RESTARTS = 200
# Solutions stay this far inside each joint's position limits [rad or m].
LIMIT_MARGIN_RAD = 0.02
# Damping: lambda = DAMPING_GAIN * |error|^2 + DAMPING_FLOOR (large steps damped, the last
# ones Gauss-Newton), and at most MAX_STEP_RAD per joint per iteration.
DAMPING_GAIN = 0.05
DAMPING_FLOOR = 1e-10
MAX_STEP_RAD = 1.0
# The pull towards the preferred posture in the task's null space, once the error (position
# + rotation) is below NULL_SPACE_FROM: the way there projected on the null space, times a
# gain (NULL_SPACE_GAIN at first, then the secant's within MIN_PULL_GAIN and MAX_PULL_GAIN,
# _pull_gain), at most POSTURE_STEP_RAD a joint, until it moves no joint more than
# POSTURE_REST_RAD (or for POSTURE_ITERATIONS at most).
NULL_SPACE_GAIN = 1.0
NULL_SPACE_FROM = 1e-2
POSTURE_STEP_RAD = 0.3
POSTURE_REST_RAD = 1e-4
POSTURE_ITERATIONS = 60
MIN_PULL_GAIN, MAX_PULL_GAIN = 0.5, 20.0

_FACTORED = eigenpy.ComputationInfo.Success
_EYE3 = np.eye(3)


class UrdfArmError(ValueError):
    """An arm the URDF does not describe as a serial chain of the named joints to the tool."""


class UrdfArm(FrameLookup):
    """FK and IK of the chain of ``joint_names`` (in that order) from the URDF's root link to
    ``tool_link`` translated by ``tool_offset`` (in the link's frame). ``free_yaw``: the tool's
    rotation about its z axis is free (a suction cup's), the IK keeps it nearest the seed's.
    ``floor``: solutions that put a joint's origin lower than this in base_link are refused
    (the floor, or the table the arm stands on). ``reference_frames``: frames a target may be
    given in, as transforms from base_link (``world``, for a fixed base)."""

    def __init__(self, urdf: Path, joint_names: Sequence[str], tool_link: str,
                 tool_offset: Vector = (0.0, 0.0, 0.0), free_yaw: bool = False,
                 floor: Optional[float] = None,
                 reference_frames: Optional[Dict[str, np.ndarray]] = None,
                 preferred: Optional[Vector] = None) -> None:
        try:
            full = pin.buildModelFromUrdf(str(urdf))
        except (RuntimeError, ValueError) as exc:
            raise UrdfArmError(f'{urdf}: not a URDF pinocchio reads: {exc}') from None
        names = list(full.names)
        unknown = [j for j in joint_names if j not in names]
        if unknown:
            raise UrdfArmError(f'{urdf}: no joint {unknown} (joints: {names[1:]})')
        if not full.existFrame(tool_link):
            raise UrdfArmError(f'{urdf}: no link "{tool_link}"')
        moving = [names[j] for j in _ancestors(full, full.frames[full.getFrameId(tool_link)]
                                               .parentJoint)]
        undriven = [n for n in reversed(moving) if n not in joint_names]
        if undriven:
            raise UrdfArmError(f'{urdf}: joints {undriven} move {tool_link} but are not among '
                               f'the arm\'s joints {list(joint_names)}')
        others = [full.getJointId(n) for n in names[1:] if n not in joint_names]
        model = pin.buildReducedModel(full, others, pin.neutral(full)) if others else full
        for j in range(1, model.njoints):
            if model.joints[j].nq != 1:
                raise UrdfArmError(f'{urdf}: joint {model.names[j]} is not revolute or '
                                   'prismatic (continuous and floating joints are not '
                                   'supported)')
        link = model.frames[model.getFrameId(tool_link)]
        chain = _ancestors(model, link.parentJoint)
        off_chain = [model.names[j] for j in range(1, model.njoints) if j not in chain]
        if off_chain:
            raise UrdfArmError(f'{urdf}: joints {off_chain} do not move {tool_link}: an arm '
                               'is the chain from the base to its tool')
        placement = link.placement * pin.SE3(np.eye(3), np.asarray(tool_offset, float))
        self._tool = model.addFrame(pin.Frame('arm_tool', link.parentJoint, placement,
                                              pin.FrameType.OP_FRAME))
        self.model, self.data = model, model.createData()
        self.joint_names = tuple(joint_names)
        # pinocchio's order (the tree's) -> ours, and back.
        self._index = np.array([model.getJointId(n) - 1 for n in joint_names])
        self.lower = model.lowerPositionLimit[self._index].copy()
        self.upper = model.upperPositionLimit[self._index].copy()
        self.velocity_limits = model.velocityLimit[self._index].copy()
        self.effort_limits = model.effortLimit[self._index].copy()
        if not (np.all(np.isfinite(self.lower)) and np.all(self.lower < self.upper)):
            raise UrdfArmError(f'{urdf}: every arm joint needs position limits')
        if not np.all(self.velocity_limits > 0.0):
            raise UrdfArmError(f'{urdf}: every arm joint needs a velocity limit')
        self.tool_frame, self.tool_link = 'arm_tool', tool_link
        self.free_yaw, self.floor = free_yaw, floor
        self.reference_frames = {'base_link': np.eye(4), **(reference_frames or {})}
        self.dof = len(self.joint_names)
        self._shoulder, self._reach = self._reach_bound()
        # The posture the null space pulls towards (the arm's home; by default the middle of
        # its limits): where the task leaves the arm free, it does not wander along a motion.
        middle = (self.lower + self.upper) / 2
        self.preferred = middle if preferred is None else np.clip(
            np.asarray(preferred, float), self.lower, self.upper)

    def _reach_bound(self) -> Tuple[np.ndarray, float]:
        """The first joint's origin and how far from it the tool can be at most (the chain's
        joint-to-joint distances, constant for revolute joints, plus each prismatic joint's
        travel): a target further off is out of reach without a search."""
        origins = self.joint_origins(np.clip(np.zeros(self.dof), self.lower, self.upper))
        reach = float(np.sum(np.linalg.norm(np.diff(origins, axis=0), axis=1)))
        for j in range(1, self.model.njoints):
            if self.model.joints[j].shortname().startswith('JointModelP'):
                reach += float(self.model.upperPositionLimit[j - 1]
                               - self.model.lowerPositionLimit[j - 1])
        return origins[0], reach

    # --- forward ------------------------------------------------------------------------------
    def _model_q(self, q: Vector) -> np.ndarray:
        out = np.empty(self.dof)
        out[self._index] = np.asarray(q, float)
        return out

    def fk(self, positions: Vector) -> np.ndarray:
        """4x4 pose of the tool frame in base_link."""
        pin.framesForwardKinematics(self.model, self.data, self._model_q(positions))
        pose: np.ndarray = self.data.oMf[self._tool].homogeneous
        return pose

    def joint_origins(self, positions: Vector) -> np.ndarray:
        """The joints' origins (and the tool's) in base_link, one row each."""
        pin.framesForwardKinematics(self.model, self.data, self._model_q(positions))
        rows = [self.data.oMi[j].translation for j in range(1, self.model.njoints)]
        return np.array(rows + [self.data.oMf[self._tool].translation])

    def above_floor(self, positions: Vector) -> bool:
        """Every joint's origin but the first, and the tool's, above ``floor`` (if given)."""
        if self.floor is None:
            return True
        return bool(np.min(self.joint_origins(positions)[1:, 2]) >= self.floor)

    def within_limits(self, positions: Vector, tol: float = 1e-9) -> bool:
        q = np.asarray(positions, float)
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    # --- inverse ------------------------------------------------------------------------------
    def ik(self, target: np.ndarray, seed: Optional[Vector] = None) -> ArmSolution:
        """Joint positions within the limits that put the tool frame at ``target`` (4x4 in
        base_link), from ``seed`` (else the preferred posture) and, failing that, from
        restarts; a failure names why."""
        target = np.asarray(target, float)
        if target.shape != (4, 4) or not math.isfinite(float(target.sum())):
            return ArmSolution(False, reason='target must be a finite 4x4 pose')
        far = float(np.linalg.norm(target[:3, 3] - self._shoulder))
        if far > self._reach + 1e-9:
            return ArmSolution(False, reason=f'out of reach: {far:.3f} m from the first joint, '
                                             f'the arm reaches {self._reach:.3f} m')
        goal = pin.SE3(_orthonormal(target[:3, :3]), target[:3, 3].copy())
        start = self.preferred if seed is None else np.clip(np.asarray(seed, float), self.lower,
                                                    self.upper)
        prefer = self._model_q(self.preferred)
        first = self._model_q(start)
        rng: Optional[np.random.Generator] = None
        best: Tuple[float, str] = (math.inf, '')
        nearest: Tuple[float, np.ndarray] = (math.inf, first)
        # Solutions keep LIMIT_MARGIN_RAD inside the limits (a motion planned through one at a
        # limit overshoots it between its samples); a pose reached only nearer its limits is
        # solved within them, from the nearest posture found within the margin and fewer
        # starts.
        inner = np.minimum(LIMIT_MARGIN_RAD, (self.upper - self.lower) / 4)
        for margin, starts in ((inner, RESTARTS + 1), (0.0 * inner, RESTARTS // 4 + 1)):
            low, high = self._model_q(self.lower + margin), self._model_q(self.upper - margin)
            for attempt in range(starts):
                # (The seed first: a motion's successive solutions stay on one branch. Then
                # the preferred posture, then postures drawn from a generator seeded by the
                # target.)
                if attempt == 0:
                    q0 = first if margin is inner else nearest[1]
                elif attempt == 1 and seed is not None:
                    q0 = np.minimum(np.maximum(prefer, low), high)
                else:
                    rng = rng or np.random.default_rng(_target_key(target))
                    q0 = rng.uniform(low, high)
                q, error = self._descend(goal, q0, prefer, low, high)
                if error > POSITION_TOLERANCE + ROTATION_TOLERANCE:
                    nearest = min(nearest, (error, q), key=lambda n: n[0])
                    best = min(best, (error, f'out of reach within the joint limits (nearest: '
                                             f'{error:.3g} off)'))
                    continue
                positions = q[self._index]
                if self.above_floor(positions):
                    return self._answer(positions, target)
                best = min(best, (0.0, f'every solution found puts a joint below the floor '
                                       f'({self.floor:.3f} m in base_link)'))
        return ArmSolution(False, reason=best[1])

    def _descend(self, goal: pin.SE3, q: np.ndarray, prefer: np.ndarray, low: np.ndarray,
                 high: np.ndarray) -> Tuple[np.ndarray, float]:
        """Damped least squares from ``q``: the posture and its error (position + rotation).
        An arm the task leaves free (more joints than its rows) is drawn towards ``prefer`` in
        the task's null space once near the target, until that pull comes to rest (at most
        POSTURE_ITERATIONS): the posture nearest ``prefer`` on the branch the start leads to,
        whatever the start on it, so that a motion's successive solutions do not wander.
        Then it converges on the task alone. (Written for speed: an iteration is some twenty
        calls into pinocchio and numpy, bench/bench_arm_ik.py.)"""
        model, data, tool = self.model, self.data, self._tool
        rows = 5 if self.free_yaw else 6        # (pinocchio's log6: linear, then angular z last)
        posture = rows < self.dof
        tolerance = POSITION_TOLERANCE + ROTATION_TOLERANCE
        error = math.inf
        history: List[float] = []      # (the task's errors, its own iterations in a row)
        gain, last = NULL_SPACE_GAIN, None
        for iteration in range(MAX_ITERATIONS):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacement(model, data, tool)
            here = data.oMf[tool]
            offset = here.actInv(_turned_to(goal, here) if self.free_yaw else goal)
            e = pin.log6(offset).vector
            lx, ly, lz, ax, ay, az = e.tolist()
            error = math.sqrt(lx * lx + ly * ly + lz * lz) + math.sqrt(ax * ax + ay * ay + az * az)
            pulling = posture and error < NULL_SPACE_FROM and iteration < POSTURE_ITERATIONS
            if error <= tolerance and not pulling:
                break
            if pulling:
                history.clear()     # (a stall is told on the task's own iterations in a row)
            else:
                history.append(error)
                if (len(history) > STALL_ITERATIONS
                        and error > 0.5 * history[-STALL_ITERATIONS - 1]):
                    break
            jac = pin.Jlog6(offset.inverse()) @ pin.getFrameJacobian(model, data, tool,
                                                                     pin.LOCAL)
            squared = lx * lx + ly * ly + lz * lz + ax * ax + ay * ay + (
                0.0 if self.free_yaw else az * az)
            damping = DAMPING_GAIN * squared + DAMPING_FLOOR
            if pulling:
                step, null = self._step(jac[:rows], e[:rows], damping, q, prefer, low, high,
                                        POSTURE_STEP_RAD, gain)
            else:
                step, null = self._step(jac[:rows], e[:rows], damping, q, None, low, high)
            biggest = max(-float(step.min()), float(step.max()))
            if pulling and biggest < POSTURE_REST_RAD:
                posture = False             # (at rest: the closest it comes to ``prefer``)
            elif pulling and null is not None:
                gain, last = _pull_gain(q, null, last), (q, null)
            if biggest > MAX_STEP_RAD:
                step *= MAX_STEP_RAD / biggest
            q = np.minimum(np.maximum(q + step, low), high)
        return q, error

    def _step(self, jt: np.ndarray, et: np.ndarray, damping: float, q: np.ndarray,
              prefer: Optional[np.ndarray], low: np.ndarray, high: np.ndarray,
              pull_most: float = 0.0,
              gain: float = NULL_SPACE_GAIN) -> Tuple[np.ndarray, Optional[np.ndarray]]:
        """The damped least-squares step (``damping`` on the diagonal), joints at a limit
        that it would push further out left still (their columns dropped: the others take up
        the task), and, with ``prefer``, the way to it projected on the task's null space,
        times ``gain`` (scaled down to move no joint further than ``pull_most``). With the
        step, that projection (at a gain of one)."""
        pull = None if prefer is None else prefer - q
        at_low, at_high = q <= low, q >= high
        limited = bool((at_low | at_high).any())
        j, free, null = jt, None, None
        for _ in range(3):
            inner = j @ j.T
            inner.flat[::inner.shape[0] + 1] += damping
            factor = _spd_factor(inner)
            step: np.ndarray = j.T @ factor.solve(et)
            if pull is not None:
                if free is not None:
                    pull = pull * free
                null = pull - j.T @ factor.solve(j @ pull)
                most = max(-float(null.min()), float(null.max()))
                step = step + null * min(gain, pull_most / most) if most > 0.0 else step
            if not limited:
                break
            blocked = (at_low & (step < 0.0)) | (at_high & (step > 0.0))
            if free is not None:
                blocked &= free
            if not blocked.any():
                break
            free = ~blocked if free is None else free & ~blocked
            j = jt * free
        return step, null

    def _answer(self, positions: np.ndarray, target: np.ndarray) -> ArmSolution:
        reached = self.fk(positions)
        position_error = float(np.linalg.norm(reached[:3, 3] - target[:3, 3]))
        if self.free_yaw:       # the angle between the tool axes
            cos = float(np.clip(reached[:3, 2] @ target[:3, 2], -1.0, 1.0))
            rotation_error = math.acos(cos)
        else:
            rotation_error = float(np.linalg.norm(pin.log3(reached[:3, :3].T @ target[:3, :3])))
        return ArmSolution(True, positions.copy(), '', position_error, rotation_error)


def _pull_gain(q: np.ndarray, null: np.ndarray,
               last: Optional[Tuple[np.ndarray, np.ndarray]]) -> float:
    """The null-space pull's gain for its next step: the settle is a descent of the distance
    to the preferred posture along the self-motion, ``null`` its way down at ``q`` and
    ``last`` the posture and way of the pull before. A gain of one is the whole way where the
    self-motion is straight; it curves, and the step that takes it the rest of the way is
    the secant's (Barzilai and Borwein's), kept within MIN_PULL_GAIN and MAX_PULL_GAIN."""
    if last is None:
        return NULL_SPACE_GAIN
    moved, turned = q - last[0], last[1] - null
    curvature = float(moved @ turned)
    if curvature <= 0.0:
        return MAX_PULL_GAIN
    return min(MAX_PULL_GAIN, max(MIN_PULL_GAIN, float(moved @ moved) / curvature))


class _LuSolve:
    """numpy's general solve, for a matrix that rounding leaves not positive definite."""

    def __init__(self, matrix: np.ndarray) -> None:
        self.matrix = matrix

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        out: np.ndarray = np.linalg.solve(self.matrix, rhs)
        return out


def _spd_factor(matrix: np.ndarray) -> Union[eigenpy.LLT, _LuSolve]:
    """``matrix`` (symmetric positive definite: damped) factored once for the solves of one
    step: by Cholesky (a fifth of numpy's general solve's time on 6x6), by LU where rounding
    leaves it not positive definite."""
    llt = eigenpy.LLT(matrix)
    return llt if llt.info() == _FACTORED else _LuSolve(matrix)


def _ancestors(model: pin.Model, joint: int) -> List[int]:
    out = []
    while joint > 0:
        out.append(joint)
        joint = model.parents[joint]
    return out


def _orthonormal(rotation: np.ndarray) -> np.ndarray:
    """The rotation nearest ``rotation`` (a target's rotation may come rounded)."""
    (a, b, c), (d, e, f), (g, h, i) = rotation.tolist()
    if (a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) > 0.0
            and float(np.abs(rotation @ rotation.T - _EYE3).max()) < 1e-12):
        same: np.ndarray = rotation.copy()      # (a rotation already: as given)
        return same
    u, _, vt = np.linalg.svd(rotation)
    out: np.ndarray = u @ vt
    if np.linalg.det(out) < 0.0:
        out = -out
    return out


def _turned_to(goal: pin.SE3, here: pin.SE3) -> pin.SE3:
    """``goal`` turned about its own z axis to the yaw nearest ``here``'s (a tool free to turn
    about its axis)."""
    r = goal.rotation
    x = here.rotation[:, 0]
    angle = math.atan2(float(x @ r[:, 1]), float(x @ r[:, 0]))
    c, s = math.cos(angle), math.sin(angle)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return pin.SE3(r @ turn, goal.translation)


def _target_key(target: np.ndarray) -> int:
    """A generator seed from the target's bits: the same request, the same restarts."""
    return int.from_bytes(np.ascontiguousarray(target[:3]).tobytes()[::7][:8], 'little')
