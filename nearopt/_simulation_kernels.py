"""The compiled loops of :func:`nearopt.verify`'s forward simulation (numba): the arithmetic of
an explicit Runge-Kutta method over several lanes, between Pinocchio's batched ABA calls.

States and slopes are (2n, lanes): θ over θ̇, and θ̇ over θ̈. Compiled on first use and cached.
"""

from __future__ import annotations

from .timing._kernels import cached_jit, inline_jit


@inline_jit(error_model="numpy")
def _store(slopes, k, acceleration):  # pragma: no cover - compiled
    """ABA's answer ``acceleration`` (n, lanes) into the θ̈ half of ``slopes[k]``."""
    n, lanes = acceleration.shape
    for r in range(n):
        for lane in range(lanes):
            slopes[k, n + r, lane] = acceleration[r, lane]


@inline_jit(error_model="numpy")
def _combined(slopes, weights, count, r, lane):  # pragma: no cover - compiled
    """Σ_{j < count} weights[j] slopes[j, r, lane]."""
    total = 0.0
    for j in range(count):
        total += weights[j] * slopes[j, r, lane]
    return total


@cached_jit(error_model="numpy")
def stage(state, slopes, coefficients, i, h, u, damping, acceleration, at, tau):  # pragma: no cover
    """Stage i of a step of lengths h (per lane) from ``state``: the previous stage's
    ``acceleration`` (ABA's answer) into ``slopes[i − 1]``, the stage's state
    ``at = state + h Σ_{j<i} a_ij slopes[j]``, its θ̇ into ``slopes[i]`` and the torque ABA takes,
    ``tau = u − D θ̇``."""
    m, lanes = state.shape
    n = m // 2
    if i > 0:
        _store(slopes, i - 1, acceleration)
    for r in range(m):
        for lane in range(lanes):
            at[r, lane] = state[r, lane] + h[lane] * _combined(slopes, coefficients[i], i, r, lane)
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
    _store(slopes, stages - 1, acceleration)
    for r in range(m):
        for lane in range(lanes):
            state[r, lane] += h[lane] * _combined(slopes, weights, stages, r, lane)
    return 0
