"""Small helpers that write URDF elements (used by the robot description generators)."""
from __future__ import annotations

import math
from typing import Optional, Sequence, Tuple

import numpy as np

from controllers.arrays import Vector

Triple = Vector
# A link's shape: its kind (box, cylinder, sphere), size and centre in the link's frame.
Shape = Tuple[str, Sequence[float], Triple]
# Joint limits: lower, upper (None: a continuous joint), effort, velocity.
Limit = Tuple[Optional[float], Optional[float], float, float]


def num(v: float) -> str:
    if abs(v) < 1e-15:
        return '0'
    return f'{v:.17g}'


def vec(v: Vector) -> str:
    return ' '.join(num(float(x)) for x in v)


def rpy(rot: np.ndarray) -> Tuple[float, float, float]:
    """URDF roll-pitch-yaw (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    pitch = math.asin(max(-1.0, min(1.0, -rot[2, 0])))
    if abs(rot[2, 0]) < 1.0 - 1e-12:
        roll = math.atan2(rot[2, 1], rot[2, 2])
        yaw = math.atan2(rot[1, 0], rot[0, 0])
    else:  # gimbal lock: put everything in yaw
        roll = 0.0
        yaw = math.atan2(-rot[0, 1], rot[1, 1])
    return roll, pitch, yaw


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def inertia(kind: str, size: Sequence[float], mass: float) -> Tuple[float, float, float]:
    if kind == 'box':
        x, y, z = size
        return (mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12,
                mass * (x * x + y * y) / 12)
    if kind == 'sphere':
        i = 2.0 / 5.0 * mass * size[0] ** 2
        return (i, i, i)
    r, h = size                       # cylinder along z
    side = mass * (3 * r * r + h * h) / 12
    return (side, side, mass * r * r / 2)


def geometry(kind: str, size: Sequence[float]) -> str:
    if kind == 'box':
        return f'<box size="{vec(size)}"/>'
    if kind == 'sphere':
        return f'<sphere radius="{num(size[0])}"/>'
    return f'<cylinder radius="{num(size[0])}" length="{num(size[1])}"/>'


def link(name: str, mass: float, shape: Optional[Shape] = None, material: str = 'grey',
         collision: bool = True, visual_shape: Optional[Shape] = None,
         inertia_diag: Optional[Triple] = None) -> str:
    lines = [f'  <link name="{name}">']
    if shape is not None:
        kind, size, centre = shape
        vkind, vsize, vrpy = visual_shape or (kind, size, (0.0, 0.0, 0.0))
        lines += ['    <visual>', f'      <origin xyz="{vec(centre)}" rpy="{vec(vrpy)}"/>',
                  f'      <geometry>{geometry(vkind, vsize)}</geometry>',
                  f'      <material name="{material}"/>', '    </visual>']
        if collision:
            lines += ['    <collision>', f'      <origin xyz="{vec(centre)}" rpy="0 0 0"/>',
                      f'      <geometry>{geometry(kind, size)}</geometry>', '    </collision>']
        ixx, iyy, izz = inertia_diag or inertia(kind, size, mass)
    else:
        centre = (0.0, 0.0, 0.0)
        ixx = iyy = izz = 1e-9
    lines += ['    <inertial>', f'      <origin xyz="{vec(centre)}" rpy="0 0 0"/>',
              f'      <mass value="{num(mass)}"/>',
              f'      <inertia ixx="{ixx:.6g}" ixy="0" ixz="0" iyy="{iyy:.6g}" iyz="0" '
              f'izz="{izz:.6g}"/>', '    </inertial>', '  </link>']
    return '\n'.join(lines)


def joint(name: str, kind: str, parent: str, child: str, xyz: Triple,
          rpy: Triple = (0.0, 0.0, 0.0), axis: Optional[Triple] = None,
          limit: Optional[Limit] = None) -> str:
    lines = [f'  <joint name="{name}" type="{kind}">', f'    <parent link="{parent}"/>',
             f'    <child link="{child}"/>', f'    <origin xyz="{vec(xyz)}" rpy="{vec(rpy)}"/>']
    if axis is not None:
        lines.append(f'    <axis xyz="{vec(axis)}"/>')
    if limit is not None:
        lower, upper, effort, velocity = limit
        bounds = ('' if lower is None or upper is None
                  else f'lower="{num(lower)}" upper="{num(upper)}" ')
        lines.append(f'    <limit {bounds}effort="{num(effort)}" velocity="{num(velocity)}"/>')
    lines.append('  </joint>')
    return '\n'.join(lines)
