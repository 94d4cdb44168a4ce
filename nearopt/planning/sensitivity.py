"""How stage 1's optimum J*(θ) changes with the path: the gradient that drives path optimisation.

Stage 1 solves, on a grid σ_0 … σ_N, ``min_b Obj(b; θ)`` subject to the rows of
:class:`~nearopt.timing.Discretisation` (torque and acceleration limits at the samples r, one
speed row b θ'_i² ≤ v_i² per joint at the knots and inside segments). Its optimal value J*(θ)
depends on the path only through the samples θ, θ', θ'' at those places. By the envelope theorem
(sensitivity of a parametric program at a KKT point with unique multipliers),

    dJ*/dp = ∂Obj/∂p + Σ_rows μ_row ∂row/∂p      at the optimum b*,

so one stage-1 solve gives the exact gradient with respect to any path parameterisation p without
differentiating through the solver. The multipliers μ are recovered from the KKT stationarity
condition ∇_b Obj + Σ μ ∇_b row = 0 over the rows active at b*, by non-negative least squares; the
residual of that fit is reported (it is ~0 at a true KKT point). ∂u/∂θ, ∂u/∂θ̇ and ∂u/∂θ̈ come from
Pinocchio's analytic RNEA derivatives. Where two rows tie (two joints at their speed limit at the
same knot) the multipliers are not unique and J* has a kink: the result is then one element of its
subdifferential.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import nnls

from ..timing import Discretisation, TimingProblem

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..cost import Cost
    from ..robot import Robot

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
        A row within this fraction of its range (or of its bound, for one-sided rows) from a limit
        counts as active; inactive ones get a zero multiplier from the fit.
    """
    disc = Discretisation(problem)
    p = problem
    n, big_n = p.dof, p.segments
    z = np.asarray(b, dtype=float)[1:-1]
    value, grad = disc.objective(z, cost)

    # multipliers: columns are the signed gradients of the active rows (and of the b caps)
    rows = disc.values(z)
    span = np.where(np.isfinite(disc.lower), disc.upper - disc.lower, np.abs(disc.upper))
    tol = active_tolerance * span
    upper = np.flatnonzero(rows >= disc.upper - tol)
    lower = np.flatnonzero(rows <= disc.lower + tol)
    caps = np.flatnonzero(np.isfinite(disc.z_upper) & (z >= disc.z_upper * (1 - active_tolerance)))
    jac = disc.jacobian(z)
    columns = np.hstack(
        [jac[upper].toarray().T, -jac[lower].toarray().T, np.eye(big_n - 1)[:, caps]]
    )
    if columns.shape[1]:
        mu, rnorm = nnls(columns, -grad, maxiter=50 * columns.shape[1])
    else:
        mu, rnorm = np.zeros(0), float(np.linalg.norm(grad))
    signed = np.zeros(rows.size)
    signed[upper] += mu[: upper.size]
    signed[lower] -= mu[upper.size : upper.size + lower.size]

    # the samples: node, segment, θ, θ̇ = λθ', θ̈ = bθ'' + aθ', u
    node, seg = disc.node, disc.seg
    bk = disc.b(z)
    lam = np.sqrt(bk)[node]
    acc = (np.diff(bk) / (2.0 * disc.ds))[seg]
    w = 0.5 * disc.segment_times(z)[seg]
    th, dth = p.theta[node], p.dtheta[node]
    qd = lam[:, None] * dth
    u = disc.torque(z).reshape(n, 2 * big_n).T
    df_dq, df_dqd, df_du = cost.gradients(th, qd, u)
    # ∂L/∂u at every sample: the cost's share and the torque rows' multipliers
    zeta = w[:, None] * df_du + signed[disc.blocks.torque].reshape(n, 2 * big_n).T
    du_dq, du_dv, h = robot.inverse_dynamics_derivatives(
        th, qd, bk[node, None] * p.ddtheta[node] + acc[:, None] * dth
    )
    h_zeta = np.einsum("rij,ri->rj", h, zeta)
    g0 = np.einsum("rij,ri->rj", du_dq, zeta) + w[:, None] * df_dq
    g1 = lam[:, None] * (np.einsum("rij,ri->rj", du_dv, zeta) + w[:, None] * df_dqd)
    g1 += acc[:, None] * h_zeta
    g2 = bk[node, None] * h_zeta
    # acceleration rows θ̈_i = θ'_i a + θ''_i b
    block = disc.blocks.acceleration
    sample, joint, mult = disc.location[block], disc.joint[block], signed[block]
    np.add.at(g1, (sample, joint), mult * acc[sample])
    np.add.at(g2, (sample, joint), mult * bk[node[sample]])
    d0, d1, d2 = (np.zeros((big_n + 1, n)) for _ in range(3))
    np.add.at(d0, node, g0)
    np.add.at(d1, node, g1)
    np.add.at(d2, node, g2)
    # speed rows b θ'_i² ≤ v_i² at the knots and inside segments: ∂/∂θ'_i = 2 b θ'_i
    block = disc.blocks.speed
    knot, joint = disc.location[block], disc.joint[block]
    np.add.at(d1, (knot, joint), signed[block] * 2.0 * bk[knot] * p.dtheta[knot, joint])
    interior = p.interior_speed
    d_inside = np.zeros((0, n)) if interior is None else np.zeros_like(interior.dtheta)
    block = disc.blocks.interior_speed
    if block.stop > block.start:
        point, joint = disc.location[block], disc.joint[block]
        k, weight = interior.segment[point], interior.weight[point]
        b_at = (1.0 - weight) * bk[k] + weight * bk[k + 1]
        slope = interior.dtheta[point, joint]
        np.add.at(d_inside, (point, joint), signed[block] * 2.0 * b_at * slope)
    return PathSensitivity(
        value=value,
        theta=d0,
        dtheta=d1,
        ddtheta=d2,
        interior_sigma=np.zeros(0) if interior is None else interior.sigma,
        interior_dtheta=d_inside,
        residual=float(rnorm / max(np.linalg.norm(grad), 1e-300)),
    )
