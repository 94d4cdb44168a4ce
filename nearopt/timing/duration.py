"""Stage 1 with its duration set: t_e = T exactly, or t_e ≤ T.

For f0 = 1 + Σ w_i u_i² the timing problem is convex in b, and so is t_e = Σ 2Δσ_k / (√b_k +
√b_{k+1}). The optimum under t_e ≤ T (where it binds) is therefore the optimum of the Lagrangian
f0 + μ = (1 + μ)(1 + Σ w_i/(1 + μ) u_i²) for some μ ≥ 0, i.e. of the same cost with its weights
scaled by ρ = 1/(1 + μ) ≤ 1; and t_e of that optimum does not decrease as ρ grows (more weight on
the torques, less on time). So a duration is met by a search over ρ, each step one solve of the
kernel of :mod:`nearopt.timing` (from its own start: a start from the last answer took twice
the iterations, and stopped at a t_e that differed by 1e-8 from one start to another), false
position on log t_e against log ρ alternating with bisection:

* t_e ≤ T: the free optimum if it is at most T; else ρ ∈ (0, 1) (ρ → 0 is the time-optimal
  timing: a T below its duration is refused with that duration);
* t_e = T above the free optimum's duration: ρ > 1, up to the torque-only optimum (ρ → ∞). The
  time-optimal cost f0 = 1 has J = T for *every* timing of duration T: of those, nearopt returns
  the one of least Σ_i u_i²/U_i² (U_i the effort limit), from the weights ρ/U_i².
  For a T beyond the torque-only optimum's duration (an arm whose gravity costs more
  torque the longer it holds it), a motion at rest at both ends is that optimum slowed down
  uniformly to T (b → αb: every torque then lies between gravity's and the optimum's, so every
  limit holds) — no longer an optimum of J, which the problem's convexity does not reach there.

The search stops within ``DURATION_TOLERANCE`` of T, below it; a motion at rest at both ends is
then slowed down uniformly to exactly T (by the caller), a moving one is left as it is.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..cost import Cost, TimeCost, TorqueCost
from ..errors import ConfigurationError, InfeasiblePathError
from ..trajectory import segment_times
from .solvers import TimingSolution

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .problem import TimingProblem

__all__ = ["DURATION_TOLERANCE", "check_duration", "solve_for_duration", "duration_of"]

DURATION_TOLERANCE = 1e-9  # relative: the search stops with t_e in [T (1 − this), T]
MAX_SOLVES = 60  # solves of one search
ROUNDING = 1e-12  # relative: a t_e this far above T is T (the sums of t_e round)

Solve = Callable[["TimingProblem", Cost, "NDArray[np.float64] | None"], TimingSolution]


def check_duration(name: str, value: object) -> float | None:
    """A duration [s] as a positive finite float (None stays None); ConfigurationError else."""
    if value is None:
        return None
    try:
        t = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ConfigurationError(f"{name} must be a number of seconds, got {value!r:.60}") from None
    if not (math.isfinite(t) and t > 0.0):
        raise ConfigurationError(f"{name} must be a positive, finite number of seconds, got {t!r}")
    return t


def duration_of(problem: TimingProblem, b: NDArray[np.float64]) -> float:
    """t_e [s] of the timing b on the problem's grid."""
    return float(np.sum(segment_times(problem.sigma, b)))


def solve_for_duration(
    problem: TimingProblem,
    cost: Cost,
    duration: float,
    *,
    exact: bool,
    solve: Solve,
    guess: NDArray[np.float64] | None = None,
    below: float = 0.0,
) -> tuple[TimingSolution, TorqueCost]:
    """The optimal timing of ``cost`` with t_e ≤ ``duration`` (``exact`` False) or t_e =
    ``duration`` [s], and the cost of scaled weights whose optimum it is (see the module).

    ``solve(problem, cost, guess)`` solves stage 1 without a duration. With ``below`` > 0 the
    search aims that fraction below ``duration`` (the caller slows the motion down to it), and
    a time-optimal motion between the two is returned as it is.

    Raises
    ------
    ConfigurationError
        If ``cost`` is not f0 = 1 + Σ w u² (a duration needs the convex family).
    InfeasiblePathError
        If ``duration`` is below the path's time-optimal duration (named), or, for a motion that
        starts or ends moving, above the longest one the torque-only optimum takes.
    """
    if not isinstance(cost, TorqueCost):
        raise ConfigurationError(
            "a duration is kept for f0 = 1 + Σ w u² (TimeCost, TorqueCost); "
            f"got {cost.describe() if hasattr(cost, 'describe') else type(cost).__name__}"
        )
    limit, duration = duration, duration * (1.0 - below)
    n = problem.dof
    weights = cost.torque_weights(n)
    free = solve(problem, cost, guess)
    t_free = duration_of(problem, free.b)
    if _within(t_free, duration) or (not exact and t_free <= duration * (1.0 + ROUNDING)):
        return free, cost
    if not np.any(weights > 0.0):  # f0 = 1: ties broken by the least Σ u²/U²
        if t_free > duration:
            if t_free <= limit * (1.0 + ROUNDING):
                return free, cost
            raise _too_short(limit, t_free)
        effort = np.maximum(np.abs(problem.torque.lower), np.abs(problem.torque.upper))
        base = 1.0 / np.where(np.isfinite(effort) & (effort > 0.0), effort, 1.0) ** 2
        low = (0.0, t_free, free)
        rho, high = 1.0, None
    else:
        base = weights
        if t_free > duration:
            low = (0.0, *_at(problem, solve, TimeCost(), None))
            if low[1] > limit * (1.0 + ROUNDING):
                raise _too_short(limit, low[1])
            if low[1] >= duration * (1.0 - DURATION_TOLERANCE):
                return low[2], TimeCost()
            return _search(problem, solve, base, duration, low, (1.0, t_free, free))
        low, rho, high = (1.0, t_free, free), 10.0, None
    while high is None:  # grow ρ until t_e passes T
        sol_t = _at(problem, solve, TorqueCost(weights=rho * base), None)
        if _within(sol_t[0], duration):
            return sol_t[1], TorqueCost(weights=rho * base)
        if sol_t[0] > duration:
            high = (rho, *sol_t)
        elif rho > 1e12 or sol_t[0] <= low[1] * (1.0 + 1e-12):
            return _beyond(problem, duration, sol_t, rho, base)
        else:
            low, rho = (rho, *sol_t), rho * 10.0
    return _search(problem, solve, base, duration, low, high)


