"""The torque rate u̇ = du/dt along a path under a C¹ timing b(s) = ṡ² (a = b'/2, a' = da/ds).

With u = m a + c b + g + δ √b (eq. 10: m = Hθ', c = Hθ'' + h(θ, θ'), g = g(θ), δ = Dθ'),

    u̇ = √b du/ds = √b (m' a + m a' + c' b + 2 c a + g') + δ' b + δ a,    δ' = Dθ''.

Without damping this is √b times a form affine in (b, a, a'): the jerk's shape
θ⃛ = √b (θ‴b + 3θ″a + θ′a′) with a constant term g', so a torque-rate limit |u̇_i| ≤ r_i falls
out of the jerk-limited timing's construction (:mod:`nearopt.timing.jerk`). The derivatives
m', c', g' along s are fourth-order central differences over ±h, ±2h, the path continued along
its own cubic (exact for a piecewise-cubic path: θ‴ is constant on each piece) so that a point
on a breakpoint gets its own segment's one-sided derivative. The step h = :data:`STEP` times
the path's length: measured against central differences of the torques in time on a ur5 spline,
1e-2 leaves 1e-2 relative, 1e-3 1e-6, 1e-4 7e-10 (truncation ∝ h⁴; rounding ~1e-16/h).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..robot import Robot

__all__ = ["STEP", "TorqueRateCoefficients", "torque_rate_coefficients"]

STEP = 1e-4
"""The central differences' step h, relative to the path's length."""

_SHIFTS = np.array([-2.0, -1.0, 1.0, 2.0])
_WEIGHTS = np.array([1.0, -8.0, 8.0, -1.0]) / 12.0


@dataclass(frozen=True)
class TorqueRateCoefficients:
    """The torque's path coefficients and their derivatives along s at P points, each (P, n):
    m, c, g, δ of eq. (10) and dm, dc, dg, dδ = d/ds of each (see the module docstring)."""

    m: NDArray[np.float64]
    c: NDArray[np.float64]
    g: NDArray[np.float64]
    delta: NDArray[np.float64]
    dm: NDArray[np.float64]
    dc: NDArray[np.float64]
    dg: NDArray[np.float64]
    ddelta: NDArray[np.float64]

    def rate(
        self, b: NDArray[np.float64], a: NDArray[np.float64], da: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """u̇ [N·m/s or N/s] at the points for the timing's b, a, a' there (each (P,)),
        shape (P, n)."""
        b, a, da = (np.asarray(x, dtype=float)[:, None] for x in (b, a, da))
        inner = self.dm * a + self.m * da + self.dc * b + 2.0 * self.c * a + self.dg
        return np.sqrt(np.maximum(b, 0.0)) * inner + self.ddelta * b + self.delta * a

    def forms(
        self, bw: NDArray[np.float64], aw: NDArray[np.float64], daw: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Where b, a and a' are linear in some variables x (b = bw·x, a = aw·x, a' = daw·x,
        each weight (P, k)): L of u̇ = √b (L·x + g') + E·x and E, each (P, n, k)."""
        lin = (
            (self.dm + 2.0 * self.c)[:, :, None] * aw[:, None, :]
            + self.m[:, :, None] * daw[:, None, :]
            + self.dc[:, :, None] * bw[:, None, :]
        )
        damped = self.ddelta[:, :, None] * bw[:, None, :] + self.delta[:, :, None] * aw[:, None, :]
        return lin, damped


def torque_rate_coefficients(
    robot: Robot,
    q: NDArray[np.float64],
    q1: NDArray[np.float64],
    q2: NDArray[np.float64],
    q3: NDArray[np.float64],
    length: float,
) -> TorqueRateCoefficients:
    """The coefficients at P points of a piecewise-cubic path: θ, θ', θ'' there and θ‴ of the
    piece each point belongs to (each (P, n)); ``length`` the path's (the step's scale).
    4P + P points of Pinocchio's RNEA, three each, in one batched call."""
    q, q1, q2, q3 = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, q1, q2, q3))
    h = STEP * max(float(length), 1e-12)
    offsets = np.concatenate([[0.0], _SHIFTS * h])[:, None, None]  # (5, 1, 1)
    theta = q + offsets * q1 + offsets**2 / 2 * q2 + offsets**3 / 6 * q3
    dtheta = q1 + offsets * q2 + offsets**2 / 2 * q3
    ddtheta = q2 + offsets * q3
    count, n = q.shape
    coef = robot.path_coefficients(
        theta.reshape(-1, n), dtheta.reshape(-1, n), ddtheta.reshape(-1, n)
    )
    m, c, g = (x.reshape(5, count, n) for x in (coef.m, coef.c, coef.g))

    def derivative(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.einsum("k,kpn->pn", _WEIGHTS, x[1:]) / h

    return TorqueRateCoefficients(
        m[0],
        c[0],
        g[0],
        robot.damping * q1,
        derivative(m),
        derivative(c),
        derivative(g),
        robot.damping * q2,
    )
