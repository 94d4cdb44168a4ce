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
  For a T beyond the torque-only optimum's duration (an arm whose gravity costs more torque
  the longer it holds it, or moving ends that the optimum keeps fast), t_e ≥ T binds and is not
  convex: the convex–concave procedure minimises J + ν c·b with c = −∇t_e at the last answer (a
  price on speed where it shortens the motion most, t_e's tangent lying below it), ν searched
  so that t_e = T, until b settles: a stationary point of J under t_e = T (a local optimum).

The search stops within ``DURATION_TOLERANCE`` of T, below it; a motion at rest at both ends is
then slowed down uniformly to exactly T (by the caller), a moving one is left as it is.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..cost import Cost, TimeCost, TorqueCost
from ..errors import ConfigurationError, InfeasiblePathError, SolverError
from ..trajectory import segment_times
from ..validate import is_number
from .solvers import TimingSolution

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .problem import TimingProblem

__all__ = [
    "AS_FAST",
    "DURATION_TOLERANCE",
    "as_fast_as",
    "check_duration",
    "solve_for_duration",
    "duration_of",
    "duration_gradient",
]

DURATION_TOLERANCE = 1e-9  # relative: the search stops with t_e in [T (1 − this), T]
MAX_SOLVES = 60  # solves of one search
ROUNDING = 1e-12  # relative: a t_e this far above T is T (the sums of t_e round)
AS_FAST = 1e-9
"""Relative: a time-optimal motion this far above an exact duration T is as fast as T (t_e ≤ T,
``max_duration``, keeps :data:`ROUNDING`, as verify checks it). Stage 1 is solved to 1e-9, and
two solves of one path (another start, other margins) put its fastest t_e up to ~1e-11 apart: a
plan asked for its own t_e was refused by 1.5e-11. Such a motion is returned as it is (t_e = T
to 1e-9 relative, as verify checks it), never sped up to T."""
CCP_ROUNDS = 12  # convex–concave rounds beyond the torque-only optimum's duration
CCP_SETTLED = 1e-6  # relative change of the discretised J at which they stop

Solve = Callable[
    ["TimingProblem", Cost, "NDArray[np.float64] | None", "NDArray[np.float64] | None", bool],
    TimingSolution,
]  # (problem, cost, guess, price, the kernel alone)


def as_fast_as(fastest: float, duration: float, exact: bool) -> bool:
    """Whether a time-optimal motion of ``fastest`` [s] meets the duration T = ``duration`` [s]
    asked for: t_e = T (``exact``) to :data:`AS_FAST`, t_e ≤ T to :data:`ROUNDING`."""
    return fastest <= duration * (1.0 + (AS_FAST if exact else ROUNDING))


def check_duration(name: str, value: object) -> float | None:
    """A duration [s] as a positive finite float (None stays None); ConfigurationError else."""
    if value is None:
        return None
    if not is_number(value):  # not a string or a bool that float() would read
        raise ConfigurationError(f"{name} must be a number of seconds, got {value!r:.60}")
    t = float(value)  # type: ignore[arg-type]
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
) -> tuple[TimingSolution, TorqueCost | None]:
    """The optimal timing of ``cost`` with t_e ≤ ``duration`` (``exact`` False) or t_e =
    ``duration`` [s], and the cost of scaled weights whose optimum it is (see the module;
    ``cost`` itself where the duration does not bind, None beyond every optimum of the
    family).

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
    free = solve(problem, cost, guess, None, False)
    t_free = duration_of(problem, free.b)
    if _within(t_free, duration) or (not exact and t_free <= duration * (1.0 + ROUNDING)):
        return free, cost
    if not np.any(weights > 0.0):  # f0 = 1: ties broken by the least Σ u²/U²
        if t_free > duration:
            if as_fast_as(t_free, limit, exact):
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
            if not as_fast_as(low[1], limit, exact):
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
        elif rho > 1e12 or sol_t[0] - low[1] < 1e-6 * (duration - sol_t[0]):
            # t_e no longer grows with ρ: T lies beyond the torque-only optimum's duration
            try:
                return _beyond(problem, solve, duration, sol_t[1], TorqueCost(weights=rho * base))
            except (InfeasiblePathError, SolverError) as exc:
                raise InfeasiblePathError(
                    f"no timing of this path was found that lasts {duration:.12g} s: the slowest "
                    f"optimum of the cost's family lasts {sol_t[0]:.12g} s, and slowing down "
                    f"further (a price on speed) failed: {exc}"
                ) from None
        else:
            low, rho = (rho, *sol_t), rho * 10.0
    return _search(problem, solve, base, duration, low, high)


def _within(t: float, duration: float) -> bool:
    return duration * (1.0 - DURATION_TOLERANCE) <= t <= duration * (1.0 + ROUNDING)


def _at(
    problem: TimingProblem,
    solve: Solve,
    cost: TorqueCost,
    guess: NDArray[np.float64] | None,
    price: NDArray[np.float64] | None = None,
) -> tuple[float, TimingSolution]:
    """t_e and the solution of one member of the family. The kernel alone from its own start
    first; where it fails (it was seen to cycle on damped arms with moving ends), from
    ``guess`` (a neighbour's answer), then with the weights or the price nudged by 1e-9 (the
    search reads t_e of what was solved: a nudge only moves it along the family); then
    Clarabel."""
    for nudge, start in ((1.0, None), (1.0, guess), (1.0 + 1e-9, None)):
        if nudge == 1.0 and start is guess and guess is None:
            continue
        weights = cost.torque_weights(problem.dof) * (nudge if price is None else 1.0)
        priced = None if price is None else price * nudge
        try:
            sol = solve(problem, TorqueCost(weights=weights), start, priced, True)
        except SolverError:
            continue
        return duration_of(problem, sol.b), sol
    sol = solve(problem, cost, guess, price, False)
    return duration_of(problem, sol.b), sol


def _search(
    problem: TimingProblem,
    solve: Solve,
    base: NDArray[np.float64],
    duration: float,
    low: tuple,
    high: tuple,
) -> tuple[TimingSolution, TorqueCost]:
    """The weights ρ·``base`` whose optimum lasts T, between ``low`` (t_e < T) and ``high``
    (t_e > T), each (ρ, t_e, solution); ρ = 0 at ``low`` is the time-optimal end."""

    def at(x: float, guess: NDArray[np.float64] | None) -> tuple[float, TimingSolution]:
        return _at(problem, solve, TorqueCost(weights=math.exp(x) * base), guess)

    x_hi = math.log(high[0])
    x_lo = math.log(low[0]) if low[0] > 0.0 else x_hi - 30.0
    x, sol = _root(at, duration, (x_lo, *low[1:]), (x_hi, *high[1:]), problem.at_rest)
    return sol, TorqueCost(weights=math.exp(x) * base)


def _root(
    at: Callable[[float, NDArray[np.float64] | None], tuple[float, TimingSolution]],
    duration: float,
    low: tuple,
    high: tuple,
    settle: bool,
) -> tuple[float, TimingSolution]:
    """x with t_e(x) = T to :data:`DURATION_TOLERANCE`, t_e increasing in x, between ``low``
    and ``high`` (x, t_e, solution): false position on log t_e (Illinois), bisection every
    other step — t_e may stay flat near one end (a degenerate optimum) and then rise steeply,
    where false position alone crawls. With ``settle`` (a motion at rest, slowed down to T by
    the caller), the best answer below T is taken when the bracket closes; else that is an
    error."""
    target = math.log(duration * (1.0 - 0.5 * DURATION_TOLERANCE))
    (x_lo, t_lo, best), (x_hi, t_hi, _) = low, high
    f_lo, f_hi = math.log(t_lo) - target, math.log(t_hi) - target
    side = 0
    for step in range(MAX_SOLVES):
        x = (x_lo * f_hi - x_hi * f_lo) / (f_hi - f_lo)
        if step % 2 or not x_lo < x < x_hi:
            x = 0.5 * (x_lo + x_hi)
        t, sol = at(x, best.b)
        if _within(t, duration):
            return x, sol
        f = math.log(t) - target
        if f < 0.0:
            x_lo, f_lo, best = x, f, sol
            f_hi, side = (0.5 * f_hi, side) if side == -1 else (f_hi, -1)
        else:
            x_hi, f_hi = x, f
            f_lo, side = (0.5 * f_lo, side) if side == 1 else (f_lo, 1)
        if x_hi - x_lo < 1e-13:
            break
    if not settle:
        raise InfeasiblePathError(
            f"stage 1 found no timing of duration {duration:.9g} s within "
            f"{DURATION_TOLERANCE:g} of it (the nearest: {math.exp(f_lo + target):.9g} s)"
        )
    return x_lo, best


def _beyond(
    problem: TimingProblem,
    solve: Solve,
    duration: float,
    slowest: TimingSolution,
    cost: TorqueCost,
) -> tuple[TimingSolution, None]:
    """T beyond the longest optimum of the family (the torque-only one, ``slowest``): a
    stationary point of J under t_e = T by the convex–concave procedure. t_e ≥ T is the
    constraint that binds there, t_e is convex in b, so its tangent at the last iterate b^j
    lies below it: minimise J + ν c^j·b with c^j = −∇t_e(b^j) ≥ 0 (a price on speed where it
    shortens the motion most), ν ≥ 0 found so that t_e = T; repeat from the answer until J
    settles (a fixed point is a KKT point of min J s.t. t_e = T)."""
    found, x_prev, last = slowest, None, math.inf
    for _ in range(CCP_ROUNDS):
        price = -duration_gradient(problem, found.b)
        reach = max(float(price @ found.b), 1e-300)
        start = math.log(duration / reach) if x_prev is None else x_prev

        def at(
            x: float, guess: NDArray[np.float64] | None, price: NDArray[np.float64] = price
        ) -> tuple[float, TimingSolution]:
            return _at(problem, solve, cost, guess, math.exp(x) * price)

        x_prev, found = _price_root(at, duration, start, problem.at_rest)
        value = found.objective
        if abs(value - last) <= CCP_SETTLED * abs(value):
            break
        last = value
    return found, None


def _price_root(
    at: Callable[[float, NDArray[np.float64] | None], tuple[float, TimingSolution]],
    duration: float,
    start: float,
    settle: bool,
) -> tuple[float, TimingSolution]:
    """x = log ν with t_e(x) = T: a bracket grown by factors of 4 from ``start`` (t_e grows
    with x), then :func:`_root`."""
    t0, sol0 = at(start, None)
    if _within(t0, duration):
        return start, sol0
    step = math.log(4.0) if t0 < duration else -math.log(4.0)
    near = (start, t0, sol0)
    for _grow in range(40):
        x = near[0] + step
        t, sol = at(x, near[2].b)
        if _within(t, duration):
            return x, sol
        if (t > duration) == (step > 0):  # passed T: the bracket
            low, high = (near, (x, t, sol)) if step > 0 else ((x, t, sol), near)
            return _root(at, duration, low, high, settle)
        near = (x, t, sol)
    raise InfeasiblePathError(
        f"stage 1 found no timing of duration {duration:.6g} s: the nearest lasts {near[1]:.6g} s"
    )


def duration_gradient(problem: TimingProblem, b: NDArray[np.float64]) -> NDArray[np.float64]:
    """∂t_e/∂b_k at every knot (0 at the fixed ends), shape (N+1,) [s³]."""
    lam = np.sqrt(b)
    ds = np.diff(problem.sigma)
    per = -2.0 * ds / (lam[:-1] + lam[1:]) ** 2  # ∂Δt_k/∂(λ_k + λ_{k+1})
    grad = np.zeros(b.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        half = np.where(lam > 0.0, 0.5 / lam, 0.0)
    grad[:-1] += per * half[:-1]
    grad[1:] += per * half[1:]
    grad[0] = grad[-1] = 0.0
    return grad


def _too_short(duration: float, fastest: float) -> InfeasiblePathError:
    """The error of a duration below the path's fastest motion (``excess``: by how much [s])."""
    return InfeasiblePathError(
        f"duration {duration:.12g} s is shorter than the time-optimal motion along this path, "
        f"{fastest:.12g} s: no timing within the limits is that fast",
        excess=fastest - duration,
    )
