"""The discretised stage-1 problem: every constraint row and sample, built once.

Notation: knots σ_0 = 0 < … < σ_N = 1, b_k = λ(σ_k)², segment k = [σ_k, σ_{k+1}] with the constant
path acceleration a_k = (b_{k+1} − b_k) / (2Δσ_k). Samples r = 0 … 2N−1: sample r < N is the start
of segment r (knot r), sample r ≥ N the end of segment r − N (knot r − N + 1); ``node[r]`` and
``seg[r]`` say which. The free variables are z = (b_1 … b_{N−1}); b_0 and b_N are fixed
(``problem.b_ends``: 0 at rest).

:class:`Discretisation` turns a :class:`~nearopt.timing.TimingProblem` into rows

    lower ≤ A b + d·√b_node + offset ≤ upper,

in blocks (:class:`RowBlocks`):

* torque: u_{r,i} = m_i a_seg + c_i b_node + d_i √b_node + g_i at every sample and joint
  (joint-major: row i·2N + r), within the effort limits minus the margins;
* acceleration: θ̈_{r,i} = θ'_i a_seg + θ''_i b_node, likewise, for joints with a limit;
* speed: b_k θ'_i(σ_k)² ≤ v_i² at every free knot, one row per joint that moves and has a limit;
* interior speed: ((1 − w) b_k + w b_{k+1}) θ'_i(σ_p)² ≤ v_i² at points inside segments, where the
  knots' own rows do not imply it (for the solver only on a problem without points between the
  samples; stage 2's model keeps them);
* between the samples (blocks ``torque_between``, ``acceleration_between``, ``speed_between``):
  for torques and accelerations, the bound of :class:`~nearopt.timing.BetweenSamples` on every
  interval between the points of ``problem.interior`` (b = (1 − w) b_k + w b_{k+1} and a = a_k
  there, so the values and their second differences are rows of the segment's two knots): the
  sums q_i ± κ_l/8 ± Δκ/8 of :func:`~nearopt.timing._kernels.envelope_rows`, for the joints with
  a limit, on the sides that the segment's samples do not imply (most are: each segment's
  polygon of (b_k, b_{k+1}) is clipped in 2-D); for a damped quantity, its values at those points
  instead (the damping's √b at the nearer knot, exact in the first and the last segment, where
  one knot is at rest), and always its values at the points next to the rest ends. For the joint
  speeds, one row per point b(w) ≤ min_i v_i² B_i (the tangent lines of
  :func:`~nearopt.timing.between.speed_lines` below v_i² / θ'_i², with the bound at the knots
  folded into ``z_cap``): b and the bound are linear between two points, so they hold for all σ,
  whatever the number of joints. So one solve holds the limits between the samples too.

Every row couples at most two neighbouring knots (those of its segment): it is held in *pair form*,
``coef_left · b_left + coef_right · b_{left+1} + sqrt_coef · √b_sqrt_node + offset``, from which
the sparse matrix A is derived. The banded interior-point kernel (:mod:`nearopt.timing.interior`)
reads the pair form; the SOCP and NLP back ends read these rows (:meth:`Discretisation.solver_rows`,
the same rows with the redundant speed rows of a fixed path left out), and so do the stage-1
sensitivity and stage 2 (which differentiate each row with respect to the path).
"""

from __future__ import annotations

from functools import cached_property
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.sparse as sp

from ..trajectory import segment_times
from .problem import SPEED_SAFETY, safe_limits

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..cost import Cost
    from ..robot import PathCoefficients
    from .problem import PathQuantity, TimingProblem

__all__ = ["Discretisation", "RowBlocks", "LinearRows"]

# rows between the samples of one joint that differ by less than MERGE (relative to their size)
# are merged into one that implies both (the optimum is at most that much slower); those that cut
# into the polygon the others leave by less than TOUCH are left out (the motion may exceed their
# bound by that much, which the check after the solve takes back by a uniform slow-down)
MERGE = 1e-7
TOUCH = 1e-7


class RowBlocks(NamedTuple):
    """Where each kind of row lies in :attr:`Discretisation.matrix` (slices of the rows)."""

    torque: slice
    acceleration: slice
    speed: slice
    interior_speed: slice
    torque_between: slice = slice(0, 0)
    acceleration_between: slice = slice(0, 0)
    speed_between: slice = slice(0, 0)


