"""The pipeline cell's props in PyBullet: the conveyor, the material source and the suction tool.

The belt is a static box; each physics step, whatever rests on its top surface is given the belt's
velocity along the belt (no slip: the belt carries it; lifting it breaks the contact). With an end
stop, what reaches the stop, or a material held there, stays put while the belt runs on beneath
it (controllers.conveyor's accumulation rule, which the coordinator predicts with). The source
drops the scenario's materials, in a seeded random order, at the belt's upstream end, one each
time the belt has travelled a seeded random gap. The suction tool holds a material with a fixed
constraint while it is on and the material was within reach when it was switched on.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Any, List, Optional, Sequence, Tuple

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from controllers.arrays import Vector
from controllers.conveyor import Item, advance
from controllers.transforms import matrix_to_quaternion
from world_description.perturbations import MaterialDraw, PerturbationDraws
from world_description.world_config import ConveyorConfig, MaterialsConfig
from world_description.world_schema import END_STOP_HEIGHT_M, END_STOP_THICKNESS_M

BELT_THICKNESS_M = 0.04
BELT_COLOR = (0.15, 0.15, 0.17, 1.0)
END_STOP_COLOR = (0.8, 0.7, 0.1, 1.0)
STAND_COLOR = (0.45, 0.47, 0.5, 1.0)


@dataclass
class MaterialBody:
    """A material as the simulator holds it: a rigid body of the scenario (ground truth)."""
    index: int                 # order of appearance, 0-based: its ground-truth id
    color: str
    body: int
    spawned_at: float          # simulated time [s]
    size: float = 0.05         # cube edge [m] (its class's)
    mass: float = 0.1          # [kg]
    name: str = ''             # a spawned material's name (the simulation interfaces)


class Conveyor:
    def __init__(self, client: BulletClient, config: ConveyorConfig) -> None:
        self._p, self.config = client, config
        self.direction = np.array([math.cos(config.yaw), math.sin(config.yaw), 0.0])
        self.lateral = np.array([-math.sin(config.yaw), math.cos(config.yaw), 0.0])
        self.top = np.asarray(config.position, float)
        self._direction, self._lateral, self._top = (
            tuple(float(v) for v in a) for a in (self.direction, self.lateral, self.top))
        self._speed = config.belt_speed
        self.travel = 0.0                     # belt travel since the start [m]
        orn = client.getQuaternionFromEuler((0.0, 0.0, config.yaw))
        half = (config.length / 2, config.width / 2, BELT_THICKNESS_M / 2)
        belt_col = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        belt_vis = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=half,
                                            rgbaColor=BELT_COLOR)
        centre = self.top - np.array([0.0, 0.0, BELT_THICKNESS_M / 2])
        self.body = client.createMultiBody(0.0, belt_col, belt_vis, basePosition=centre,
                                           baseOrientation=orn)
        # No friction: carry() imposes the belt's velocity on what rests on it each step, and
        # friction against a static box would brake it within the step.
        client.changeDynamics(self.body, -1, lateralFriction=0.0, rollingFriction=0.0,
                              spinningFriction=0.0)
        # The stop's face is the belt's downstream end: the whole belt stays usable.
        self.stop_along = config.length if config.end_stop else math.inf
        self.stop_body: Optional[int] = None
        if config.end_stop:
            stop_half = (END_STOP_THICKNESS_M / 2, config.width / 2,
                         (END_STOP_HEIGHT_M + BELT_THICKNESS_M) / 2)
            stop_centre = (self.point(config.length + END_STOP_THICKNESS_M / 2)
                           + np.array([0.0, 0.0, (END_STOP_HEIGHT_M - BELT_THICKNESS_M) / 2]))
            self.stop_body = client.createMultiBody(
                0.0, client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=stop_half),
                client.createVisualShape(pybullet.GEOM_BOX, halfExtents=stop_half,
                                         rgbaColor=END_STOP_COLOR),
                basePosition=stop_centre, baseOrientation=orn)
        stand_h = centre[2] - BELT_THICKNESS_M / 2
        self.stand_body: Optional[int] = None
        if stand_h > 0.01:
            stand_half = (config.length / 2 * 0.95, config.width / 2 * 0.8, stand_h / 2)
            stand_col = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=stand_half)
            stand_vis = client.createVisualShape(pybullet.GEOM_BOX, halfExtents=stand_half,
                                                 rgbaColor=STAND_COLOR)
            self.stand_body = client.createMultiBody(
                0.0, stand_col, stand_vis, basePosition=(centre[0], centre[1], stand_h / 2),
                baseOrientation=orn)

    @property
    def speed(self) -> float:
        return self._speed

    @speed.setter
    def speed(self, value: float) -> None:
        if not (math.isfinite(value) and 0.0 <= value <= 2.0):
            raise ValueError(f'belt speed must be within [0, 2] m/s, got {value}')
        self._speed = float(value)

    def point(self, along: float, across: float = 0.0) -> np.ndarray:
        """A point on the belt's top surface, ``along`` from its upstream end."""
        return (self.top + (along - self.config.length / 2) * self.direction
                + across * self.lateral)

    def on_belt(self, body: int) -> bool:
        """Whether ``body`` rests on the belt (a contact whose normal points up)."""
        for contact in self._p.getContactPoints(bodyA=self.body, bodyB=body):
            if contact[7][2] < -0.7:       # the normal on B points towards A (the belt): down
                return True
        return False

    def resting(self, bodies: Sequence[int]) -> List[int]:
        """Those of ``bodies`` that rest on the belt (as :meth:`on_belt`, with one query for
        them all)."""
        down = {c[2] for c in self._p.getContactPoints(bodyA=self.body) if c[7][2] < -0.7}
        return [body for body in bodies if body in down]

    def item(self, body: int) -> Item:
        """A body as the accumulation rule sees it: its centre and extents along and across."""
        lo, hi = self._p.getAABB(body)
        # (Plain floats: numpy's overhead on 3-vectors was most of a step's conveyor work.)
        rel = [(a + b) / 2 - t for a, b, t in zip(lo, hi, self._top)]
        extent = [b - a for a, b in zip(lo, hi)]
        d, n = self._direction, self._lateral
        return Item(along=rel[0] * d[0] + rel[1] * d[1] + rel[2] * d[2] + self.config.length / 2,
                    across=rel[0] * n[0] + rel[1] * n[1] + rel[2] * n[2],
                    length=abs(d[0]) * extent[0] + abs(d[1]) * extent[1] + abs(d[2]) * extent[2],
                    width=abs(n[0]) * extent[0] + abs(n[1]) * extent[1] + abs(n[2]) * extent[2])

    def in_lane(self, body: int) -> bool:
        """Whether ``body`` (off the belt: being lifted from it) is still low enough over the
        belt to block what the belt carries: its bottom below one of its own heights up."""
        lo, hi = (np.asarray(c, float) for c in self._p.getAABB(body))
        it = self.item(body)
        return (lo[2] < self.top[2] + (hi[2] - lo[2]) and 0.0 <= it.along <= self.stop_along
                and abs(it.across) <= self.config.width / 2)

    def carry(self, bodies: List[int], dt: float, lifted: Sequence[int] = (),
              speed: Optional[float] = None) -> None:
        """Move what rests on the belt this step as the accumulation rule says (the model the
        coordinator predicts with): at the belt's speed, or up to where the end stop, an item
        held ahead, or one being lifted off ahead (``lifted``: bodies off the belt, carried by
        a gripper) holds it, and no further; advance the belt's travel. ``speed``: this step's
        (the set speed drifting, a perturbation), else the set speed."""
        travel = (self._speed if speed is None else speed) * dt
        self.travel += travel
        resting = self.resting(bodies)
        items = [self.item(b) for b in resting]
        obstacles = [self.item(b) for b in lifted if self.in_lane(b)]
        ahead = advance(items, self.stop_along, travel, obstacles)
        for body, it, along in zip(resting, items, ahead):
            v, _ = self._p.getBaseVelocity(body)
            speed = (along - it.along) / dt
            vx, vy = speed * self._direction[0], speed * self._direction[1]
            # The vertical stays the contact's: its upward push-out, thrown away each step
            # before, let a carried material ride 5 mm deep in the belt at a 1/120 s step.
            self._p.resetBaseVelocity(body, (vx, vy, v[2]), (0.0, 0.0, 0.0))


