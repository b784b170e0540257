"""youBot arm IK over 1000 targets made by FK of random in-limit configurations."""
import statistics
import sys
import time

import numpy as np

from controllers.youbot_arm import youbot_arm_chain
from controllers.youbot_ik import solve_ik


def main() -> int:
    chain = youbot_arm_chain()
    lower, upper = chain.limits
    rng = np.random.default_rng(2026)
    targets = [chain.fk(rng.uniform(lower, upper)) for _ in range(1000)]
    t0 = time.perf_counter()
    for _ in range(200):
        chain.fk(np.zeros(5))
    fk_us = (time.perf_counter() - t0) / 200 * 1e6
    times, errors, failures = [], [], 0
    for target in targets:
        start = time.perf_counter()
        result = solve_ik(target)
        times.append(time.perf_counter() - start)
        if result.success and chain.within_limits(result.q):
            errors.append(result.position_error)
        else:
            failures += 1
    median_ms = 1e3 * statistics.median(times)
    p99_ms = 1e3 * float(np.percentile(times, 99))
    print(f'youBot arm IK, 1000 FK-generated targets: success {100 * len(errors) / 1000:.1f} %, '
          f'max position error {max(errors):.2e} m, median solve {median_ms:.3f} ms, '
          f'p99 {p99_ms:.3f} ms; FK {fk_us:.1f} us')
    return 0 if failures <= 5 else 1


if __name__ == '__main__':
    sys.exit(main())
