"""Write robot_description/urdf/youbot.urdf from the published youBot numbers.

The arm's joint frames are the frames of the pipeline paper's MDH table (docs/robot-models.md §3),
so the description and controllers/youbot_arm.py describe one arm; the joints themselves use the
datasheet angles (zero at the straight-up "candle", the convention of the paper's limits).
Run `generate_urdf` after changing the numbers; tests/unit/test_youbot_urdf.py fails if the
committed file differs from what this module writes.

    generate_urdf youbot [--check]
"""
from __future__ import annotations

import math
from typing import List

import numpy as np

from controllers.mecanum import BASE_LINK_HEIGHT_M, WHEEL_RADIUS_M
from controllers.youbot_arm import (
    ARM_BASE_IN_BASE_LINK_M,
    CRAIG_ROWS_DEG_M,
    DATASHEET_LIMITS_DEG,
    GRIPPER_TCP_OFFSET_M,
    JOINT_NAMES,
    JOINT_VELOCITY_LIMIT,
    THETA_OFFSET_RAD,
    THETA_SIGN,
)
from robot_description import urdf_writer as uw

BASE_SIZE_M = (0.57, 0.36, 0.10)
BASE_MASS_KG = 22.0
WHEEL_MASS_KG = 1.4
WHEEL_WIDTH_M = 0.05
WHEEL_X_M, WHEEL_Y_M, WHEEL_Z_M = 0.228, 0.158, -0.034
# Virtual omni-wheel: the sphere spins about the contact roller's axis (docs/robot-models.md §2).
WHEELS = (('fl', 1, 1, -45.0), ('fr', 1, -1, 45.0), ('rr', -1, -1, -45.0),
          ('rl', -1, 1, 45.0))
ARM_MOUNT_M = (0.143, 0.0, 0.046)
PLATE_M = (-0.159, 0.0, 0.046)
# Link masses 0..5 (docs/robot-models.md §3); gripper palm and fingers from the vendor's data.
ARM_MASSES_KG = (0.961, 1.390, 1.318, 0.821, 0.769, 0.687)
ARM_EFFORT_NM = (9.5, 9.5, 6.0, 2.0, 1.0)
PALM_MASS_KG, FINGER_MASS_KG = 0.199, 0.010
FINGER_TRAVEL_M, FINGER_EFFORT_N, FINGER_VELOCITY_MPS = 0.0115, 10.0, 0.02
FRAME_MASS_KG = 1e-3                      # pure frames: PyBullet gives a link without mass 1 kg

# Each arm link's shape in its own (MDH) frame: (kind, size, centre).
ARM_SHAPES = (
    ('box', (0.16, 0.12, 0.032), (0.0, 0.0, 0.016)),            # arm_link_0: mounting plate
    ('cylinder', (0.055, 0.115), (0.012, 0.0, -0.0575)),         # arm_link_1: turret
    ('box', (0.175, 0.06, 0.07), (0.0775, 0.0, 0.0)),             # arm_link_2: along x to j3
    ('box', (0.155, 0.05, 0.06), (0.0675, 0.0, 0.0)),             # arm_link_3: along x to j4
    ('box', (0.05, 0.08, 0.05), (0.0, 0.04, 0.0)),                # arm_link_4: wrist, along y
    ('cylinder', (0.03, 0.03), (0.0, 0.0, -0.015)),               # arm_link_5: flange
)


def _base() -> List[str]:
    parts = [uw.link('base_link', BASE_MASS_KG, ('box', BASE_SIZE_M, (0.0, 0.0, 0.0)), 'dark')]
    wheel_inertia = uw.inertia('cylinder', (WHEEL_RADIUS_M, WHEEL_WIDTH_M), WHEEL_MASS_KG)
    for name, sx, sy, yaw_deg in WHEELS:
        # The link's y axis is the spin axis: anisotropic friction [1, 0, 1] leaves the contact
        # free along it, and a rotation about y keeps that direction fixed.
        side, _, axle = wheel_inertia
        parts.append(uw.link(f'wheel_link_{name}', WHEEL_MASS_KG,
                           ('sphere', (WHEEL_RADIUS_M,), (0.0, 0.0, 0.0)), 'black',
                           visual_shape=('cylinder', (WHEEL_RADIUS_M, WHEEL_WIDTH_M),
                                         (math.pi / 2, 0.0, 0.0)),
                           inertia_diag=(side, axle, side)))
        parts.append(uw.joint(f'wheel_joint_{name}', 'continuous', 'base_link',
                            f'wheel_link_{name}', (sx * WHEEL_X_M, sy * WHEEL_Y_M, WHEEL_Z_M),
                            (0.0, 0.0, math.radians(yaw_deg)), (0.0, 1.0, 0.0),
                            (None, None, 20.0, 30.0)))
    plate = ('box', (0.25, 0.32, 0.01), (0.0, 0.0, 0.005))
    parts.append(uw.link('plate_link', 0.3, plate, 'plate'))
    parts.append(uw.joint('plate_joint', 'fixed', 'base_link', 'plate_link', PLATE_M))
    return parts


