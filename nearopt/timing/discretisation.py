"""The discretised stage-1 problem as functions of the free speeds z = b_1 … b_{N−1}.

:class:`Discretisation` holds the torque samples of a :class:`~nearopt.timing.TimingProblem` as
linear functions of z (plus the damping term d√b), the interior speed rows and the discretised cost
with its gradient; the solvers and the sensitivity read them from here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..trajectory import segment_times

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..cost import Cost
    from .problem import TimingProblem

__all__ = ["Discretisation"]


class Discretisation:
    """Torque samples and the cost as functions of the free variables z = b_1 … b_{N−1}."""

    def __init__(self, problem: TimingProblem) -> None:
        p = problem
        big_n, n = p.segments, p.dof
        ds = np.diff(p.s)
        # sample r: node[r], segment seg[r]; r < N: start of segment r, r ≥ N: end of segment r − N
        self.node = np.concatenate([np.arange(big_n), np.arange(1, big_n + 1)])
        self.seg = np.concatenate([np.arange(big_n), np.arange(big_n)])
        self.ds = ds
        self.problem = p
        rows = np.arange(2 * big_n)
        blocks = []
        for i in range(n):
            m, c = p.coef.m[self.node, i], p.coef.c[self.node, i]
            slope = m / (2.0 * ds[self.seg])
            blocks.append(
                sp.coo_matrix(
                    (
                        np.concatenate([-slope, slope, c]),
                        (np.tile(rows, 3), np.concatenate([self.seg, self.seg + 1, self.node])),
                    ),
                    shape=(2 * big_n, big_n + 1),
                )
            )
        # rows joint-major (i·2N + r); columns: the free knots 1 … N−1
        self.k_full = sp.vstack(blocks).tocsr()
        self.k = self.k_full[:, 1:-1].tocsc()
        self.u0 = p.coef.g[self.node].T.ravel()
        self.damp = p.coef.d[self.node].T.ravel()
        self.has_damping = bool(np.any(self.damp != 0.0))
        self.lower = np.repeat(p.u_lower, 2 * big_n)
        self.upper = np.repeat(p.u_upper, 2 * big_n)
        # interior speed limits as rows S z ≤ bound (S ≥ 0)
        speed = p.interior_speed
        count = 0 if speed is None else speed.bound.size
        cols = np.concatenate([speed.segment, speed.segment + 1]) if count else np.zeros(0, int)
        vals = np.concatenate([1.0 - speed.weight, speed.weight]) if count else np.zeros(0)
        self.speed = sp.csr_matrix(
            (vals, (np.tile(np.arange(count), 2), cols)), shape=(count, big_n + 1)
        )[:, 1:-1].tocsr()
        self.speed_bound = speed.bound if count else np.zeros(0)
        if p.margin is not None:
            self.lower = self.lower + p.margin.T.ravel()
            self.upper = self.upper - p.margin.T.ravel()

    def b(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([[0.0], z, [0.0]])

    def torque(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """All torque samples, joint-major, shape (n·2N,)."""
        u = self.k @ z + self.u0
        if self.has_damping:
            u += self.damp * np.tile(np.sqrt(self.b(z))[self.node], self.problem.dof)
        return u

    def torque_jacobian(self, z: NDArray[np.float64]) -> sp.csc_matrix:
        if not self.has_damping:
            return self.k
        return (self.k + sp.diags(self.damp) @ self._sqrt_b_jacobian(z)).tocsc()

    def _sqrt_b_jacobian(self, z: NDArray[np.float64]) -> sp.csr_matrix:
        """∂√b(node[r]) / ∂z for every sample row (tiled over joints)."""
        big_n = self.problem.segments
        col = self.node - 1
        free = (col >= 0) & (col < big_n - 1)
        vals = np.zeros(self.node.size)
        vals[free] = 0.5 / np.sqrt(z[col[free]])
        j = sp.coo_matrix(
            (vals[free], (np.arange(self.node.size)[free], col[free])),
            shape=(self.node.size, big_n - 1),
        )
        return sp.vstack([j] * self.problem.dof).tocsr()

    def segment_times(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        return segment_times(self.problem.s, self.b(z))

    def objective(self, z: NDArray[np.float64], cost: Cost) -> tuple[float, NDArray[np.float64]]:
        """The discretised J and its gradient with respect to z."""
        p = self.problem
        n, big_n = p.dof, p.segments
        b = self.b(z)
        lam = np.sqrt(b)
        dt = segment_times(p.s, b)
        u = self.torque(z).reshape(n, 2 * big_n).T
        q = p.theta[self.node]
        qd = p.dtheta[self.node] * lam[self.node, None]
        f = cost(q, qd, u)
        _, df_dqd, df_du = cost.gradients(q, qd, u)
        fbar = 0.5 * (f[:big_n] + f[big_n:])
        value = float(np.sum(dt * fbar))
        # ∂/∂b of every knot (b_0 and b_N are dropped at the end)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv2lam = np.where(lam > 0, 0.5 / lam, 0.0)
        ddt = -dt / (lam[:-1] + lam[1:])  # ∂Δt_k/∂λ, the same for both ends
        grad = np.zeros(b.size)
        np.add.at(grad, np.arange(big_n), ddt * inv2lam[:-1] * fbar)
        np.add.at(grad, np.arange(1, big_n + 1), ddt * inv2lam[1:] * fbar)
        weight = 0.5 * dt[self.seg]  # each sample's share of its segment's time
        du = weight[:, None] * df_du  # ∂J/∂u at every sample, (2N, n)
        grad += np.asarray(self.k_full.T @ du.T.ravel()).ravel()
        # through λ = √b of the sample's knot: θ̇ = λθ' and the damping torque dλ
        node_term = weight * np.sum(df_dqd * p.dtheta[self.node], axis=1) + np.sum(
            du * p.coef.d[self.node], axis=1
        )
        np.add.at(grad, self.node, node_term * inv2lam[self.node])
        return value, grad[1:-1]
