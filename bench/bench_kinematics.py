"""Arm IK over 1000 targets made by FK of random in-limit configurations: the youBot's MDH
chain (flange, theta), its kinematics node core (gripper_tcp), and the JAKA Zu 12."""
import statistics
import sys
import time

import numpy as np

from controllers.youbot_arm import youbot_arm_chain
from controllers.youbot_ik import solve_ik
from controllers.youbot_kinematics import YoubotKinematics
from controllers.zu12_arm import zu12_chain
from controllers.zu12_ik import solve_ik as solve_zu12

N = 1000


def _report(label, times, errors, in_limits, failures, unreachable_ok):
    median_ms = 1e3 * statistics.median(times)
    p99_ms = 1e3 * float(np.percentile(times, 99))
    print(f'{label}: success {100 * len(errors) / N:.1f} % of {N}, all within limits: '
          f'{in_limits}, max position error {max(errors):.2e} m, median solve '
          f'{median_ms:.3f} ms (p99 {p99_ms:.3f} ms, {len(times) / sum(times):.0f} solves/s); '
          f'unreachable targets reported as failures: {unreachable_ok}')
    return failures <= N * 0.005


def main() -> int:
    chain = youbot_arm_chain()
    lower, upper = chain.limits
    rng = np.random.default_rng(2026)
    targets = [chain.fk(rng.uniform(lower, upper)) for _ in range(N)]
    t0 = time.perf_counter()
    for _ in range(200):
        chain.fk(np.zeros(5))
    fk_us = (time.perf_counter() - t0) / 200 * 1e6
    times, errors, failures, in_limits = [], [], 0, True
    for target in targets:
        start = time.perf_counter()
        result = solve_ik(target)
        times.append(time.perf_counter() - start)
        if result.success:
            errors.append(result.position_error)
            in_limits &= chain.within_limits(result.q)
        else:
            failures += 1
    far = np.eye(4)
    far[:3, 3] = (0.9, 0.0, 0.2)
    ok = _report('MDH chain (flange, table theta)', times, errors, in_limits, failures,
                 not solve_ik(far).success)
    print(f'  FK {fk_us:.1f} us per call')

    kin = YoubotKinematics('gripper_tcp')
    targets = [kin.fk(rng.uniform(kin.lower, kin.upper)) for _ in range(N)]
    times, errors, failures, in_limits = [], [], 0, True
    for target in targets:
        seed = rng.uniform(kin.lower, kin.upper)
        start = time.perf_counter()
        result = kin.ik(target, seed)
        times.append(time.perf_counter() - start)
        if result.success:
            errors.append(result.position_error)
            in_limits &= kin.within_limits(result.positions)
        else:
            failures += 1
    ok &= _report('kinematics node core (gripper_tcp in base_link)', times, errors, in_limits,
                  failures, not kin.ik(far).success)

    zu12 = zu12_chain()
    lower, upper = zu12.limits
    targets = [zu12.fk(rng.uniform(lower, upper)) for _ in range(N)]
    times, errors, failures, in_limits = [], [], 0, True
    for target in targets:
        seed = rng.uniform(lower, upper)
        start = time.perf_counter()
        result = solve_zu12(target, seed, zu12)
        times.append(time.perf_counter() - start)
        if result.success:
            errors.append(result.position_error)
            in_limits &= zu12.within_limits(result.q)
        else:
            failures += 1
    far[:3, 3] = (2.0, 0.0, 0.5)
    ok &= _report('JAKA Zu 12 (flange, full 6-DOF poses)', times, errors, in_limits, failures,
                  not solve_zu12(far).success)
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
