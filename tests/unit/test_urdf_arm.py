"""Arms as data (issue 64): the generic IK from a URDF against the analytic solvers, its limits,
continuity along a motion and refusals; the model registry finds the fast paths by the URDF's
kinematics, not by names; a world's arm entry gives the model."""
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet_data
import pytest

from cell_layout.arm_models import ArmModelError, arm_model
from controllers.arm_registry import ArmSpec, arm_kinematics, generic_kinematics
from controllers.urdf_arm import UrdfArm, UrdfArmError
from controllers.youbot_kinematics import YoubotKinematics
from controllers.zu12_kinematics import Zu12Kinematics
from robot_description import urdf_path
from world_description.world_config import load_world

WORLDS = Path(__file__).resolve().parents[2] / 'world_description' / 'worlds'
PANDA = Path(pybullet_data.getDataPath()) / 'franka_panda' / 'panda.urdf'
PANDA_JOINTS = tuple(f'panda_joint{i}' for i in range(1, 8))
ZU12_JOINTS = tuple(f'joint_{i}' for i in range(1, 7))
YOUBOT_JOINTS = tuple(f'arm_joint_{i}' for i in range(1, 6))
DOWN = np.diag([1.0, -1.0, -1.0])


def _reached(kin, target, solution, tol=1e-6):
    pose = kin.fk(solution.positions)
    rotation = np.linalg.norm(pin.log3(pose[:3, :3].T @ target[:3, :3]))
    return (np.linalg.norm(pose[:3, 3] - target[:3, 3]) <= tol and rotation <= tol
            and kin.within_limits(solution.positions))


@pytest.mark.parametrize('analytic, urdf, joints, tool', [
    (Zu12Kinematics('suction_tcp'), 'zu12', ZU12_JOINTS, 'suction_tcp'),
    (YoubotKinematics('gripper_tcp'), 'youbot', YOUBOT_JOINTS, 'gripper_tcp'),
])
def test_the_generic_ik_reaches_what_the_analytic_solvers_reach(analytic, urdf, joints, tool):
    """Poses the analytic solver reaches (its forward kinematics at postures over the limits),
    solved by the generic solver from a posture drawn over the limits: its own forward
    kinematics within 1e-6 m and 1e-6 rad, within the limits (bench_arm_ik.py: 10,000)."""
    generic = generic_kinematics(ArmSpec(urdf_path(urdf), joints, tool))
    rng = np.random.default_rng(64)
    for q in rng.uniform(analytic.lower, analytic.upper, (200, len(joints))):
        assert np.allclose(generic.fk(q), analytic.fk(q), atol=1e-12)
    solved = 0
    while solved < 150:
        target = analytic.fk(rng.uniform(analytic.lower, analytic.upper))
        if not analytic.ik(target).success:
            continue
        solution = generic.ik(target, rng.uniform(generic.lower, generic.upper))
        assert solution.success, solution.reason
        assert _reached(generic, target, solution)
        solved += 1


def _panda(**kw):
    return UrdfArm(PANDA, PANDA_JOINTS, 'panda_hand', (0.0, 0.0, 0.14), **kw)


def test_a_seven_joint_arm_follows_a_motion_on_one_branch_and_keeps_its_posture():
    """Along a pick's path (a straight line over a belt and down), each solution seeded with
    the one before: no joint moves more than 0.1 rad for 6 mm of the tool's way, and the arm
    ends near its preferred posture, not wandering along its null space."""
    home = np.array([0.596, -0.223, 0.782, -1.33, 0.17, 1.176, 0.713])
    arm = _panda(preferred=home)
    q = arm.ik(_target((0.0, 0.45, 0.55)), home).positions
    assert q is not None
    for k in range(60):
        z = 0.45 + 0.1 * max(0.0, 1.0 - k / 12)
        solution = arm.ik(_target((0.006 * k, 0.45, z)), q)
        assert solution.success and _reached(arm, _target((0.006 * k, 0.45, z)), solution)
        assert np.max(np.abs(solution.positions - q)) < 0.1
        q = solution.positions
    assert np.max(np.abs(q - home)) < 1.0


def _target(p, rotation=DOWN):
    target = np.eye(4)
    target[:3, :3], target[:3, 3] = rotation, p
    return target


def test_a_free_yaw_leaves_the_tool_turned_as_the_seed_has_it():
    arm = _panda(free_yaw=True)
    turned = _target((0.4, 0.1, 0.3), DOWN @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]))
    solution = arm.ik(turned)
    assert solution.success and solution.rotation_error < 1e-6 and solution.position_error < 1e-6
    # (The tool's axis is the target's; its turn about the axis is its own.)
    assert np.allclose(arm.fk(solution.positions)[:3, 2], turned[:3, 2], atol=1e-6)


def test_the_generic_ik_answers_without_raising_and_says_why():
    arm = _panda()
    assert 'finite 4x4' in arm.ik(np.full((4, 4), np.nan)).reason
    far = arm.ik(_target((3.0, 0.0, 0.5)))
    assert not far.success and 'out of reach: 3.0' in far.reason
    # Below the floor it stands on: refused with the floor named.
    low = UrdfArm(PANDA, PANDA_JOINTS, 'panda_hand', (0.0, 0.0, 0.14), floor=0.0)
    answer = low.ik(_target((0.5, 0.0, -0.05)))
    assert not answer.success and ('floor' in answer.reason or 'out of reach' in answer.reason)
    # Same request, same answer (the restarts are seeded by the target).
    target = _target((0.3, -0.3, 0.2))
    assert np.array_equal(arm.ik(target).positions, arm.ik(target).positions)


