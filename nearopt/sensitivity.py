"""How stage 1's optimum J*(θ) changes with the path: the gradient that drives path optimisation.

Stage 1 solves, on a grid σ_0 … σ_N, ``min_b Obj(b; θ)`` subject to the torque limits
``u_min ≤ u_r(b; θ) ≤ u_max`` at the samples r and the speed bounds ``b_k ≤ b̄_k(θ')``. Its optimal
value J*(θ) depends on the path only through the samples θ(σ_k), θ'(σ_k), θ''(σ_k). By the envelope
theorem (sensitivity of a parametric program at a KKT point with unique multipliers),

    dJ*/dp = ∂Obj/∂p + Σ_r μ_r^T ∂u_r/∂p + Σ_k ν_k ∂(b_k − b̄_k)/∂p      at the optimum b*,

so one stage-1 solve gives the exact gradient with respect to any path parameterisation p without
differentiating through the solver. The multipliers μ ≥ 0 (torque limits) and ν ≥ 0 (speed bounds)
are recovered from the KKT stationarity condition ∇_b Obj + Σ μ ∇_b u + ν = 0 over the constraints
active at b*, by non-negative least squares; the residual of that fit is reported (it is ~0 at a
true KKT point). ∂u/∂θ, ∂u/∂θ̇ and ∂u/∂θ̈ come from Pinocchio's analytic RNEA derivatives.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import nnls

from .timing import Discretisation, TimingProblem

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from .cost import Cost
    from .robot import Robot

__all__ = ["PathSensitivity", "timing_sensitivity"]


@dataclass(frozen=True)
class PathSensitivity:
    """The gradient of stage 1's optimal (discretised) cost with respect to the path samples.

    Attributes
    ----------
    value
        J* = Obj(b*), the discretised optimal cost.
    theta, dtheta, ddtheta
        ∂J*/∂θ(σ_k), ∂J*/∂θ'(σ_k), ∂J*/∂θ''(σ_k) (derivatives with respect to σ = s/s_e),
        each of shape (N + 1, n).
    interior_sigma, interior_dtheta
        The points σ_p inside segments where joint speeds are limited too
        (:class:`~nearopt.timing.InteriorSpeed`) and ∂J*/∂θ'(σ_p), shape (P,) and (P, n).
    residual
        ‖∇_b Obj + Σ μ ∇_b u + ν‖ / ‖∇_b Obj‖ of the multipliers' fit (≈ 0 at a KKT point).
    """

    value: float
    theta: NDArray[np.float64]
    dtheta: NDArray[np.float64]
    ddtheta: NDArray[np.float64]
    interior_sigma: NDArray[np.float64]
    interior_dtheta: NDArray[np.float64]
    residual: float

    def gradient(
        self,
        basis: Callable[[NDArray[np.float64], int], NDArray[np.float64]],
        sigma: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """dJ*/dc for a path θ(σ) = B(σ) c: ``basis(σ, order)`` gives B, B' or B'' at σ.

        ``sigma`` are the grid's knots; returns an array of the shape of c (K, n).
        """
        grad = sum(
            basis(sigma, k).T @ d for k, d in enumerate((self.theta, self.dtheta, self.ddtheta))
        )
        if self.interior_sigma.size:
            grad = grad + basis(self.interior_sigma, 1).T @ self.interior_dtheta
        return grad


def timing_sensitivity(
    robot: Robot,
    problem: TimingProblem,
    b: NDArray[np.float64],
    cost: Cost,
    *,
    active_tolerance: float = 1e-6,
) -> PathSensitivity:
    """∂J*/∂(θ, θ', θ'') at the grid knots for the stage-1 optimum ``b`` of ``problem``.

    Parameters
    ----------
    robot
        The arm the problem was built for.
    problem
        Stage 1 on a grid (:func:`~nearopt.timing.build_timing_problem`).
    b
        The optimal b = λ² at the knots (``solve_timing(problem, cost).b``).
    cost
        The running cost f0 that was minimised.
    active_tolerance
        A torque sample within this fraction of its limit range from a limit (or a speed bound
        within this fraction of itself) counts as active; inactive ones get μ = 0 from the fit.
    """
    disc = Discretisation(problem)
    p = problem
    n, big_n = p.dof, p.segments
    z = np.asarray(b, dtype=float)[1:-1]
    value, grad = disc.objective(z, cost)

    # multipliers: columns are the signed gradients of the active constraints
    u_flat = disc.torque(z)
    tol = active_tolerance * (disc.upper - disc.lower)
    upper = np.flatnonzero(u_flat >= disc.upper - tol)
    lower = np.flatnonzero(u_flat <= disc.lower + tol)
    jac = disc.torque_jacobian(z).tocsr()
    ub = p.b_upper[1:-1]
    speed = np.flatnonzero(np.isfinite(ub) & (z >= ub * (1.0 - active_tolerance)))
    inside = np.flatnonzero(disc.speed @ z >= disc.speed_bound * (1.0 - active_tolerance))
    columns = np.hstack(
        [
            jac[upper].toarray().T,
            -jac[lower].toarray().T,
            np.eye(big_n - 1)[:, speed],
            disc.speed[inside].toarray().T,
        ]
    )
    if columns.shape[1]:
        mu, rnorm = nnls(columns, -grad, maxiter=50 * columns.shape[1])
    else:
        mu, rnorm = np.zeros(0), float(np.linalg.norm(grad))
    signed = np.zeros(u_flat.size)
    signed[upper] += mu[: upper.size]
    signed[lower] -= mu[upper.size : upper.size + lower.size]
    nu = mu[upper.size + lower.size : upper.size + lower.size + speed.size]
    nu_inside = mu[upper.size + lower.size + speed.size :]

    # the samples: node, segment, θ, θ̇ = λθ', θ̈ = bθ'' + aθ', u
    node, seg = disc.node, disc.seg
    bk = np.concatenate([[0.0], z, [0.0]])
    lam = np.sqrt(bk)[node]
    acc = (np.diff(bk) / (2.0 * disc.ds))[seg]
    dt = disc.segment_times(z)
    w = 0.5 * dt[seg]
    th, dth = p.theta[node], p.dtheta[node]
    ddth = p.ddtheta[node]
    qd = lam[:, None] * dth
    u = u_flat.reshape(n, 2 * big_n).T
    df_dq, df_dqd, df_du = cost.gradients(th, qd, u)
    zeta = w[:, None] * df_du + signed.reshape(n, 2 * big_n).T  # ∂L/∂u at every sample
    du_dq, du_dv, h = robot.inverse_dynamics_derivatives(
        th, qd, bk[node, None] * ddth + acc[:, None] * dth
    )
    h_zeta = np.einsum("rij,ri->rj", h, zeta)
    g0 = np.einsum("rij,ri->rj", du_dq, zeta) + w[:, None] * df_dq
    g1 = lam[:, None] * (np.einsum("rij,ri->rj", du_dv, zeta) + w[:, None] * df_dqd)
    g1 += acc[:, None] * h_zeta
    g2 = bk[node, None] * h_zeta
    d0, d1, d2 = (np.zeros((big_n + 1, n)) for _ in range(3))
    np.add.at(d0, node, g0)
    np.add.at(d1, node, g1)
    np.add.at(d2, node, g2)
    # speed bounds b̄ = min_i v_i² / θ'_i² at the knots and at interior points
    v = robot.limits.velocity
    if speed.size:
        knots = speed + 1
        rows, joint, value = _speed_bound_gradient(p.dtheta[knots], v, nu)
        d1[knots[rows], joint] += value
    interior = p.interior_speed
    d_inside = np.zeros((0, n)) if interior is None else np.zeros_like(interior.dtheta)
    if inside.size:
        rows, joint, value = _speed_bound_gradient(interior.dtheta[inside], v, nu_inside)
        d_inside[inside[rows], joint] = value
    return PathSensitivity(
        value=value,
        theta=d0,
        dtheta=d1,
        ddtheta=d2,
        interior_sigma=np.zeros(0) if interior is None else interior.sigma,
        interior_dtheta=d_inside,
        residual=float(rnorm / max(np.linalg.norm(grad), 1e-300)),
    )


def _speed_bound_gradient(
    dtheta: NDArray[np.float64], velocity: NDArray[np.float64], nu: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """∂/∂θ' of Σ ν (b − b̄) with b̄ = min_i v_i² / θ'_i²: 2 ν v_i² / θ'_i³ for the binding joint i.

    Returns the rows, their binding joints and the values.
    """
    with np.errstate(divide="ignore"):
        ratio = np.where(dtheta != 0, velocity**2 / dtheta**2, np.inf)
    rows = np.arange(dtheta.shape[0])
    joint = np.argmin(ratio, axis=1)
    return rows, joint, nu * 2.0 * velocity[joint] ** 2 / dtheta[rows, joint] ** 3
