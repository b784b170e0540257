"""Small helpers that write URDF elements (used by the robot description generators)."""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Callable

import numpy as np


def generator_main(doc: str, render: Callable[[], str], out: Path) -> int:
    """Command line of a description generator: write ``out``, or ``--check`` it."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument('--check', action='store_true',
                        help='exit 1 if the committed file differs from the generated one')
    args = parser.parse_args()
    text = render()
    if args.check:
        same = out.is_file() and out.read_text() == text
        print(f'{out}: {"up to date" if same else "differs from the generator"}')
        return 0 if same else 1
    out.write_text(text)
    print(f'wrote {out}')
    return 0


def num(v: float) -> str:
    if abs(v) < 1e-15:
        return '0'
    return f'{v:.17g}'


def vec(v) -> str:
    return ' '.join(num(float(x)) for x in v)


def rpy(rot: np.ndarray) -> tuple:
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


def inertia(kind: str, size: tuple, mass: float) -> tuple:
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


def geometry(kind: str, size: tuple) -> str:
    if kind == 'box':
        return f'<box size="{vec(size)}"/>'
    if kind == 'sphere':
        return f'<sphere radius="{num(size[0])}"/>'
    return f'<cylinder radius="{num(size[0])}" length="{num(size[1])}"/>'


def link(name: str, mass: float, shape=None, material: str = 'grey', collision: bool = True,
          visual_shape=None, inertia_diag=None) -> str:
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


def joint(name: str, kind: str, parent: str, child: str, xyz, rpy=(0.0, 0.0, 0.0),
           axis=None, limit=None) -> str:
    lines = [f'  <joint name="{name}" type="{kind}">', f'    <parent link="{parent}"/>',
             f'    <child link="{child}"/>', f'    <origin xyz="{vec(xyz)}" rpy="{vec(rpy)}"/>']
    if axis is not None:
        lines.append(f'    <axis xyz="{vec(axis)}"/>')
    if limit is not None:
        lower, upper, effort, velocity = limit
        bounds = '' if lower is None else f'lower="{num(lower)}" upper="{num(upper)}" '
        lines.append(f'    <limit {bounds}effort="{num(effort)}" velocity="{num(velocity)}"/>')
    lines.append('  </joint>')
    return '\n'.join(lines)
