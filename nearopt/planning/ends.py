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

from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from ..errors import ConfigurationError
from ..path import BSplinePath
from ..validate import real_array

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..robot import Robot
    from ..timing import Discretisation
    from .linearisation import PathBasis

__all__ = [
    "EndTerms",
    "MovingEnds",
    "check_at_limits",
    "braking_distance",
    "check_velocities",
    "check_velocity",
    "end_terms",
    "leaving_along",
    "stopping_short",
    "turned_onto",
]


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
    robot: Robot,
    path: BSplinePath,
    ends: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None],
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
    legs: Sequence[tuple[float, float]],
    velocity_limits: bool = True,
) -> list[BSplinePath]:
    """The straight line ``path`` (a B-spline θ0 → θe) with the boundary velocities ``ends``
    (qd0, qde), once for each of ``legs``: it leaves θ0 along qd0 for a distance D — its first
    interior control point on that ray at D/2, the second near D — then runs straight (control
    points at their Greville abscissae) to θe, or to the point E before θe where it turns onto
    the ray against qde. Each of ``legs`` is a (D, E) [rad], each no more than the position
    ``bounds`` (lower, upper) leave room for (convex hull: the whole path stays within them).

    The second control point sets the path's curvature at the end (:func:`_turning`): the arm
    moving at qd0 needs torques H θ̈ + h + g + D θ̇ within its limits, and along a path θ̈ = θ'' b
    + θ' ṡ̈ has only ṡ̈ free. The curvature is the least whose θ̈ ⊥ θ' leaves the torques a
    margin in their limits and slows no joint at its speed limit down too late (θ̈ along θ' is
    stage 1's choice): a moving arm that Coriolis forces would carry out of its torque limits on
    a straight leg turns the way they push it; one at a speed limit turns so that joint slows.
    That θ̈ depends on the end's state and direction only: it is found once for all the legs.
    ``velocity_limits``: whether the speed limits are held.

    Raises
    ------
    ConfigurationError
        Where a velocity points out of the position limits at its end (no path can leave or
        arrive that way), naming the joint.
    """
    count = path.control_points.shape[0]
    moving = []  # (end, qd, its step inwards, the room along it, θ̈ there)
    for qd, end in zip(ends, (0, count - 1), strict=True):
        if qd is None:
            continue
        at = path.control_points[end]
        step = qd / np.linalg.norm(qd) * (1.0 if end == 0 else -1.0)  # from the end inwards
        room = _room(at, step, bounds, robot.joint_names, qd, end == 0)
        qdd = _end_acceleration(robot, at, qd, qd, end == 0, velocity_limits)
        moving.append((end, qd, step, room, qdd))
    return [_with_legs(path, moving, leg, bounds) for leg in legs]


def _with_legs(
    path: BSplinePath,
    moving: list[tuple],
    legs: tuple[float, float],
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
) -> BSplinePath:
    """One path of :func:`leaving_along`, with the end legs ``legs`` (D, E) [rad]."""
    lower, upper = bounds
    points = path.control_points.copy()
    count = points.shape[0]
    breaks = path.knots[4:-4] if count > 4 else None
    s = BSplinePath.greville(count, breaks)
    anchors = {0: points[0], count - 1: points[-1]}
    for end, qd, step, room, qdd in moving:
        inner = 2 if end == 0 else count - 3
        reach = legs[0 if end == 0 else 1]
        # the first control point (the direction) on the ray within the room the position
        # bounds leave along it; the second the whole leg out, each joint within its bounds: a
        # joint moving slowly towards a limit close by turns back alone (a panda joint 9e-5 rad
        # from its limit cut every leg to 0.037 rad, and the whole arm, moving at its speed
        # limits, could not turn that sharply)
        points[inner] = np.clip(points[end] + reach * step, lower, upper)
        points[(1 if end == 0 else count - 2)] = points[end] + min(0.5 * reach, room) * step
        turn = _turning(BSplinePath(points, breaks), qd, end == 0, qdd)
        size = float(np.linalg.norm(turn))  # a bend sharper than the leg is long: the leg's
        if size > reach:  # (a slow end's curvature costs little; its θ̈ ⊥ θ' / b is noise)
            turn = turn * (reach / size)
        anchors[inner] = np.clip(points[inner] + turn, lower, upper)
    first = 2 if any(m[0] == 0 for m in moving) else 0
    last = count - 3 if any(m[0] == count - 1 for m in moving) else count - 1
    a, b = anchors[first], anchors[last]
    for j in range(first, last + 1):
        points[j] = a + (b - a) * (s[j] - s[first]) / (s[last] - s[first])
    return BSplinePath(points, breaks)


