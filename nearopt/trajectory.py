"""Time trajectories θ(t) of a path timed by stage 1, evaluated like a path.

A timing is the squared path speed b(s) = λ(s)² at knots s_0 = 0 < … < s_N = s_e, linear in s
between knots, i.e. a constant path acceleration s̈ = a_k = (b_{k+1} − b_k) / (2Δs_k) on each
segment (Verscheure et al., 2009). In time this is exact and closed-form: on segment k, with
τ = t − t_k,

    s(τ) = s_k + λ_k τ + ½ a_k τ²,  ṡ(τ) = λ_k + a_k τ,  s̈ = a_k,  Δt_k = 2Δs_k / (λ_k + λ_{k+1}),

so the duration is finite even at rest (λ ∝ √s near s = 0), unlike a λ(s) that starts at 0 linearly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Literal

import numpy as np

from .errors import ConfigurationError
from .validate import check_rate, is_number

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

    from .path import Path

__all__ = [
    "Motion",
    "MotionCost",
    "MotionPart",
    "Trajectory",
    "ChainedTrajectory",
    "Samples",
    "segment_times",
]

InverseDynamics = Callable[
    ["NDArray[np.float64]", "NDArray[np.float64]", "NDArray[np.float64]"], "NDArray[np.float64]"
]


@dataclass(frozen=True)
class Samples:
    """A motion sampled at a controller rate, read-only arrays.

    Attributes
    ----------
    t
        Sample times from 0 to t_e inclusive [s], shape (M,) (the last step may be shorter).
    q, qd, qdd
        θ [rad or m], θ̇ [rad/s or m/s], θ̈ [rad/s² or m/s²] at those times, each (M, n).
    tau
        u by inverse dynamics (eq. 1) [N·m or N], shape (M, n).
    """

    t: NDArray[np.float64]
    q: NDArray[np.float64]
    qd: NDArray[np.float64]
    qdd: NDArray[np.float64]
    tau: NDArray[np.float64]

    def __post_init__(self) -> None:
        for value in (self.t, self.q, self.qd, self.qdd, self.tau):
            value.setflags(write=False)


def segment_times(s: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Δt_k = 2 Δs_k / (λ_k + λ_{k+1}), exact for b = λ² linear in s on each segment, (N,)."""
    lam = np.sqrt(np.asarray(b, dtype=float))
    return 2.0 * np.diff(np.asarray(s, dtype=float)) / (lam[:-1] + lam[1:])


def _times(t: ArrayLike) -> NDArray[np.float64]:
    """Times asked of a motion [s]: numbers, not NaN (a time outside [0, t_e] is clamped)."""
    try:
        times = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        raise ConfigurationError(f"times are numbers of seconds, got {t!r:.60}") from None
    if np.any(np.isnan(times)):
        raise ConfigurationError(f"a time is NaN: {t!r:.60}")
    return times


