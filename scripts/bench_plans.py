"""Whole plans and their stage 1: wall time, stage-1 timings and the time spent in them.

Three plans: the paper's example (``nearopt.plan`` with its defaults), a panda free plan (seeded
motion, f0 = 1 + 0.001 Σ u²) and the same arm in the work cell of ``bench_cell.py``. For each:
J, the median wall time of ``--repeat`` plans, the number of stage-1 timings (calls of
``optimal_timing``) and their share of the wall time, and the median time of the check
``nearopt plan`` makes before it writes the plan (``verify`` at 1 kHz) against the plan's. Run
it against another checkout of nearopt with ``PYTHONPATH=that/checkout python
scripts/bench_plans.py`` to compare commits.

    python scripts/bench_plans.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bench_cell import CELL, pairs_for

import nearopt
import nearopt.timing.driver as driver
from nearopt.collision import CollisionModel
from nearopt.paper_example import COST, THETA_0, THETA_E


class Stage1Clock:
    """Counts the calls of ``optimal_timing`` everywhere it is used, and their time."""

    def __init__(self) -> None:
        self.calls, self.seconds = 0, 0.0
        self._real = driver.optimal_timing
        modules = [
            m
            for m in __import__("sys").modules.values()
            if m is not None and getattr(m, "__name__", "").startswith("nearopt")
        ]
        self._patched = [m for m in modules if getattr(m, "optimal_timing", None) is self._real]

    def __enter__(self) -> Stage1Clock:
        def timed(*args: object, **kwargs: object) -> object:
            start = time.perf_counter()
            try:
                return self._real(*args, **kwargs)
            finally:
                self.calls += 1
                self.seconds += time.perf_counter() - start

        for module in self._patched:
            module.optimal_timing = timed
        return self

    def __exit__(self, *_: object) -> None:
        for module in self._patched:
            module.optimal_timing = self._real


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(f"nearopt from {nearopt.__file__}")
    two_link = nearopt.Robot.from_name("two_link")
    panda = nearopt.Robot.from_name("panda")
    cost = nearopt.TorqueCost(0.001)
    rng = np.random.default_rng(3)
    lo = np.maximum(panda.limits.position_lower, -np.pi)
    hi = np.minimum(panda.limits.position_upper, np.pi)
    mid, half = 0.5 * (lo + hi), 0.3 * (hi - lo)
    free = rng.uniform(mid - half, mid + half, (2, panda.n))
    cell = pairs_for(panda, CollisionModel(panda, CELL), 1, 11)[0]
    plans = {
        "paper's example": lambda: nearopt.plan(two_link, THETA_0, THETA_E, COST),
        "panda free": lambda: nearopt.plan(panda, free[0], free[1], cost),
        "panda cell": lambda: nearopt.plan(
            panda, cell[0], cell[1], cost, scene=CollisionModel(panda, CELL)
        ),
    }
    plans["paper's example"]()  # the first plan of a process loads what it needs
    print(
        f"{'plan':<17}{'J':>10}{'wall [s]':>10}{'timings':>9}{'stage 1 [s]':>13}{'share':>7}"
        f"{'verify [s]':>12}{'/ wall':>8}"
    )
    for label, run in plans.items():
        walls, stage1, checks, calls, result = [], [], [], 0, None
        for _ in range(args.repeat):
            with Stage1Clock() as clock:
                start = time.perf_counter()
                result = run()
                walls.append(time.perf_counter() - start)
            stage1.append(clock.seconds)
            calls = clock.calls
            start = time.perf_counter()
            report = verify_as_the_command(result)
            checks.append(time.perf_counter() - start)
            assert report.passed, str(report)
        k = int(np.argsort(walls)[len(walls) // 2])
        check = float(np.median(checks))
        print(
            f"{label:<17}{result.J:>10.6f}{walls[k]:>10.2f}{calls:>9}{stage1[k]:>13.2f}"
            f"{100 * stage1[k] / walls[k]:>6.0f}%{check:>12.3f}{100 * check / walls[k]:>7.1f}%",
            flush=True,
        )


def verify_as_the_command(result: nearopt.PlanResult) -> nearopt.VerificationReport:
    """The check ``nearopt plan`` makes before it writes a plan (at 1 kHz, with the plan's cost,
    J and collision model), spelled so that older checkouts run it too."""
    return nearopt.verify(
        result.trajectory,
        result.robot,
        rate=1000.0,
        cost=result.cost,
        J=result.J,
        collisions=result.collisions,
    )


if __name__ == "__main__":
    main()
