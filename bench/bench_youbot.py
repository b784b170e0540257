"""youBot benchmark: base odometry error under cmd_vel, arm tracking error, and the cost of the
Mecanum drive and trajectory controllers against raw PyBullet stepping of the same model.

Physics only (no DDS): the simulator's SimRunner, which the node steps the same way. Prints the
figures and writes JSON to bench/results/.
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from controllers.arm_model import motion_duration
from controllers.base_fidelity import tracking_errors
from controllers.diff_drive import Pose2D
from controllers.joint_trajectory import TrajectoryPoint, TrajectoryRequest
from controllers.mecanum import BASE_LINK_HEIGHT_M
from controllers.transforms import yaw_from_quaternion
from controllers.youbot_arm import theta_from_datasheet
from controllers.youbot_kinematics import REFERENCE_FRAMES, YoubotKinematics
from robot_description import urdf_path
from sim_bridge.runner import DriveLimits, NullSink, SimRunner
from sim_bridge.world import URDF_FLAGS, SimWorld
from world_description import YOUBOT_WORLD
from world_description.resources import resolve_resource
from world_description.world_config import load_world

HERE = Path(__file__).resolve().parent
DT = 1.0 / 240.0
K = 0.386
CASES = [('vx', (0.2, 0.0, 0.0)), ('vy', (0.0, 0.2, 0.0)), ('wz', (0.0, 0.0, 0.5)),
         ('combined', (0.15, -0.1, 0.3)), ('vx fast', (0.8, 0.0, 0.0)),
         ('vy fast', (0.0, 0.8, 0.0)), ('wz fast', (0.0, 0.0, 1.5)),
         ('combined fast', (0.5, 0.5, 1.0))]


def _world():
    world = SimWorld(load_world(resolve_resource(YOUBOT_WORLD)), time_step=DT)
    return world, SimRunner(world, DriveLimits(cmd_vel_timeout=0.5), 100.0)


def _pose(robot):
    s = robot.sensors.base_state()
    return Pose2D(s.position[0], s.position[1], yaw_from_quaternion(s.orientation))


def startup_seconds(limits, command) -> float:
    """How long the base takes to reach ``command`` at its acceleration limits, plus 0.3 s to
    settle; at least 0.5 s."""
    vx, vy, wz = command
    ramps = [0.0]
    if limits.max_accel:
        ramps += [abs(vx) / limits.max_accel, abs(vy) / limits.max_accel]
    if limits.max_turn_accel:
        ramps.append(abs(wz) / limits.max_turn_accel)
    return max(0.5, max(ramps) + 0.3)


def base_fidelity():
    world, runner = _world()
    robot, sink = world.robots['youbot'], NullSink()
    rows = {}
    for label, command in CASES:
        runner.reset()
        runner.advance(120, sink)
        # The start-up: the ramp to the command at the base's acceleration limits, and 0.3 s
        # more to settle (at least 0.5 s); then the measured 2 s window.
        settle = int(round(startup_seconds(world.config.robots[0].limits, command) / DT))
        twists, start = [], None
        for k in range(settle + int(2.0 / DT)):
            if k % 24 == 0:
                runner.command('youbot', *command)
            if k == settle:
                start = _pose(robot)
            runner.advance(1, sink)
            if k >= settle:
                s = robot.sensors.base_state()
                twists.append((s.linear[0], s.linear[1], s.angular[2]))
        e = tracking_errors(command, 2.0, start, _pose(robot), tuple(np.mean(twists, 0)), K)
        rows[label] = {'command': command, 'twist_error': e.twist_error,
                       'position_error': e.position_error, 'cross_drift': e.cross_drift,
                       'yaw_error': e.yaw_error}
    world.close()
    return rows


def arm_tracking(trials: int):
    world, runner = _world()
    robot, sink = world.robots['youbot'], NullSink()
    arm = robot.controllers['arm_controller']
    kin = YoubotKinematics()
    rng = np.random.default_rng(7)
    moving, final = [], []
    for _ in range(trials):
        q0 = arm.actual()[0]
        waypoints = []
        while len(waypoints) < 3:
            q = rng.uniform(kin.lower * 0.8, kin.upper * 0.8)
            if _clear_of_the_floor(kin, waypoints[-1] if waypoints else q0, q):
                waypoints.append(q)
        t, points, previous = 0.0, [], q0
        for q in waypoints:
            t += motion_duration(previous, q, kin.velocity_limits, 0.8)
            points.append(TrajectoryPoint(t, tuple(q)))
            previous = q
        result = runner.set_trajectory('youbot', 'arm_controller',
                                       TrajectoryRequest(kin.joint_names, tuple(points)))
        assert result.accepted, result.reason
        for _ in range(int(t / DT)):
            runner.advance(1, sink)
            moving.append(arm.desired.positions - arm.actual()[0])
        runner.advance(int(0.5 / DT), sink)
        final.append(np.abs(arm.actual()[0] - waypoints[-1]).max())
    world.close()
    moving = np.abs(np.array(moving))
    return {'trials': trials, 'rms_rad': float(np.sqrt((moving ** 2).mean())),
            'p99_rad': float(np.percentile(moving, 99)), 'max_rad': float(moving.max()),
            'final_max_rad': float(max(final))}


def _clear_of_the_floor(kin, q0, q1, margin=0.05):
    """Every joint frame and the gripper stay ``margin`` above the ground along the joint-space
    line from q0 to q1 (the arm does not collide with its own base here, but with the floor)."""
    ground = -BASE_LINK_HEIGHT_M + margin            # base_link above the ground
    for s in np.linspace(0.0, 1.0, 11):
        q = (1 - s) * np.asarray(q0) + s * np.asarray(q1)
        frames = kin.chain.frames(theta_from_datasheet(q))
        heights = [(REFERENCE_FRAMES['arm_base_frame'] @ f)[2, 3] for f in frames]
        if min(heights + [kin.fk(q)[2, 3]]) < ground:
            return False
    return True


def stepping_cost(seconds: float):
    """Steps per wall second: raw PyBullet (floor + youBot URDF, no motors) against the
    simulator's runner driving the base and following an arm trajectory."""
    p = BulletClient(connection_mode=pybullet.DIRECT)
    p.setTimeStep(DT)
    p.setGravity(0, 0, -9.81)
    p.createMultiBody(0.0, p.createCollisionShape(pybullet.GEOM_PLANE))
    p.loadURDF(str(urdf_path('youbot')), (0, 0, BASE_LINK_HEIGHT_M), flags=URDF_FLAGS)
    n = int(seconds / DT)
    t0 = time.perf_counter()
    for _ in range(n):
        p.stepSimulation()
    raw = n / (time.perf_counter() - t0)
    p.disconnect()
    world, runner = _world()
    kin = YoubotKinematics()
    sink = NullSink()
    runner.set_trajectory('youbot', 'arm_controller', TrajectoryRequest(
        kin.joint_names, (TrajectoryPoint(seconds, (0.5, 0.5, 0.5, 0.5, 0.5)),)))
    t0 = time.perf_counter()
    for k in range(n):
        if k % 24 == 0:
            runner.command('youbot', 0.2, 0.1, 0.2)
        runner.advance(1, sink)
    sim = n / (time.perf_counter() - t0)
    world.close()
    return {'raw_steps_per_s': raw, 'sim_steps_per_s': sim, 'ratio': sim / raw,
            'sim_rtf': sim * DT}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--arm-trials', type=int, default=20)
    parser.add_argument('--seconds', type=float, default=20.0, help='of simulated stepping')
    args = parser.parse_args()
    results = {'base': base_fidelity(), 'arm': arm_tracking(args.arm_trials),
               'stepping': stepping_cost(args.seconds)}
    print('youBot base, 2 s windows after the start-up (the ramp at the acceleration limits and '
          '0.3 s, at least 0.5 s; relative errors; limits 3 % / 2 %)')
    print('| command (vx, vy, wz) | twist | position | yaw | cross drift |')
    print('|---|---|---|---|---|')
    for label, r in results['base'].items():
        print(f'| {label} {r["command"]} | {100 * r["twist_error"]:.2f} % | '
              f'{100 * r["position_error"]:.2f} % | {100 * r["yaw_error"]:.2f} % | '
              f'{100 * r["cross_drift"]:.2f} % |')
    a = results['arm']
    print(f'\nyouBot arm, {a["trials"]} random 3-point trajectories at 80 % of the velocity '
          f'limits: tracking error RMS {a["rms_rad"] * 1e3:.2f} mrad, p99 '
          f'{a["p99_rad"] * 1e3:.2f} mrad, max {a["max_rad"] * 1e3:.2f} mrad; '
          f'0.5 s after the end: max {a["final_max_rad"] * 1e3:.3f} mrad')
    s = results['stepping']
    print(f'\nstepping: raw PyBullet {s["raw_steps_per_s"]:.0f} steps/s, simulator with Mecanum '
          f'drive and arm controllers {s["sim_steps_per_s"]:.0f} steps/s (ratio '
          f'{s["ratio"]:.2f}; real-time factor {s["sim_rtf"]:.1f} at dt 1/240 s)')
    out_dir = HERE / 'results'
    out_dir.mkdir(exist_ok=True)
    (out_dir / 'bench_youbot.json').write_text(json.dumps(results, indent=2))
    worst = max(max(r['twist_error'], r['position_error'], r['yaw_error'])
                for r in results['base'].values())
    return 0 if worst < 0.03 else 1


if __name__ == '__main__':
    sys.exit(main())
