"""The JAKA Zu 12: description generated from the DH table, FK against pinocchio, analytic IK."""
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet
import pytest
from pybullet_utils.bullet_client import BulletClient

from controllers.transforms import pose_matrix, quaternion_to_matrix
from controllers.zu12_arm import JOINT_NAMES, JOINT_VELOCITY_LIMITS, zu12_chain
from controllers.zu12_ik import solve_ik
from controllers.zu12_kinematics import Zu12Kinematics
from robot_description import urdf_path, zu12_urdf
from sim_bridge.world import URDF_FLAGS

URDF = urdf_path('zu12')


def test_the_committed_urdf_is_what_the_generator_writes():
    assert Path(URDF).read_text() == zu12_urdf.render(), 'run generate_urdf zu12'


def _pin():
    model = pin.buildModelFromUrdf(str(URDF))
    return model, model.createData()


def test_fk_agrees_with_pinocchio_at_1000_random_configurations():
    model, data = _pin()
    assert [model.names[i] for i in range(1, model.njoints)] == list(JOINT_NAMES)
    flange = model.getFrameId('flange')
    chain = zu12_chain()
    lower, upper = chain.limits
    rng = np.random.default_rng(12)
    worst_pos = worst_rot = 0.0
    for _ in range(1000):
        q = rng.uniform(lower, upper)
        pin.framesForwardKinematics(model, data, q)
        expected, got = data.oMf[flange].homogeneous, chain.fk(q)
        worst_pos = max(worst_pos, float(np.abs(got[:3, 3] - expected[:3, 3]).max()))
        worst_rot = max(worst_rot,
                        float(np.linalg.norm(pin.log3(got[:3, :3].T @ expected[:3, :3]))))
    assert worst_pos < 1e-9 and worst_rot < 1e-9


def test_the_published_zero_pose_limits_and_speeds():
    model, data = _pin()
    pin.framesForwardKinematics(model, data, np.zeros(6))
    flange = data.oMf[model.getFrameId('flange')]
    assert flange.translation == pytest.approx((1.1665, 0.028, 0.02765), abs=1e-12)
    assert flange.rotation == pytest.approx(np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]),
                                            abs=1e-12)
    assert np.degrees(model.lowerPositionLimit) == pytest.approx([-360, -85, -175, -85, -360,
                                                                  -360])
    assert np.degrees(model.upperPositionLimit) == pytest.approx([360, 265, 175, 265, 360, 360])
    assert np.degrees(model.velocityLimit) == pytest.approx([120, 120, 120, 180, 180, 180])
    tcp = data.oMf[model.getFrameId('flange')].inverse() * data.oMf[
        model.getFrameId('suction_tcp')]
    assert tcp.translation == pytest.approx((0.0, 0.0, 0.1))


def test_pybullet_loads_it_with_the_same_flange():
    p = BulletClient(connection_mode=pybullet.DIRECT)
    try:
        body = p.loadURDF(str(URDF), useFixedBase=True, flags=URDF_FLAGS)
        links = {p.getJointInfo(body, j)[12].decode(): j for j in range(p.getNumJoints(body))}
        joints = {p.getJointInfo(body, j)[1].decode(): j for j in range(p.getNumJoints(body))}
        q = [0.3, 1.2, -0.8, 0.5, 1.0, -2.0]
        for name, value in zip(JOINT_NAMES, q):
            p.resetJointState(body, joints[name], value)
        state = p.getLinkState(body, links['flange'], computeForwardKinematics=True)
        expected = zu12_chain().fk(q)
        assert np.asarray(state[4]) == pytest.approx(expected[:3, 3], abs=1e-6)
        assert np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3) == \
            pytest.approx(expected[:3, :3], abs=1e-6)
    finally:
        p.disconnect()