def turned_onto(
    robot: Robot,
    path: BSplinePath,
    ends: tuple[NDArray[np.float64] | None, NDArray[np.float64] | None],
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
    share: float = 1.0,
) -> BSplinePath:
    """``path`` with its first (last) interior control point moved onto the ray along qd0
    (against qde) from its end, ``share`` of its distance from the end out or 16 braking
    distances (the longer, but no farther than it was, nor than the position ``bounds`` leave
    room for: the convex hull keeps the path within them): a path from rest that leaves θ0
    along qd0 (arrives along qde), for a nearly resting end whose direction hardly matters; a
    small share changes the path least. ConfigurationError where a velocity points out of the
    bounds at its end."""
    points = path.control_points.copy()
    for qd, end, inner, sign in ((ends[0], 0, 1, 1.0), (ends[1], -1, -2, -1.0)):
        if qd is None or not np.any(qd):
            continue
        step = sign * qd / np.linalg.norm(qd)  # from the end inwards
        room = _room(points[end], step, bounds, robot.joint_names, qd, end == 0)
        leg = float(np.linalg.norm(points[inner] - points[end]))
        brake = braking_distance(robot, points[end], qd, end == 0)
        leg = min(leg, max(16.0 * brake, share * leg), room)
        points[inner] = points[end] + leg * step
    return BSplinePath(points, path.knots[4:-4] if points.shape[0] > 4 else None)


def braking_distance(
    robot: Robot, q: NDArray[np.float64], qd: NDArray[np.float64] | None, start: bool
) -> float:
    """How far along qd the arm at (q, qd) travels while braking to rest as hard as its torque
    limits allow at that state (at the end: while speeding up to qd) [rad]: |qd|²/(2a), a the
    largest acceleration against (along) qd whose torque H θ̈ + h + g + D θ̇ is within the
    limits; inf where there is none, 0 at rest. An estimate of the leg a moving end needs."""
    if qd is None:
        return 0.0
    unit = qd / np.linalg.norm(qd) * (-1.0 if start else 1.0)  # the direction of θ̈
    push = robot.mass_matrix(q) @ unit
    bias = robot.inverse_dynamics(q, qd, np.zeros(robot.n))
    lo, hi = robot.limits.effort_lower, robot.limits.effort_upper
    with np.errstate(divide="ignore", invalid="ignore"):
        most = np.where(
            push > 0.0, (hi - bias) / push, np.where(push < 0.0, (lo - bias) / push, np.inf)
        )
    a = float(np.min(most))
    return float(qd @ qd) / (2.0 * a) if a > 0.0 else np.inf


def stopping_short(
    robot: Robot,
    q: NDArray[np.float64],
    qd: NDArray[np.float64] | None,
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
    start: bool,
) -> str | None:
    """Why no timing can start at (q, qd) — the first joint that moves toward a position bound
    faster than it can stop within the room left, braking as hard as the torque limits allow
    any one joint at that state (at the end: the first that arrives from a bound faster than it
    could have sped up within the room); None where each can. The bound is the state's: over a
    room of a few mrad it hardly changes, over a long one it is an estimate (it is asked only
    where no path could be timed)."""
    if qd is None:
        return None
    lower, upper = bounds
    sign = np.sign(qd) * (1.0 if start else -1.0)  # toward the bound the joint must not pass
    room = np.where(sign > 0.0, upper - q, np.where(sign < 0.0, q - lower, np.inf))
    inverse = np.linalg.inv(robot.mass_matrix(q))
    bias = robot.inverse_dynamics(q, qd, np.zeros(robot.n))
    lo, hi = robot.limits.effort_lower, robot.limits.effort_upper
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    # the state's velocity terms (Coriolis, centrifugal, damping) as a share of the torque
    # limits: where they are large, the braking they leave at the state says little about the
    # braking later, as the arm slows (a two-link arm at 34 rad/s: 0.28 rad/s² there, while its
    # own plan stopped it in 0.08 s)
    still = robot.inverse_dynamics(q, np.zeros(robot.n), np.zeros(robot.n))
    with np.errstate(divide="ignore", invalid="ignore"):
        share = float(np.max(np.where(half > 0.0, np.abs(bias - still) / half, 0.0)))
    for i in np.flatnonzero(np.isfinite(room) & (sign != 0.0)):
        # the largest θ̈_i away from that bound over the torque box (at the end, in time forward:
        # the acceleration that built the speed up)
        most = -sign[i] * (inverse[i] @ (mid - bias)) + np.abs(inverse[i]) @ half
        need = qd[i] ** 2 / (2.0 * most) if most > 0.0 else np.inf
        if need > room[i]:
            word = "qd0" if start else "qde"
            side = "upper" if (sign[i] > 0.0) else "lower"
            limit = upper[i] if sign[i] > 0.0 else lower[i]
            act = "stop" if start else "have sped up"
            brake = "braking" if start else "speeding up"
            head = (
                f"{word} of joint {robot.joint_names[i]} is {qd[i]:.6g} rad/s, "
                f"{room[i]:.3g} rad from its {side} position limit {limit:.6g} rad"
            )
            if share > VELOCITY_TERMS:
                return (
                    f"no path nearopt tries from that state could be timed; {head}, and "
                    f"{brake} as hard as the torque limits allow at that state "
                    f"({max(most, 0.0):.4g} rad/s²) would take {need:.3g} rad — an estimate "
                    f"only: that state's velocity terms are {share:.0%} of the torque limits "
                    "and change as the arm slows"
                )
            return (
                f"{head}: it cannot {act} within that room ({brake} as hard as the torque "
                f"limits allow there, {max(most, 0.0):.4g} rad/s², takes {need:.3g} rad)"
            )
    return None


