"""Stage 2 with moving ends: a path that leaves θ0 along the start velocity and reaches θe along
the end velocity.

θ̇(0) = √b_0 θ'(0), so a start velocity qd0 ≠ 0 needs θ'(0) along qd0. For the clamped cubic
B-spline of stage 2, θ'(0) = B'_1(0)(c_1 − c_0): the first interior control point lies on the ray
c_1 = θ0 + α qd0/|qd0|, α > 0 — n − 1 linear rows Q Δc_1 = 0 of the convex model (Q an
orthonormal basis of the directions across qd0) — and b_0 = (qd0·θ'(0)/|θ'(0)|²)² = |qd0|²/
(B'_1(0) α)² follows from the path exactly (stage 1 times every iterate with it). Likewise
θ'(1) = B'_{K+1}(1)(θe − c_K) along qde.

In the model, b_0 is fixed but depends on the path: the rows' terms in b_0 change with Δp by
A_{:,0} ∂b_0/∂p Δp (and the damping's d√b_0), the segment's time 2Δσ_0/(λ_0 + λ_1) by its
derivative in λ_0 (a price on Δp, the first-order term at the model's timing) and so does t_e in
a duration's row. The model is therefore exact to first order in the path at the iterate, as
without moving ends; the trial is timed exactly as always.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from ..errors import ConfigurationError
from ..path import BSplinePath

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..robot import Robot
    from ..timing import Discretisation
    from .linearisation import PathBasis

__all__ = ["EndTerms", "MovingEnds", "check_velocities", "end_terms", "leaving_along"]


class MovingEnds(NamedTuple):
    """The boundary velocities a stage-2 run keeps [rad/s or m/s], None where at rest; where the
    interior control points of the ends are in p (the first; the last) and whether θe is in p
    too (a goal pose's end that moves)."""

    qd0: NDArray[np.float64] | None
    qde: NDArray[np.float64] | None
    q0: NDArray[np.float64]
    qe: NDArray[np.float64]
    last: int
    goal_moves: bool

    @property
    def moving(self) -> bool:
        return self.qd0 is not None or self.qde is not None

    def onto_rays(self, p: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """p with its first (last) interior control point put back on the ray from θ0 along qd0
        (to θe against qde), to rounding; None where a step took it across θ0 (θe): the path
        would leave against the velocity."""
        n = self.q0.size
        p = p.copy()
        if self.qd0 is not None:
            d = self.qd0 / np.linalg.norm(self.qd0)
            alpha = float(d @ (p[:n] - self.q0))
            if not alpha > 0.0:
                return None
            p[:n] = self.q0 + alpha * d
        if self.qde is not None:
            d = self.qde / np.linalg.norm(self.qde)
            end = p[-n:] if self.goal_moves else self.qe
            at = slice(self.last * n, (self.last + 1) * n)
            alpha = float(d @ (end - p[at]))
            if not alpha > 0.0:
                return None
            p[at] = end - alpha * d
        return p

    def direction_rows(self, p_size: int) -> sp.csr_matrix:
        """The model's rows Q Δc_1 = 0 (and Q (Δθe − Δc_K) = 0): the step keeps the ends'
        directions, shape (≤ 2(n − 1), p_size)."""
        n = self.q0.size
        blocks = []
        if self.qd0 is not None:
            across = la.null_space(self.qd0[None, :]).T
            row = np.zeros((n - 1, p_size))
            row[:, :n] = across
            blocks.append(row)
        if self.qde is not None:
            across = la.null_space(self.qde[None, :]).T
            row = np.zeros((n - 1, p_size))
            row[:, self.last * n : (self.last + 1) * n] = -across
            if self.goal_moves:
                row[:, -n:] += across
            blocks.append(row)
        return sp.csr_matrix(np.vstack(blocks) if blocks else np.zeros((0, p_size)))


class EndTerms(NamedTuple):
    """The model's terms in b_0, b_N through the path: ∂(rows)/∂p by them (add to the rows'
    path Jacobian), ∂b_0/∂p and ∂b_N/∂p, and the price on Δp of the end segments' time."""

    jacobian: sp.csr_matrix
    gradients: tuple[NDArray[np.float64], NDArray[np.float64]]
    price: NDArray[np.float64]


def end_terms(
    disc: Discretisation,
    z: NDArray[np.float64],
    basis: PathBasis,
    ends: MovingEnds,
    weights: NDArray[np.float64],
) -> EndTerms:
    """:class:`EndTerms` at the timing z (see the module docstring)."""
    problem = disc.problem
    b = disc.b(z)
    lam = np.sqrt(b)
    p_size = basis.knots[1].shape[1] * problem.dof
    big_n = problem.segments
    jac = sp.csr_matrix((disc.offset.size, p_size))
    grads = [np.zeros(p_size), np.zeros(p_size)]
    price = np.zeros(p_size)
    dt = np.diff(problem.sigma) * 2.0 / (lam[:-1] + lam[1:])
    u = disc.torque(z).reshape(problem.dof, 2 * big_n)
    energy = weights @ u**2
    fbar = 1.0 + 0.5 * (energy[:big_n] + energy[big_n:])
    for k, (qd, knot, seg) in enumerate(((ends.qd0, 0, 0), (ends.qde, big_n, big_n - 1))):
        if qd is None or b[knot] <= 0.0:
            continue
        t = problem.dtheta[knot]
        vt, tt = float(qd @ t), float(t @ t)
        dbdt = 2.0 * vt * qd / tt**2 - 4.0 * vt**2 * t / tt**3  # ∂b/∂θ' of (qd·θ'/|θ'|²)²
        grads[k] = np.kron(basis.knots[1][knot], dbdt)
        column = disc.matrix[:, knot].toarray().ravel()
        damped = (disc.sqrt_node == knot) & (disc.sqrt_coef != 0.0)
        column[damped] += 0.5 * disc.sqrt_coef[damped] / lam[knot]
        rows, cols = np.flatnonzero(column), np.flatnonzero(grads[k])
        jac = jac + sp.csr_matrix(
            (np.outer(column[rows], grads[k][cols]).ravel(),
             (np.repeat(rows, cols.size), np.tile(cols, rows.size))),
            shape=jac.shape,
        )  # fmt: skip
        # J's end segment Δt f̄ = 2Δσ f̄/(λ_k + λ_{k±1}) in λ_k = √b_k, at fixed torques
        price += -dt[seg] * fbar[seg] / (lam[seg] + lam[seg + 1]) * grads[k] / (2.0 * lam[knot])
    return EndTerms(jac.tocsr(), (grads[0], grads[1]), price)


def leaving_along(
    path: BSplinePath,
    qd0: NDArray[np.float64] | None,
    qde: NDArray[np.float64] | None,
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
    names: tuple[str, ...],
    stretch: float = 1.0,
) -> BSplinePath:
    """The straight line ``path`` (a B-spline θ0 → θe) with the boundary velocities: it leaves θ0
    along qd0 for a distance D — its first two interior control points on that ray, at D/2 and
    D — then runs straight (control points at their Greville abscissae) to θe, or to the point
    E before θe on the ray against qde where the last two lie. D (E) is ``stretch`` × the
    distance of the line's second control point from its end, and no more than the position
    ``bounds`` (lower, upper) leave room for (convex hull: the whole path stays within them).
    No curvature at a moving end: the arm turns where stage 1 can slow down for it.

    Raises
    ------
    ConfigurationError
        Where a velocity points out of the position limits at its end (no path can leave or
        arrive that way), naming the joint.
    """
    lower, upper = bounds
    points = path.control_points.copy()
    count = points.shape[0]
    s = BSplinePath.greville(count, path.knots[4:-4] if count > 4 else None)
    anchors = {0: points[0], count - 1: points[-1]}
    for qd, end, word in ((qd0, 0, "qd0"), (qde, count - 1, "qde")):
        if qd is None:
            continue
        step = qd / np.linalg.norm(qd) * (1.0 if end == 0 else -1.0)  # from the end inwards
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(
                step > 0.0,
                (upper - points[end]) / step,
                np.where(step < 0.0, (lower - points[end]) / step, np.inf),
            )
        if np.min(room) <= 0.0:
            i = int(np.argmin(room))
            where = "leave q0 out of" if end == 0 else "reach qe from beyond"
            raise ConfigurationError(
                f"{word} of joint {names[i]} is {qd[i]:.6g} rad/s at {points[end][i]:.6g} rad: "
                f"it would {where} its position limits [{lower[i]:.6g}, {upper[i]:.6g}] rad",
                joint=names[i],
            )
        inner = 2 if end == 0 else count - 3
        reach = stretch * float(np.linalg.norm(points[inner] - points[end]))
        reach = min(reach, float(np.min(room)))
        anchors[inner] = points[end] + reach * step
        points[(1 if end == 0 else count - 2)] = points[end] + 0.5 * reach * step
    first, last = (2 if qd0 is not None else 0), (count - 3 if qde is not None else count - 1)
    a, b = anchors[first], anchors[last]
    for j in range(first, last + 1):
        points[j] = a + (b - a) * (s[j] - s[first]) / (s[last] - s[first])
    return BSplinePath(points, path.knots[4:-4] if count > 4 else None)


def check_velocities(
    robot: Robot, qd0: object, qde: object, velocity_limits: bool
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """(qd0, qde) of a plan's arguments as joint vectors, None where at rest (None or zeros);
    ConfigurationError naming the joint for a wrong shape, a value that is not finite or one
    beyond the joint's speed limit (where those are enforced)."""
    out: list[NDArray[np.float64] | None] = []
    for name, value in (("qd0", qd0), ("qde", qde)):
        if value is None:
            out.append(None)
            continue
        try:
            v = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            v = np.full(0, np.nan)
        if v.shape != (robot.n,) or not np.all(np.isfinite(v)) or isinstance(value, str):
            raise ConfigurationError(
                f"{name} must be {robot.n} finite joint velocities [rad/s or m/s], got "
                f"{value!r:.80}"
            )
        limit = robot.limits.velocity
        over = np.abs(v) - limit * (1.0 + 1e-12) if velocity_limits else np.zeros(robot.n)
        if np.any(over > 0.0):
            i = int(np.argmax(over))
            raise ConfigurationError(
                f"{name} of joint {robot.joint_names[i]} is {v[i]:.6g} rad/s: beyond its speed "
                f"limit {limit[i]:.6g} rad/s",
                joint=robot.joint_names[i],
            )
        out.append(v if np.any(v != 0.0) else None)
    return out[0], out[1]
