"""Arm kinematics at library speed: FK, and IK over 1000 targets made by FK of random in-limit
configurations, for the youBot's MDH chain (flange, theta), its kinematics node core
(gripper_tcp in base_link, the datasheet angles) and the JAKA Zu 12 (full 6-DOF poses).

Pinocchio's FK of the Zu 12's description, timed in the same run, is the baseline. The goals
(issue 12): FK <= 20 us, youBot IK >= 20,000 solves/s, Zu 12 IK median <= 0.1 ms. Wall times
on a busy machine are longer; the FK's CPU time per call is printed beside its wall time.
"""
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from controllers.youbot_arm import youbot_arm_chain
from controllers.youbot_ik import solve_ik
from controllers.youbot_kinematics import YoubotKinematics
from controllers.zu12_arm import zu12_chain
from controllers.zu12_ik import solve_ik as solve_zu12
from controllers.zu12_kinematics import Zu12Kinematics

N = 1000
FK_CALLS = 5000


def _per_call_us(call, calls: int = FK_CALLS, repeats: int = 5):
    """Best of ``repeats`` batches: wall and CPU microseconds per call."""
    best_wall = best_cpu = float('inf')
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.thread_time()
        for _ in range(calls):
            call()
        best_wall = min(best_wall, (time.perf_counter() - wall) / calls * 1e6)
        best_cpu = min(best_cpu, (time.thread_time() - cpu) / calls * 1e6)
    return best_wall, best_cpu


def _solve_all(solve, targets, seeds, within_limits):
    """Times each solve; returns (times, errors, failures, all within limits)."""
    for target, seed in zip(targets[:50], seeds[:50]):   # warm-up
        solve(target, seed)
    times, errors, failures, in_limits = [], [], 0, True
    for target, seed in zip(targets, seeds):
        start = time.perf_counter()
        q, error = solve(target, seed)
        times.append(time.perf_counter() - start)
        if q is None:
            failures += 1
        else:
            errors.append(error)
            in_limits &= within_limits(q)
    return times, errors, failures, in_limits


def _report(label, run, unreachable_fails):
    times, errors, failures, in_limits = run
    median_ms = 1e3 * statistics.median(times)
    p99_ms = 1e3 * float(np.percentile(times, 99))
    print(f'{label}: success {100 * len(errors) / N:.1f} % of {N}, all within limits: '
          f'{in_limits}, max position error {max(errors):.2e} m, median solve '
          f'{median_ms:.3f} ms (p99 {p99_ms:.3f} ms), {len(times) / sum(times):,.0f} solves/s; '
          f'unreachable targets reported as failures: '
          f'{unreachable_fails}')
    return failures <= N * 0.005 and in_limits and unreachable_fails, median_ms, \
        len(times) / sum(times)


def _pinocchio_fk_us():
    """Pinocchio (C++) FK of the Zu 12's description to its flange frame, per call, or None
    when pinocchio is not installed."""
    try:
        import pinocchio as pin

        from robot_description import urdf_path
    except ImportError:
        return None
    model = pin.buildModelFromUrdf(str(urdf_path('zu12')))
    data = model.createData()
    flange = model.getFrameId('flange')
    q = np.full(model.nq, 0.3)

    def fk():
        pin.forwardKinematics(model, data, q)
        return pin.updateFramePlacement(model, data, flange)
    return _per_call_us(fk)


def _verdict(ok: bool) -> str:
    return 'met' if ok else 'NOT met'


def _node_ik(kinematics):
    def solve(target, seed):
        result = kinematics.ik(target, seed)
        return (result.positions, result.position_error) if result.success else (None, 0)
    return solve


