"""The PyBullet world: loads a WorldConfig (its robots: robot.py, their drives and joint groups:
actuation.py, its cameras: camera.py), steps physics, keeps free bodies sane, renders cameras."""
from __future__ import annotations

import math
from pathlib import Path
from typing import (
    Any,
    Callable,
    Dict,
    List,
    Optional,
    Tuple,
)

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from sim_bridge.actuation import OMNI_WHEEL_SCALE, DiffDrive, JointGroup, MecanumDrive
from sim_bridge.backdrop import StaticBackdrop, static_visuals
from sim_bridge.camera import SimCamera, perturb_frame
from sim_bridge.cell import Conveyor, MaterialBody, MaterialSource, Suction
from sim_bridge.client import Client
from sim_bridge.errors import WorldError
from sim_bridge.free_bodies import Lost, base_problem, moving_within_reason
from sim_bridge.joint_speed import Braked
from sim_bridge.robot import URDF_FLAGS, SimRobot
from sim_bridge.sensors import BaseState, JointStates, Transform
from world_description.perturbations import PerturbationDraws
from world_description.resources import resolve_resource
from world_description.world_config import (
    WorldConfig,
)

# (The robots, their actuation and the cameras are modules of their own; their names are the
# world's too, as they were before the split.)
__all__ = ['FLOOR_COLOR', 'OMNI_WHEEL_SCALE', 'URDF_FLAGS', 'BaseState', 'DiffDrive',
           'JointGroup', 'JointStates', 'MecanumDrive', 'SimCamera', 'SimRobot', 'SimWorld',
           'Transform', 'WorldError', 'add_obstacle', 'build_floor', 'draw']

FLOOR_COLOR = (0.82, 0.80, 0.76, 1.0)


def build_floor(p: BulletClient, size: float) -> int:
    """Infinite collision plane, but only a plain finite patch is drawn: PyBullet's large
    textured plane is the biggest cost of a CPU-rendered frame."""
    plane = p.createCollisionShape(pybullet.GEOM_PLANE)
    visual = p.createVisualShape(pybullet.GEOM_BOX, halfExtents=(size / 2, size / 2, 0.0005),
                                 rgbaColor=FLOOR_COLOR, visualFramePosition=(0.0, 0.0, -0.0005))
    floor = p.createMultiBody(0.0, plane, visual)
    p.changeDynamics(floor, -1, lateralFriction=1.0)
    return int(floor)


