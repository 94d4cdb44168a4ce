"""The paper's example (Section 7) as data: the two-link arm of eq. (31) with the parameters of
Table 1, the motion θ0 → θe, the cost of eq. (32), the iterations of Table 2 and the best optimum
known for it. The tests, the benchmarks and the main job (``scripts/01_paper_example.py``) take
the example from here.

The closed form :func:`eq31` is written with ``sin`` and ``cos`` passed in, so that the same
expressions serve NumPy (tests against Pinocchio) and CasADi symbols (the IPOPT references).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .cost import TorqueCost

THETA_0 = np.deg2rad([45.0, -90.0])
"""The start θ0 [rad] (Table 1: 45°, −90°), at rest."""
THETA_E = np.deg2rad([-90.0, 0.0])
"""The goal θe [rad] (Table 1: −90°, 0°), at rest."""
BETA = 0.03
"""β of eq. (32) [1/(N·m)²]."""
COST = TorqueCost(BETA)
"""f0 = 1 + β (u1² + u2²), eq. (32)."""


@dataclass(frozen=True)
class ArmParameters:
    """The two-link arm of Table 1: two equal uniform links, θ from the upward vertical.

    Attributes
    ----------
    inertia
        I, each link's moment of inertia about its centre of mass [kg·m²].
    mass
        m, each link's mass [kg].
    half_length
        l, half a link's length (its centre of mass from its joint) [m].
    gravity
        g [m/s²].
    torque_limits
        |u_i| ≤ u_max,i [N·m].
    """

    inertia: float
    mass: float
    half_length: float
    gravity: float
    torque_limits: tuple[float, float]


TABLE_1 = ArmParameters(
    inertia=4.167e-3, mass=1.0, half_length=0.1, gravity=9.81, torque_limits=(10.0, 5.0)
)


@dataclass(frozen=True)
class PaperIteration:
    """One row of Table 2: iteration j, its cost J^j and the step α that led to it."""

    index: int
    J: float
    alpha: float | None


TABLE_2 = (
    PaperIteration(0, 0.95859, None),
    PaperIteration(1, 0.72659, 0.30),
    PaperIteration(2, 0.58449, 0.38),
    PaperIteration(3, 0.58954, 0.01),
    PaperIteration(4, 0.58710, 0.01),
    PaperIteration(5, 0.58204, 0.01),
    PaperIteration(6, 0.57766, 0.01),
)
"""Table 2: J^j and α for j = 0 … 6 (the paper stops at J = 0.57766)."""

BEST_KNOWN_J = 0.55146
"""The best known optimum of the example: a direct transcription of eq. (31) (RK4 multiple
shooting, K = 200 intervals) solved by IPOPT, ``scripts/bench_planner.py``."""
BEST_KNOWN_DURATION = 0.3421
"""Its final time te [s]."""


def eq31(
    q: Any, qd: Any, *, sin: Callable[[Any], Any] = np.sin, cos: Callable[[Any], Any] = np.cos
) -> tuple[tuple[tuple[Any, Any], tuple[Any, Any]], tuple[Any, Any], tuple[Any, Any]]:
    """H(θ), h(θ, θ̇) and g(θ) of eq. (31) with :data:`TABLE_1`'s parameters, so that
    H θ̈ + h + g = u, without friction.

    Parameters
    ----------
    q, qd
        θ [rad] and θ̇ [rad/s], indexable by 0 and 1 (NumPy arrays or CasADi symbols).
    sin, cos
        The functions to use (``np.sin``/``np.cos`` or ``casadi.sin``/``casadi.cos``).

    Returns
    -------
    tuple
        ``((H11, H12), (H12, H22))`` [kg·m²], ``(h1, h2)`` and ``(g1, g2)`` [N·m].
    """
    inertia, mass, half = TABLE_1.inertia, TABLE_1.mass, TABLE_1.half_length
    ml2, mgl = mass * half**2, mass * TABLE_1.gravity * half
    c2, s2 = cos(q[1]), sin(q[1])
    h12 = inertia + ml2 * (1 + 2 * c2)
    mass_matrix = ((2 * inertia + 2 * ml2 * (3 + 2 * c2), h12), (h12, inertia + ml2))
    coriolis = (-2 * ml2 * s2 * (2 * qd[0] * qd[1] + qd[1] ** 2), 2 * ml2 * s2 * qd[0] ** 2)
    gravity = (-mgl * (3 * sin(q[0]) + sin(q[0] + q[1])), -mgl * sin(q[0] + q[1]))
    return mass_matrix, coriolis, gravity