def test_ik_round_trips_1000_fk_targets():
    chain = zu12_chain()
    lower, upper = chain.limits
    rng = np.random.default_rng(5)
    solved = 0
    for _ in range(1000):
        target = chain.fk(rng.uniform(lower, upper))
        result = solve_ik(target, rng.uniform(lower, upper), chain)
        if result.success:
            assert chain.within_limits(result.q)
            assert result.position_error < 1e-7 and result.rotation_error < 1e-7
            solved += 1
    assert solved >= 995


def test_the_seed_picks_the_nearest_of_the_eight_solutions():
    chain = zu12_chain()
    q = np.array([0.4, 1.1, -0.9, 0.7, 1.3, -0.5])
    result = solve_ik(chain.fk(q), q + 0.02, chain)
    assert result.q == pytest.approx(q, abs=1e-9)
    assert len(result.candidates) >= 4


def test_unreachable_targets_fail_with_a_reason():
    far = pose_matrix((2.0, 0.0, 0.5), (0, 0, 0, 1))
    result = solve_ik(far)
    assert not result.success and 'out of reach' in result.reason
    assert not solve_ik(np.full((4, 4), np.nan)).success


def test_kinematics_with_the_suction_tool_and_the_world_frame():
    base = pose_matrix((1.0, -0.5, 0.0), (0, 0, math.sin(0.3), math.cos(0.3)))
    kin = Zu12Kinematics(world_to_base=base)
    assert kin.velocity_limits == pytest.approx(JOINT_VELOCITY_LIMITS)
    down = quaternion_to_matrix((1, 0, 0, 0))             # tool z pointing down
    target_world = np.eye(4)
    target_world[:3, :3] = down
    target_world[:3, 3] = (1.6, -0.2, 0.3)
    target = kin.in_base_link('world', target_world)
    result = kin.ik(target, np.array([0.0, 1.5, -1.5, 1.5, 1.57, 0.0]))
    assert result.success, result.reason
    assert (base @ kin.fk(result.positions))[:3, 3] == pytest.approx((1.6, -0.2, 0.3), abs=1e-9)
    with pytest.raises(KeyError):
        Zu12Kinematics().in_base_link('world', target_world)


def test_the_floor_check_sees_every_joint_frame_above_the_shoulder():
    """above_floor (float arithmetic) against the joint frames multiplied out in numpy."""
    kin = Zu12Kinematics()
    lower, upper = kin.chain.limits
    rng = np.random.default_rng(8)
    verdicts = set()
    for _ in range(500):
        q = rng.uniform(lower, upper)
        lowest = min(f[2, 3] for f in kin.chain.frames(q)[1:])
        assert kin.above_floor(q) == (lowest >= kin.min_frame_height)
        verdicts.add(kin.above_floor(q))
    assert verdicts == {True, False}


def test_ik_never_answers_with_an_arm_through_the_floor():
    kin = Zu12Kinematics()
    lower, upper = kin.chain.limits
    rng = np.random.default_rng(9)
    answered = 0
    for _ in range(300):
        target = kin.fk(rng.uniform(lower, upper))
        result = kin.ik(target, rng.uniform(lower, upper))
        if result.success:
            answered += 1
            assert kin.above_floor(result.positions)
            assert result.position_error < 1e-9 and result.rotation_error < 1e-9
        else:
            assert 'floor' in result.reason or 'limits' in result.reason, result.reason
    assert answered > 100


def test_generate_urdf_checks_and_writes_the_descriptions(tmp_path, capsys):
    from robot_description.generate_urdf import main
    assert main(['--check']) == 0                      # the committed files are up to date
    assert 'zu12.urdf: up to date' in capsys.readouterr().out
    assert main(['zu12', '--out', str(tmp_path)]) == 0
    assert (tmp_path / 'zu12.urdf').read_text() == Path(URDF).read_text()
    assert not (tmp_path / 'youbot.urdf').exists()
    (tmp_path / 'zu12.urdf').write_text('<robot/>')
    assert main(['zu12', '--check', '--out', str(tmp_path)]) == 1
    with pytest.raises(SystemExit) as refused:
        main(['ur5', '--out', str(tmp_path)])
    assert refused.value.code == 2 and 'no generator for ur5' in capsys.readouterr().err