class MaterialSource:
    """Drops the scenario's materials on the belt in a seeded random order and spacing; and
    materials of the world's classes spawned by request (the simulation interfaces), which the
    plan does not count. A material's index is its order of appearance, planned or spawned."""

    def __init__(self, client: BulletClient, conveyor: Conveyor, config: MaterialsConfig,
                 seed: Optional[int] = None,
                 draws: Optional[PerturbationDraws] = None) -> None:
        self._p, self._conveyor, self.config = client, conveyor, config
        self._colors = dict(config.colors)
        self.seed = config.seed if seed is None else seed
        # Each material's mass, edge and friction off its class's (the world's perturbations).
        self._draws = draws
        self.materials: List[MaterialBody] = []
        self.restart()

    def restart(self) -> None:
        """Remove every material and plan the scenario again from the seed."""
        for m in self.materials:
            self._p.removeBody(m.body)
        self.materials = []
        self._dropped = 0               # materials of the plan dropped so far
        self._next_index = 0
        rng = random.Random(self.seed)
        order = [color for color, n in self.config.counts for _ in range(n)]
        rng.shuffle(order)
        lo, hi = self.config.gap
        gaps = [0.0] + [rng.uniform(lo, hi) for _ in order[1:]]
        jitter = self.config.lateral_jitter
        self.plan: List[Tuple[str, float, float]] = []      # (colour, belt travel, across)
        travel = self._conveyor.travel
        for color, gap in zip(order, gaps):
            travel += gap
            self.plan.append((color, travel, rng.uniform(-jitter, jitter)))

    @property
    def done(self) -> bool:
        return self._dropped == len(self.plan)

    def update(self, sim_time: float) -> Optional[MaterialBody]:
        """Drop the next material once the belt has travelled its gap; return it."""
        if self.done:
            return None
        color, travel, across = self.plan[self._dropped]
        if self._conveyor.travel + 1e-12 < travel:
            return None
        size = self.config.cls(color).size * self._drawn(self._next_index).size_factor
        position = self.drop_point(size, across)
        orn = self._p.getQuaternionFromEuler((0.0, 0.0, self._conveyor.config.yaw))
        self._dropped += 1
        return self.spawn(color, position, orn, sim_time)

    def _drawn(self, index: int) -> MaterialDraw:
        """The ``index``-th material's draw (its class's own values without perturbations)."""
        return self._draws.material(index) if self._draws is not None else MaterialDraw()

    def drop_point(self, size: float, across: float = 0.0) -> np.ndarray:
        """Where a material of edge ``size`` is dropped: its centre just above the belt's
        upstream end."""
        position = self._conveyor.point(self.config.start_offset + size / 2, across)
        position[2] += size / 2 + 1e-4
        return position

    def spawn(self, color: str, position: Vector, orientation: Vector,
              sim_time: float) -> MaterialBody:
        """A material of class ``color`` at a pose (its centre), from now on one of the cell's
        materials (KeyError: no such class)."""
        cls = self.config.cls(color)
        drawn = self._drawn(self._next_index)
        size, mass = cls.size * drawn.size_factor, cls.mass * drawn.mass_factor
        half = (size / 2,) * 3
        col = self._p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        vis = self._p.createVisualShape(pybullet.GEOM_BOX, halfExtents=half,
                                        rgbaColor=self._colors[color])
        body = self._p.createMultiBody(
            mass, col, vis, basePosition=[float(v) for v in position],
            baseOrientation=[float(v) for v in orientation])
        self._p.changeDynamics(body, -1, lateralFriction=drawn.friction)
        material = MaterialBody(self._next_index, color, body, sim_time, size, mass)
        self._next_index += 1
        self.materials.append(material)
        return material

    def remove(self, material: MaterialBody) -> None:
        """Take a material out of the cell (a held one must be released first)."""
        self._p.removeBody(material.body)
        self.materials.remove(material)

    def pose(self, material: MaterialBody) -> Tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of a material's centre."""
        pos, orn = self._p.getBasePositionAndOrientation(material.body)
        return np.asarray(pos), np.array(self._p.getMatrixFromQuaternion(orn)).reshape(3, 3)