class SimWorld:
    """Owns one PyBullet client. Every physics step goes through :meth:`step`."""

    def __init__(self, config: WorldConfig, time_step: float = 1.0 / 240.0,
                 gui: bool = False, scenario_seed: Optional[int] = None) -> None:
        if not (0.0 < time_step <= 0.1):
            raise ValueError(f'time_step must be within (0, 0.1] s, got {time_step}')
        self.config = config
        self.time_step = time_step
        self.step_count = 0
        self._p = Client(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        p = self._p
        p.setTimeStep(time_step)
        p.setGravity(0.0, 0.0, config.gravity)
        self.floor = build_floor(self._p, config.floor_size)
        self._obstacle_names: Dict[int, str] = {}
        self.obstacles: Dict[int, Any] = {}          # body: its ObstacleConfig
        # Fixed cameras' static scenes in the default light, by camera (None: the static
        # bodies are drawn in each frame). False: every frame of every camera is drawn whole
        # (a reference).
        self.backdrops = True
        self._backdrops: Dict[str, Optional[StaticBackdrop]] = {}
        self._relit = False            # a frame was rendered with light arguments
        for obstacle in config.obstacles:
            body = add_obstacle(self._p, obstacle)
            self.obstacles[body] = obstacle
            self._obstacle_names[body] = (f'the {obstacle.name}' if obstacle.name else
                                          f'an obstacle ({obstacle.shape})')
        base_dir = Path(config.source).parent if config.source else None
        # The world's perturbations, drawn from the scenario's seed (off unless the world file
        # turns them on).
        self.draws = PerturbationDraws(config.perturbations, scenario_seed if scenario_seed
                                       is not None else config.materials.seed
                                       if config.materials else 0)
        self.robots: Dict[str, SimRobot] = {}
        for rc in config.robots:
            robot = SimRobot(p, rc, resolve_resource(rc.urdf, base_dir), base_dir, time_step)
            if config.perturbations.robots.active:
                offsets = self.draws.joint_offsets(
                    rc.name, [j for c in rc.controllers for j in c.joints if j in robot.revolute])
                robot.sensors.set_perturbations(
                    {robot.movable_joint(j, 'perturbations'): v for j, v in offsets.items()
                     if v != 0.0},
                    self.draws.odometry_scale(rc.name))
                robot.reset()
            self.robots[rc.name] = robot
        self.cameras: List[SimCamera] = [
            SimCamera(cc, self.robots[cc.robot] if cc.robot else None,
                      self.draws.camera_pose_error(cc.name)) for cc in config.cameras]
        self.conveyor = Conveyor(p, config.conveyor) if config.conveyor else None
        # (The world file's reader holds materials to a conveyor to be placed on.)
        self.source = (MaterialSource(p, self.conveyor, config.materials, scenario_seed,
                                      self.draws)
                       if config.materials and self.conveyor else None)
        # Where every static body (floor, obstacles, the belt and its stands) belongs: a
        # non-finite robot state spreads NaN into the static bodies it touches, and a body
        # loaded again then falls through a floor whose pose is NaN.
        robot_bodies = {robot.body for robot in self.robots.values()}
        self._static_poses = {
            body: p.getBasePositionAndOrientation(body)
            for body in (p.getBodyUniqueId(i) for i in range(p.getNumBodies()))
            if body not in robot_bodies and p.getDynamicsInfo(body, -1)[0] == 0.0}
        # Their visual shapes, hidden while a fixed camera draws what moves (None: they cannot
        # be drawn again alike, and every frame is drawn whole).
        self._static_visuals = static_visuals(p, list(self._static_poses))
        # Bodies spawned into the world by others (entities.py): name, and what to call when
        # the world takes one out; and the bodies taken out since take_lost.
        self._guests: Dict[int, Tuple[str, Callable[[], None]]] = {}
        self._lost: List[Lost] = []
        self._braked: List[Tuple[str, float, List[Braked]]] = []
        self.suctions: Dict[str, Suction] = {}
        for name, robot in self.robots.items():
            sc = robot.config.suction
            if sc is not None:
                try:
                    self.suctions[name] = Suction(p, robot, sc.link, sc.reach, sc.max_payload,
                                                   sc.offset)
                except ValueError as exc:
                    raise WorldError(str(exc)) from None

    @property
    def client(self) -> BulletClient:
        """The world's PyBullet client."""
        return self._p

    @property
    def sim_time(self) -> float:
        return self.step_count * self.time_step

    @property
    def sim_time_ns(self) -> int:
        # Integer nanoseconds so that lock-step time is exact after any number of steps.
        return self.step_count * round(self.time_step * 1e9)

    @property
    def materials(self) -> List[MaterialBody]:
        return self.source.materials if self.source is not None else []

    def step(self) -> None:
        for suction in self.suctions.values():
            suction.update(self.source)
        if self.conveyor is not None:
            held = {s.held.body for s in self.suctions.values() if s.held is not None}
            self.conveyor.carry([m.body for m in self.materials if m.body not in held],
                                self.time_step, sorted(held),
                                self.draws.belt_speed(self.conveyor.speed, self.sim_time))
            if self.source is not None:
                self.source.update(self.sim_time)
        self._p.stepSimulation()
        self.step_count += 1
        self.check_free_bodies(pose=False)
        for name, robot in self.robots.items():
            braked = robot.speed_limiter.enforce()
            if braked:
                self._braked.append((name, self.sim_time, braked))

    def take_braked(self) -> List[Tuple[str, float, List[Braked]]]:
        """The joints brought back to their speed limits since the last call: (robot, time [s],
        what was braked)."""
        braked, self._braked = self._braked, []
        return braked

    def adopt(self, body: int, name: str, forget: Callable[[], None]) -> None:
        """Watch a body spawned by another part (its ``name``): one that leaves the world is
        removed, and ``forget()`` called."""
        self._guests[body] = (name, forget)

    def disown(self, body: int) -> None:
        """Stop watching a body (its owner removes it)."""
        self._guests.pop(body, None)

    def check_free_bodies(self, pose: bool = True) -> None:
        """Take out every material and spawned body whose state is not finite or has left
        the world (free_bodies.py), before it is stepped again (a material held by a suction
        cup is released first); each is in ``take_lost()``. ``pose=False``: velocities only
        (after every step)."""
        taken = False
        quick = not pose
        for m in list(self.materials):
            if quick and moving_within_reason(self._p, m.body):
                continue
            problem = base_problem(self._p, m.body, pose)
            if problem:
                for suction in self.suctions.values():
                    if suction.held is m:
                        suction.release(self.source)
                assert self.source is not None
                self.source.remove(m)
                self._lost.append(Lost(m.name or f'material_{m.index}',
                                       f'taken out of the world: {problem}'))
                taken = True
        for body, (name, forget) in list(self._guests.items()):
            if quick and moving_within_reason(self._p, body):
                continue
            problem = base_problem(self._p, body, pose)
            if problem:
                del self._guests[body]
                self._p.removeBody(body)
                forget()
                self._lost.append(Lost(name, f'taken out of the world: {problem}'))
                taken = True
        if taken:
            for name in self.repair_static():
                self._lost.append(Lost(name, 'put back where it belongs: its pose was not '
                                             'finite'))

    def take_lost(self) -> List[Lost]:
        """The bodies taken out of the world since the last call (and static bodies put back)."""
        lost, self._lost = self._lost, []
        return lost

    def repair_static(self) -> List[str]:
        """Put back every static body whose pose is no longer finite; their names."""
        repaired = []
        for body, (pos, orn) in self._static_poses.items():
            now_pos, now_orn = self._p.getBasePositionAndOrientation(body)
            if not math.isfinite(sum(now_pos) + sum(now_orn)):
                self._p.resetBasePositionAndOrientation(body, pos, orn)
                repaired.append(self.body_name(body))
        return repaired

    def reset(self) -> None:
        """Put every robot back at its start pose, at rest, and start the materials' scenario
        again (same seed). Simulated time keeps running."""
        for suction in self.suctions.values():
            suction.reset()
        for robot in self.robots.values():
            robot.reset()
        if self.source is not None:
            self.source.restart()

    def render(self, camera: SimCamera,
               lighting: Optional[Dict[str, Any]] = None) -> np.ndarray:
        """Render an RGBA frame (height x width x 4, uint8) with the CPU renderer, as the
        camera gives it: with the world's camera perturbations (noise, colour, blur), if any.
        ``lighting``: as :meth:`render_ideal`."""
        frame = self.render_ideal(camera, lighting)
        c = self.config.perturbations.camera
        if not (c.pixel_noise > 0.0 or c.brightness > 0.0 or c.white_balance > 0.0
                or c.blur > 0.0):
            return frame
        name = camera.config.name
        noise = (self.draws.frame_noise(name, self.sim_time_ns, (*frame.shape[:2], 3))
                 if c.pixel_noise > 0.0 else None)
        return perturb_frame(frame, self.draws.camera_gains(name), noise, c.blur)

    def render_ideal(self, camera: SimCamera,
                     lighting: Optional[Dict[str, Any]] = None) -> np.ndarray:
        """Render an RGBA frame (height x width x 4, uint8) with the CPU renderer: the scene
        itself, no camera perturbation.

        ``lighting``: getCameraImage's light arguments (lightDirection, lightColor,
        lightAmbientCoeff, lightDiffuseCoeff, lightSpecularCoeff), to vary the lighting.

        A fixed camera's frames in the default light are drawn without the static bodies, over
        an image of them drawn once (see sim_bridge.backdrop): the same image, bit for bit, for
        the cost of the pixels the moving bodies cover (the belt camera's frame: 15 ms drawn
        whole, 6 ms with the floor alone filled in, 1.5 ms now).
        """
        backdrop = None
        # PyBullet keeps the light arguments of the last frame that gave any for the frames
        # after it: once a frame was lit otherwise, the default light is unknown here.
        self._relit = self._relit or bool(lighting)
        if camera.robot is None and self.backdrops and not self._relit:
            key = camera.config.name
            if key not in self._backdrops:
                self._backdrops[key] = self._measure_backdrop(camera)
            backdrop = self._backdrops[key]
        if backdrop is None or self._static_visuals is None:
            return draw(self._p, camera, lighting)[0]
        self._show_static(False)
        try:
            rgba, depth = draw(self._p, camera, lighting)
        finally:
            self._show_static(True)
        return backdrop.fill(rgba, depth)

    def _show_static(self, shown: bool) -> None:
        for v in self._static_visuals or ():
            self._p.changeVisualShape(v.body, v.link, rgbaColor=v.rgba if shown else v.hidden())

    def _measure_backdrop(self, camera: SimCamera) -> Optional[StaticBackdrop]:
        """The static scene as this fixed camera sees it in the default light, drawn alone in
        a client of its own; None (draw every frame whole) if it cannot be drawn again alike."""
        if self._static_visuals is None:
            return None
        return StaticBackdrop.measure(self._static_visuals,
                                      lambda client: draw(client, camera, None))

    def body_name(self, body: int, link: int = -1) -> str:
        """What a body of the world is, for messages: 'the floor', 'youbot's arm_link_5', ..."""
        if body == self.floor:
            return 'the floor'
        if body in self._obstacle_names:
            return self._obstacle_names[body]
        if self.conveyor is not None and body in (self.conveyor.body,
                                                  getattr(self.conveyor, 'stop_body', None)):
            return 'the conveyor'
        for name, robot in self.robots.items():
            if body == robot.body:
                return f"{name}'s {robot.link_name(link)}"
        for m in self.materials:
            if body == m.body:
                return f'material {m.index} ({m.color})'
        return f'body {body}'

    def contacts_of(self, group: 'JointGroup') -> List[str]:
        """What the links a joint group moves touch: ['gripper_finger_link_l on the floor']."""
        robot = group.robot
        found = []
        for c in self._p.getContactPoints(bodyA=robot.body):
            if c[3] in group.moved_links and (c[2], c[4]) != (robot.body, c[3]):
                text = f'{robot.link_name(c[3])} on {self.body_name(c[2], c[4])}'
                if text not in found:
                    found.append(text)
        return found

    def close(self) -> None:
        try:
            self._p.disconnect()
        except pybullet.error:
            pass


def draw(client: BulletClient, camera: SimCamera, lighting: Optional[Dict[str, Any]]
         ) -> Tuple[np.ndarray, np.ndarray]:
    """A camera's frame drawn by PyBullet's CPU renderer: RGBA and depth."""
    c = camera.config
    _, _, rgba, depth, _ = client.getCameraImage(
        c.width, c.height, camera.view_matrix(), camera.projection, shadow=0,
        renderer=pybullet.ER_TINY_RENDERER, flags=pybullet.ER_NO_SEGMENTATION_MASK,
        **(lighting or {}))
    return (np.asarray(rgba, dtype=np.uint8).reshape(c.height, c.width, 4),
            np.asarray(depth, dtype=np.float32).reshape(c.height, c.width))


def add_obstacle(p: BulletClient, obstacle: Any) -> int:
    """An obstacle of the world file as a fixed body; its id."""
    s = obstacle.size
    if obstacle.shape == 'box':
        kwargs = {'halfExtents': [v / 2 for v in s]}
        col = p.createCollisionShape(pybullet.GEOM_BOX, **kwargs)
        vis = p.createVisualShape(pybullet.GEOM_BOX, rgbaColor=obstacle.color, **kwargs)
    elif obstacle.shape == 'cylinder':
        col = p.createCollisionShape(pybullet.GEOM_CYLINDER, radius=s[0], height=s[1])
        vis = p.createVisualShape(pybullet.GEOM_CYLINDER, radius=s[0], length=s[1],
                                  rgbaColor=obstacle.color)
    else:
        col = p.createCollisionShape(pybullet.GEOM_SPHERE, radius=s[0])
        vis = p.createVisualShape(pybullet.GEOM_SPHERE, radius=s[0], rgbaColor=obstacle.color)
    if not obstacle.collision:
        col = -1
    body = p.createMultiBody(0.0, col, vis, basePosition=obstacle.position,
                             baseOrientation=p.getQuaternionFromEuler((0.0, 0.0, obstacle.yaw)))
    return int(body)
