"""The generic IK (controllers/urdf_arm.py) against the analytic solvers, and its speed on a
7-joint arm (issue 64).

For each arm with an analytic solver (the Zu 12's, the youBot arm's, both registered fast paths
of controllers/arm_registry.py): POSES random poses the analytic solver reaches (the tool's pose
at a posture drawn over the joint limits, kept where the analytic solver solves it), each solved
by the generic solver from a posture drawn over the limits (as far from the answer as a seed can
be). A pose counts as reached when the generic solution's own forward kinematics is within
1e-6 m and 1e-6 rad of the target and its joints within their limits.

For the Franka Emika Panda (PyBullet's bundled URDF, 7 joints, no analytic solver): POSES poses
drawn the same way, solved from three seeds: a posture drawn over the limits, none (the middle
of the limits), and the posture 1 cm of tool travel before (a motion's successive solutions).
Median and 95th percentile times per pose; the goal: median <= 1 ms. The machine's speed is
timed before and after (pinocchio's calls of one IK iteration): this machine's speed varies
by half from hour to hour, and the IK's times with it.

    python3 bench/bench_arm_ik.py [--poses 10000]
"""
import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pybullet_data

from controllers.arm_registry import ArmSpec, generic_kinematics
from controllers.youbot_kinematics import YoubotKinematics
from controllers.zu12_kinematics import Zu12Kinematics
from robot_description import urdf_path

OUT = Path(__file__).resolve().parent / 'results' / 'bench_arm_ik.json'
TOLERANCE = 1e-6
PANDA = Path(pybullet_data.getDataPath()) / 'franka_panda' / 'panda.urdf'


def _reached(kin, target, solution) -> bool:
    if not solution.success or not kin.within_limits(solution.positions):
        return False
    pose = kin.fk(solution.positions)
    rotation = float(np.linalg.norm(pin.log3(pose[:3, :3].T @ target[:3, :3])))
    return bool(np.linalg.norm(pose[:3, 3] - target[:3, 3]) <= TOLERANCE
                and rotation <= TOLERANCE)


def _against(name, analytic, spec, poses, rng):
    generic = generic_kinematics(spec)
    targets, times, missed = 0, [], []
    while targets < poses:
        q = rng.uniform(analytic.lower, analytic.upper)
        target = analytic.fk(q)
        if not analytic.ik(target).success:
            continue                    # (not a pose the analytic solver reaches)
        targets += 1
        seed = rng.uniform(generic.lower, generic.upper)
        start = time.perf_counter()
        solution = generic.ik(target, seed)
        times.append(time.perf_counter() - start)
        if not _reached(generic, target, solution):
            missed.append({'posture': q.round(6).tolist(), 'why': solution.reason})
    result = {'poses': targets, 'reached': targets - len(missed), 'missed': missed[:10],
              'median_ms': 1e3 * float(np.median(times)),
              'p95_ms': 1e3 * float(np.percentile(times, 95))}
    print(f'{name}: the generic IK reached {result["reached"]}/{targets} poses the analytic '
          f'solver reaches (median {result["median_ms"]:.2f} ms, 95 % '
          f'{result["p95_ms"]:.2f} ms)')
    return result


def _panda(poses, rng):
    spec = ArmSpec(PANDA, tuple(f'panda_joint{i}' for i in range(1, 8)), 'panda_link8',
                   (0.0, 0.0, 0.1))
    kin = generic_kinematics(spec)
    out = {}
    for how in ('random seed', 'no seed', 'along a motion'):
        times, missed = [], 0
        for _ in range(poses):
            q = rng.uniform(kin.lower, kin.upper)
            target = kin.fk(q)
            seed = None
            if how == 'random seed':
                seed = rng.uniform(kin.lower, kin.upper)
            elif how == 'along a motion':
                # The posture 1 cm of tool travel back along a random direction.
                step = rng.normal(size=3)
                before = target.copy()
                before[:3, 3] -= 0.01 * step / np.linalg.norm(step)
                back = kin.ik(before, q)
                if not back.success:
                    continue
                seed = back.positions
            start = time.perf_counter()
            solution = kin.ik(target, seed)
            times.append(time.perf_counter() - start)
            missed += not _reached(kin, target, solution)
        out[how] = {'poses': len(times), 'reached': len(times) - missed,
                    'median_ms': 1e3 * float(np.median(times)),
                    'p95_ms': 1e3 * float(np.percentile(times, 95))}
        print(f'Panda (7 joints), {how}: {out[how]["reached"]}/{len(times)} reached, median '
              f'{out[how]["median_ms"]:.3f} ms, 95 % {out[how]["p95_ms"]:.3f} ms')
    return out


def _machine_speed() -> float:
    """This machine's speed as the IK meets it: one iteration's calls into pinocchio (the
    Panda's joint Jacobians, its tool's placement and Jacobian) [us], so that a median taken
    on a slower or busier machine can be read against the figures in docs/benchmarks.md."""
    kin = generic_kinematics(ArmSpec(PANDA, tuple(f'panda_joint{i}' for i in range(1, 8)),
                                     'panda_link8', (0.0, 0.0, 0.1)))
    model, data, q = kin.model, kin.data, (kin.lower + kin.upper) / 2
    frame = model.getFrameId('arm_tool')
    rounds = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(2000):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacement(model, data, frame)
            pin.getFrameJacobian(model, data, frame, pin.LOCAL)
        rounds.append((time.perf_counter() - start) / 2000 * 1e6)
    return float(np.median(rounds))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--poses', type=int, default=10000)
    args = parser.parse_args()
    rng = np.random.default_rng(64)
    before = _machine_speed()
    zu12 = Zu12Kinematics('suction_tcp')
    youbot = YoubotKinematics('gripper_tcp')
    result = {
        'zu12': _against('Zu 12', zu12, ArmSpec(urdf_path('zu12'), zu12.joint_names,
                                                'suction_tcp'), args.poses, rng),
        'youbot': _against('youBot arm', youbot, ArmSpec(urdf_path('youbot'),
                                                         youbot.joint_names, 'gripper_tcp'),
                           args.poses, rng),
        'panda': _panda(args.poses, rng),
    }
    result['machine_us'] = {'before': before, 'after': _machine_speed()}
    print(f'this machine: pinocchio\'s calls of one IK iteration took {before:.2f} us before '
          f'and {result["machine_us"]["after"]:.2f} us after (quiet, fast: about 1.1 us)')
    median = result['panda']['random seed']['median_ms']
    every = all(result[a]['reached'] == result[a]['poses'] for a in ('zu12', 'youbot'))
    print(f'goals: every pose the analytic solvers reach, reached: {"met" if every else "NOT met"}'
          f'; 7-joint median <= 1 ms (random seed): '
          f'{"met" if median <= 1.0 else "NOT met"} ({median:.3f} ms)')
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(result, indent=1))
    return 0 if every and math.isfinite(median) else 1


if __name__ == '__main__':
    raise SystemExit(main())
