"""Planner benchmark: nearopt's plan of the paper's example against CasADi + IPOPT, same problem.

The paper's example (Table 1, eqs. 31-32): the planar two-link arm from rest at θ0 = (45°, −90°)
to rest at θe = (−90°, 0°), free final time te, |u1| ≤ 10 and |u2| ≤ 5 N m, minimising
J = ∫ (1 + 0.03 (u1² + u2²)) dt (best known J ≈ 0.5515 at te ≈ 0.342 s). It is planned by
:func:`nearopt.plan` and, as the reference, solved by a direct transcription: multiple shooting
with one RK4 step per interval, piecewise-constant torques on K equal intervals of length te/K,
te a decision variable, solved by IPOPT. The dynamics are eq. (31) written out in CasADi symbols
and checked against Pinocchio's forward dynamics on the bundled URDF before the solve. J of the
IPOPT solution is the continuous-time cost of its piecewise-constant torques, integrated by the
same RK4 as an extra quadrature state; its convergence with K (measured):

    K      J            te [s]
    50     0.5516423    0.342151
    100    0.5514992    0.342097
    200    0.5514634    0.342084
    400    0.5514545    0.342081
    800    0.5514523    0.342081

(error O(1/K²), limit ≈ 0.551452), so the default K = 200 gives J to about 1e-5; the same optimum
is found from initial guesses te = 0.25 ... 1.0 s. Also plans a seeded random pair of configurations
for ur5 and panda (nearopt only). Prints method, J, te, median wall time of --repeat runs (for
IPOPT: building the NLP and solving it), iterations and, for two_link, the nearopt/IPOPT ratios.

    python scripts/bench_planner.py [--K 200] [--repeat 3] [--grid 200]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from benchlib import median_time

import nearopt

THETA_0 = np.deg2rad([45.0, -90.0])  # Table 1
THETA_E = np.deg2rad([-90.0, 0.0])
BETA = 0.03  # eq. (32)
INERTIA, MASS, HALF_LENGTH, GRAVITY = 4.167e-3, 1.0, 0.1, 9.81  # Table 1
U_MAX = np.array([10.0, 5.0])


@dataclass(frozen=True)
class Row:
    """One line of the table.

    Attributes
    ----------
    method
        What produced it, e.g. ``"nearopt"`` or ``"IPOPT K=200"``.
    J
        The cost ∫ (1 + β Σ u²) dt of the motion.
    te
        Its duration [s].
    wall
        Median wall time [s].
    iterations
        Iterations of the optimiser.
    status
        How the optimiser stopped.
    """

    method: str
    J: float
    te: float
    wall: float
    iterations: int
    status: str


def two_link_dynamics(q: Any, qd: Any, u: Any) -> Any:
    """θ̈ of the paper's two-link arm, eq. (31), without friction.

    Parameters
    ----------
    q, qd, u
        θ [rad], θ̇ [rad/s] and the torques [N m], CasADi or NumPy vectors of length 2.

    Returns
    -------
    Any
        θ̈ [rad/s²] (a CasADi expression or DM).
    """
    ml2, mgl = MASS * HALF_LENGTH**2, MASS * GRAVITY * HALF_LENGTH
    c2, s2 = ca.cos(q[1]), ca.sin(q[1])
    m12 = INERTIA + ml2 * (1 + 2 * c2)
    mass_matrix = ca.vertcat(
        ca.horzcat(2 * INERTIA + 2 * ml2 * (3 + 2 * c2), m12),
        ca.horzcat(m12, INERTIA + ml2),
    )
    bias = ca.vertcat(
        -2 * ml2 * s2 * (2 * qd[0] * qd[1] + qd[1] ** 2)
        - mgl * (3 * ca.sin(q[0]) + ca.sin(q[0] + q[1])),
        2 * ml2 * s2 * qd[0] ** 2 - mgl * ca.sin(q[0] + q[1]),
    )
    return ca.solve(mass_matrix, u - bias)


def check_dynamics(robot: nearopt.Robot, samples: int = 5, tol: float = 1e-9) -> float:
    """Compare :func:`two_link_dynamics` with Pinocchio's at seeded random states.

    Parameters
    ----------
    robot
        The bundled ``two_link`` arm.
    samples
        Number of random (θ, θ̇, u).
    tol
        Largest acceptable difference [rad/s²].

    Returns
    -------
    float
        The largest difference found.

    Raises
    ------
    RuntimeError
        If it exceeds ``tol``.
    """
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(samples):
        q, qd = rng.uniform(-np.pi, np.pi, 2), rng.uniform(-10.0, 10.0, 2)
        u = rng.uniform(-U_MAX, U_MAX)
        ours = np.asarray(two_link_dynamics(ca.DM(q), ca.DM(qd), ca.DM(u))).ravel()
        worst = max(worst, float(np.max(np.abs(ours - robot.forward_dynamics(q, qd, u)))))
    if worst > tol:
        raise RuntimeError(f"eq. (31) and Pinocchio disagree by {worst:.3g} rad/s²")
    return worst


def ipopt_two_link(K: int, te_guess: float = 0.45) -> Row:
    """Solve the paper's example by RK4 multiple shooting with IPOPT.

    Parameters
    ----------
    K
        Shooting intervals (piecewise-constant torques).
    te_guess
        Initial guess for te [s].

    Returns
    -------
    Row
        The solution's continuous-time J and te, IPOPT's iteration count and return status
        (``wall`` is 0; the caller times the call).
    """
    x, u, dt = ca.SX.sym("x", 5), ca.SX.sym("u", 2), ca.SX.sym("dt")

    def rhs(z: Any) -> Any:
        return ca.vertcat(z[2:4], two_link_dynamics(z[0:2], z[2:4], u), 1 + BETA * ca.sumsqr(u))

    k1 = rhs(x)
    k2 = rhs(x + dt / 2 * k1)
    k3 = rhs(x + dt / 2 * k2)
    k4 = rhs(x + dt * k3)
    step = ca.Function("step", [x, u, dt], [x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])

    X, U, te = ca.MX.sym("X", 4, K + 1), ca.MX.sym("U", 2, K), ca.MX.sym("te")
    stepped = step.map(K)(ca.vertcat(X[:, :K], ca.MX.zeros(1, K)), U, te / K)
    w = ca.veccat(X, U, te)
    g = ca.veccat(stepped[:4, :] - X[:, 1:])
    nlp = {"x": w, "f": ca.sum2(stepped[4, :]), "g": g}
    solver = ca.nlpsol(
        "shooting", "ipopt", nlp,
        {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"},
    )

    rest = np.zeros(2)
    lbx = [np.full((4, K + 1), -np.inf), np.tile(-U_MAX[:, None], (1, K)), [0.01]]
    ubx = [np.full((4, K + 1), np.inf), np.tile(U_MAX[:, None], (1, K)), [10.0]]
    for bounds in (lbx, ubx):
        bounds[0][:, 0] = np.r_[THETA_0, rest]
        bounds[0][:, -1] = np.r_[THETA_E, rest]
    s = np.linspace(0.0, 1.0, K + 1)
    q_guess = THETA_0[:, None] + (THETA_E - THETA_0)[:, None] * s
    qd_guess = np.tile(((THETA_E - THETA_0) / te_guess)[:, None], (1, K + 1))
    qd_guess[:, [0, -1]] = 0.0
    mid = 0.5 * (q_guess[:, :-1] + q_guess[:, 1:])
    mgl = MASS * GRAVITY * HALF_LENGTH
    u_guess = np.vstack([
        -mgl * (3 * np.sin(mid[0]) + np.sin(mid[0] + mid[1])),
        -mgl * np.sin(mid[0] + mid[1]),
    ])
    u_guess = np.clip(u_guess, -U_MAX[:, None], U_MAX[:, None])
    x0 = [np.vstack([q_guess, qd_guess]), u_guess, [te_guess]]

    def flat(parts: list) -> np.ndarray:
        return np.concatenate([np.asarray(p, dtype=float).ravel(order="F") for p in parts])

    sol = solver(x0=flat(x0), lbx=flat(lbx), ubx=flat(ubx), lbg=0.0, ubg=0.0)
    stats = solver.stats()
    return Row(
        method=f"IPOPT K={K}",
        J=float(sol["f"]),
        te=float(sol["x"][-1]),
        wall=0.0,
        iterations=int(stats["iter_count"]),
        status=str(stats["return_status"]),
    )


def random_pair(robot: nearopt.Robot, seed: int = 11) -> tuple[np.ndarray, np.ndarray]:
    """A seeded random θ0, θe within the position limits clipped to ±π (as in bench_timing).

    Parameters
    ----------
    robot
        The arm.
    seed
        Seed of NumPy's default generator.

    Returns
    -------
    tuple of ndarray
        θ0 and θe [rad].
    """
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    return rng.uniform(lo, hi), rng.uniform(lo, hi)


def nearopt_row(robot: nearopt.Robot, q0: np.ndarray, qe: np.ndarray, repeat: int,
                **options: Any) -> Row:
    """Plan with :func:`nearopt.plan` for the paper's cost, ``repeat`` times.

    Parameters
    ----------
    robot
        The arm.
    q0, qe
        Start and goal [rad].
    repeat
        Runs; the wall time reported is their median.
    **options
        Passed to :func:`nearopt.plan`.

    Returns
    -------
    Row
        The last run's J, te, iterations and status with the median wall time.
    """
    wall, res = median_time(lambda: nearopt.plan(robot, q0, qe, nearopt.TorqueCost(BETA),
                                                 **options), repeat)
    return Row(f"nearopt {robot.name}", res.J, res.duration, wall, len(res.history) - 1,
               res.status)


def print_row(row: Row) -> None:
    """Print one table line.

    Parameters
    ----------
    row
        The line.
    """
    print(f"{row.method:<20}{row.J:>11.6f}{row.te:>10.5f}{row.wall:>10.3f}{row.iterations:>7d}"
          f"  {row.status}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--K", type=int, default=200, help="IPOPT's shooting intervals")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--grid", type=int, default=200, help="nearopt's grid on two_link")
    parser.add_argument("--robots", nargs="*", default=["ur5", "panda"],
                        help="arms planned by nearopt only")
    parser.add_argument("--robot-grid", type=int, default=100, help="their grid")
    parser.add_argument("--robot-iterations", type=int, default=50,
                        help="their max_iterations")
    args = parser.parse_args()

    robot = nearopt.Robot.from_name("two_link")
    print(f"eq. (31) vs Pinocchio: max |Δθ̈| = {check_dynamics(robot):.1e} rad/s²\n")
    print(f"{'method':<20}{'J':>11}{'te [s]':>10}{'wall [s]':>10}{'iter':>7}  status")
    ours = nearopt_row(robot, THETA_0, THETA_E, args.repeat, grid=args.grid)
    print_row(ours)
    wall, ref = median_time(lambda: ipopt_two_link(args.K), args.repeat)
    ref = Row(ref.method, ref.J, ref.te, wall, ref.iterations, ref.status)
    print_row(ref)
    ratio_j, ratio_t = ours.J / ref.J, ours.wall / ref.wall
    print(f"{'ratio nearopt/IPOPT':<20}{ratio_j:>11.6f}{'':>10}{ratio_t:>10.2f}")
    for name in args.robots:
        arm = nearopt.Robot.from_name(name)
        q0, qe = random_pair(arm)
        print_row(nearopt_row(arm, q0, qe, args.repeat, grid=args.robot_grid,
                              max_iterations=args.robot_iterations))


if __name__ == "__main__":
    main()
