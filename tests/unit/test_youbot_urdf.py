"""The youBot description: generated from the published numbers, loadable by PyBullet and
pinocchio, and carrying the paper's MDH frames (FK agrees with pinocchio within 1e-9)."""
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from controllers.youbot_arm import (
    ARM_BASE_IN_BASE_LINK_M,
    DATASHEET_LIMITS_DEG,
    GRIPPER_TCP_OFFSET_M,
    JOINT_NAMES,
    datasheet_from_theta,
    theta_from_datasheet,
    youbot_arm_chain,
)
from robot_description import urdf_path, youbot_urdf
from sim_bridge.world import URDF_FLAGS

URDF = urdf_path('youbot')
ROOT = ET.parse(URDF).getroot()
LOWER = np.radians([lo for lo, _ in DATASHEET_LIMITS_DEG])
UPPER = np.radians([hi for _, hi in DATASHEET_LIMITS_DEG])


def test_the_committed_urdf_is_what_the_generator_writes():
    assert Path(URDF).read_text() == youbot_urdf.render(), \
        'run generate_urdf youbot after changing the numbers'


def test_parts_joints_and_published_masses():
    links = {link.get('name'): link for link in ROOT.findall('link')}
    masses = {name: float(link.find('inertial/mass').get('value'))
              for name, link in links.items()}
    assert masses['base_link'] == 22.0
    for wheel in ('fl', 'fr', 'rr', 'rl'):
        assert masses[f'wheel_link_{wheel}'] == 1.4
    assert [masses[f'arm_link_{i}'] for i in range(6)] == [0.961, 1.390, 1.318, 0.821, 0.769,
                                                           0.687]
    moving = {j.get('name'): j.get('type') for j in ROOT.findall('joint')
              if j.get('type') != 'fixed'}
    assert moving == {**{f'wheel_joint_{w}': 'continuous' for w in ('fl', 'fr', 'rr', 'rl')},
                      **{name: 'revolute' for name in JOINT_NAMES},
                      'gripper_finger_joint_l': 'prismatic',
                      'gripper_finger_joint_r': 'prismatic'}
    for side in 'lr':
        limit = ROOT.find(f"joint[@name='gripper_finger_joint_{side}']/limit")
        assert (float(limit.get('lower')), float(limit.get('upper'))) == (0.0, 0.0115)


def test_limits_are_the_papers_in_the_descriptions_own_convention():
    for name, lo, hi in zip(JOINT_NAMES, LOWER, UPPER):
        limit = ROOT.find(f"joint[@name='{name}']/limit")
        assert float(limit.get('lower')) == pytest.approx(lo, abs=1e-12)
        assert float(limit.get('upper')) == pytest.approx(hi, abs=1e-12)
        assert float(limit.get('velocity')) == pytest.approx(math.pi / 2)
    # ... and they convert to the table's theta limits of the chain.
    chain_lo, chain_hi = youbot_arm_chain().limits
    ends = np.sort(np.stack([theta_from_datasheet(LOWER), theta_from_datasheet(UPPER)]), axis=0)
    assert ends[0] == pytest.approx(chain_lo) and ends[1] == pytest.approx(chain_hi)


def test_inertias_are_plausible_not_the_published_oversized_ones():
    base = ROOT.find("link[@name='base_link']/inertial/inertia")
    assert float(base.get('ixx')) == pytest.approx(0.256, rel=0.01)
    assert float(base.get('iyy')) == pytest.approx(0.614, rel=0.01)
    assert float(base.get('izz')) == pytest.approx(0.833, rel=0.01)
    wheel = ROOT.find("link[@name='wheel_link_fl']/inertial/inertia")
    assert float(wheel.get('iyy')) == pytest.approx(0.00158, rel=0.01)   # about the axle
    for link in ROOT.findall('link'):
        inertia = link.find('inertial/inertia')
        d = sorted(float(inertia.get(k)) for k in ('ixx', 'iyy', 'izz'))
        assert d[0] + d[1] >= d[2] * (1 - 1e-6), f'{link.get("name")}: triangle inequality'


