"""Write robot_description/urdf/zu12.urdf from the JAKA Zu 12's standard DH table.

Standard DH puts joint i's rotation before the link's fixed part: T(i-1, i) = RotZ(theta_i)
[TransZ(d_i) TransX(a_i) RotX(alpha_i)]. In the URDF, link_i is frame i-1 turned by theta_i, and
joint i+1's origin is the fixed part of row i, so `flange` (link_6 plus row 6's fixed part) is
the table's frame 6 and the joint positions are the table's theta (docs/robot-models.md §4).
tests/unit/test_zu12.py fails if the committed file differs from what this module writes.

    generate_urdf zu12 [--check]
"""
from __future__ import annotations

import math
from typing import List, Tuple

from controllers.arrays import Vector
from controllers.zu12_arm import (
    JOINT_NAMES,
    JOINT_VELOCITY_LIMITS,
    LIMITS_DEG,
    SUCTION_TCP_OFFSET_M,
    flange_offset,
)
from robot_description import urdf_writer as uw

# About 41 kg in all (the vendor's figure), spread over the links; efforts of the joint sizes.
BASE_MASS_KG = 4.0
LINK_MASSES_KG = (6.0, 10.0, 5.0, 2.0, 2.0, 1.0)
EFFORTS_NM = (330.0, 330.0, 150.0, 36.0, 36.0, 36.0)
SUCTION_MASS_KG = 0.3
FRAME_MASS_KG = 1e-3
# Each link's shape in its own URDF frame: (kind, size, centre); it joins the joint to the next.
LINK_SHAPES = (
    ('cylinder', (0.07, 0.09), (0.0, 0.0, 0.0975)),
    ('box', (0.70, 0.10, 0.11), (0.2975, 0.0, 0.0)),
    ('box', (0.64, 0.08, 0.08), (0.2858, 0.0, 0.0)),
    ('cylinder', (0.045, 0.1315), (0.0, 0.0, -0.06575)),
    ('cylinder', (0.045, 0.115), (0.0, 0.0, 0.0575)),
    ('cylinder', (0.04, 0.1035), (0.0, 0.0, 0.05175)),
)

HEADER = '''<?xml version="1.0"?>
<!--
  JAKA Zu 12, written by robot_description/zu12_urdf.py from the manufacturer's standard DH
  table (docs/robot-models.md §4); do not edit by hand. base_link on the floor; joint positions are
  the table's theta (all offsets 0) with the published ranges and speeds; `flange` is the
  table's frame 6, `suction_tcp` the contact point of the suction tool on the flange's z axis.
  Masses spread the vendor's 41 kg over the links; inertias are solid-shape values.
-->
<robot name="zu12">
  <material name="white"><color rgba="0.92 0.92 0.92 1.0"/></material>
  <material name="grey"><color rgba="0.55 0.55 0.58 1.0"/></material>
  <material name="dark"><color rgba="0.2 0.2 0.22 1.0"/></material>
'''


def _parts() -> List[str]:
    parts = [uw.link('base_link', BASE_MASS_KG, ('cylinder', (0.08, 0.05), (0.0, 0.0, 0.025)),
                     'grey')]
    origin: Tuple[Vector, Vector] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    parent = 'base_link'
    for i, name in enumerate(JOINT_NAMES):
        lo, hi = (math.radians(v) for v in LIMITS_DEG[i])
        child = f'link_{i + 1}'
        parts.append(uw.link(child, LINK_MASSES_KG[i], LINK_SHAPES[i],
                             'white' if i % 2 == 0 else 'grey'))
        parts.append(uw.joint(name, 'revolute', parent, child, origin[0], origin[1],
                              (0.0, 0.0, 1.0), (lo, hi, EFFORTS_NM[i], JOINT_VELOCITY_LIMITS[i])))
        fixed = flange_offset(i)
        parent, origin = child, (fixed[:3, 3], uw.rpy(fixed[:3, :3]))
    parts.append(uw.link('flange', FRAME_MASS_KG))
    parts.append(uw.joint('flange_joint', 'fixed', 'link_6', 'flange', origin[0], origin[1]))
    tool = ('cylinder', (0.02, SUCTION_TCP_OFFSET_M), (0.0, 0.0, SUCTION_TCP_OFFSET_M / 2))
    parts.append(uw.link('suction_tool', SUCTION_MASS_KG, tool, 'dark'))
    parts.append(uw.joint('suction_tool_joint', 'fixed', 'flange', 'suction_tool',
                          (0.0, 0.0, 0.0)))
    parts.append(uw.link('suction_tcp', FRAME_MASS_KG))
    parts.append(uw.joint('suction_tcp_joint', 'fixed', 'suction_tool', 'suction_tcp',
                          (0.0, 0.0, SUCTION_TCP_OFFSET_M)))
    return parts


def render() -> str:
    return HEADER + '\n'.join(_parts()) + '\n</robot>\n'

