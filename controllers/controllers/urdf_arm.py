"""An arm's kinematics from its URDF, for any serial arm (no ROS): pinocchio's model of the
chain from the URDF's root link (the robot's base_link) to a tool frame (a link and an offset
in it), the joints an arm controller drives (every other joint held at its zero), their limits
as the URDF gives them.

Forward kinematics is pinocchio's. Inverse kinematics is damped least squares (Levenberg-
Marquardt on the pose error's SE(3) log, steps clipped to the joint limits), seeded from the
given posture; an arm with more joints than the task needs (a 7-joint arm; a 6-joint arm whose
tool is free to turn about its axis, as a suction cup is) moves in the task's null space
towards a preferred posture: the seed, so that successive solutions along a motion stay on
one branch. Where the seed does not converge, the search restarts from postures drawn from a
generator seeded by the target, so the same request always gives the same answer.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pinocchio as pin

from controllers.arm_model import ArmSolution, FrameLookup
from controllers.arrays import Vector

# Converged: the tool within these of the target [m, rad] (promised: 1e-6 of each).
POSITION_TOLERANCE = 1e-9
ROTATION_TOLERANCE = 1e-9
# Iterations per start, and starts after the seed's (drawn within the limits).
MAX_ITERATIONS = 100
# A start is given up once its error has not halved in STALL_ITERATIONS iterations.
STALL_ITERATIONS = 8
RESTARTS = 200
# Solutions stay this far inside each joint's position limits [rad or m].
LIMIT_MARGIN_RAD = 0.02
# Damping: lambda = DAMPING_GAIN * |error|^2 + DAMPING_FLOOR (large steps damped, the last
# ones Gauss-Newton), and at most MAX_STEP_RAD per joint per iteration.
DAMPING_GAIN = 0.05
DAMPING_FLOOR = 1e-10
MAX_STEP_RAD = 1.0
# The pull towards the preferred posture in the task's null space: this share of the way
# there per iteration, at most POSTURE_STEP_RAD a joint, once the error (position + rotation)
# is below NULL_SPACE_FROM, until the pull moves no joint more than POSTURE_REST_RAD (or for
# POSTURE_ITERATIONS at most).
NULL_SPACE_GAIN = 1.0
NULL_SPACE_FROM, NULL_SPACE_UNTIL = 1e-2, 1e-7
POSTURE_STEP_RAD = 0.3
POSTURE_REST_RAD = 1e-4
POSTURE_ITERATIONS = 60
# Whether a seeded solve settles too (else: it keeps near its seed).
SETTLE_FROM_SEED = True
# The error's rows: angular x, y; linear x, y, z; angular z (dropped for a free yaw).
_ROWS = np.array([3, 4, 0, 1, 2, 5])


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
        rng = np.random.default_rng(_target_key(target))
        best: Tuple[float, str] = (math.inf, '')
        # Solutions keep LIMIT_MARGIN_RAD inside the limits (a motion planned through one at a
        # limit overshoots it between its samples); a pose reached only nearer its limits is
        # solved within them, from fewer starts.
        inner = np.minimum(LIMIT_MARGIN_RAD, (self.upper - self.lower) / 4)
        for margin, starts in ((inner, RESTARTS + 1), (0.0 * inner, RESTARTS // 4 + 1)):
            low, high = self._model_q(self.lower + margin), self._model_q(self.upper - margin)
            for attempt in range(starts):
                q0 = first if attempt == 0 else rng.uniform(low, high)
                # (From the seed, the arm moves little in the null space: a motion's
                # successive solutions stay on one branch. From no seed or a restart, it
                # settles nearest the preferred posture.)
                q, error = self._descend(goal, q0, prefer, low, high,
                                         settle=SETTLE_FROM_SEED or seed is None or attempt > 0)
                if error > POSITION_TOLERANCE + ROTATION_TOLERANCE:
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
                 high: np.ndarray, settle: bool = True) -> Tuple[np.ndarray, float]:
        """Damped least squares from ``q``: the posture and its error (position + rotation).
        An arm the task leaves free (more joints than its rows) is drawn towards ``prefer`` in
        the task's null space once near the target: with ``settle``, until that pull comes to
        rest (at most POSTURE_ITERATIONS); without, no joint further per iteration than the
        task's error (a seed's posture kept but for a drift back towards ``prefer``: the
        nearest point to ``prefer`` can jump as the target moves, 1 rad for a 1 cm step
        down to the floor). Then it converges on the task alone."""
        model, data, tool = self.model, self.data, self._tool
        rows = _ROWS[:5] if self.free_yaw else _ROWS
        posture = len(rows) < self.dof
        error, history = math.inf, []
        for iteration in range(MAX_ITERATIONS):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacement(model, data, tool)
            here = data.oMf[tool]
            aim = _turned_to(goal, here) if self.free_yaw else goal
            offset = here.actInv(aim)
            e = pin.log6(offset).vector
            lx, ly, lz, ax, ay, az = e.tolist()
            error = math.sqrt(lx * lx + ly * ly + lz * lz) + math.sqrt(ax * ax + ay * ay + az * az)
            pulling = (posture and error < NULL_SPACE_FROM and iteration < POSTURE_ITERATIONS
                       and (settle or error > NULL_SPACE_UNTIL))
            if error <= POSITION_TOLERANCE + ROTATION_TOLERANCE and not pulling:
                break
            if not pulling:
                history.append(error)
                if (len(history) > STALL_ITERATIONS
                        and error > 0.5 * history[-STALL_ITERATIONS - 1]):
                    break
            jac = pin.Jlog6(offset.inverse()) @ pin.getFrameJacobian(model, data, tool,
                                                                     pin.LOCAL)
            step = self._step(jac[rows], e[rows], q, prefer if pulling else None, low, high,
                              POSTURE_STEP_RAD if settle else error)
            biggest = float(np.abs(step).max())
            if pulling and biggest < POSTURE_REST_RAD:
                posture = False             # (at rest: the closest it comes to ``prefer``)
            if biggest > MAX_STEP_RAD:
                step *= MAX_STEP_RAD / biggest
            q = np.clip(q + step, low, high)
        return q, error

    def _step(self, jt: np.ndarray, et: np.ndarray, q: np.ndarray, prefer: Optional[np.ndarray],
              low: np.ndarray, high: np.ndarray, pull_most: float = 0.0) -> np.ndarray:
        """The damped least-squares step, joints at a limit that it would push further out
        left still (their columns dropped: the others take up the task), and, with
        ``prefer``, the pull towards it in the task's null space (at most ``pull_most`` a
        joint)."""
        damping = DAMPING_GAIN * float(et @ et) + DAMPING_FLOOR
        j, free = jt, None
        for _ in range(3):
            inner = j @ j.T
            inner.flat[::inner.shape[0] + 1] += damping
            if prefer is None:
                step: np.ndarray = j.T @ np.linalg.solve(inner, et)
            else:
                pull = np.clip(NULL_SPACE_GAIN * (prefer - q), -pull_most, pull_most)
                if free is not None:
                    pull *= free
                step = pull + j.T @ np.linalg.solve(inner, et - j @ pull)
            blocked = ((q <= low) & (step < 0.0)) | ((q >= high) & (step > 0.0))
            if free is not None:
                blocked &= free
            if not blocked.any():
                break
            free = ~blocked if free is None else free & ~blocked
            j = jt * free
        return step

    def _answer(self, positions: np.ndarray, target: np.ndarray) -> ArmSolution:
        reached = self.fk(positions)
        position_error = float(np.linalg.norm(reached[:3, 3] - target[:3, 3]))
        if self.free_yaw:       # the angle between the tool axes
            cos = float(np.clip(reached[:3, 2] @ target[:3, 2], -1.0, 1.0))
            rotation_error = math.acos(cos)
        else:
            rotation_error = float(np.linalg.norm(pin.log3(reached[:3, :3].T @ target[:3, :3])))
        return ArmSolution(True, positions.copy(), '', position_error, rotation_error)


def _ancestors(model: pin.Model, joint: int) -> List[int]:
    out = []
    while joint > 0:
        out.append(joint)
        joint = model.parents[joint]
    return out


def _orthonormal(rotation: np.ndarray) -> np.ndarray:
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
