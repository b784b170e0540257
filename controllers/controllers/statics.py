"""Static joint torques of a serial arm under gravity, from its URDF (no ROS, no physics engine).

What an arm can hold still is limited by its joints' efforts, not only by its reach: the
youBot's shoulder (9.5 N m) cannot hold a 0.38 kg material with the arm stretched out over a
far pool drop, and the simulated arm sagged 0.24 rad there. A planner checks a pose with
``ArmStatics.torques(q, payload)`` against ``ArmStatics.effort``.

The model is the URDF's: each joint's origin and axis, each link's mass and centre of mass
(inertial origin). Joint i holds the weight of every link after it (fingers and all) and the
payload at the tool link: tau_i = axis_i . sum_j (c_j - o_i) x (m_j g).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Set, Tuple

import numpy as np

from controllers.arrays import Vector

GRAVITY = np.array([0.0, 0.0, -9.81])


def _rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    x, y, z = axis / np.linalg.norm(axis)
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                     [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                     [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)]])


def _origin(element: Optional[ET.Element]) -> np.ndarray:
    """The 4x4 transform of a URDF <origin> (identity if absent)."""
    T = np.eye(4)
    if element is not None:
        T[:3, 3] = [float(v) for v in element.get('xyz', '0 0 0').split()]
        T[:3, :3] = _rpy_matrix(*(float(v) for v in element.get('rpy', '0 0 0').split()))
    return T


@dataclass(frozen=True)
class _Joint:
    name: str
    parent: str
    child: str
    origin: np.ndarray              # parent link frame -> joint frame at zero
    axis: np.ndarray                # in the joint frame
    revolute: bool


class ArmStatics:
    """Gravity torques of the joints ``joints`` (in order) of a URDF's tree, with a payload at
    ``tool`` (a link). The base link's frame is the reference; gravity is along its -z (the
    arm's base standing level)."""

    def __init__(self, urdf: Path, joints: Sequence[str], tool: str) -> None:
        root = ET.parse(str(urdf)).getroot()
        self._joints: Dict[str, _Joint] = {}
        for j in root.iter('joint'):
            axis = j.find('axis')
            self._joints[j.get('name', '')] = _Joint(
                j.get('name', ''), j.find('parent').get('link', ''),    # type: ignore[union-attr]
                j.find('child').get('link', ''),                         # type: ignore[union-attr]
                _origin(j.find('origin')),
                np.array([float(v) for v in (axis.get('xyz', '1 0 0') if axis is not None
                                             else '1 0 0').split()]),
                j.get('type') in ('revolute', 'continuous'))
        self._mass: Dict[str, Tuple[float, np.ndarray]] = {}
        for link in root.iter('link'):
            inertial = link.find('inertial')
            if inertial is not None and inertial.find('mass') is not None:
                mass = float(inertial.find('mass').get('value', '0'))   # type: ignore[union-attr]
                self._mass[link.get('name', '')] = (mass, _origin(inertial.find('origin')))
        self.joints = tuple(joints)
        self.effort = np.array([float(j.find('limit').get('effort', 'nan'))  # type: ignore
                                for name in self.joints for j in root.iter('joint')
                                if j.get('name') == name])
        by_child = {j.child: j for j in self._joints.values()}
        # The chain from the first joint's parent link down to the tool.
        chain: List[_Joint] = []
        name = tool
        while name in by_child:
            chain.append(by_child[name])
            name = by_child[name].parent
            if chain[-1].name == self.joints[0]:
                break
        chain.reverse()
        if not chain or chain[0].name != self.joints[0]:
            raise ValueError(f'{tool} does not hang from joint {self.joints[0]}')
        self._chain = chain
        self._base = chain[0].parent
        self._tool = tool
        # Every link after the first joint (the chain's and their fixed or moving branches,
        # such as the fingers), with the chain link it hangs from.
        self._below: Dict[str, List[Tuple[str, np.ndarray]]] = {}
        on_chain = {j.child for j in chain}
        for child in on_chain:
            self._below[child] = self._branch(child, on_chain)

    def _branch(self, link: str, on_chain: Set[str]) -> List[Tuple[str, np.ndarray]]:
        """Links hanging from ``link`` off the chain (fingers: at their zero), with their
        transform from ``link``'s frame."""
        out = []
        for j in self._joints.values():
            if j.parent == link and j.child not in on_chain:
                out.append((j.child, j.origin))
                out += [(name, j.origin @ T) for name, T in self._branch(j.child, on_chain)]
        return out

    def torques(self, q: Vector, payload: float = 0.0) -> np.ndarray:
        """The torque each of ``joints`` applies to hold the arm at rest at ``q`` [N m], about
        its axis, with ``payload`` kg at the tool link's origin."""
        q = np.asarray(q, float)
        index = {name: k for k, name in enumerate(self.joints)}
        T = np.eye(4)
        frames: List[Tuple[np.ndarray, np.ndarray]] = []     # (origin, axis) per chain joint
        points: List[Tuple[int, float, np.ndarray]] = []     # (after joint k, mass, position)
        for k, j in enumerate(self._chain):
            T = T @ j.origin
            axis = T[:3, :3] @ (j.axis / np.linalg.norm(j.axis))
            if j.revolute and j.name in index:
                R = np.eye(4)
                R[:3, :3] = _axis_rotation(j.axis, float(q[index[j.name]]))
                T = T @ R
            frames.append((T[:3, 3].copy(), axis))
            for name, offset in [(j.child, np.eye(4))] + self._below[j.child]:
                if name in self._mass:
                    mass, com = self._mass[name]
                    points.append((k, mass, (T @ offset @ com)[:3, 3]))
        if payload > 0.0:
            points.append((len(self._chain) - 1, payload, T[:3, 3].copy()))
        out = np.zeros(len(self.joints))
        for k, j in enumerate(self._chain):
            if j.name not in index or not j.revolute:
                continue
            origin, axis = frames[k]
            # The moment of the weights beyond it about its origin: sum m (p - o) x g, that is
            # (sum m p - (sum m) o) x g.
            beyond = [(mass, p) for after, mass, p in points if after >= k]
            first = sum((mass * p for mass, p in beyond), np.zeros(3))
            r = first - sum(mass for mass, _ in beyond) * origin
            g = GRAVITY
            moment = np.array([r[1] * g[2] - r[2] * g[1], r[2] * g[0] - r[0] * g[2],
                               r[0] * g[1] - r[1] * g[0]])
            out[index[j.name]] = -float(axis @ moment)         # (what the joint applies)
        return out

    def load(self, q: Vector, payload: float = 0.0) -> float:
        """The largest joint's share of its effort held at rest at ``q`` (1.0: at its limit)."""
        return float(np.max(np.abs(self.torques(q, payload)) / self.effort))
