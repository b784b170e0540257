"""Perturbations: realistic sources of failure a world file can turn on (its ``perturbations``
section; all off by default), so that a cell's rates fall below 100 % for real reasons.

Each is drawn from the trial's seed, from a stream of its own: the same seed gives the same run,
and changing one perturbation's parameters leaves the other perturbations' draws as they were.

- camera: pixel noise (new in each frame), a brightness and white-balance shift (one per trial),
  a blur, and a mis-calibrated camera (rendered from a pose a few millimetres and tenths of a
  degree off the one the vision is told);
- materials: each material's mass and edge spread around its class's, its friction;
- robots: each arm joint's constant tracking offset, a slower arm, odometry that drifts;
- timing: the belt's speed drifting around its set point.
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Dict, Optional, Sequence, Tuple

import numpy as np

# A factor drawn around 1 (a mass, an edge, a gain) stays within these: a spread wide enough to
# reach 0 or below describes no real material or camera.
FACTOR_RANGE = (0.5, 1.5)


@dataclass(frozen=True)
class CameraPerturbation:
    pixel_noise: float = 0.0        # std of each pixel's channels, new in each frame [levels]
    brightness: float = 0.0         # std of the trial's brightness offset (0.1: 10 %)
    white_balance: float = 0.0      # std of each channel's gain around 1, for the trial
    blur: float = 0.0               # Gaussian blur's sigma [px]
    position_error: float = 0.0     # std of its position off its calibration [m], per axis
    angle_error: float = 0.0        # std of its rotation off its calibration [deg], per axis

    @property
    def active(self) -> bool:
        return any(v > 0.0 for v in (self.pixel_noise, self.brightness, self.white_balance,
                                     self.blur, self.position_error, self.angle_error))


@dataclass(frozen=True)
class MaterialPerturbation:
    mass_spread: float = 0.0        # relative std of each material's mass
    size_spread: float = 0.0        # relative std of each material's edge
    # Each material's friction coefficient (against the plate, the pool, a gripper) drawn
    # uniformly from [lo, hi] (None: 0.8, as without). The belt carries what rests on it by its
    # accumulation rule, whatever the friction.
    friction: Optional[Tuple[float, float]] = None

    @property
    def active(self) -> bool:
        return self.mass_spread > 0.0 or self.size_spread > 0.0 or self.friction is not None


@dataclass(frozen=True)
class RobotPerturbation:
    joint_offset: float = 0.0       # std of each arm joint's constant tracking offset [rad]
    velocity_scale: float = 1.0     # the arms follow their trajectories this much slower (< 1)
    odometry_drift: float = 0.0     # std of the odometry's relative scale error, per axis

    @property
    def active(self) -> bool:
        return self.joint_offset > 0.0 or self.velocity_scale != 1.0 or self.odometry_drift > 0.0


@dataclass(frozen=True)
class TimingPerturbation:
    belt_speed_drift: float = 0.0   # the belt speed's drift, relative to its set point
    belt_drift_period: float = 30.0  # [s]

    @property
    def active(self) -> bool:
        return self.belt_speed_drift > 0.0


@dataclass(frozen=True)
class Perturbations:
    camera: CameraPerturbation = field(default_factory=CameraPerturbation)
    materials: MaterialPerturbation = field(default_factory=MaterialPerturbation)
    robots: RobotPerturbation = field(default_factory=RobotPerturbation)
    timing: TimingPerturbation = field(default_factory=TimingPerturbation)

    @property
    def active(self) -> bool:
        return (self.camera.active or self.materials.active or self.robots.active
                or self.timing.active)


@dataclass(frozen=True)
class MaterialDraw:
    mass_factor: float = 1.0
    size_factor: float = 1.0
    friction: float = 0.8


class PerturbationDraws:
    """One trial's perturbations: every value drawn from the seed, each from its own stream
    (named, and keyed by what it perturbs: a camera, a material's index, a robot's joint)."""

    def __init__(self, config: Perturbations, seed: int) -> None:
        self.config, self.seed = config, int(seed)

    def rng(self, stream: str, *keys: int) -> np.random.Generator:
        """The generator of one stream: the same for the same seed, stream and keys."""
        return np.random.default_rng(
            [self.seed & 0xFFFFFFFF, self.seed >> 32 & 0xFFFFFFFF,
             zlib.crc32(stream.encode())] + [int(k) & 0xFFFFFFFF for k in keys])

    # --- camera ---------------------------------------------------------------------------
    def camera_gains(self, camera: str) -> np.ndarray:
        """The trial's gain of each colour channel (R, G, B): brightness times white balance."""
        c = self.config.camera
        rng = self.rng('camera.colour', zlib.crc32(camera.encode()))
        brightness = 1.0 + c.brightness * rng.standard_normal()
        balance = 1.0 + c.white_balance * rng.standard_normal(3)
        gains: np.ndarray = np.clip(brightness * balance, *FACTOR_RANGE)
        return gains

    def camera_pose_error(self, camera: str) -> Tuple[np.ndarray, np.ndarray]:
        """The camera's position [m] and rotation (roll, pitch, yaw about its optical frame's
        axes) [rad] off its calibrated pose, for the trial."""
        c = self.config.camera
        rng = self.rng('camera.pose', zlib.crc32(camera.encode()))
        return (c.position_error * rng.standard_normal(3),
                np.radians(c.angle_error) * rng.standard_normal(3))

    def frame_noise(self, camera: str, time_ns: int, shape: Sequence[int]) -> np.ndarray:
        """The pixel noise of the frame a camera takes at ``time_ns`` (float32 levels)."""
        rng = self.rng('camera.noise', zlib.crc32(camera.encode()), time_ns & 0xFFFFFFFF,
                       time_ns >> 32)
        noise: np.ndarray = rng.standard_normal(tuple(shape), dtype=np.float32)
        noise *= np.float32(self.config.camera.pixel_noise)
        return noise

    # --- materials --------------------------------------------------------------------------
    def material(self, index: int) -> MaterialDraw:
        """The ``index``-th material's (in order of appearance) mass and edge factors and its
        friction."""
        m = self.config.materials
        rng = self.rng('materials', index)
        mass = float(np.clip(1.0 + m.mass_spread * rng.standard_normal(), *FACTOR_RANGE))
        size = float(np.clip(1.0 + m.size_spread * rng.standard_normal(), *FACTOR_RANGE))
        friction = 0.8 if m.friction is None else float(rng.uniform(*m.friction))
        return MaterialDraw(mass, size, friction)

    # --- robots ----------------------------------------------------------------------------
    def joint_offsets(self, robot: str, joints: Sequence[str]) -> Dict[str, float]:
        """Each joint's constant offset [rad] between where its controller is told to go and
        where it goes."""
        sigma = self.config.robots.joint_offset
        return {j: float(sigma * self.rng('robots.joints', zlib.crc32(f'{robot}/{j}'.encode()))
                         .standard_normal()) for j in joints}

    def odometry_scale(self, robot: str) -> Tuple[float, float, float]:
        """The factors the robot's odometry gets its x, y and yaw motion wrong by."""
        sigma = self.config.robots.odometry_drift
        sx, sy, syaw = (np.clip(1.0 + sigma * self.rng(
            'robots.odometry', zlib.crc32(robot.encode())).standard_normal(3), *FACTOR_RANGE))
        return float(sx), float(sy), float(syaw)

    # --- timing ----------------------------------------------------------------------------
    def belt_speed(self, set_speed: float, sim_time: float) -> float:
        """The belt's speed at ``sim_time``: its set point, drifting slowly around it."""
        t = self.config.timing
        if t.belt_speed_drift <= 0.0:
            return set_speed
        rng = self.rng('timing.belt')
        phase, second = rng.uniform(0.0, 2.0 * math.pi, 2)
        w = 2.0 * math.pi / t.belt_drift_period
        # Two incommensurate sines: a drift that does not repeat within a run.
        drift = 0.7 * math.sin(w * sim_time + phase) + 0.3 * math.sin(
            w * math.sqrt(5.0) * sim_time + second)
        return max(0.0, set_speed * (1.0 + t.belt_speed_drift * drift))