VELOCITY_TERMS = 0.1
"""The share of the torque limits above which a state's velocity terms make the braking it
leaves an estimate, not a bound (:func:`stopping_short`)."""


def _room(
    at: NDArray[np.float64],
    step: NDArray[np.float64],
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
    names: list[str] | tuple[str, ...],
    qd: NDArray[np.float64],
    start: bool,
) -> float:
    """How far from ``at`` along ``step`` the position bounds leave room [rad]; a
    ConfigurationError naming the joint where there is none."""
    lower, upper = bounds
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(
            step > 0.0,
            (upper - at) / step,
            np.where(step < 0.0, (lower - at) / step, np.inf),
        )
    if np.min(room) <= 0.0:
        i = int(np.argmin(room))
        word, where = ("qd0", "leave q0 out of") if start else ("qde", "reach qe from beyond")
        raise ConfigurationError(
            f"{word} of joint {names[i]} is {qd[i]:.6g} rad/s at {at[i]:.6g} rad: it would "
            f"{where} its position limits [{lower[i]:.6g}, {upper[i]:.6g}] rad",
            joint=names[i],
        )
    return float(np.min(room))


def _turning(
    path: BSplinePath,
    qd: NDArray[np.float64],
    start: bool,
    qdd: NDArray[np.float64] | None,
) -> NDArray[np.float64]:
    """The shift of the second control point from the end (along a straight end leg) that gives
    the path at that end the curvature of :func:`leaving_along` [rad]: θ'' ⊥ θ' = θ̈ ⊥ θ' / b of
    the acceleration ``qdd`` of :func:`_end_acceleration` (None: the straight leg, no shift;
    stage 1 then says where it fails)."""
    if qdd is None:
        return np.zeros_like(qd)
    s = 0.0 if start else path.s_end
    tangent, curvature = (path(np.array([s]), k)[0] for k in (1, 2))
    b = float(qd @ tangent / (tangent @ tangent)) ** 2
    unit = tangent / np.linalg.norm(tangent)
    across = (qdd - (qdd @ unit) * unit) / b  # θ'' ⊥ θ' [rad per unit of s²]
    # θ''(end) is affine in the second control point, with the same factor for every joint
    moved = path.control_points.copy()
    moved[2 if start else -3] += 1.0
    factor = float((BSplinePath(moved, path.knots[4:-4])(np.array([s]), 2)[0] - curvature)[0])
    return across / factor


def _end_acceleration(
    robot: Robot,
    q: NDArray[np.float64],
    qd: NDArray[np.float64],
    tangent: NDArray[np.float64],
    start: bool,
    velocity_limits: bool,
) -> NDArray[np.float64] | None:
    """The acceleration θ̈ [rad/s²] at the state (q, qd) of a path leaving (``start``) or
    reaching q along ``tangent``: the least θ̈ ⊥ θ' whose torque H θ̈ + h + g + D θ̇ keeps a
    margin of 25 % (else 10 %, else none) of each torque range, that keeps any acceleration
    limit with the same margin, and that does not speed up (at the end: slow down towards the
    end) a joint at 99 % or more of its speed limit. A small quadratic programme (Clarabel);
    None without a solution."""
    import clarabel

    n = qd.size
    unit = tangent / np.linalg.norm(tangent)
    across = np.eye(n) - np.outer(unit, unit)
    mass, bias = robot.mass_matrix(q), robot.inverse_dynamics(q, qd, np.zeros(n))
    lim = robot.limits
    lo, hi = lim.effort_lower, lim.effort_upper
    speed = lim.velocity if velocity_limits else np.full(n, np.inf)
    fast = np.flatnonzero(np.abs(qd) >= 0.99 * speed)
    sign = np.sign(qd[fast]) * (1.0 if start else -1.0)  # s_i θ̈_i ≤ 0 (≥ 0 at the end)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    for share in (0.25, 0.1, 0.0):
        margin = share * (hi - lo)
        rows = [mass, -mass, np.eye(n), -np.eye(n), np.eye(n)[fast] * sign[:, None]]
        rhs = [
            hi - margin - bias,
            bias - lo - margin,
            (1.0 - 2.0 * share) * lim.acceleration,
            (1.0 - 2.0 * share) * lim.acceleration,
            np.zeros(fast.size),
        ]
        a, r = np.vstack(rows), np.concatenate(rhs)
        keep = np.isfinite(r)
        solver = clarabel.DefaultSolver(
            sp.csc_matrix(np.triu(2.0 * across)),
            np.zeros(n),
            sp.csc_matrix(a[keep]),
            r[keep],
            [clarabel.NonnegativeConeT(int(keep.sum()))],
            settings,
        )
        sol = solver.solve()
        if sol.status == clarabel.SolverStatus.Solved:
            return np.asarray(sol.x)
    return None