class LinearRows(NamedTuple):
    """Rows linear in z: ``lower ≤ matrix @ z ≤ upper`` (±inf where a side is open)."""

    matrix: sp.csr_matrix
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]


class Discretisation:
    """Every constraint row of stage 1 and the discretised cost, as functions of z.

    Attributes
    ----------
    problem
        The problem the rows come from.
    node, seg
        Knot and segment of every sample, shape (2N,).
    ds
        Δσ_k, shape (N,).
    left, coef_left, coef_right
        The pair form of every row: the first knot of the row's segment (the knot itself for a
        speed row at a knot) and the coefficients of b at it and at the next knot, shape (R,).
    matrix
        A: coefficients of b at every knot, sparse (R, N+1), built from the pair form.
    sqrt_coef, sqrt_node
        d and the knot of √b in every row, shape (R,) (d = 0 but in damped torque rows).
    offset, lower, upper
        The rows' constants and limits, shape (R,), margins and the safety margin applied.
    blocks
        The row ranges of each kind.
    joint
        The joint of every row, shape (R,).
    location
        Where every row lies: the sample r (torque, acceleration), the knot k (speed), the
        interior point p (interior speed) or the segment k (the rows between the samples),
        shape (R,).
    position
        For the rows between the samples, w ∈ [0, 1] of the point in its segment whose value
        the row bounds (NaN for the other rows), shape (R,).
    z_upper
        Upper bounds on z from ``problem.b_upper`` (inf where none), shape (N−1,).
    z_cap
        ``z_upper`` and the knots' speed rows as bounds on z, shape (N−1,).
    has_damping
        Whether any row has a √b term.
    """

    def __init__(self, problem: TimingProblem) -> None:
        p = problem
        big_n = p.segments
        self.problem = p
        self.ds = np.diff(p.sigma)
        self.node = np.concatenate([np.arange(big_n), np.arange(1, big_n + 1)])
        self.seg = np.concatenate([np.arange(big_n), np.arange(big_n)])
        parts = [self._samples(p.torque, keep_all=True)]
        parts.append(self._samples(p.acceleration) if p.acceleration is not None else None)
        parts += [self._speed_at_knots(), self._speed_inside()]
        sizes = [0 if part is None else part[0].size for part in parts]
        stacks = [part for part in parts if part is not None]
        ends = np.cumsum([0, *sizes])
        self.blocks = RowBlocks(
            *(slice(int(a), int(b)) for a, b in zip(ends[:-1], ends[1:], strict=True))
        )
        (
            self.left,
            self.coef_left,
            self.coef_right,
            self.sqrt_coef,
            self.offset,
            self.lower,
            self.upper,
            self.joint,
            self.location,
        ) = (np.concatenate([s[k] for s in stacks]) for k in range(9))
        self.sqrt_node = np.zeros(self.offset.size, dtype=int)
        torque_rows = self.blocks.torque
        self.sqrt_node[torque_rows] = self.node[self.location[torque_rows]]
        b_upper = np.full(big_n + 1, np.inf) if p.b_upper is None else p.b_upper
        self.z_upper = np.asarray(b_upper[1:-1], dtype=float)
        self._reduce()
        self._add_inside()
        self.has_damping = bool(np.any(self.sqrt_coef != 0.0))

    @classmethod
    def of(cls, problem: TimingProblem) -> Discretisation:
        """The rows of ``problem``: those built last, if they were built for this very problem
        (stage 2 builds its model on the rows stage 1 timed the iterate with; the rows are
        never changed once built), else new ones."""
        last = _LAST[0]
        if last is not None and last.problem is problem:
            return last
        rows = cls(problem)
        _LAST[0] = rows
        return rows

    @cached_property
    def matrix(self) -> sp.csr_matrix:
        """A, the coefficients of b at every knot, sparse (R, N+1)."""
        rows = np.arange(self.left.size)
        return sp.coo_matrix(
            (
                np.concatenate([self.coef_left, self.coef_right]),
                (np.concatenate([rows, rows]), np.concatenate([self.left, self.left + 1])),
            ),
            shape=(self.left.size, self.problem.segments + 1),
        ).tocsr()

    @cached_property
    def _free(self) -> sp.csc_matrix:
        return self.matrix[:, 1:-1].tocsc()

    def _reduce(self) -> None:
        """For a fixed path the speed rows of different joints at one place are proportional:
        turn those at the knots into bounds on z, and inside segments keep the tightest row of
        each point unless the knots' bounds imply it (b inside is a convex combination), or
        none if the problem has its points between the samples (``speed_between`` holds the
        speeds everywhere)."""
        knots = self.blocks.speed
        cap = self.z_upper.copy()
        with np.errstate(divide="ignore"):
            if knots.stop > knots.start:
                col = self.left[knots] - 1  # one coefficient per row: the knot's own b
                np.minimum.at(cap, col, self.upper[knots] / self.coef_left[knots])
            self.z_cap = cap
            inside = np.arange(self.blocks.interior_speed.start, self.blocks.interior_speed.stop)
            keep = np.ones(inside.size, dtype=bool)
            if self.problem.interior is not None:  # the rows between the samples imply them
                keep[:] = False
            elif inside.size:
                scale = np.abs(self.coef_left[inside]) + np.abs(self.coef_right[inside])  # θ'_i²
                bound = self.upper[inside] / scale
                order = np.lexsort((bound, self.location[inside]))
                first = np.r_[True, np.diff(self.location[inside][order]) != 0]
                keep = np.zeros(inside.size, dtype=bool)
                keep[order[first]] = True
                k = self.problem.interior_speed.segment[self.location[inside]]
                ends = self.problem.with_ends(cap)
                keep &= bound < np.maximum(ends[k], ends[k + 1])
        self.solver_index = np.concatenate([np.arange(self.blocks.speed.start), inside[keep]])

    def _add_inside(self) -> None:
        """Append the rows between the samples (the ``*_between`` blocks) that the samples
        leave open."""
        p = self.problem
        inside = p.interior
        end = self.offset.size
        self.position = np.full(end, np.nan)
        starts = [end]
        if inside is not None:
            speed = self._speed_between()  # first: it tightens the caps of the knots
            # the samples' undamped rows, by segment: the polygon each segment's samples allow
            sample_rows = np.arange(self.blocks.acceleration.stop)
            sample_rows = sample_rows[self.sqrt_coef[sample_rows] == 0.0]
            sample_rows = sample_rows[np.argsort(self.left[sample_rows], kind="stable")]
            seg_rows = np.searchsorted(self.left[sample_rows], np.arange(p.segments + 1))
            polygon = (
                seg_rows,
                self.coef_left[sample_rows],
                self.coef_right[sample_rows],
                self.offset[sample_rows],
                self.lower[sample_rows],
                self.upper[sample_rows],
                p.with_ends(self.z_cap),
            )
            blocks = [
                lambda: self._between(p.torque, inside.torque, polygon),
                lambda: (
                    []
                    if p.acceleration is None
                    else self._between(p.acceleration, inside.acceleration, polygon)
                ),
                lambda: speed,
            ]
            for block in blocks:
                for part in block():
                    self._append(part)
                starts.append(self.offset.size)
        else:
            starts += [end] * 3
        self.blocks = self.blocks._replace(
            torque_between=slice(starts[0], starts[1]),
            acceleration_between=slice(starts[1], starts[2]),
            speed_between=slice(starts[2], starts[3]),
        )
        self.solver_index = np.concatenate([self.solver_index, np.arange(end, self.offset.size)])

    _FIELDS = (
        "left",
        "coef_left",
        "coef_right",
        "sqrt_coef",
        "sqrt_node",
        "offset",
        "lower",
        "upper",
        "joint",
        "location",
        "position",
    )

    def _append(self, rows: tuple) -> None:
        for name, new in zip(self._FIELDS, rows, strict=True):
            setattr(self, name, np.concatenate([getattr(self, name), new]))

    def _between(
        self, quantity: PathQuantity, coef: PathCoefficients, polygon: tuple
    ) -> list[tuple]:
        """A quantity's rows between the samples: the envelope rows of :func:`envelope_rows`
        on the evenly spaced points if it is undamped, else its value at those points (the
        damping's √b at the nearer knot); its value at the points next to the rest ends."""
        from ._kernels import envelope_rows, needed_inside

        p = self.problem
        inside = p.interior
        big_n, points = p.segments, inside.points
        even = big_n * points
        limited = np.flatnonzero(np.isfinite(quantity.lower) | np.isfinite(quantity.upper))
        if limited.size == 0:
            return []
        lower, upper = safe_limits(quantity)
        out = []
        damped = bool(np.any(quantity.coef.d != 0.0) or np.any(coef.d != 0.0))
        if not damped:
            # pair coefficients at the P + 2 points of every segment, (N, P + 2, J)
            two_ds = (2.0 * self.ds)[:, None, None]
            w = np.concatenate([[0.0], inside.weight[:points], [1.0]])[None, :, None]
            m = self._along(quantity.coef.m, coef.m[:even], limited)
            c = self._along(quantity.coef.c, coef.c[:even], limited)
            g = self._along(quantity.coef.g, coef.g[:even], limited)
            pcl = c * (1.0 - w) - m / two_ds
            pcr = c * w + m / two_ds
            seg, point, joint, cl, cr, off, lo, up = envelope_rows(
                *polygon,
                np.ascontiguousarray(pcl),
                np.ascontiguousarray(pcr),
                np.ascontiguousarray(g),
                lower[limited],
                upper[limited],
                1e-9,
                TOUCH,
                MERGE,
            )
            zero = np.zeros(seg.size)
            out.append(
                (
                    seg,
                    cl,
                    cr,
                    zero,
                    seg.copy(),
                    off,
                    lo,
                    up,
                    limited[joint],
                    seg.copy(),
                    w.ravel()[point],
                )
            )
            chosen = np.arange(even, inside.segment.size)  # the points next to the rest ends
        else:
            chosen = np.arange(inside.segment.size)
        rows = self._inside(quantity, coef, limited, chosen)
        order = np.argsort(rows[0], kind="stable")  # by segment
        rows = tuple(x[order] for x in rows)
        left, cl, cr, sd, sn, off, lo, up = rows[:8]
        need_up, need_lo = needed_inside(
            *polygon,
            np.searchsorted(left, np.arange(big_n + 1)),
            cl,
            cr,
            off,
            sd,
            (sn == left + 1).astype(float),
            lo,
            up,
            1e-9,
        )
        need_up &= np.isfinite(up)
        need_lo &= np.isfinite(lo)
        keep = need_up | need_lo
        rows = (*rows[:6], np.where(need_lo, lo, -np.inf), np.where(need_up, up, np.inf), *rows[8:])
        out.append(tuple(x[keep] for x in rows))
        return out

    def _speed_between(self) -> list[tuple]:
        """Rows that keep every joint speed within its limit for all σ: b ≤ v_i² B at the points
        of ``problem.interior`` by the lines of :func:`~nearopt.timing.between.speed_lines`
        (b and the bound are both linear between two points, so it holds in between), as rows
        b(w) c ≤ v_j² (c = v_j² / bound, j the joint that sets it) where the knots' caps do not
        imply them; at the knots, caps on z (``z_cap`` tightened)."""
        from .between import speed_envelope, speed_lines

        p = self.problem
        inside = p.interior
        limited = np.flatnonzero(np.isfinite(p.velocity))
        if limited.size == 0:
            return []
        big_n, points = p.segments, inside.points
        fixed = (p.b_ends[0] > 0.0, p.b_ends[1] > 0.0)
        starts, ends = speed_lines(
            *speed_envelope(self._along(p.dtheta, inside.dtheta[: big_n * points], limited), fixed),
            fixed,
        )
        v2 = p.velocity[limited] ** 2 * (1.0 - 2.0 * SPEED_SAFETY)
        # every point's bound: the smallest over the joints and the two intervals meeting there
        pad = np.full((big_n, 1, limited.size), np.inf)
        both = np.concatenate(
            [np.concatenate([v2 * starts, pad], axis=1), np.concatenate([pad, v2 * ends], axis=1)],
            axis=2,
        )
        pick = np.argmin(both, axis=2)  # (N, P + 2)
        bound = np.take_along_axis(both, pick[:, :, None], axis=2)[:, :, 0]
        joint = pick % limited.size
        knot_bound = np.full(big_n + 1, np.inf)
        np.minimum.at(knot_bound, np.arange(big_n), bound[:, 0])
        np.minimum.at(knot_bound, np.arange(1, big_n + 1), bound[:, -1])
        self.z_cap = np.minimum(self.z_cap, knot_bound[1:-1])
        cap = p.with_ends(self.z_cap)
        w = np.arange(1, points + 1) / (points + 1)
        inner = bound[:, 1:-1]
        keep = inner < (1.0 - w) * cap[:-1, None] + w * cap[1:, None]
        seg, point = np.nonzero(keep)
        limit = v2[joint[:, 1:-1][keep]]
        scale = limit / inner[keep]
        count = seg.size
        return [
            (
                seg,
                (1.0 - w[point]) * scale,
                w[point] * scale,
                np.zeros(count),
                seg.copy(),
                np.zeros(count),
                np.full(count, -np.inf),
                limit,
                limited[joint[:, 1:-1][keep]],
                seg.copy(),
                w[point],
            )
        ]

    def _along(
        self, at_knots: NDArray[np.float64], inside: NDArray[np.float64], joints: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """Values at the start, the evenly spaced points and the end of every segment, for the
        given joints, (N, P + 2, J)."""
        big_n = self.problem.segments
        inner = inside[:, joints].reshape(big_n, -1, joints.size)
        return np.concatenate(
            [at_knots[:-1, None][:, :, joints], inner, at_knots[1:, None][:, :, joints]], axis=1
        )

    def _inside(
        self,
        quantity: PathQuantity,
        coef: PathCoefficients,
        limited: NDArray[np.int64],
        chosen: NDArray[np.int64],
    ) -> tuple:
        """A quantity's rows at the interior points ``chosen``, for the joints ``limited``:
        the fields of :attr:`_FIELDS` (location: the segment; position: the point's w)."""
        p = self.problem
        inside = p.interior
        big_n = p.segments
        k, w = inside.segment[chosen], inside.weight[chosen]
        lower, upper = safe_limits(quantity)
        # the segment's margin (that of its samples): where tighten() found the motion leaving
        # a limit between the samples, the points inside the segment are held within it too
        margin = np.zeros((k.size, limited.size))
        if quantity.margin is not None:  # capped as at the samples: b = 0 stays inside
            g = coef.g[chosen][:, limited]
            room = np.minimum(upper[limited] - g, g - lower[limited])
            margin = np.maximum(quantity.margin[k], quantity.margin[big_n + k])[:, limited]
            margin = np.minimum(margin, np.maximum(0.9 * room, 0.0))
        slope = coef.m[chosen][:, limited] / (2.0 * self.ds[k])[:, None]
        curv = coef.c[chosen][:, limited]
        # √b at a point: exact in an end segment whose end is at rest, else at the nearer knot
        first = (k == 0) & (p.b_ends[0] == 0.0)
        last = (k == big_n - 1) & (p.b_ends[1] == 0.0)
        node = np.where(first, 1, np.where(last, big_n - 1, np.where(w < 0.5, k, k + 1)))
        root = np.where(first, np.sqrt(w), np.where(last, np.sqrt(1.0 - w), 1.0))
        count = k.size
        joints = limited.size
        return (
            np.tile(k, joints),
            (curv * (1.0 - w)[:, None] - slope).T.ravel(),
            (curv * w[:, None] + slope).T.ravel(),
            (coef.d[chosen][:, limited] * root[:, None]).T.ravel(),
            np.tile(node, joints),
            coef.g[chosen][:, limited].T.ravel(),
            (lower[limited][None, :] + margin).T.ravel(),
            (upper[limited][None, :] - margin).T.ravel(),
            np.repeat(limited, count),
            np.tile(k, joints),
            np.tile(w, joints),
        )

    # ---------------------------------------------------------------- building the rows
    def _samples(self, quantity: PathQuantity, keep_all: bool = False) -> tuple | None:
        """Rows q_{r,i} = m a_seg + c b_node + d √b_node + g within the limits, joint-major."""
        p, node, seg = self.problem, self.node, self.seg
        big_n, n = p.segments, p.dof
        coef = quantity.coef
        limited = np.isfinite(quantity.lower) | np.isfinite(quantity.upper)
        joints = [i for i in range(n) if keep_all or limited[i]]
        if not joints:
            return None
        margin = np.zeros((2 * big_n, n)) if quantity.margin is None else quantity.margin
        lower, upper = safe_limits(quantity)
        rows = np.arange(2 * big_n)
        joints = np.array(joints)
        slope = coef.m[node][:, joints] / (2.0 * self.ds[seg])[:, None]  # (2N, J)
        at_left = (node == seg)[:, None]
        curv = coef.c[node][:, joints]
        return (
            np.tile(seg, joints.size),
            np.where(at_left, curv - slope, -slope).T.ravel(),
            np.where(at_left, slope, slope + curv).T.ravel(),
            coef.d[node][:, joints].T.ravel(),
            coef.g[node][:, joints].T.ravel(),
            (lower[joints][:, None] + margin[:, joints].T).ravel(),
            (upper[joints][:, None] - margin[:, joints].T).ravel(),
            np.repeat(joints, 2 * big_n),
            np.tile(rows, joints.size),
        )

    def _speed_rows(
        self,
        left: NDArray[np.int64],
        weights: tuple[NDArray[np.float64], NDArray[np.float64]],
        dtheta: NDArray[np.float64],
        keep: NDArray[np.bool_],
    ) -> tuple | None:
        """Rows (w_l b_left + w_r b_{left+1}) θ'_i² ≤ v_i² at points with slopes ``dtheta`` (P, n),
        for every joint with a limit (also where θ'_i = 0: the rows are the same for every
        path)."""
        p = self.problem
        v = p.velocity
        point, joint = np.nonzero(keep & np.isfinite(v)[None, :])
        if point.size == 0:
            return None
        count = point.size
        slope2 = dtheta[point, joint] ** 2
        upper = v[joint] ** 2 * (1.0 - 2.0 * SPEED_SAFETY)
        zero = np.zeros(count)
        return (
            left[point],
            weights[0][point] * slope2,
            weights[1][point] * slope2,
            zero,
            zero.copy(),
            np.full(count, -np.inf),
            upper,
            joint,
            point,
        )

    def _speed_at_knots(self) -> tuple | None:
        p = self.problem
        knots = np.arange(p.segments + 1)
        keep = np.zeros(p.dtheta.shape, dtype=bool)
        keep[1:-1] = True  # b_0 and b_N are fixed (the caller checks their speeds)
        ones = np.ones(knots.size)
        return self._speed_rows(knots, (ones, 0.0 * ones), p.dtheta, keep)

    def _speed_inside(self) -> tuple | None:
        p = self.problem
        inside = p.interior_speed
        if inside is None:
            return None
        keep = np.ones(inside.dtheta.shape, dtype=bool)
        return self._speed_rows(
            inside.segment, (1.0 - inside.weight, inside.weight), inside.dtheta, keep
        )

    # ---------------------------------------------------------------- evaluating
    def b(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """b at every knot from the free ones, shape (N+1,)."""
        return self.problem.with_ends(z)

    def values(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """Every row's value A b + d √b + offset, shape (R,)."""
        b = self.b(z)
        return (
            self.coef_left * b[self.left]
            + self.coef_right * b[self.left + 1]
            + self.sqrt_coef * np.sqrt(b)[self.sqrt_node]
            + self.offset
        )

    def excess(self, z: NDArray[np.float64]) -> float:
        """The largest violation of any row (≤ 0 when z is feasible), in the rows' units."""
        value = self.values(z)
        return float(max(np.max(value - self.upper), np.max(self.lower - value)))

    def relative_excess(self, z: NDArray[np.float64]) -> float:
        """The largest violation of any row relative to its range (or bound, one-sided rows)."""
        value = self.values(z)
        span = np.where(np.isfinite(self.lower), self.upper - self.lower, np.abs(self.upper))
        excess = np.maximum(value - self.upper, self.lower - value) / np.maximum(span, 1e-300)
        return float(np.max(excess))

    def torque(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """All torque samples, joint-major (row i·2N + r), shape (n·2N,)."""
        return self.values(z)[self.blocks.torque] if self.blocks.torque.stop else np.zeros(0)

    def torque_cost(self, z: NDArray[np.float64], weights: NDArray[np.float64]) -> float:
        """The discretised J of f0 = 1 + Σ w_i u_i² (the value of :meth:`objective` for a
        :class:`~nearopt.TorqueCost` with these weights), without its gradient."""
        p = self.problem
        b = self.b(z)
        lam = np.sqrt(b)
        dt = segment_times(p.sigma, b)
        rows = self.blocks.torque
        u = (
            self.coef_left[rows] * b[self.left[rows]]
            + self.coef_right[rows] * b[self.left[rows] + 1]
            + self.sqrt_coef[rows] * lam[self.sqrt_node[rows]]
            + self.offset[rows]
        ).reshape(p.dof, 2 * p.segments)
        energy = weights @ u**2  # Σ_i w_i u_i² at every sample
        return float(np.sum(dt * (1.0 + 0.5 * (energy[: p.segments] + energy[p.segments :]))))

    def linear_rows(self, z_lin: NDArray[np.float64] | None) -> LinearRows:
        """The rows as ``lower ≤ M z ≤ upper``, the damping d√b replaced by its tangent at
        ``z_lin`` (exact there), or dropped when ``z_lin`` is None."""
        matrix, const = self._free, self.offset + self._ends_terms()
        if self.has_damping and z_lin is not None:
            jac, value = self._sqrt_tangent(z_lin)
            matrix = (matrix + jac).tocsc()
            const = const + value - jac @ z_lin
        return LinearRows(matrix.tocsr(), self.lower - const, self.upper - const)

    def _ends_terms(self) -> NDArray[np.float64]:
        """Every row's terms in the fixed b_0 and b_N (0 at rest): A's first and last columns
        times them (the damping's d√b there is among :meth:`_sqrt_tangent`'s values)."""
        p = self.problem
        if p.at_rest:
            return np.zeros(self.offset.size)
        ends = self.matrix[:, [0, -1]] @ np.asarray(p.b_ends, dtype=float)
        return np.asarray(ends).ravel()

    def solver_rows(
        self, z_lin: NDArray[np.float64] | None
    ) -> tuple[LinearRows, NDArray[np.float64]]:
        """:meth:`linear_rows` reduced for a solver of this fixed path: the torque and
        acceleration rows, the tightest speed row at each point inside a segment, and upper
        bounds on z (from the knots' speed rows and ``problem.b_upper``)."""
        rows = self.linear_rows(z_lin)
        keep = self.solver_index
        return LinearRows(rows.matrix[keep], rows.lower[keep], rows.upper[keep]), self.z_cap

    def jacobian(self, z: NDArray[np.float64]) -> sp.csr_matrix:
        """∂(rows)/∂z at z, sparse (R, N−1)."""
        if not self.has_damping:
            return self._free.tocsr()
        return (self._free + self._sqrt_tangent(z)[0]).tocsr()

    def _sqrt_tangent(self, z: NDArray[np.float64]) -> tuple[sp.csr_matrix, NDArray[np.float64]]:
        """∂(d √b_node)/∂z and d √b_node for every row."""
        big_n = self.problem.segments
        col = self.sqrt_node - 1
        free = (col >= 0) & (col < big_n - 1) & (self.sqrt_coef != 0.0)
        root = np.sqrt(self.b(z))[self.sqrt_node]
        vals = np.zeros(col.size)
        vals[free] = 0.5 * self.sqrt_coef[free] / np.sqrt(z[col[free]])
        jac = sp.csr_matrix(
            (vals[free], (np.flatnonzero(free), col[free])), shape=(col.size, big_n - 1)
        )
        return jac, self.sqrt_coef * root

    def segment_times(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """Δt_k of every segment [s], shape (N,)."""
        return segment_times(self.problem.sigma, self.b(z))

    def objective(self, z: NDArray[np.float64], cost: Cost) -> tuple[float, NDArray[np.float64]]:
        """The discretised J = Σ Δt_k ½ [f0(k⁺) + f0((k+1)⁻)] and its gradient with respect to z."""
        p = self.problem
        n, big_n = p.dof, p.segments
        b = self.b(z)
        lam = np.sqrt(b)
        dt = segment_times(p.sigma, b)
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
        torque = self.matrix[self.blocks.torque]
        grad += np.asarray(torque.T @ du.T.ravel()).ravel()
        # through λ = √b of the sample's knot: θ̇ = λθ' and the damping torque dλ
        damp = self.sqrt_coef[self.blocks.torque].reshape(n, 2 * big_n).T
        node_term = weight * np.sum(df_dqd * p.dtheta[self.node], axis=1) + np.sum(
            du * damp, axis=1
        )
        np.add.at(grad, self.node, node_term * inv2lam[self.node])
        return value, grad[1:-1]


_LAST: list[Discretisation | None] = [None]  # the rows built last (Discretisation.of)
