"""200 random plans in one process: bounded time each, and no memory growth worth noting."""

from __future__ import annotations

import gc
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import load, random_configuration

import nearopt

PLANS = 200
TIME_LIMIT = 5.0  # the user's budget per plan [s]


def resident_mib() -> float:
    """The process's resident memory now [MiB] (from /proc, not the peak)."""
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * 4096 / 2**20


@pytest.mark.slow
def test_two_hundred_plans_neither_leak_nor_hang() -> None:
    robots = [load("two_link"), load("ur5")]
    rng = np.random.default_rng(200)
    memory, longest, outcomes = [], 0.0, {"planned": 0, "infeasible": 0}
    for k in range(PLANS):
        robot = robots[k % 2]
        q0, qe = random_configuration(robot, rng), random_configuration(robot, rng)
        cost = nearopt.TorqueCost(0.03) if k % 3 else nearopt.TimeCost()
        start = time.perf_counter()
        try:
            result = nearopt.plan(
                robot,
                q0,
                qe,
                cost,
                grid=30,
                options=nearopt.SCPOptions(control_points=4, grid=30),
                max_iterations=4,
                time_limit=TIME_LIMIT,
            )
            assert result.J <= result.initial.J
            outcomes["planned"] += 1
        except nearopt.InfeasiblePathError:
            outcomes["infeasible"] += 1
        longest = max(longest, time.perf_counter() - start)
        if k % 25 == 24:
            gc.collect()
            memory.append(resident_mib())
    # the budget is checked between iterations: one iteration may run past it, not more
    assert longest < 2 * TIME_LIMIT, longest
    assert outcomes["planned"] >= PLANS // 2, outcomes
    # after a warm-up of 50 plans, 150 more may not grow the resident set by more than 20 MiB
    growth = memory[-1] - memory[1]
    print(
        f"\n200 plans: {outcomes}, longest {longest:.2f} s, resident MiB every 25: "
        f"{[round(m, 1) for m in memory]}"
    )
    assert growth < 20.0, (memory, growth)