def _pin_model():
    model = pin.buildModelFromUrdf(str(URDF))
    return model, model.createData()


def _pin_q(model, phi):
    q = pin.neutral(model)
    for name, value in zip(JOINT_NAMES, phi):
        q[model.joints[model.getJointId(name)].idx_q] = value
    return q


def test_mdh_fk_agrees_with_pinocchio_at_1000_random_configurations():
    model, data = _pin_model()
    base, flange = model.getFrameId('arm_base_frame'), model.getFrameId('arm_link_5')
    chain = youbot_arm_chain()
    rng = np.random.default_rng(4)
    worst_pos = worst_rot = 0.0
    for _ in range(1000):
        phi = rng.uniform(LOWER, UPPER)
        pin.framesForwardKinematics(model, data, _pin_q(model, phi))
        expected = (data.oMf[base].inverse() * data.oMf[flange]).homogeneous
        got = chain.fk(theta_from_datasheet(phi))
        worst_pos = max(worst_pos, float(np.abs(got[:3, 3] - expected[:3, 3]).max()))
        # Rotation error as an angle (log map; accurate for tiny angles, unlike acos).
        rel = got[:3, :3].T @ expected[:3, :3]
        worst_rot = max(worst_rot, float(np.linalg.norm(pin.log3(rel))))
    assert worst_pos < 1e-9 and worst_rot < 1e-9
    # Every intermediate joint frame too, at one configuration.
    phi = rng.uniform(LOWER, UPPER)
    pin.framesForwardKinematics(model, data, _pin_q(model, phi))
    for i, frame in enumerate(chain.frames(theta_from_datasheet(phi))[:5]):
        link = (data.oMf[base].inverse() * data.oMf[model.getFrameId(f'arm_link_{i + 1}')])
        assert frame == pytest.approx(link.homogeneous, abs=1e-12)


def test_robot_models_test_poses_in_the_description():
    model, data = _pin_model()
    base, flange = model.getFrameId('arm_base_frame'), model.getFrameId('arm_link_5')
    for phi, position in ((datasheet_from_theta(np.zeros(5)), (0.323, 0.0, 0.260)),
                          (np.zeros(5), (0.033, 0.0, 0.550))):          # table zero, candle
        pin.framesForwardKinematics(model, data, _pin_q(model, phi))
        pose = data.oMf[base].inverse() * data.oMf[flange]
        assert pose.translation == pytest.approx(position, abs=1e-12)
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    assert data.oMf[base].translation == pytest.approx(ARM_BASE_IN_BASE_LINK_M, abs=1e-12)
    tcp = data.oMf[flange].inverse() * data.oMf[model.getFrameId('gripper_tcp')]
    assert tcp.translation == pytest.approx((0.0, 0.0, GRIPPER_TCP_OFFSET_M), abs=1e-12)


def test_pybullet_loads_it_with_the_same_frames():
    p = BulletClient(connection_mode=pybullet.DIRECT)
    try:
        body = p.loadURDF(str(URDF), flags=URDF_FLAGS)
        index = {p.getJointInfo(body, j)[12].decode(): j for j in range(p.getNumJoints(body))}
        joints = {p.getJointInfo(body, j)[1].decode(): j for j in range(p.getNumJoints(body))}
        assert p.getDynamicsInfo(body, -1)[0] == pytest.approx(22.0)
        model, data = _pin_model()
        phi = np.array([0.4, -0.3, 1.1, -0.7, 2.0])
        for name, value in zip(JOINT_NAMES, phi):
            p.resetJointState(body, joints[name], value)
        pin.framesForwardKinematics(model, data, _pin_q(model, phi))
        for link in ('arm_link_5', 'gripper_tcp'):
            state = p.getLinkState(body, index[link], computeForwardKinematics=True)
            rot = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            expected = data.oMf[model.getFrameId(link)]
            assert np.asarray(state[4]) == pytest.approx(expected.translation, abs=1e-6)
            assert rot == pytest.approx(expected.rotation, abs=1e-6)
    finally:
        p.disconnect()
