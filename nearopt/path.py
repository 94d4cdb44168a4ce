"""Spatial paths θ(s) (Section 3): a joint-space curve and its s-derivatives, without timing.

A path is evaluated like TOPP-RA's: ``path(s, order)`` returns θ(s), θ'(s) or θ''(s) for an array of
path parameters s ∈ [0, s_end]. The time needed to follow a path does not depend on how s is scaled
(the paper uses the tip's arc length; nearopt's own paths use s ∈ [0, 1]).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

import numpy as np
from scipy.interpolate import BSpline, CubicSpline

from .errors import ConfigurationError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

__all__ = ["Path", "StraightPath", "SplinePath", "BSplinePath"]

Order = Literal[0, 1, 2]


@runtime_checkable
class Path(Protocol):
    """A joint path θ(s), s ∈ [0, s_end]."""

    @property
    def s_end(self) -> float:
        """Length s_e of the path parameter's range [unit of s]."""

    @property
    def dof(self) -> int:
        """Number of joints n."""

    @property
    def breakpoints(self) -> NDArray[np.float64]:
        """Interior s where the path is not smooth (a spline's knots, where θ'' has a kink or a
        jump) [unit of s], shape (B,); empty for a smooth path. Stage 1 puts a grid knot on each,
        so that the torque is smooth inside every segment. Optional: a path without this
        attribute is taken as smooth."""

    def __call__(self, s: ArrayLike, order: Order = 0) -> NDArray[np.float64]:
        """θ(s) (order 0), θ'(s) (1) or θ''(s) (2) at the given s, shape (len(s), n)."""