def _arm() -> List[str]:
    parts = [uw.link('arm_link_0', ARM_MASSES_KG[0], ARM_SHAPES[0], 'orange')]
    parts.append(uw.joint('arm_joint_0', 'fixed', 'base_link', 'arm_link_0', ARM_MOUNT_M))
    base_in_mount = np.subtract(ARM_BASE_IN_BASE_LINK_M, ARM_MOUNT_M)
    parts.append(uw.link('arm_base_frame', FRAME_MASS_KG))
    parts.append(uw.joint('arm_base_frame_joint', 'fixed', 'arm_link_0', 'arm_base_frame',
                        base_in_mount))
    for i, ((alpha_deg, a, d), (lo, hi)) in enumerate(zip(CRAIG_ROWS_DEG_M,
                                                           DATASHEET_LIMITS_DEG)):
        # Craig: RotX(alpha) TransX(a) RotZ(theta) TransZ(d) with theta = sign*phi + offset
        # equals the fixed origin RotX(alpha) TransX(a) TransZ(d) RotZ(offset), then a turn by
        # phi about (0, 0, sign).
        rot = uw.rot_x(math.radians(alpha_deg)) @ uw.rot_z(float(THETA_OFFSET_RAD[i]))
        xyz = np.array([a, 0.0, 0.0]) + uw.rot_x(math.radians(alpha_deg)) @ np.array([0, 0, d])
        if i == 0:
            xyz = xyz + base_in_mount
        parent = f'arm_link_{i}'
        parts.append(uw.link(f'arm_link_{i + 1}', ARM_MASSES_KG[i + 1], ARM_SHAPES[i + 1],
                           'orange' if i % 2 else 'grey'))
        parts.append(uw.joint(JOINT_NAMES[i], 'revolute', parent, f'arm_link_{i + 1}', xyz,
                            uw.rpy(rot), (0.0, 0.0, float(THETA_SIGN[i])),
                            (math.radians(lo), math.radians(hi), ARM_EFFORT_NM[i],
                             JOINT_VELOCITY_LIMIT)))
    return parts


def _gripper() -> List[str]:
    palm = ('box', (0.04, 0.1, 0.045), (0.0, 0.0, 0.0225))
    parts = [uw.link('gripper_palm_link', PALM_MASS_KG, palm, 'dark'),
             uw.joint('gripper_palm_joint', 'fixed', 'arm_link_5', 'gripper_palm_link',
                    (0.0, 0.0, 0.0))]
    for side, sign in (('l', 1.0), ('r', -1.0)):
        finger = ('box', (0.02, 0.01, 0.07), (0.0, sign * 0.005, 0.035))
        parts.append(uw.link(f'gripper_finger_link_{side}', FINGER_MASS_KG, finger, 'grey'))
        parts.append(uw.joint(f'gripper_finger_joint_{side}', 'prismatic', 'gripper_palm_link',
                            f'gripper_finger_link_{side}', (0.0, 0.0, 0.045), axis=(0, sign, 0),
                            limit=(0.0, FINGER_TRAVEL_M, FINGER_EFFORT_N, FINGER_VELOCITY_MPS)))
    parts.append(uw.link('gripper_tcp', FRAME_MASS_KG))
    parts.append(uw.joint('gripper_tcp_joint', 'fixed', 'gripper_palm_link', 'gripper_tcp',
                        (0.0, 0.0, GRIPPER_TCP_OFFSET_M)))
    return parts


HEADER = f'''<?xml version="1.0"?>
<!--
  KUKA youBot, written by robot_description/youbot_urdf.py from the published numbers
  (docs/robot-models.md §2-3); do not edit by hand.
  base_link: centre of the base box, {BASE_LINK_HEIGHT_M} m above the ground (REP-103: x forward,
  z up).
  Wheels: "virtual omni-wheels" (docs/robot-models.md §2): each wheel collides as a sphere of the
  wheel radius whose joint axis (link y) is the contact roller's axis, yawed -45 deg (FL, RR) or
  +45 deg (FR, RL) from the wheel axle; the simulator gives it anisotropic friction [1, 0, 1]
  and drives it at u/sqrt(2) for a forward-positive wheel speed u, and reports sqrt(2) q as the
  wheel angle. Drawn as a cylinder on that axis.
  Arm: arm_base_frame is frame 0 of the paper's MDH table and arm_link_1..5 are its frames 1..5;
  the joints turn by the datasheet angles (zero at the straight-up candle; the limits are the
  paper's), theta = sign * phi + offset. gripper_tcp is the grasp point between the fingers.
  Masses are the published ones; inertias are solid box/cylinder values of the shapes (the
  published inertias are about 10x too large).
-->
<robot name="youbot">
  <material name="dark"><color rgba="0.25 0.25 0.28 1.0"/></material>
  <material name="grey"><color rgba="0.6 0.6 0.62 1.0"/></material>
  <material name="black"><color rgba="0.08 0.08 0.08 1.0"/></material>
  <material name="orange"><color rgba="0.95 0.5 0.1 1.0"/></material>
  <material name="plate"><color rgba="0.45 0.45 0.5 1.0"/></material>
'''


def render() -> str:
    return HEADER + '\n'.join(_base() + _arm() + _gripper()) + '\n</robot>\n'