class Motion:
    """What every timed motion offers on top of :meth:`states`, :attr:`t` (the times where the
    acceleration may jump) and :attr:`duration`: values at times, torques, samples at a rate, its
    phases and integrals. :class:`Trajectory` (one timed path) and :class:`ChainedTrajectory`
    (motions one after another) are motions."""

    t: NDArray[np.float64]
    _inverse_dynamics: InverseDynamics

    @property
    def duration(self) -> float:
        """t_e, the time the motion takes [s]."""
        return float(self.t[-1])

    def states(self, t: ArrayLike) -> tuple[NDArray[np.float64], ...]:  # pragma: no cover
        """θ(t), θ̇(t), θ̈(t) in one pass, each of shape (M, n)."""
        raise NotImplementedError

    def __call__(self, t: ArrayLike, order: Literal[0, 1, 2] = 0) -> NDArray[np.float64]:
        """θ(t) (order 0), θ̇(t) (1) or θ̈(t) (2), shape (M, n); at a knot, the segment after it."""
        if isinstance(order, bool) or order not in (0, 1, 2):
            raise ConfigurationError(f"order must be 0, 1 or 2, got {order!r}")
        return self.states(_times(t))[order]

    def torque(self, t: ArrayLike) -> NDArray[np.float64]:
        """u(t) by inverse dynamics (eq. 1) [N·m or N], shape (M, n)."""
        return self._inverse_dynamics(*self.states(_times(t)))

    def sample(self, rate: float) -> Samples:
        """Samples at ``rate`` [Hz] from 0 to t_e inclusive (the last step shorter).

        Raises
        ------
        ConfigurationError
            If the rate is not a number of Hz in (0, 1e6] (:func:`~nearopt.validate.check_rate`)
            or would give more than 1e8 samples.
        """
        rate = check_rate(rate, "the sampling rate")
        if self.duration * rate > 1e8:
            raise ConfigurationError(
                f"sampling at rate {rate:g} Hz over {self.duration:.4g} s would give more than "
                "1e8 samples"
            )
        count = int(np.floor(self.duration * rate + 1e-9)) + 1
        t = np.arange(count) / rate
        if t[-1] < self.duration:
            t = np.append(t, self.duration)
        q, qd, qdd = self.states(t)
        return Samples(t, q, qd, qdd, self._inverse_dynamics(q, qd, qdd))

    def phases(self, threshold: float = 0.1) -> NDArray[np.float64]:
        """Durations of the motion's constant-acceleration phases [s], in order.

        θ̈ varies smoothly inside every segment of the timing and jumps at its knots by
        θ'·Δs̈. A phase ends where some joint's θ̈ jumps by more than ``threshold`` times that
        joint's largest |θ̈| (a bang-bang switch, a speed limit reached); the small steps between
        neighbouring segments of a smooth profile do not end one. Samples at a rate below
        1 / min(phases) can miss a whole phase: they are then not a faithful record of the motion.
        """
        knots = self.t[1:-1]
        if knots.size == 0:
            return np.array([self.duration])
        after = self.states(knots)[2]
        before = self.states(knots - 1e-12 * max(1.0, self.duration))[2]
        peak = np.maximum(np.max(np.abs(after), axis=0), np.max(np.abs(before), axis=0))
        switch = np.any(np.abs(after - before) > threshold * peak, axis=1)
        return np.diff(np.concatenate([[0.0], knots[switch], [self.duration]]))

    def until(self, t: float) -> MotionPart:
        """The motion's first ``t`` seconds [s], 0 < t ≤ t_e: where a plan was interrupted (the
        arm then moves on with θ(t), θ̇(t); re-plan from them with ``plan(…, qd0=θ̇(t))``)."""
        return MotionPart(self, t)

    def faithful_rate(self, threshold: float = 0.1) -> float:
        """The sampling rate [Hz] below which samples can miss a phase: 1 / the shortest phase."""
        return float(1.0 / np.min(self.phases(threshold)))

    def integrate(self, f0: Callable[..., NDArray[np.float64]], tolerance: float = 1e-10) -> float:
        """∫ f0(θ, θ̇, u) dt over the motion, by adaptive Gauss-Kronrod quadrature.

        Every segment of the timing (where the motion is smooth) gets a 7/15-point Gauss-Kronrod
        rule; intervals whose two estimates differ by more than their share of ``tolerance`` × |J|
        are halved, up to 10 times, and no more once halving them no longer halves their
        difference (rounding: a 33 µs so100 motion, its torques from accelerations of 1e5
        rad/s², differed by 2e3 times the share at every level, and took 3·10⁶ evaluations).

        Parameters
        ----------
        f0
            A cost: called with θ, θ̇, u of shape (M, n), returns shape (M,).
        tolerance
            Relative accuracy asked of the integral.
        """
        lo, hi = self.t[:-1], self.t[1:]
        total, before = 0.0, np.inf  # (the differences of the intervals halved last)
        for level in range(11):
            half = 0.5 * (hi - lo)
            # the right-continuous evaluation picks the segment each node lies in (nodes are
            # interior to the intervals, which lie within segments)
            t = ((lo + hi)[:, None] * 0.5 + half[:, None] * _KRONROD_X[None, :]).ravel()
            q, qd, qdd = self.states(t)
            f = np.asarray(f0(q, qd, self._inverse_dynamics(q, qd, qdd))).reshape(lo.size, -1)
            kronrod = half * (f @ _KRONROD_W)
            error = np.abs(kronrod - half * (f @ _GAUSS_W))
            scale = abs(total + np.sum(kronrod))
            bad = error > tolerance * max(scale, 1e-300) / max(1, lo.size)
            total += float(np.sum(kronrod[~bad]))
            stalled = float(np.sum(error)) > 0.5 * before  # rounding, not the rule's error
            if not np.any(bad) or level == 10 or stalled:
                return total + float(np.sum(kronrod[bad]))
            before = float(np.sum(error[bad]))
            mid = 0.5 * (lo[bad] + hi[bad])
            lo, hi = np.concatenate([lo[bad], mid]), np.concatenate([mid, hi[bad]])
        return total


class MotionCost:
    """J and t_e of a timing's result (a record with a ``trajectory`` and the ``cost`` it
    minimised): ∫ f0 dt along the motion and its duration."""

    trajectory: Motion
    cost: Callable[..., NDArray[np.float64]]

    @cached_property
    def J(self) -> float:  # noqa: N802 - the paper's name
        """∫ f0 dt of the motion [s·(unit of f0)], by adaptive Gauss-Kronrod quadrature."""
        return self.trajectory.integrate(self.cost)

    @property
    def duration(self) -> float:
        """t_e [s]."""
        return self.trajectory.duration


