"""The compiled loops of :func:`nearopt.verify`'s forward simulation (numba): the arithmetic of
an explicit Runge-Kutta method over several lanes, between Pinocchio's batched ABA calls.

States and slopes are (2n, lanes): θ over θ̇, and θ̇ over θ̈. Compiled on first use and cached.
"""

from __future__ import annotations

from .timing._kernels import cached_jit


@cached_jit(error_model="numpy")
def stage(state, slopes, coefficients, i, h, u, damping, acceleration, at, tau):  # pragma: no cover
    """Stage i of a step of lengths h (per lane) from ``state``: the previous stage's
    ``acceleration`` (ABA's answer) into ``slopes[i − 1]``, the stage's state
    ``at = state + h Σ_{j<i} a_ij slopes[j]``, its θ̇ into ``slopes[i]`` and the torque ABA takes,
    ``tau = u − D θ̇``."""
    m, lanes = state.shape
    n = m // 2
    if i > 0:
        for r in range(n):
            for lane in range(lanes):
                slopes[i - 1, n + r, lane] = acceleration[r, lane]
    for r in range(m):
        for lane in range(lanes):
            total = 0.0
            for j in range(i):
                total += coefficients[i, j] * slopes[j, r, lane]
            at[r, lane] = state[r, lane] + h[lane] * total
    for r in range(n):
        for lane in range(lanes):
            slopes[i, r, lane] = at[n + r, lane]
            tau[r, lane] = u[r, lane] - damping[r] * at[n + r, lane]
    return 0


@cached_jit(error_model="numpy")
def advance(state, slopes, weights, h, acceleration):  # pragma: no cover - compiled
    """The last stage's ``acceleration`` into the slopes, then the step:
    ``state += h Σ_i b_i slopes[i]``."""
    stages, m, lanes = slopes.shape
    n = m // 2
    for r in range(n):
        for lane in range(lanes):
            slopes[stages - 1, n + r, lane] = acceleration[r, lane]
    for r in range(m):
        for lane in range(lanes):
            total = 0.0
            for i in range(stages):
                total += weights[i] * slopes[i, r, lane]
            state[r, lane] += h[lane] * total
    return 0