def _as_joint_vector(x: ArrayLike, what: str) -> NDArray[np.float64]:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ConfigurationError(
            f"{what} must be a joint vector of numbers, got {x!r:.60}"
        ) from None
    if a.ndim != 1 or a.size == 0:
        raise ConfigurationError(f"{what} must be a 1-D joint vector, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        i = int(np.argmax(~np.isfinite(a)))
        raise ConfigurationError(f"{what}[{i}] is {a[i]}")
    return a


class StraightPath:
    """The straight joint-space line of eqs. (28)-(29): θ(s) = θ0 + (θe − θ0) s / s_e.

    Parameters
    ----------
    theta0, thetae
        Start and end configurations θ0, θe [rad or m], shape (n,).
    s_end
        Length of the parameter range s_e (default 1) [unit of s].
    """

    def __init__(self, theta0: ArrayLike, thetae: ArrayLike, s_end: float = 1.0) -> None:
        self.theta0 = _as_joint_vector(theta0, "theta0")
        self.thetae = _as_joint_vector(thetae, "thetae")
        if self.theta0.shape != self.thetae.shape:
            raise ConfigurationError(
                f"theta0 has {self.theta0.size} joints but thetae has {self.thetae.size}"
            )
        if not (np.isfinite(s_end) and s_end > 0):
            raise ConfigurationError(f"s_end must be a positive number, got {s_end}")
        self._s_end = float(s_end)

    @property
    def s_end(self) -> float:
        return self._s_end

    @property
    def dof(self) -> int:
        return self.theta0.size

    @property
    def breakpoints(self) -> NDArray[np.float64]:
        return np.zeros(0)

    def __call__(self, s: ArrayLike, order: Order = 0) -> NDArray[np.float64]:
        s = np.atleast_1d(np.asarray(s, dtype=float))[:, None]
        slope = (self.thetae - self.theta0) / self._s_end
        if order == 0:
            return self.theta0 + slope * s
        if order == 1:
            return np.repeat(slope[None], s.shape[0], axis=0)
        if order == 2:
            return np.zeros((s.shape[0], self.dof))
        raise ValueError(f"order must be 0, 1 or 2, got {order}")


class SplinePath:
    """A C² cubic spline through joint samples, θ(s_k) = θ_k.

    Parameters
    ----------
    s
        Strictly increasing path parameters, starting at 0, shape (K,), K ≥ 2.
    theta
        Joint samples [rad or m], shape (K, n).
    dtheta_ends
        Optional (θ'(0), θ'(s_e)), each (n,), to clamp the end slopes; otherwise not-a-knot.
    """

    def __init__(
        self,
        s: ArrayLike,
        theta: ArrayLike,
        dtheta_ends: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> None:
        s = np.asarray(s, dtype=float)
        theta = np.asarray(theta, dtype=float)
        if s.ndim != 1 or s.size < 2 or s[0] != 0.0 or np.any(np.diff(s) <= 0):
            raise ConfigurationError("s must be strictly increasing from 0, with ≥ 2 samples")
        if theta.ndim != 2 or theta.shape[0] != s.size or not np.all(np.isfinite(theta)):
            raise ConfigurationError(
                f"theta must be finite with shape ({s.size}, n), got {theta.shape}"
            )
        bc: object = "not-a-knot" if s.size > 3 else "natural"
        if dtheta_ends is not None:
            bc = ((1, np.asarray(dtheta_ends[0], float)), (1, np.asarray(dtheta_ends[1], float)))
        self._spline = CubicSpline(s, theta, axis=0, bc_type=bc)
        self._s_end = float(s[-1])
        self._breaks = s[1:-1].copy()
        self._breaks.setflags(write=False)

    @property
    def s_end(self) -> float:
        return self._s_end

    @property
    def dof(self) -> int:
        return int(self._spline.c.shape[-1])

    @property
    def breakpoints(self) -> NDArray[np.float64]:
        return self._breaks

    def __call__(self, s: ArrayLike, order: Order = 0) -> NDArray[np.float64]:
        s = np.atleast_1d(np.asarray(s, dtype=float))
        return np.asarray(self._spline(s, nu=order))


class BSplinePath:
    """A clamped cubic B-spline θ(s) = Σ_j B_j(s) c_j on s ∈ [0, 1].

    The path stage 2 optimises: θ(0) = c_0 and θ(1) = c_last exactly, and by the convex-hull
    property θ(s) stays within any box that holds every control point (how joint position limits
    are kept). Control points placed on a line at the Greville abscissae give that line exactly.

    Parameters
    ----------
    control_points
        c_0 … c_{K+1} [rad or m], shape (K + 2, n), K ≥ 2 interior points.
    breaks
        The K − 2 interior knots, strictly increasing in (0, 1); default: uniform.
    """

    degree = 3

    def __init__(self, control_points: ArrayLike, breaks: ArrayLike | None = None) -> None:
        c = np.array(control_points, dtype=float)
        if c.ndim != 2 or c.shape[0] < 4 or not np.all(np.isfinite(c)):
            raise ConfigurationError(
                f"control_points must be finite with shape (K + 2, n), K ≥ 2; got {c.shape}"
            )
        c.flags.writeable = False
        self.control_points = c
        self.knots = self.knot_vector(c.shape[0], breaks)
        self.knots.setflags(write=False)
        self._spline = BSpline(self.knots, c, self.degree)

    @classmethod
    def knot_vector(cls, count: int, breaks: ArrayLike | None = None) -> NDArray[np.float64]:
        """The clamped knot vector for ``count`` control points and the given interior knots
        (default: uniform), shape (count + 4,)."""
        k = cls.degree
        if breaks is None:
            inner = np.linspace(0.0, 1.0, count - k + 1)[1:-1]
        else:
            inner = np.asarray(breaks, dtype=float).ravel()
            if (
                inner.size != count - k - 1
                or np.any(np.diff(inner) <= 0)
                or np.any(inner <= 0.0)
                or np.any(inner >= 1.0)
            ):
                raise ConfigurationError(
                    f"breaks must be {count - k - 1} increasing values in (0, 1) for {count} "
                    f"control points, got {inner.tolist()}"
                )
        return np.concatenate([np.zeros(k + 1), inner, np.ones(k + 1)])

    @classmethod
    def line(
        cls, theta0: ArrayLike, thetae: ArrayLike, interior: int, breaks: ArrayLike | None = None
    ) -> BSplinePath:
        """The straight line of eqs. (28)-(29) with ``interior`` free control points."""
        a = _as_joint_vector(theta0, "theta0")
        e = _as_joint_vector(thetae, "thetae")
        return cls(a + np.outer(cls.greville(interior + 2, breaks), e - a), breaks)

    @classmethod
    def greville(cls, count: int, breaks: ArrayLike | None = None) -> NDArray[np.float64]:
        """Greville abscissae (knot averages) of the ``count`` basis functions."""
        t = cls.knot_vector(count, breaks)
        return np.array([t[j + 1 : j + cls.degree + 1].mean() for j in range(count)])

    def refined(self) -> BSplinePath:
        """The same curve with a knot inserted in the middle of every other span, the first
        included (Boehm's knot insertion, SciPy's ``BSpline.insert_knot``): about 1.5 times the
        control points, every derivative unchanged."""
        spans = np.unique(self.knots)
        middles = 0.5 * (spans[:-1] + spans[1:])[::2]
        spline = self._spline
        for x in middles:
            spline = spline.insert_knot(float(x))
        return BSplinePath(spline.c, spline.t[self.degree + 1 : -(self.degree + 1)])

    def basis(self, s: ArrayLike, order: Order = 0) -> NDArray[np.float64]:
        """∂θ^(order)(s) / ∂c_j, the basis functions' values, shape (len(s), K + 2)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        count = self.control_points.shape[0]
        return np.asarray(BSpline(self.knots, np.eye(count), self.degree)(s, nu=order))

    @property
    def s_end(self) -> float:
        return 1.0

    @property
    def dof(self) -> int:
        return self.control_points.shape[1]

    @property
    def breakpoints(self) -> NDArray[np.float64]:
        return np.unique(self.knots[(self.knots > 0.0) & (self.knots < 1.0)])

    def __call__(self, s: ArrayLike, order: Order = 0) -> NDArray[np.float64]:
        s = np.atleast_1d(np.asarray(s, dtype=float))
        return np.asarray(self._spline(s, nu=order))