class Trajectory(Motion):
    """A path θ(s) followed with the speed profile b(s) = λ(s)², as a function of time.

    Parameters
    ----------
    path
        The spatial path θ(s).
    s
        Knots s_0 = 0 < … < s_N = s_e [unit of s], shape (N+1,).
    b
        λ² at the knots [(unit of s / s)²], ≥ 0, shape (N+1,); b > 0 at interior knots.
    inverse_dynamics
        u(θ, θ̇, θ̈) for arrays of shape (M, n) (e.g. ``Robot.inverse_dynamics_batch``).
    """

    def __init__(
        self,
        path: Path,
        s: ArrayLike,
        b: ArrayLike,
        inverse_dynamics: InverseDynamics,
    ) -> None:
        s = np.asarray(s, dtype=float)
        b = np.asarray(b, dtype=float)
        if s.ndim != 1 or s.shape != b.shape or s.size < 2 or np.any(np.diff(s) <= 0):
            raise ConfigurationError("knots s must increase strictly and match b in shape")
        if np.any(b < 0) or not np.all(np.isfinite(b)) or np.any(b[1:-1] <= 0):
            raise ConfigurationError("b must be finite, ≥ 0, and > 0 at interior knots")
        self.path = path
        self.s = s
        self.b = b
        self.lam = np.sqrt(b)
        self.a = np.diff(b) / (2.0 * np.diff(s))
        self.t = np.concatenate([[0.0], np.cumsum(segment_times(s, b))])
        self._inverse_dynamics = inverse_dynamics
        for arr in (self.s, self.b, self.lam, self.a, self.t):
            arr.setflags(write=False)

    @property
    def dof(self) -> int:
        """Number of joints n."""
        return self.path.dof

    def path_parameter(self, t: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """s(t), ṡ(t) = λ, s̈(t) at the given times (clipped to [0, t_e]), each of shape (M,)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        k = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.s.size - 2)
        tau = t - self.t[k]
        acc = self.a[k]
        s = np.minimum(self.s[k] + self.lam[k] * tau + 0.5 * acc * tau**2, self.s[-1])
        sd = np.maximum(self.lam[k] + acc * tau, 0.0)
        return s, sd, acc

    def time_at(self, s: ArrayLike) -> NDArray[np.float64]:
        """t(s): when the motion reaches path parameters s ∈ [0, s_e] [s], shape (M,) (the
        inverse of :meth:`path_parameter`, exact on each segment)."""
        s = np.clip(np.atleast_1d(np.asarray(s, dtype=float)), 0.0, self.s[-1])
        k = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, self.s.size - 2)
        ds = s - self.s[k]
        lam, acc = self.lam[k], self.a[k]
        # s_k + λ τ + ½ a τ² = s: τ = 2 Δs / (λ + √(λ² + 2 a Δs)) (stable for a → 0 and λ = 0)
        root = np.sqrt(np.maximum(lam**2 + 2.0 * acc * ds, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = np.where(ds > 0.0, 2.0 * ds / (lam + root), 0.0)
        return self.t[k] + tau

    def states(self, t: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """θ(t), θ̇(t), θ̈(t) in one pass, each of shape (M, n)."""
        s, sd, sdd = self.path_parameter(t)
        d1 = self.path(s, 1)
        qdd = self.path(s, 2) * (sd**2)[:, None] + d1 * sdd[:, None]
        return self.path(s, 0), d1 * sd[:, None], qdd


class ChainedTrajectory(Motion):
    """Motions one after another: the whole motion of a task whose targets the arm stops at
    (:func:`~nearopt.plan_task`), or a plan cut short and the plan that took over from its moving
    state (``ChainedTrajectory([first.until(t), replanned])``).

    Parameters
    ----------
    parts
        The motions in order; each starts where the previous one ends (at rest, or moving on).
    joined
        Check that each part starts where the previous one ends (False: pieces drawn side by
        side, e.g. the first paths of a task's segments, which need not join where a goal
        configuration moved along its pose).

    Attributes
    ----------
    parts
        The motions.
    starts
        When each part starts [s], shape (len(parts),) (the first at 0).
    t
        The times where the acceleration may jump: every part's knot times [s].
    """

    def __init__(self, parts: tuple[Motion, ...] | list[Motion], joined: bool = True) -> None:
        parts = tuple(parts)
        if not parts:
            raise ConfigurationError("a chained trajectory needs at least one motion")
        for before, after in zip(parts, parts[1:] if joined else (), strict=False):
            qa, qb = before(before.duration, 0)[0], after(0.0, 0)[0]
            if not np.allclose(qa, qb, rtol=0.0, atol=1e-9):
                raise ConfigurationError(
                    "each motion of a chained trajectory starts where the previous one ends "
                    f"(a jump of {np.max(np.abs(qa - qb)):.3g} rad)"
                )
        self.parts = parts
        self._dof = int(parts[0](0.0, 0).shape[1])
        durations = np.array([p.duration for p in parts])
        self.starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        self.t = np.unique(
            np.concatenate([p.t + t0 for p, t0 in zip(parts, self.starts, strict=True)])
        )
        self._inverse_dynamics = parts[0]._inverse_dynamics
        for arr in (self.starts, self.t):
            arr.setflags(write=False)

    @property
    def dof(self) -> int:
        """Number of joints n."""
        return self._dof

    def part_at(self, t: ArrayLike) -> NDArray[np.intp]:
        """The index of the part each time lies in (a boundary: the part that starts there),
        shape (M,)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        return np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, len(self.parts) - 1)

    def states(self, t: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """θ(t), θ̇(t), θ̈(t) in one pass, each of shape (M, n)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        k = self.part_at(t)
        out = tuple(np.empty((t.size, self.dof)) for _ in range(3))
        for index in np.unique(k):
            mask = k == index
            for array, value in zip(
                out, self.parts[index].states(t[mask] - self.starts[index]), strict=True
            ):
                array[mask] = value
        return out

    def jerk(self, t: ArrayLike) -> NDArray[np.float64]:
        """θ⃛(t) of the parts that have one (jerk-limited timings), inf in the others (θ̈ jumps
        at their knots), shape (M, n)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        k = self.part_at(t)
        out = np.full((t.size, self.dof), np.inf)
        for index in np.unique(k):
            part, mask = self.parts[index], k == index
            if hasattr(part, "jerk"):
                out[mask] = part.jerk(t[mask] - self.starts[index])
        return out


class MotionPart(Motion):
    """The first ``end`` seconds of a motion (:meth:`Motion.until`): it ends at θ(end), θ̇(end),
    moving unless ``end`` = t_e.

    Raises
    ------
    ConfigurationError
        If ``end`` is not a time in (0, t_e] [s].
    """

    def __init__(self, motion: Motion, end: float) -> None:
        if not is_number(end) or not 0.0 < float(end) <= motion.duration:
            raise ConfigurationError(
                f"a motion of {motion.duration:.6g} s is cut at a time in (0, "
                f"{motion.duration:.6g}] s, got {end!r:.40}"
            )
        end = float(end)
        self.motion = motion
        self.t = np.append(motion.t[motion.t < end], end)
        self.t.setflags(write=False)
        self._inverse_dynamics = motion._inverse_dynamics

    def states(self, t: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """θ(t), θ̇(t), θ̈(t) of the motion for t in [0, end], each of shape (M, n)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        return self.motion.states(t)

    def jerk(self, t: ArrayLike) -> NDArray[np.float64]:
        """θ⃛(t) of the motion if it has one (a jerk-limited timing), inf otherwise (θ̈ jumps
        at its knots), shape (M, n)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        jerk = getattr(self.motion, "jerk", None)
        if jerk is None:
            return np.full((t.size, self.states(t[:1])[0].shape[1]), np.inf)
        return jerk(t)


# Gauss-Kronrod 7/15 on [-1, 1] (QUADPACK's qk15): Kronrod nodes and weights, and the weights of
# the 7-point Gauss rule on its nodes (every second Kronrod node)
_X = np.array(
    [
        0.991455371120812639206854697526329,
        0.949107912342758524526189684047851,
        0.864864423359769072789712788640926,
        0.741531185599394439863864773280788,
        0.586087235467691130294144845693013,
        0.405845151377397166906606412076961,
        0.207784955007898467600689403773245,
        0.0,
    ]
)
_WK = np.array(
    [
        0.022935322010529224963732008058970,
        0.063092092629978553290700663189204,
        0.104790010322250183839876322541518,
        0.140653259715525918745189590510238,
        0.169004726639267902826583426598550,
        0.190350578064785409913256402421014,
        0.204432940075298892414161999234649,
        0.209482141084727828012999174891714,
    ]
)
_WG = np.array(
    [
        0.0,
        0.129484966168869693270611432679082,
        0.0,
        0.279705391489276667901467771423780,
        0.0,
        0.381830050505118944950369775488975,
        0.0,
        0.417959183673469387755102040816327,
    ]
)
_KRONROD_X = np.concatenate([-_X[:-1], _X[::-1]])
_KRONROD_W = np.concatenate([_WK[:-1], _WK[::-1]])
_GAUSS_W = np.concatenate([_WG[:-1], _WG[::-1]])