def _within(t: float, duration: float) -> bool:
    return duration * (1.0 - DURATION_TOLERANCE) <= t <= duration * (1.0 + ROUNDING)


def _at(
    problem: TimingProblem, solve: Solve, cost: TorqueCost, guess: NDArray[np.float64] | None
) -> tuple[float, TimingSolution]:
    sol = solve(problem, cost, guess)
    return duration_of(problem, sol.b), sol


def _search(
    problem: TimingProblem,
    solve: Solve,
    base: NDArray[np.float64],
    duration: float,
    low: tuple,
    high: tuple,
) -> tuple[TimingSolution, TorqueCost]:
    """False position (Illinois) on log t_e against log ρ between ``low`` (t_e < T) and
    ``high`` (t_e > T), each (ρ, t_e, solution); ρ = 0 at ``low`` is the time-optimal end."""
    target = math.log(duration * (1.0 - 0.5 * DURATION_TOLERANCE))
    (r_lo, t_lo, s_lo), (r_hi, t_hi, _) = low, high
    x_lo = math.log(r_lo) if r_lo > 0.0 else math.log(r_hi) - 30.0
    x_hi = math.log(r_hi)
    f_lo, f_hi = math.log(t_lo) - target, math.log(t_hi) - target
    side = 0
    best = s_lo
    for step in range(MAX_SOLVES):
        # false position, and bisection every other step: t_e(ρ) may stay flat near the
        # time-optimal end (a degenerate optimum) and then rise steeply, where false position
        # alone crawls
        x = (x_lo * f_hi - x_hi * f_lo) / (f_hi - f_lo)
        if step % 2 or not x_lo < x < x_hi:
            x = 0.5 * (x_lo + x_hi)
        cost = TorqueCost(weights=math.exp(x) * base)
        t, sol = _at(problem, solve, cost, None)
        if _within(t, duration):
            return sol, cost
        f = math.log(t) - target
        if f < 0.0:
            x_lo, f_lo, s_lo, best = x, f, sol, sol
            f_hi, side = (0.5 * f_hi, side) if side == -1 else (f_hi, -1)
        else:
            x_hi, f_hi = x, f
            f_lo, side = (0.5 * f_lo, side) if side == 1 else (f_lo, 1)
        if x_hi - x_lo < 1e-13:
            break
    if not problem.at_rest:
        raise InfeasiblePathError(
            f"stage 1 found no timing of duration {duration:.9g} s within "
            f"{DURATION_TOLERANCE:g} of it (the nearest: {duration_of(problem, best.b):.9g} s)"
        )
    return best, TorqueCost(weights=math.exp(x_lo) * base)


def _beyond(
    problem: TimingProblem,
    duration: float,
    slowest: tuple[float, TimingSolution],
    rho: float,
    base: NDArray[np.float64],
) -> tuple[TimingSolution, TorqueCost]:
    """T beyond the torque-only optimum's duration: that optimum, to be slowed down uniformly
    by the caller (at rest at both ends); refused for a motion that starts or ends moving."""
    if not problem.at_rest:
        raise InfeasiblePathError(
            f"duration {duration:.6g} s is longer than any optimum of this cost takes with "
            f"these moving ends (the torque-only optimum takes {slowest[0]:.6g} s); a "
            "longer path, or slower ends, would do"
        )
    return slowest[1], TorqueCost(weights=rho * base)


def _too_short(duration: float, fastest: float) -> InfeasiblePathError:
    return InfeasiblePathError(
        f"duration {duration:.6g} s is shorter than the time-optimal motion along this path, "
        f"{fastest:.9g} s: no timing within the limits is that fast"
    )
