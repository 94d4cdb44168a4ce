"""The paper's path update (Sections 5-6): torque gradient η(t), improved torques, next path.

Along the current motion x^j(t) = (θ, θ̇), u^j(t), the cost with a terminal penalty (eqs. 21, 33)

    J = F(x(T)) + ∫_0^T f0(x, u) dt,   F = γ Σ_i (x_i(T) − x_ei)²,

has the gradient with respect to the torques (eq. 23, with T = t_e ± Δt as in eq. 27)

    η(t) = B(t)^T p(t) + ∂f0/∂u,   ṗ = −A(t)^T p − ∂f0/∂x,   p(T) = ∂F/∂x(x(T)),

where A = ∂f/∂x and B = ∂f/∂u of ẋ = f(x, u) come from Pinocchio's ABA derivatives (eqs. 24-26).
This costate p is the adjoint form of the state-transition matrix: p(t)^T = F_x^T Φ(T, t) +
∫_t^T f0_x^T Φ(τ, t) dτ satisfies exactly that equation, so eq. (23) is evaluated with one
backward integration of 2n equations instead of (2n)² for Φ.

The paper leaves open what the nominal motion on [0, t_e ± Δt] is. Here it is the current motion
uniformly re-timed to last T = t_e ± Δt: it still ends at rest at θe, so the improved torques and
the boundary-value problem below give paths that are reached faster (−Δt: the faster motion's
torques, clipped to the limits) or with less torque (+Δt). (Truncating the motion at t_e − Δt or
resting at θe after t_e were tried: the first makes the boundary-value problem fail for all but
tiny α, the second adds a flat end to the path that costs about 1 % of J.)

The next path solves eq. (20), ẋ = f(x, u*(t)) with u* = clip(u − αη) (eqs. 22, 30), as a two-point
boundary-value problem θ(0) = θ0, θ(T) = θe with free end velocities. Eq. (19), the same problem in
s, is singular at both ends because λ(0) = λ(s_e) = 0 (θ'' ∝ 1/λ²); in t it is regular, so it is
solved in t (SciPy's ``solve_bvp`` collocation, analytic Jacobian from A) and the solution is
re-parameterised by σ = t/T: the next path is θ^{j+1}(σ), a cubic spline through the solution,
which stage 1 then re-times from rest to rest.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.integrate import solve_bvp, solve_ivp

from ..errors import InfeasiblePathError, SolverError
from ..path import Path, SplinePath
from ..timing import TimingResult, optimal_timing
from .records import MethodOutcome, PaperOptions, Run, StopReason

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..cost import Cost
    from ..robot import Robot
    from ..trajectory import Trajectory

__all__ = ["torque_gradient", "nominal_motion", "boundary_value_path", "paper_iterations"]


def nominal_motion(
    robot: Robot, trajectory: Trajectory, horizon: float, samples: int = 401
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """x^j(t) and u^j(t) on a uniform grid of [0, T], the motion uniformly re-timed to last T.

    θ_T(t) = θ^j(t t_e / T): the same path from rest to rest, slower (T > t_e) or faster (T < t_e);
    u by inverse dynamics (a faster motion may leave the torque limits; eq. (30) clips u* later).

    Returns
    -------
    t, x, u
        Times (M,), states (M, 2n) and torques (M, n).
    """
    t = np.linspace(0.0, horizon, samples)
    ratio = trajectory.duration / horizon
    q, qd, qdd = trajectory.states(np.minimum(t * ratio, trajectory.duration))
    qd, qdd = qd * ratio, qdd * ratio**2
    return t, np.hstack([q, qd]), robot.inverse_dynamics_batch(q, qd, qdd)


def torque_gradient(
    robot: Robot,
    t: NDArray[np.float64],
    x: NDArray[np.float64],
    u: NDArray[np.float64],
    cost: Cost,
    target: NDArray[np.float64],
    gamma: float,
) -> NDArray[np.float64]:
    """η(t) of eqs. (23)/(27) at the times ``t`` of a nominal motion (adjoint form).

    Parameters
    ----------
    robot
        The arm.
    t, x, u
        The nominal motion on [0, T]: times (M,), states (M, 2n), torques (M, n).
    cost
        The running cost f0(θ, θ̇, u).
    target
        x_e = (θe, 0), shape (2n,).
    gamma
        γ of eq. (33).

    Returns
    -------
    NDArray
        η at the times t, shape (M, n) [units of J per N·m·s].
    """
    n = robot.n
    jac = [robot.dynamics_jacobians(xk[:n], xk[n:], uk) for xk, uk in zip(x, u, strict=True)]
    a = np.array([j[0] for j in jac])
    b = np.array([j[1] for j in jac])
    df_dq, df_dqd, df_du = cost.gradients(x[:, :n], x[:, n:], u)
    df_dx = np.hstack([df_dq, df_dqd])

    def costate(tau: float, p: NDArray[np.float64]) -> NDArray[np.float64]:
        k = int(np.clip(np.searchsorted(t, tau) - 1, 0, t.size - 2))
        w = (tau - t[k]) / (t[k + 1] - t[k])
        a_t = (1 - w) * a[k] + w * a[k + 1]
        return -a_t.T @ p - ((1 - w) * df_dx[k] + w * df_dx[k + 1])

    p_end = 2.0 * gamma * (x[-1] - target)
    sol = solve_ivp(
        costate, (t[-1], t[0]), p_end, t_eval=t[::-1], rtol=1e-9, atol=1e-12, method="DOP853"
    )
    if not sol.success or sol.y.shape[1] != t.size:
        raise SolverError(f"the costate of eq. (23) could not be integrated: {sol.message}")
    p = sol.y[:, ::-1].T
    return np.einsum("kij,ki->kj", b, p) + df_du


def boundary_value_path(
    robot: Robot,
    t: NDArray[np.float64],
    x_guess: NDArray[np.float64],
    u_star: NDArray[np.float64],
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    tolerance: float = 1e-6,
) -> SplinePath | None:
    """The next path θ^{j+1}(σ), σ = t/T, from eq. (20) with θ(0) = θ0, θ(T) = θe.

    The torques u*(t) are interpolated linearly between the times ``t``. Returns None if the
    collocation does not converge. The ends are met to the collocation's tolerance and then set
    exactly (the change is below 1e-8 rad or the path is rejected).
    """
    n = robot.n

    def torque(tau: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.column_stack([np.interp(tau, t, u_star[:, i]) for i in range(n)])

    def fun(tau: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        u = torque(tau)
        qdd = np.array([robot.forward_dynamics(y[:n, k], y[n:, k], u[k]) for k in range(tau.size)])
        return np.vstack([y[n:], qdd.T])

    def fun_jac(tau: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        u = torque(tau)
        return np.stack(
            [robot.dynamics_jacobians(y[:n, k], y[n:, k], u[k])[0] for k in range(tau.size)],
            axis=-1,
        )

    def bc(ya: NDArray[np.float64], yb: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([ya[:n] - q0, yb[:n] - qe])

    try:
        sol = solve_bvp(fun, bc, t, x_guess.T, fun_jac=fun_jac, tol=tolerance, max_nodes=4000)
    except (ValueError, np.linalg.LinAlgError):
        return None
    if sol.status != 0:
        return None
    tau = np.linspace(0.0, t[-1], 201)
    y = sol.sol(tau)
    theta = y[:n].T.copy()
    if max(np.max(np.abs(theta[0] - q0)), np.max(np.abs(theta[-1] - qe))) > 1e-8:
        return None
    theta[0], theta[-1] = q0, qe
    ends = (y[n:, 0] * t[-1], y[n:, -1] * t[-1])  # dθ/dσ = T θ̇
    return SplinePath(tau / t[-1], theta, dtheta_ends=ends)


def paper_iterations(
    robot: Robot,
    initial: TimingResult,
    cost: Cost,
    *,
    grid: int,
    velocity_limits: bool,
    position_limits: bool,
    options: PaperOptions,
    run: Run,
) -> MethodOutcome:
    """Section 6's loop from the straight line, with α and Δt found by a search.

    Each trial computes η for T = t_e ± Δt (Δt = ``delta_t`` · t_e), the improved torques and the
    two next paths, times both by stage 1 and keeps the better (step 3 of Section 6). A trial that
    does not lower J is followed by one with α / 4 or Δt / 2 (alternately), up to ``trials`` times;
    an accepted one lets the next iteration start from 2α and 1.5Δt (Δt ≤ 0.2 t_e). Accepted
    iterates lower J strictly, so the last one is the best. ``initial`` (the straight line, timed)
    has been accepted as iterate 0 by the caller.
    """
    current: TimingResult = initial
    path: Path = initial.trajectory.path
    q0 = np.asarray(path(0.0, 0)[0])
    qe = np.asarray(path(path.s_end, 0)[0])
    target = np.concatenate([qe, np.zeros(robot.n)])
    lim = robot.limits
    alpha, delta_t, trials = options.alpha, options.delta_t, options.trials
    evaluations = 0
    reason, message = StopReason.ITERATION_LIMIT, f"{run.max_iterations} iterations"
    for index in range(1, run.max_iterations + 1):
        if run.out_of_time():
            reason, message = StopReason.TIME_LIMIT, "the time limit was reached"
            break
        best: tuple[TimingResult, Path] | None = None
        for trial in range(trials):
            for sign in (1.0, -1.0):
                horizon = current.duration * (1.0 + sign * delta_t)
                t, x, u = nominal_motion(robot, current.trajectory, horizon)
                try:
                    eta = torque_gradient(robot, t, x, u, cost, target, options.gamma)
                except SolverError:
                    continue
                u_star = np.clip(u - alpha * eta, lim.effort_lower, lim.effort_upper)
                candidate = boundary_value_path(robot, t, x, u_star, q0, qe)
                if candidate is None:
                    continue
                if position_limits:
                    theta = candidate(np.linspace(0, 1, 401), 0)
                    if np.any(theta < lim.position_lower) or np.any(theta > lim.position_upper):
                        continue
                try:
                    timing = optimal_timing(
                        robot, candidate, cost, grid=grid, velocity_limits=velocity_limits
                    )
                except (InfeasiblePathError, SolverError):
                    continue
                evaluations += 1
                if best is None or timing.objective < best[0].objective:
                    best = (timing, candidate)
            if best is not None and best[0].objective < current.objective:
                break
            if trial % 2 == 0:
                alpha /= 4.0
            else:
                delta_t /= 2.0
        if best is None or best[0].objective >= current.objective:
            reason = StopReason.NO_PROGRESS
            message = (
                f"could not improve: no step of the paper's update lowers J in {trials} "
                f"trials of α (down to {alpha:.2g}) and Δt (down to {delta_t:.2g} t_e)"
            )
            break
        gain = current.objective - best[0].objective
        current, path = best
        run.report(index, current, alpha, path)
        if gain < options.tolerance * current.objective:
            reason = StopReason.CONVERGED
            message = f"converged: J changed by less than {options.tolerance:g} relative"
            break
        alpha, delta_t = 2.0 * alpha, min(1.5 * delta_t, 0.2)
    return MethodOutcome(current, reason, message, evaluations)
