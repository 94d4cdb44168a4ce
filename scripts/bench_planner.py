"""Planner benchmark: nearopt's plans against direct transcriptions solved by CasADi + IPOPT.

1. The paper's example (Table 1, eqs. 31-32): the planar two-link arm from rest at θ0 = (45°, −90°)
   to rest at θe = (−90°, 0°), free final time, |u1| ≤ 10 and |u2| ≤ 5 N·m, f0 = 1 + 0.03 Σ u².
   Planned by :func:`nearopt.plan` (default options) and, as the peer, by a direct transcription
   written the usual way: multiple shooting, one RK4 ``Function`` of eq. (31) written out in
   CasADi symbols, mapped over K = 100 intervals of piecewise-constant torques, te a decision
   variable, IPOPT. Wall times (the NLP built and solved, median of ``--repeat``) in the same run,
   and their ratio.
2. Real arms with their URDF limits (torque, speed and position): for ur5, panda, xarm7 and
   kinova, a "tied" motion (every joint from 30 % to 70 % of its range, clipped to ±π: equal
   fractions of equal ranges, so the speed limits of several joints bind together) and a seeded
   random one, each for f0 = 1 (time-optimal) and f0 = 1 + Σ 0.5 (u_i/u_max,i)² — against the
   reference of ``scripts/ipopt_reference.py`` (the full problem by RK4 multiple shooting with the
   same limits, several starts, re-simulated with pinocchio.aba). Prints J of the straight line,
   of nearopt's plan and of the reference, their gap, and nearopt's wall time, iterations and
   stage-1 solves.
3. The path's resolution: nearopt's J against the number of interior control points K on the
   same motions.
4. Wall times of full plans: panda (seeded motions) and tiago's 7-joint arm.

    python scripts/bench_planner.py [--repeat 3] [--intervals 60] [--starts 3] [--skip ...]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from benchlib import median_time
from ipopt_reference import solve_reference

import nearopt
from nearopt.catalog import package_dirs
from nearopt.paper_example import BETA, TABLE_1, THETA_0, THETA_E, eq31

U_MAX = np.array(TABLE_1.torque_limits)
ARMS = ("ur5", "panda", "xarm7", "kinova")


@dataclass(frozen=True)
class Case:
    """A motion of an arm and a cost.

    Attributes
    ----------
    robot
        The arm.
    motion
        ``"tied"`` (30 % → 70 % of every range) or ``"random"`` (seeded).
    cost
        ``"time"`` or ``"normalised"``.
    q0, qe
        Start and goal [rad].
    weights
        w_i of f0 = 1 + Σ w_i u_i² [1/(N·m)²].
    """

    robot: nearopt.Robot
    motion: str
    cost: str
    q0: np.ndarray
    qe: np.ndarray
    weights: np.ndarray

    @property
    def label(self) -> str:
        return f"{self.robot.name:<7}{self.motion:<8}{self.cost:<11}"


def two_link_dynamics(q: Any, qd: Any, u: Any) -> Any:
    """θ̈ of the paper's two-link arm, eq. (31), without friction, in CasADi symbols.

    Parameters
    ----------
    q, qd, u
        θ [rad], θ̇ [rad/s] and the torques [N·m], CasADi vectors of length 2.
    """
    (h11, h12), (h21, h22) = eq31(q, qd, sin=ca.sin, cos=ca.cos)[0]
    coriolis, gravity = eq31(q, qd, sin=ca.sin, cos=ca.cos)[1:]
    mass_matrix = ca.vertcat(ca.horzcat(h11, h12), ca.horzcat(h21, h22))
    bias = ca.vertcat(coriolis[0] + gravity[0], coriolis[1] + gravity[1])
    return ca.solve(mass_matrix, u - bias)


def ipopt_two_link(intervals: int, te_guess: float = 0.45) -> tuple[float, float, int]:
    """The paper's example by RK4 multiple shooting (eq. 31 in CasADi, mapped) and IPOPT.

    Returns J (the piecewise-constant torques' cost, integrated by the same RK4), te [s] and
    IPOPT's iterations.
    """
    k = intervals
    x, u, dt = ca.SX.sym("x", 5), ca.SX.sym("u", 2), ca.SX.sym("dt")

    def rhs(z: Any) -> Any:
        return ca.vertcat(z[2:4], two_link_dynamics(z[0:2], z[2:4], u), 1 + BETA * ca.sumsqr(u))

    k1 = rhs(x)
    k2 = rhs(x + dt / 2 * k1)
    k3 = rhs(x + dt / 2 * k2)
    k4 = rhs(x + dt * k3)
    step = ca.Function("step", [x, u, dt], [x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    states, torques, te = ca.MX.sym("X", 4, k + 1), ca.MX.sym("U", 2, k), ca.MX.sym("te")
    stepped = step.map(k)(ca.vertcat(states[:, :k], ca.MX.zeros(1, k)), torques, te / k)
    nlp = {
        "x": ca.veccat(states, torques, te),
        "f": ca.sum2(stepped[4, :]),
        "g": ca.veccat(stepped[:4, :] - states[:, 1:]),
    }
    solver = ca.nlpsol(
        "shooting", "ipopt", nlp, {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"}
    )
    rest = np.zeros(2)
    lbx = [np.full((4, k + 1), -np.inf), np.tile(-U_MAX[:, None], (1, k)), [0.01]]
    ubx = [np.full((4, k + 1), np.inf), np.tile(U_MAX[:, None], (1, k)), [10.0]]
    for bounds in (lbx, ubx):
        bounds[0][:, 0] = np.r_[THETA_0, rest]
        bounds[0][:, -1] = np.r_[THETA_E, rest]
    s = np.linspace(0.0, 1.0, k + 1)
    q_guess = THETA_0[:, None] + (THETA_E - THETA_0)[:, None] * s
    qd_guess = np.tile(((THETA_E - THETA_0) / te_guess)[:, None], (1, k + 1))
    qd_guess[:, [0, -1]] = 0.0
    x0 = [np.vstack([q_guess, qd_guess]), np.zeros((2, k)), [te_guess]]

    def flat(parts: list) -> np.ndarray:
        return np.concatenate([np.asarray(p, dtype=float).ravel(order="F") for p in parts])

    sol = solver(x0=flat(x0), lbx=flat(lbx), ubx=flat(ubx), lbg=0.0, ubg=0.0)
    return float(sol["f"]), float(sol["x"][-1]), int(solver.stats()["iter_count"])


def check_dynamics(robot: nearopt.Robot, samples: int = 5, tol: float = 1e-9) -> float:
    """The largest |θ̈| difference between :func:`two_link_dynamics` and Pinocchio's forward
    dynamics on the bundled URDF at seeded random states [rad/s²]; raises above ``tol``."""
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


def paper_example(repeat: int, intervals: int) -> None:
    print(
        f"1. The paper's example: nearopt against IPOPT (RK4 multiple shooting of eq. 31, "
        f"K = {intervals}, built and solved), median of {repeat}"
    )
    robot = nearopt.Robot.from_name("two_link")
    print(f"eq. (31) against Pinocchio on the URDF: max |Δθ̈| = {check_dynamics(robot):.1e} rad/s²")
    cost = nearopt.TorqueCost(BETA)
    wall, ours = median_time(lambda: nearopt.plan(robot, THETA_0, THETA_E, cost), repeat)
    ref_wall, (ref_j, ref_te, ref_iterations) = median_time(
        lambda: ipopt_two_link(intervals), repeat
    )
    print(f"{'':<22}{'J':>10}{'te [s]':>9}{'wall [s]':>10}{'iterations':>12}")
    print(
        f"{'nearopt plan':<22}{ours.J:>10.6f}{ours.duration:>9.4f}{wall:>10.3f}"
        f"{len(ours.history) - 1:>12d}   ({ours.evaluations} stage-1 solves)"
    )
    print(
        f"{f'IPOPT K={intervals}':<22}{ref_j:>10.6f}{ref_te:>9.4f}{ref_wall:>10.3f}"
        f"{ref_iterations:>12d}"
    )
    print(f"ratio nearopt / IPOPT: J {ours.J / ref_j:.5f}, wall time {wall / ref_wall:.2f}\n")


def cases(arms: tuple[str, ...]) -> list[Case]:
    """The tied and the random motion of every arm, for both costs."""
    out = []
    for name in arms:
        robot = nearopt.Robot.from_name(name)
        lim = robot.limits
        lo = np.maximum(lim.position_lower, -np.pi)
        hi = np.minimum(lim.position_upper, np.pi)
        rng = np.random.default_rng(11)
        motions = {
            "tied": (lo + 0.3 * (hi - lo), lo + 0.7 * (hi - lo)),
            "random": (rng.uniform(lo, hi), rng.uniform(lo, hi)),
        }
        u_max = np.maximum(np.abs(lim.effort_lower), np.abs(lim.effort_upper))
        for motion, (q0, qe) in motions.items():
            for cost, weights in (("time", np.zeros(robot.n)), ("normalised", 0.5 / u_max**2)):
                out.append(Case(robot, motion, cost, q0, qe, weights))
    return out


def plan(case: Case, **options: Any) -> tuple[nearopt.PlanResult, float]:
    cost = nearopt.TorqueCost(weights=case.weights)
    start = time.perf_counter()
    result = nearopt.plan(case.robot, case.q0, case.qe, cost, **options)
    return result, time.perf_counter() - start


def real_arms(all_cases: list[Case], intervals: int, starts: int) -> None:
    print(
        f"2. Real arms, URDF limits: nearopt against the IPOPT reference (K = {intervals}, "
        f"{starts} starts)"
    )
    print(
        f"{'arm    motion  cost':<26}{'J line':>10}{'J nearopt':>11}{'J IPOPT':>10}"
        f"{'gap':>9}{'wall [s]':>10}{'iter':>6}{'stage 1':>9}{'IPOPT [s]':>11}"
    )
    worst = -np.inf
    for case in all_cases:
        result, wall = plan(case)
        try:
            ref = solve_reference(
                case.robot, case.q0, case.qe, case.weights, intervals=intervals, starts=starts
            )
            ref_j, ref_wall = ref.J, ref.wall_time
        except RuntimeError as exc:  # no start solved: report it, go on
            ref_j, ref_wall = np.nan, np.nan
            print(f"   (IPOPT: {exc})")
        gap = result.J / ref_j - 1.0
        worst = max(worst, gap)
        print(
            f"{case.label:<26}{result.initial.J:>10.5f}{result.J:>11.5f}{ref_j:>10.5f}"
            f"{100 * gap:>8.2f}%{wall:>10.2f}{len(result.history) - 1:>6d}"
            f"{result.evaluations:>9d}{ref_wall:>11.1f}"
        )
    print(f"largest gap nearopt / IPOPT: {100 * worst:+.2f} %\n")


def resolution(all_cases: list[Case], counts: tuple[int, ...]) -> None:
    print(
        "3. J against the number of interior control points K (knots clustered at the ends; "
        "relative to the largest K)"
    )
    print(f"{'arm    motion  cost':<26}" + "".join(f"{f'K={k}':>16}" for k in counts))
    for case in all_cases:
        results = [plan(case, options=nearopt.SCPOptions(control_points=k)) for k in counts]
        best = results[-1][0].J
        print(
            f"{case.label:<26}"
            + "".join(f"{100 * (r.J / best - 1):>+9.3f}% {w:>5.1f}s" for r, w in results)
        )
    print()


def wall_times(repeat: int) -> None:
    print(f"4. Full plans at the default grid (median of {repeat} runs)")
    print(
        f"{'arm':<26}{'motion':<10}{'J line':>10}{'J':>10}{'wall [s]':>10}{'iter':>6}{'stage 1':>9}"
    )
    panda = nearopt.Robot.from_name("panda")
    tiago = nearopt.Robot.from_urdf(
        package_dirs()[0] / "example-robot-data/robots/tiago_description/robots/tiago.urdf",
        tip="arm_7_link",
        base="torso_lift_link",
        name="tiago arm",
    )
    for robot, seeds in ((panda, range(5)), (tiago, range(3))):
        lim = robot.limits
        lo = np.maximum(lim.position_lower, -np.pi)
        hi = np.minimum(lim.position_upper, np.pi)
        u_max = np.maximum(np.abs(lim.effort_lower), np.abs(lim.effort_upper))
        cost = nearopt.TorqueCost(weights=0.5 / u_max**2)
        walls = []
        for seed in seeds:
            rng = np.random.default_rng(seed)
            q0, qe = rng.uniform(lo, hi), rng.uniform(lo, hi)
            wall, result = median_time(
                lambda q0=q0, qe=qe: nearopt.plan(robot, q0, qe, cost), repeat
            )
            walls.append(wall)
            print(
                f"{robot.name:<26}{f'seed {seed}':<10}{result.initial.J:>10.5f}"
                f"{result.J:>10.5f}{wall:>10.2f}{len(result.history) - 1:>6d}"
                f"{result.evaluations:>9d}"
            )
        print(f"{robot.name:<26}{'median':<10}{'':>20}{np.median(walls):>10.2f}")
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument(
        "--paper-intervals", type=int, default=100, help="K of the paper example's IPOPT peer"
    )
    parser.add_argument("--intervals", type=int, default=60, help="K of the arm references")
    parser.add_argument("--starts", type=int, default=3, help="starts of the arm references")
    parser.add_argument("--arms", nargs="+", default=list(ARMS))
    parser.add_argument("--control-points", nargs="+", type=int, default=[8, 12, 16, 24, 48])
    parser.add_argument(
        "--skip", nargs="*", default=[], choices=["1", "2", "3", "4"], help="sections to leave out"
    )
    args = parser.parse_args()
    all_cases = cases(tuple(args.arms))
    if "1" not in args.skip:
        paper_example(args.repeat, args.paper_intervals)
    if "2" not in args.skip:
        real_arms(all_cases, args.intervals, args.starts)
    if "3" not in args.skip:
        resolution(all_cases, tuple(args.control_points))
    if "4" not in args.skip:
        wall_times(args.repeat)


if __name__ == "__main__":
    main()
