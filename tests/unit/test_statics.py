"""The arms' gravity model (controllers.statics) against the physics engine's own inverse
dynamics, and what the youBot's arm can hold."""
import numpy as np
import pybullet as p
import pytest

from controllers.statics import ArmStatics
from robot_description import urdf_path

JOINTS = [f'arm_joint_{k}' for k in range(1, 6)]


@pytest.fixture(scope='module')
def engine():
    cid = p.connect(p.DIRECT)
    p.setGravity(0, 0, -9.81, physicsClientId=cid)
    robot = p.loadURDF(str(urdf_path('youbot')), useFixedBase=True, physicsClientId=cid)
    yield cid, robot
    p.disconnect(cid)


def _engine_torques(engine, q, payload):
    cid, robot = engine
    joints = [p.getJointInfo(robot, j, physicsClientId=cid) for j in
              range(p.getNumJoints(robot, physicsClientId=cid))]
    movable = [j[0] for j in joints if j[2] != p.JOINT_FIXED]
    arm = [next(j[0] for j in joints if j[1].decode() == name) for name in JOINTS]
    tcp = next(j[0] for j in joints if j[12].decode() == 'gripper_tcp')
    qs = [0.0] * len(movable)
    for k, j in enumerate(arm):
        qs[movable.index(j)] = float(q[k])
    for j, v in zip(movable, qs):
        p.resetJointState(robot, j, v, physicsClientId=cid)
    zero = [0.0] * len(qs)
    tau = p.calculateInverseDynamics(robot, qs, zero, zero, physicsClientId=cid)
    lin, _ = p.calculateJacobian(robot, tcp, [0, 0, 0], qs, zero, zero, physicsClientId=cid)
    jac = np.array(lin)[:, [movable.index(j) for j in arm]]
    return np.array([tau[movable.index(j)] for j in arm]) + jac.T @ [0.0, 0.0, 9.81 * payload]


def test_the_static_torques_are_the_engines_at_any_pose_with_any_payload(engine):
    statics = ArmStatics(urdf_path('youbot'), JOINTS, 'gripper_tcp')
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = rng.uniform(-1.5, 1.5, 5)
        payload = float(rng.uniform(0.0, 0.5))
        assert np.allclose(statics.torques(q, payload), _engine_torques(engine, q, payload),
                           atol=1e-6)
    assert statics.effort.tolist() == [9.5, 9.5, 6.0, 2.0, 1.0]


def test_the_youbot_holds_its_load_upright_but_not_stretched_out():
    """Upright (the candle) the joints hold almost nothing; stretched out level, 0.38 kg takes
    the shoulder past its 9.5 N m (the simulated arm sagged 0.24 rad there)."""
    from cell_layout.reach import YOUBOT_LOAD_MAX, youbot_holds, youbot_statics
    statics = youbot_statics()
    assert statics.load(np.zeros(5), 0.5) < 0.05
    level = np.array([0.0, 1.5708, 0.0, 0.0, 0.0])          # shoulder forward, arm level
    assert statics.load(level, 0.38) > 1.0 > statics.load(level, 0.0) * 0.5
    assert youbot_holds([np.zeros(5)], 0.5) and not youbot_holds([np.zeros(5), level], 0.38)
    assert 0.88 < YOUBOT_LOAD_MAX < 1.0
