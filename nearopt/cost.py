"""Running costs f0(θ, θ̇, u) of the performance index J = ∫ f0 dt (eq. 4).

The built-in costs are ``1 + Σ w_i u_i²``: time (w = 0), the paper's time + torque² (w_i = β,
eq. 32) and per-joint weights. They are convex in the timing variables, so stage 1 finds their
global optimum. Any other f0 is a :class:`CallableCost` (stage 1 then finds a local optimum).

Every cost is evaluated on N samples at once: θ, θ̇, u of shape (N, n) → f0 of shape (N,), and its
gradients ∂f0/∂θ, ∂f0/∂θ̇, ∂f0/∂u of shape (N, n) (stage 2's eq. 23 needs them).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from .errors import ConfigurationError, NearoptError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

__all__ = ["Cost", "TimeCost", "TorqueCost", "CallableCost", "check_cost"]


@runtime_checkable
class Cost(Protocol):
    """A running cost f0(θ, θ̇, u) ≥ 0 [1/s · s = dimensionless per second of motion]."""

    def __call__(
        self, q: NDArray[np.float64], qd: NDArray[np.float64], u: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """f0 at N samples, shape (N,)."""

    def gradients(
        self, q: NDArray[np.float64], qd: NDArray[np.float64], u: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """(∂f0/∂θ, ∂f0/∂θ̇, ∂f0/∂u) at N samples, each (N, n)."""

    def describe(self) -> str:
        """A short text for tables and JSON output."""


class TorqueCost:
    """f0 = 1 + Σ_i w_i u_i²: time plus weighted squared torques (eq. 32 with w_i = β).

    Parameters
    ----------
    beta
        One weight β for every joint [1/(N·m)²] (the paper's example: 0.03).
    weights
        Per-joint weights w_i ≥ 0 [1/(N·m)²], shape (n,); give ``beta`` or ``weights``, not both.
    """

    def __init__(self, beta: float | None = None, *, weights: ArrayLike | None = None) -> None:
        if (beta is None) == (weights is None):
            raise ConfigurationError("give either beta or weights")
        if beta is not None and np.ndim(beta) != 0:
            raise ConfigurationError(
                f"beta is one number (f0 = 1 + β Σ u²), got {beta!r:.60}; per-joint weights "
                "go by name: TorqueCost(weights=[...])"
            )
        try:
            w = np.atleast_1d(np.asarray(beta if weights is None else weights, dtype=float))
        except (TypeError, ValueError):
            what = "beta" if weights is None else "weights"
            raise ConfigurationError(
                f"{what} must be numbers, got {beta if weights is None else weights!r:.60}"
            ) from None
        if w.ndim != 1 or not np.all(np.isfinite(w)) or np.any(w < 0):
            what = "beta" if weights is None else "weights"
            given = float(w[0]) if weights is None else w.tolist()
            raise ConfigurationError(f"{what} must be finite and ≥ 0, got {given}")
        self._w = w
        self._w.setflags(write=False)
        self.beta = None if beta is None else float(beta)

    def torque_weights(self, n: int) -> NDArray[np.float64]:
        """The weights w_i for an n-joint arm, shape (n,)."""
        if self._w.size == 1:
            return np.full(n, self._w[0])
        if self._w.size != n:
            raise ConfigurationError(f"the cost has {self._w.size} weights for {n} joints")
        return self._w.copy()

    def __call__(
        self, q: NDArray[np.float64], qd: NDArray[np.float64], u: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        return 1.0 + np.sum(self.torque_weights(u.shape[1]) * u**2, axis=1)

    def gradients(
        self, q: NDArray[np.float64], qd: NDArray[np.float64], u: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        zero = np.zeros_like(u)
        return zero, zero.copy(), 2.0 * self.torque_weights(u.shape[1]) * u

    def describe(self) -> str:
        if self.beta is not None:
            return f"time + {self.beta:g}·Σu²"
        return f"time + Σ w_i u_i², w = {self._w.tolist()}"


class TimeCost(TorqueCost):
    """f0 = 1: the duration of the motion (time-optimal planning)."""

    def __init__(self) -> None:
        super().__init__(0.0)

    def describe(self) -> str:
        return "time"


class CallableCost:
    """A user-supplied running cost f0(θ, θ̇, u), with its gradients or finite differences.

    Parameters
    ----------
    f0
        Called with θ, θ̇, u of shape (N, n); returns f0 of shape (N,). It must be positive (a
        motion must cost something per second, or "never arrive" would be optimal).
    gradients
        Optional, called likewise; returns (∂f0/∂θ, ∂f0/∂θ̇, ∂f0/∂u), each (N, n). Without it,
        central finite differences with step ``eps`` × max(1, |x|) are used (2·3n calls of f0).
    name
        Text for tables and outputs.
    eps
        Relative finite-difference step.
    """

    def __init__(
        self,
        f0: Callable[..., ArrayLike],
        gradients: Callable[..., tuple[ArrayLike, ArrayLike, ArrayLike]] | None = None,
        *,
        name: str = "user cost",
        eps: float = 1e-6,
    ) -> None:
        if not callable(f0):
            raise ConfigurationError("f0 must be callable")
        self._f0 = f0
        self._gradients = gradients
        self.name = name
        self.eps = float(eps)

    def __call__(
        self, q: NDArray[np.float64], qd: NDArray[np.float64], u: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        try:
            value = np.asarray(self._f0(q, qd, u), dtype=float).reshape(-1)
        except NearoptError:
            raise
        except Exception as exc:  # the user's code: report it as ours, with its message
            raise NearoptError(
                f"the cost {self.name!r} raised {type(exc).__name__}: {exc}"
            ) from exc
        if value.shape != (q.shape[0],):
            raise NearoptError(
                f"the cost {self.name!r} returned shape {value.shape}, expected ({q.shape[0]},)"
            )
        if not np.all(np.isfinite(value)):
            k = int(np.argmax(~np.isfinite(value)))
            raise NearoptError(
                f"the cost {self.name!r} returned {value[k]} at θ = {q[k].tolist()}, "
                f"θ̇ = {qd[k].tolist()}, u = {u[k].tolist()}"
            )
        if np.any(value <= 0.0):
            k = int(np.argmax(value <= 0.0))
            raise NearoptError(
                f"the cost {self.name!r} returned f0 = {value[k]:g} at θ = {q[k].tolist()}, "
                f"θ̇ = {qd[k].tolist()}, u = {u[k].tolist()}: f0 must be positive (a motion "
                "that costs nothing per second would be best if it never arrived)"
            )
        return value

    def gradients(
        self, q: NDArray[np.float64], qd: NDArray[np.float64], u: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        if self._gradients is not None:
            try:
                grads = tuple(np.asarray(g, dtype=float) for g in self._gradients(q, qd, u))
            except Exception as exc:
                raise NearoptError(
                    f"the gradients of cost {self.name!r} raised {type(exc).__name__}: {exc}"
                ) from exc
            if len(grads) != 3 or any(g.shape != q.shape for g in grads):
                raise NearoptError(
                    f"the gradients of cost {self.name!r} must be three arrays of shape {q.shape}"
                )
            return grads  # type: ignore[return-value]
        args = [q, qd, u]
        out = []
        for j in range(3):
            grad = np.empty_like(q)
            for i in range(q.shape[1]):
                step = self.eps * np.maximum(1.0, np.abs(args[j][:, i]))
                plus = [a.copy() for a in args]
                minus = [a.copy() for a in args]
                plus[j][:, i] += step
                minus[j][:, i] -= step
                grad[:, i] = (self(*plus) - self(*minus)) / (2 * step)
            out.append(grad)
        return out[0], out[1], out[2]

    def describe(self) -> str:
        return self.name


def check_cost(cost: object) -> Cost:
    """``cost`` if it is a nearopt cost, else a ConfigurationError saying what is expected."""
    if isinstance(cost, type):
        raise ConfigurationError(
            f"cost is a nearopt cost object, got the class {cost.__name__}: call it, e.g. "
            "TimeCost() or TorqueCost(0.001)"
        )
    if not isinstance(cost, TorqueCost | CallableCost) and not isinstance(cost, Cost):
        raise ConfigurationError(
            f"cost must be a nearopt cost — TimeCost(), TorqueCost(beta) or CallableCost(f0) "
            f"for a function f0(θ, θ̇, u) — got {type(cost).__name__} {cost!r:.60}"
        )
    return cost