@pytest.mark.parametrize('joints, tool, fragment', [
    (PANDA_JOINTS + ('elbow',), 'panda_hand', "no joint ['elbow']"),
    (PANDA_JOINTS, 'gripper', 'no link "gripper"'),
    (PANDA_JOINTS[:6], 'panda_hand', "joints ['panda_joint7'] move panda_hand but are not"),
    (PANDA_JOINTS + ('panda_finger_joint1',), 'panda_hand',
     "joints ['panda_finger_joint1'] do not move panda_hand"),
])
def test_an_arm_the_urdf_does_not_describe_is_refused_in_one_line(joints, tool, fragment):
    with pytest.raises(UrdfArmError, match=fragment.replace('[', r'\[').replace(']', r'\]')):
        UrdfArm(PANDA, joints, tool)


def test_the_registry_finds_the_fast_paths_by_the_urdfs_kinematics():
    """The Zu 12's and the youBot arm's URDFs get their analytic solvers (whatever the robot is
    called); another tool on the same chain, or another arm, the generic solver."""
    kin, solver = arm_kinematics(ArmSpec(urdf_path('zu12'), ZU12_JOINTS, 'suction_tcp',
                                         base_pose=(1.0, 2.0, 0.0, 0.5)))
    assert isinstance(kin, Zu12Kinematics) and 'analytic' in solver
    assert 'world' in kin.reference_frames
    kin, solver = arm_kinematics(ArmSpec(urdf_path('youbot'), YOUBOT_JOINTS, 'gripper_tcp'))
    assert isinstance(kin, YoubotKinematics)
    kin, solver = arm_kinematics(ArmSpec(urdf_path('zu12'), ZU12_JOINTS, 'link_6'))
    assert isinstance(kin, UrdfArm) and solver.startswith('generic')
    # The fast path's flange is a tool of its own: found there too.
    kin, _ = arm_kinematics(ArmSpec(urdf_path('zu12'), ZU12_JOINTS, 'flange'))
    assert isinstance(kin, Zu12Kinematics) and kin.tool_frame == 'flange'
    kin, solver = arm_kinematics(ArmSpec(PANDA, PANDA_JOINTS, 'panda_hand'))
    assert isinstance(kin, UrdfArm)


def test_a_worlds_arm_entry_is_its_model():
    """The Panda cell's loader: its URDF from PyBullet's data, its joints, its cup 14 cm out
    along the hand, its limits (velocity below the URDF's, Franka's accelerations, from its
    joint_limits file); a joint_limits file's velocity above the URDF's does not raise it."""
    world = load_world(WORLDS / 'cell_panda.yaml')
    model = arm_model(world.robot('panda'), WORLDS)
    assert model.spec.joints == PANDA_JOINTS and model.spec.tool_offset == (0.0, 0.0, 0.14)
    assert model.spec.base_pose == (0.35, 0.3, 0.0, 0.0)
    assert model.velocity == (1.9575,) * 4 + (2.088,) * 3
    assert model.acceleration == (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
    assert model.jerk == tuple(500.0 * a for a in model.acceleration)
    cup = model.kinematics.fk(np.array(model.spec.preferred))
    assert np.allclose(cup[:3, 2], [0.0, 0.0, -1.0], atol=1e-3)      # (pointing down)
    # The paper's Zu 12: its analytic solver, and the limits its constants give.
    from controllers import zu12_arm
    paper = load_world(WORLDS / 'pipeline_cell.yaml')
    zu12 = arm_model(paper.robot('zu12'), WORLDS)
    assert isinstance(zu12.kinematics, Zu12Kinematics)
    assert zu12.velocity == tuple(zu12_arm.JOINT_VELOCITY_LIMITS)
    assert zu12.acceleration == zu12_arm.JOINT_ACCELERATION_LIMITS
    assert zu12.jerk == zu12_arm.JOINT_JERK_LIMITS


def test_a_robot_without_an_arm_is_refused():
    world = load_world(WORLDS / 'pipeline_cell.yaml')
    from dataclasses import replace
    robot = replace(world.robot('zu12'), controllers=())
    with pytest.raises(ArmModelError, match='robot zu12: it has no arm_controller'):
        arm_model(robot, WORLDS)


def test_the_loader_is_known_by_its_model_only_through_the_registry():
    """No module of the controller, the cell's layout, the studies, the results or the IK
    node imports an arm's own kinematics or names the Zu 12 in its code (a name, an attribute,
    a keyword, a field): the loader's model comes from the world through the registry
    (controllers/arm_registry.py), and results name roles and robots. (The transport is still
    the youBot: issue 65.)"""
    import ast
    root = Path(__file__).resolve().parents[2]
    model_modules = {'controllers.zu12_arm', 'controllers.zu12_kinematics', 'controllers.zu12_ik'}
    found = []
    for package in ('coordinator', 'cell_layout', 'studies', 'arm_kinematics', 'trial_record'):
        for path in (root / package / package).rglob('*.py'):
            tree = ast.parse(path.read_text())
            for node in ast.walk(tree):
                names = []
                if isinstance(node, ast.ImportFrom) and node.module:
                    names = [node.module] + [f'{node.module}.{a.name}' for a in node.names]
                elif isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.Name):
                    names = [node.id]
                elif isinstance(node, ast.Attribute):
                    names = [node.attr]
                elif isinstance(node, ast.keyword) and node.arg:
                    names = [node.arg]
                elif isinstance(node, (ast.arg, ast.FunctionDef, ast.ClassDef)):
                    names = [node.arg if isinstance(node, ast.arg) else node.name]
                bad = [n for n in names if n in model_modules or 'zu12' in n.lower()]
                found += [f'{path.relative_to(root)}:{node.lineno}: {n}' for n in bad]
    assert found == []
