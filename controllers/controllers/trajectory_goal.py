"""A FollowJointTrajectory goal as ros2_controllers' joint trajectory controller judges it
(no ROS): path tolerances while the trajectory runs, goal tolerances once it has ended, within
``goal_time_tolerance``.

Tolerances follow control_msgs/JointTolerance: for each joint a position and a velocity bound
on |reference - feedback|; 0 (or a joint left out) means not checked, and -1 erases a default
(there are no defaults here, so it is the same as 0). Acceleration tolerances are accepted but
not checked: the simulator measures no joint acceleration.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Tuple

# control_msgs/action/FollowJointTrajectory result codes.
SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
OLD_HEADER_TIMESTAMP = -3
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5


@dataclass(frozen=True)
class Tolerance:
    position: float = 0.0
    velocity: float = 0.0
    acceleration: float = 0.0


@dataclass(frozen=True)
class Outcome:
    """How a goal ended: a result code, and in words why."""
    code: int
    message: str

    @property
    def succeeded(self) -> bool:
        return self.code == SUCCESSFUL


def check_tolerances(joint_names: Sequence[str],
                     tolerances: Sequence[Tuple[str, Tolerance]]) -> str:
    """Why these tolerances cannot be used for these joints ('' if they can)."""
    for name, tol in tolerances:
        if name not in joint_names:
            return f'a tolerance names "{name}", which is not a joint of this controller'
        for what, value in (('position', tol.position), ('velocity', tol.velocity),
                            ('acceleration', tol.acceleration)):
            if not math.isfinite(value) or (value < 0.0 and value != -1.0):
                return (f'the {what} tolerance of "{name}" is {value}: it must be finite and '
                        '>= 0 (or -1, which erases a default)')
    return ''


class GoalMonitor:
    """Judges one goal from the reference and the feedback at the times given."""

    def __init__(self, joint_names: Sequence[str], end_time: float,
                 path: Sequence[Tuple[str, Tolerance]] = (),
                 goal: Sequence[Tuple[str, Tolerance]] = (),
                 goal_time_tolerance: float = 0.0) -> None:
        self.joint_names = tuple(joint_names)
        self.end_time = end_time
        self._path = _by_index(self.joint_names, path)
        self._goal = _by_index(self.joint_names, goal)
        self.goal_time_tolerance = max(0.0, goal_time_tolerance)

    def check(self, now: float, reference: Sequence[float], reference_velocity: Sequence[float],
              feedback: Sequence[float], feedback_velocity: Sequence[float]
              ) -> Optional[Outcome]:
        """None while the goal runs; its outcome once decided."""
        if now < self.end_time:
            broken = _violation(self.joint_names, self._path, reference, reference_velocity,
                                feedback, feedback_velocity)
            if broken:
                return Outcome(PATH_TOLERANCE_VIOLATED, f'path tolerance violated: {broken}')
            return None
        broken = _violation(self.joint_names, self._goal, reference, reference_velocity,
                            feedback, feedback_velocity)
        if not broken:
            return Outcome(SUCCESSFUL, 'the trajectory was followed within its tolerances')
        late = now - self.end_time
        if self.goal_time_tolerance > 0.0 and late > self.goal_time_tolerance:
            return Outcome(GOAL_TOLERANCE_VIOLATED, f'goal tolerance violated {late:.3f} s '
                           f'after the trajectory ended (goal_time_tolerance '
                           f'{self.goal_time_tolerance:.3f} s): {broken}')
        return None


def _by_index(joint_names: Sequence[str], tolerances: Sequence[Tuple[str, Tolerance]]
              ) -> Dict[int, Tolerance]:
    return {joint_names.index(name): tol for name, tol in tolerances}


def _violation(joint_names: Sequence[str], tolerances: Dict[int, Tolerance],
               reference: Sequence[float], reference_velocity: Sequence[float],
               feedback: Sequence[float], feedback_velocity: Sequence[float]) -> str:
    for i, tol in sorted(tolerances.items()):
        error = abs(reference[i] - feedback[i])
        if tol.position > 0.0 and not error <= tol.position:
            return (f'{joint_names[i]} is {error:.4f} from its reference (position tolerance '
                    f'{tol.position:.4f})')
        speed_error = abs(reference_velocity[i] - feedback_velocity[i])
        if tol.velocity > 0.0 and not speed_error <= tol.velocity:
            return (f'{joint_names[i]} moves {speed_error:.4f} off its reference velocity '
                    f'(velocity tolerance {tol.velocity:.4f})')
    return ''