def _youbot_ik(rng, chain):
    """The youBot's IK, the MDH chain's and the node core's: whether both met their checks,
    and their solves per second."""
    lower, upper = chain.limits
    targets = [chain.fk(rng.uniform(lower, upper)) for _ in range(N)]
    far = np.eye(4)
    far[:3, 3] = (0.9, 0.0, 0.2)

    def flange_ik(target, seed):
        result = solve_ik(target, seed)
        return (result.q, result.position_error) if result.success else (None, None)
    ok, _, youbot_rate = _report('youBot MDH chain (flange, table theta, zero seed)',
                       _solve_all(flange_ik, targets, [None] * N, chain.within_limits),
                       not solve_ik(far).success)

    kin = YoubotKinematics('gripper_tcp')
    targets = [kin.fk(rng.uniform(kin.lower, kin.upper)) for _ in range(N)]
    seeds = [rng.uniform(kin.lower, kin.upper) for _ in range(N)]

    good, _, node_rate = _report('youBot kinematics node core (gripper_tcp in base_link, '
                                 'random seeds)',
                                 _solve_all(_node_ik(kin), targets, seeds, kin.within_limits),
                                 not kin.ik(far).success)

    return ok and good, youbot_rate, node_rate


def _zu12_ik(rng, zu12):
    """The Zu 12's IK and its node core's: whether it met its checks, and its median [ms]."""
    zlower, zupper = zu12.limits
    far = np.eye(4)
    targets = [zu12.fk(rng.uniform(zlower, zupper)) for _ in range(N)]
    seeds = [rng.uniform(zlower, zupper) for _ in range(N)]

    def zu12_ik(target, seed):
        result = solve_zu12(target, seed, zu12)
        return (result.q, result.position_error) if result.success else (None, None)
    far[:3, 3] = (2.0, 0.0, 0.5)
    good, zu12_median, _ = _report('JAKA Zu 12 (flange, full 6-DOF poses, random seeds)',
                                   _solve_all(zu12_ik, targets, seeds, zu12.within_limits),
                                   not solve_zu12(far).success)
    zkin = Zu12Kinematics('suction_tcp')
    targets = [zkin.fk(rng.uniform(zkin.lower, zkin.upper)) for _ in range(N)]
    # Not every FK target keeps the arm above the floor: those fail with that reason.
    _report('JAKA Zu 12 kinematics node core (suction_tcp, floor check)',
                         _solve_all(_node_ik(zkin), targets, seeds, zkin.within_limits),
                         not zkin.ik(far).success)

    return good, zu12_median


def main() -> int:
    rng = np.random.default_rng(2026)
    chain = youbot_arm_chain()
    lower, upper = chain.limits
    q0 = rng.uniform(lower, upper)
    fk_wall, fk_cpu = _per_call_us(lambda: chain.fk(q0))
    zu12 = zu12_chain()
    zlower, zupper = zu12.limits
    z0 = rng.uniform(zlower, zupper)
    zfk_wall, zfk_cpu = _per_call_us(lambda: zu12.fk(z0))
    pin_fk = _pinocchio_fk_us()

    ok, youbot_rate, node_rate = _youbot_ik(rng, chain)
    good, zu12_median = _zu12_ik(rng, zu12)
    ok &= good
    print(f'FK: youBot {fk_wall:.1f} us per call ({fk_cpu:.1f} us CPU), Zu 12 {zfk_wall:.1f} '
          f'us ({zfk_cpu:.1f} us CPU)' + ('' if pin_fk is None else
                                         f'; pinocchio (C++) Zu 12 {pin_fk[0]:.1f} us: ours '
                                         f'x{zfk_wall / pin_fk[0]:.1f}'))
    # The youBot figure (2,790 solves/s) was the MDH chain's line; the node core, with
    # its frame and angle conversions, is printed beside it.
    print(f'goals: FK <= 20 us: {_verdict(max(fk_wall, zfk_wall) <= 20)}; youBot IK (MDH chain) '
          f'>= 20,000 solves/s: {_verdict(youbot_rate >= 20000)} ({youbot_rate:,.0f}; the node '
          f'core {node_rate:,.0f}); Zu 12 IK median <= 0.1 ms: '
          f'{_verdict(zu12_median <= 0.1)} ({zu12_median:.3f} ms)')
    out = Path(__file__).resolve().parent / 'results'
    out.mkdir(exist_ok=True)
    (out / 'bench_kinematics.json').write_text(json.dumps(
        {'fk_us': {'youbot': fk_wall, 'zu12': zfk_wall}, 'youbot_ik_per_s': youbot_rate,
         'youbot_node_ik_per_s': node_rate, 'zu12_ik_median_ms': zu12_median}, indent=1))
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
