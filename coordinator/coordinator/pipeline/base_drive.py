"""The youBot's base on its way (no ROS): a Bezier path from where it is, through the cell's
way points, to a stand or home, followed by a PD path follower (run by the port in real time,
from the ticks in lock-step), until it is there or out of time. The only writer of the drive's
state."""
from __future__ import annotations

import math
from typing import Any, Optional, Sequence

from controllers.bezier import BezierPath, Pose2D, key_poses_between
from controllers.path_follower import PathFollower, PDGains, TurnLimits
from coordinator.pipeline.model import Observation, Ports, Settings, known
from coordinator.pipeline.record import EventLog
from trial_record.events import EventKind


class BaseDrive:
    def __init__(self, robot: str, ports: Ports, log: EventLog, settings: Settings) -> None:
        self.robot, self.ports, self.log, self.s = robot, ports, log, settings
        self._follower: Optional[PathFollower] = None   # while the base drives
        self._followed = False                           # the port runs the follower
        self.goal = ''                                   # the last drive's: a stand, or home
        self.target: Optional[Pose2D] = None             # the drive's end pose
        self.deadline = math.inf

    @property
    def driving(self) -> bool:
        """Whether the base is on its way."""
        return self._follower is not None

    def steer(self, obs: Observation) -> None:
        """The base along its path, with its follower, until it is there or out of time."""
        follower = known(self._follower, 'the path follower')
        status = follower.update(obs.now, obs.youbot_pose, obs.youbot_velocity[:2],
                                 obs.youbot_velocity[2])
        if not self._followed:
            self.ports.drive(*status.command)
        if not (status.finished or obs.now > self.deadline):
            return
        self._follower = None
        self.ports.follow(None)
        self.ports.drive(0.0, 0.0, 0.0)
        if not status.finished:
            self.log.event(obs.now, EventKind.DRIVE_STALLED, self.robot, detail=(
                f'{status.position_error * 1000:.0f} mm from {self.goal}'))
        self.log.event(obs.now, EventKind.ARRIVED, self.robot, detail=self.goal)

    def follow(self, obs: Observation, target: Pose2D, via: Sequence[Any], goal: str) -> None:
        """The base off along a path from where it is through ``via`` to ``target`` (at stand
        or home ``goal``)."""
        x, y, yaw = (float(v) for v in obs.youbot_pose)
        path = BezierPath(key_poses_between((x, y, yaw), target, via))
        # Mecanum: the heading turns on its own profile in time while the base travels the
        # path, both over the same time (a short path with a large turn takes the turn's).
        self._follower = PathFollower(
            path, obs.now, self.s.drive_speed, self.s.drive_accel,
            PDGains(max_speed=self.s.base_max_speed, max_turn=self.s.base_max_turn),
            turn=TurnLimits(self.s.drive_turn, self.s.drive_turn_accel))
        self._followed = self.ports.follow(self._follower)
        self.goal, self.target = goal, target
        self.log.event(obs.now, EventKind.DRIVING, self.robot,
                       detail=f'to {goal}, {path.length:.2f} m')
        self.deadline = (obs.now + self._follower.profile.duration
                                + self.s.drive_margin)

    def stand_pose(self, obs: Observation) -> Pose2D:
        """Where the base stands for its unloads: its drive's end while it is on its way."""
        if self.driving:
            return known(self.target, 'the drive\'s end')
        return obs.youbot_pose
