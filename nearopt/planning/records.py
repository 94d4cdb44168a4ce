"""The records of a plan: its iterates and its result (the bottom of the planning package)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..cost import Cost
    from ..path import Path
    from ..robot import Robot
    from ..timing import TimingResult
    from ..trajectory import Trajectory

__all__ = ["Iteration", "PlanResult"]


@dataclass(frozen=True)
class Iteration:
    """One accepted iterate j of the planner (a row of the paper's Table 2).

    Attributes
    ----------
    index
        j; 0 is the straight line.
    J
        Stage 1's optimal cost of the iterate's path on the grid (the discretised J^j).
    alpha
        The step that produced it: α of eq. (22) for ``"paper"``; for ``"quasi-newton"`` the largest
        control-point move [rad]. None for j = 0.
    duration
        t_e of the iterate's optimal timing [s].
    wall_time
        Seconds since the planner started.
    path
        The iterate's path θ^j(s) (from θ0 to θe exactly).
    """

    index: int
    J: float
    alpha: float | None
    duration: float
    wall_time: float
    path: Path


@dataclass(frozen=True)
class PlanResult:
    """A planned motion and how it was found.

    Attributes
    ----------
    robot
        The arm it was planned for (with the limits that were enforced).
    cost
        The running cost f0 that was minimised.
    trajectory
        The motion: θ(t), θ̇(t), θ̈(t), u(t) on [0, duration], from rest at θ0 to rest at θe.
    path
        Its spatial path θ(s).
    J
        ∫ f0 dt of the returned motion (Gauss-Legendre over the exact timing).
    duration
        t_e [s].
    history
        The accepted iterates, the straight line first.
    status
        ``"converged"``, ``"iteration_limit"``, ``"time_limit"`` or ``"stalled"`` (the optimiser
        found no lower J along its direction before its tolerance; the best iterate is returned).
    method
        ``"quasi-newton"`` or ``"paper"``.
    message
        What stopped the iteration, in words.
    evaluations
        Stage-1 solves spent.
    wall_time
        Seconds spent in total.
    initial
        Stage 1 on the straight line (the paper's J^0).
    timing
        Stage 1's report on the returned path.
    """

    robot: Robot
    cost: Cost
    trajectory: Trajectory
    path: Path
    J: float
    duration: float
    history: tuple[Iteration, ...]
    status: str
    method: str
    message: str
    evaluations: int
    wall_time: float
    initial: TimingResult
    timing: TimingResult