def check_velocities(
    robot: Robot, qd0: object, qde: object, velocity_limits: bool
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    """(qd0, qde) of a plan's arguments as joint vectors (:func:`check_velocity`), None where at
    rest (None, or no joint faster than :data:`REST_SPEED`)."""
    out: list[NDArray[np.float64] | None] = []
    for name, value in (("qd0", qd0), ("qde", qde)):
        v = None if value is None else check_velocity(robot, value, name, velocity_limits)
        out.append(v if v is not None and np.max(np.abs(v)) > REST_SPEED else None)
    return out[0], out[1]


def check_velocity(
    robot: Robot, value: object, name: str, velocity_limits: bool, degrees: bool = False
) -> NDArray[np.float64]:
    """A joint velocity [rad/s or m/s] as a vector of the robot's length; ConfigurationError
    for a wrong shape, a value that is not a finite real number, or one beyond the joint's speed
    limit (where those are enforced), naming ``name`` and the joint (in deg/s with ``degrees``:
    a request given in them)."""
    v = real_array(value)
    if v is None or v.shape != (robot.n,):
        got = repr(value)[:80] if v is None else f"{v.size} value{'s' if v.size != 1 else ''}"
        raise ConfigurationError(
            f"{name} must be {robot.n} joint velocities [rad/s or m/s] (one per joint of "
            f"{robot.name}: {', '.join(robot.joint_names)}), got {got}"
        )
    if not np.all(np.isfinite(v)):
        i = int(np.argmax(~np.isfinite(v)))
        raise ConfigurationError(
            f"{name} of joint {robot.joint_names[i]!r} is {v[i]}", joint=robot.joint_names[i]
        )
    limit = robot.limits.velocity
    over = np.abs(v) - limit * (1.0 + 1e-12) if velocity_limits else np.zeros(robot.n)
    if np.any(over > 0.0):
        i = int(np.argmax(over))
        unit, given, most = ("rad/s", v[i], limit[i])
        if robot.prismatic[i]:
            unit = "m/s"
        elif degrees:
            unit, given, most = ("deg/s", *np.rad2deg([v[i], limit[i]]))
        raise ConfigurationError(
            f"{name} of joint {robot.joint_names[i]!r} is {given:.6g} {unit}, beyond its speed "
            f"limit {most:.6g} {unit}",
            joint=robot.joint_names[i],
        )
    return v


def check_at_limits(
    robot: Robot,
    q: NDArray[np.float64],
    qd: NDArray[np.float64] | None,
    word: str,
    side: int = 0,
) -> None:
    """A velocity ``qd`` at the configuration ``q`` does not move a joint that sits on a
    position limit through it: ``side`` −1 where the motion starts there (qd must not point
    out), +1 where it ends there (qd must not arrive from beyond), 0 where it passes (a joint
    on a limit must be still). ConfigurationError naming the joint."""
    if qd is None:
        return
    lim = robot.limits
    out = np.where(q >= lim.position_upper, qd, 0.0) - np.where(q <= lim.position_lower, qd, 0.0)
    bad = out > 0.0 if side < 0 else out < 0.0 if side > 0 else out != 0.0
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        what = {-1: "it would leave them", 1: "it would arrive from beyond them"}.get(
            side, "a joint on a limit cannot pass through it (0 there)"
        )
        raise ConfigurationError(
            f"{word} of joint {robot.joint_names[i]} is {qd[i]:.6g} rad/s at {q[i]:.6g} rad, on "
            f"its position limits [{lim.position_lower[i]:.6g}, {lim.position_upper[i]:.6g}] "
            f"rad: {what}",
            joint=robot.joint_names[i],
        )


REST_SPEED = 1e-7
"""[rad/s or m/s] A boundary velocity no larger in any joint is planned as rest, and recorded so
(the plan's qd0 or qde is None). It is below what a joint encoder resolves, its direction —
which a moving end's path must follow — means nothing, and stage 1 with b_0 or b_N below ~1e-15
was measured to crawl (ur5: J 4.7 at 1e-8 rad/s and 9.2 at 3e-9 against 0.966 at rest and at
3e-8, a hook at the end timed at a speed that small)."""