class Suction:
    """A suction cup at a robot link. Switched on, it is armed: it grips the first material
    that comes within reach (as a vacuum cup seals on a part it touches), at once or during a
    later step; switched off, it releases what it holds."""

    def __init__(self, client: BulletClient, robot: Any, link: str, reach: float,
                 max_payload: float, offset: Tuple[float, float, float] = (0.0, 0.0, 0.0)
                 ) -> None:
        self._p, self._robot = client, robot
        if link not in robot.link_index or robot.link_index[link] == -1:
            raise ValueError(f'robot "{robot.config.name}" has no link "{link}" for suction')
        self.link, self.reach, self.max_payload = link, reach, max_payload
        # The cup's point in the link's frame (None: the link's origin).
        self._offset = np.asarray(offset, float) if any(offset) else None
        self.held: Optional[MaterialBody] = None
        self.armed = False
        self._constraint: Optional[int] = None

    def cup_pose(self) -> Tuple[np.ndarray, np.ndarray]:
        """The cup's point and its link's rotation in the world."""
        origin, rot = self._robot.link_world_pose(self.link)
        return (origin if self._offset is None else origin + rot @ self._offset), rot

    def switch_on(self, source: Optional[MaterialSource]) -> Tuple[bool, str]:
        """Arm the cup; grips now if a material is within reach."""
        self.armed = True
        ok, message = self.grip(source)
        return True, message if ok else f'on; {message} yet'

    def update(self, source: Optional[MaterialSource]) -> None:
        """Each step: an armed cup without a part grips one that came within reach."""
        if self.armed and self.held is None and source is not None and source.materials:
            self.grip(source)

    def nearest(self, source: Optional[MaterialSource]
                ) -> Optional[Tuple[MaterialBody, float]]:
        """The material nearest the cup, and its distance from the cup's centre [m]."""
        if source is None or not source.materials:
            return None
        tcp, _ = self.cup_pose()
        return min(((m, _distance_to_box(tcp, *source.pose(m), m.size / 2))
                    for m in source.materials), key=lambda md: md[1])

    def grip(self, source: Optional[MaterialSource]) -> Tuple[bool, str]:
        if self.held is not None:
            return True, f'already holding material {self.held.index} ({self.held.color})'
        if source is None:
            return False, 'no materials in this world'
        tcp, rot = self.cup_pose()
        near = self.nearest(source)
        best, best_d = near if near else (None, math.inf)
        if best is None or best_d > self.reach:
            away = f'; nearest {best_d * 1000:.1f} mm away' if best is not None else ''
            return False, f'nothing within {self.reach * 1000:.0f} mm of the suction cup{away}'
        if best.mass > self.max_payload:
            return False, f'material {best.index} is above the {self.max_payload} kg payload'
        pos, mrot = source.pose(best)
        link_index = self._robot.link_index[self.link]
        origin, _ = self._robot.link_world_pose(self.link)
        rel_pos = rot.T @ (pos - origin)
        rel_rot = rot.T @ mrot
        self._constraint = self._p.createConstraint(
            self._robot.body, link_index, best.body, -1, pybullet.JOINT_FIXED, (0.0, 0.0, 0.0),
            rel_pos.tolist(), (0.0, 0.0, 0.0), matrix_to_quaternion(rel_rot),
            (0.0, 0.0, 0.0, 1.0))
        self._p.changeConstraint(self._constraint, maxForce=self.max_payload * 9.81 * 20)
        self.held = best
        return True, f'holding material {best.index} ({best.color}), {best_d * 1000:.1f} mm away'

    def release(self, source: Optional[MaterialSource] = None) -> Tuple[bool, str]:
        self.armed = False
        if self.held is None:
            near = self.nearest(source)
            return True, 'off; nothing held' + (
                f' (nearest: material {near[0].index} ({near[0].color}), '
                f'{near[1] * 1000:.1f} mm from the cup)' if near else '')
        self._p.removeConstraint(self._constraint)
        message = f'released material {self.held.index} ({self.held.color})'
        self.held, self._constraint = None, None
        return True, message

    def reset(self) -> None:
        self.armed = False
        if self._constraint is not None:
            try:
                self._p.removeConstraint(self._constraint)
            except pybullet.error:
                pass
        self.held, self._constraint = None, None


def _distance_to_box(point: np.ndarray, centre: np.ndarray, rot: np.ndarray,
                     half: float) -> float:
    local = rot.T @ (point - centre)
    closest = np.clip(local, -half, half)
    return float(np.linalg.norm(local - closest))

