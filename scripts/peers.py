"""The peer stage-1 solvers (copp-py's TOPP2-RA and COPP2-SOCP, TOPP-RA) on nearopt's problem.

Each function times one path on exactly nearopt's knots σ = s/s_e (given, not chosen by the
peer) with nearopt's discretisation, so that durations and wall times compare in one process:

* b = (dσ/dt)² at the stations (the peers' path is θ(σ), so their "ṡ²" is nearopt's b);
* torque u = m a + c b + g (a = ½ db/dσ constant on a segment), imposed at both ends of every
  segment with that segment's a: toppra's ``DiscretizationType.Interpolation``, and what copp's
  TOPP2 does (``Constraints.fill_acc_topp2`` pushes the rows of both stations of a segment with
  that segment's ``b = (a[k+1] − a[k])/(2Δs)``); the same for joint accelerations θ'a + θ''b;
* speed b θ'_i² ≤ v_i² at the stations only; rest at both ends; Δt_k = 2Δσ_k/(√b_k + √b_{k+1}).

Damping: both peers build the torque rows from an inverse-dynamics callback ID(q, q̇, q̈) as
g = ID(θ, 0, 0), m = ID(θ, 0, θ') − g, c = ID(θ, θ', θ'') − g, i.e. whatever the callback adds
for q̇ = θ' lands in the b (= ṡ²) coefficient; their rows are linear in (ṡ², s̈), with no √b
term. A viscous D q̇ would be imposed as D θ' b instead of D θ' √b, so the functions here refuse
a damped arm (use ``robot.with_limits(damping=0.0)``).

Measured caveats (self-test): with joint acceleration limits the greedy forward pass of RA
(copp and toppra alike) is not the optimum of this discrete problem: nearopt's SOCP and copp's
own COPP2-SOCP (Time only, same rows) find feasible profiles ~1e-5 shorter at N = 200. toppra
0.6.10 backs every forward step off by max(1e-8, 1e-4·x) (``x_next = max(x_next − TINY,
0.9999 x_next)``): ~1e-6 longer than copp, with rows exceeded by up to ~1e-7 relative.

``wall_time`` is the whole call (sampling the path, building the peer's constraint objects with
the Pinocchio callbacks, the solve); ``solve_time`` the solver call alone.

    python scripts/peers.py      # self-test against nearopt's stage 1 (panda, ur5)
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import copp_py as copp
import numpy as np
import pinocchio as pin
import toppra as ta

__all__ = [
    "PeerResult",
    "copp_topp2_ra",
    "toppra_duration",
    "copp_copp2_socp_energy",
    "duration_from_b",
]


@dataclass(frozen=True)
class PeerResult:
    """One peer solve on nearopt's knots.

    Attributes
    ----------
    duration
        t_e [s] from b by Δt_k = 2Δσ_k/(√b_k + √b_{k+1}).
    wall_time
        The whole call [s]: sampling, constraint objects (with the torque callbacks), solve.
    solve_time
        The solver call alone [s].
    b
        (dσ/dt)² at the knots, shape (N+1,), b_0 = b_N = 0.
    note
        What was solved, by which API.
    objective
        The peer's own objective value where it reports one (COPP2-SOCP), else None.
    """

    duration: float
    wall_time: float
    solve_time: float
    b: np.ndarray
    note: str
    objective: float | None = None


def duration_from_b(sigma: np.ndarray, b: np.ndarray) -> float:
    """Σ Δt_k = Σ 2Δσ_k/(√b_k + √b_{k+1}), exact for b linear in σ on each segment [s]."""
    lam = np.sqrt(np.maximum(np.asarray(b, dtype=float), 0.0))
    return float(np.sum(2.0 * np.diff(sigma) / (lam[:-1] + lam[1:])))


def _check(robot, sigma: np.ndarray, torque: bool) -> np.ndarray:
    sigma = np.asarray(sigma, dtype=float)
    if (
        sigma.ndim != 1
        or sigma.size < 3
        or sigma[0] != 0.0
        or sigma[-1] != 1.0
        or np.any(np.diff(sigma) <= 0)
    ):
        raise ValueError("sigma must increase strictly from 0 to 1 (≥ 3 knots)")
    if torque and np.any(np.asarray(robot.damping) != 0.0):
        raise ValueError(
            f"{robot.name} has viscous damping {np.asarray(robot.damping).tolist()}: the peers' "
            "torque rows are linear in (ṡ², s̈) and cannot hold the D θ' √b term (a callback's "
            "D q̇ would be imposed as D θ' b); use robot.with_limits(damping=0.0)"
        )
    return sigma


def _samples(path, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """θ, dθ/dσ, d²θ/dσ² at the knots, each (N+1, n), C-contiguous float64."""
    s = sigma * path.s_end
    return tuple(np.ascontiguousarray(path(s, k) * path.s_end**k, dtype=float) for k in (0, 1, 2))


def _inverse_dynamics(robot):
    """The user's Pinocchio callback u = ID(q, q̇, q̈) (no damping: see the module's doc)."""
    model = robot.model
    data = model.createData()

    def inverse_dynamics(q, dq, ddq):
        return pin.rnea(model, data, q, dq, ddq)

    return inverse_dynamics


# ---------------------------------------------------------------- copp-py
def _copp_robot(robot, path, sigma, *, velocity, torque, acceleration, callback=False):
    """A ``copp_py.Robot`` on the knots σ with θ(σ) sampled by ``set_q`` and the limits added."""
    knots = sigma.size
    theta, dtheta, ddtheta = _samples(path, sigma)
    crobot = copp.Robot(
        robot.n,
        capacity=knots,
        inverse_dynamics=_inverse_dynamics(robot) if (torque or callback) else None,
    )
    crobot.append_s(sigma)
    crobot.set_q(theta, dtheta, ddtheta, 0)
    lim = robot.limits
    if velocity:
        v = np.asarray(lim.velocity, dtype=float)
        crobot.add_velocity_limits(v, -v, start_idx_s=0, length=knots)
    if acceleration is not None:
        acc = np.broadcast_to(np.asarray(acceleration, dtype=float), (robot.n,)).copy()
        crobot.add_acceleration_limits(acc, -acc, start_idx_s=0, length=knots)
    if torque:
        crobot.add_torque_limits(
            np.asarray(lim.effort_upper, dtype=float),
            np.asarray(lim.effort_lower, dtype=float),
            start_idx_s=0,
            length=knots,
        )
    return crobot


def copp_topp2_ra(
    robot, path, sigma, *, velocity=True, torque=True, acceleration=None
) -> PeerResult:
    """copp-py's TOPP2-RA (``copp_py.solver.topp2_ra.solve``) on nearopt's knots.

    ``copp_py.Robot(n, inverse_dynamics=pin.rnea callback)``, ``append_s(σ)``,
    ``set_q(θ, θ', θ'')`` (derivatives in σ), ``add_velocity_limits``,
    ``add_acceleration_limits``, ``add_torque_limits``; then
    ``topp2_ra.Problem(robot.constraints, idx_s_interval=(0, N), a_boundary=(0, 0))`` and
    ``topp2_ra.solve`` with the default ``ReachSet2Options`` (LP tolerance 1e-8).
    """
    t0 = time.perf_counter()
    sigma = _check(robot, sigma, torque)
    crobot = _copp_robot(
        robot, path, sigma, velocity=velocity, torque=torque, acceleration=acceleration
    )
    problem = copp.solver.topp2_ra.Problem(
        crobot.constraints, idx_s_interval=(0, sigma.size - 1), a_boundary=(0.0, 0.0)
    )
    t1 = time.perf_counter()
    b = np.asarray(copp.solver.topp2_ra.solve(problem, copp.solver.topp2_ra.Options()))
    t2 = time.perf_counter()
    b = np.maximum(b, 0.0)
    return PeerResult(
        duration_from_b(sigma, b),
        t2 - t0,
        t2 - t1,
        b,
        f"copp-py {copp.version()} TOPP2-RA, stations = nearopt's knots, "
        "rows at both ends of each segment, default ReachSet2Options",
    )


def copp_copp2_socp_energy(
    robot,
    path,
    sigma,
    weights,
    *,
    velocity=True,
    torque=True,
    acceleration=None,
    fix_gravity_sign=True,
) -> PeerResult:
    """copp-py's COPP2-SOCP (Clarabel) for J = ∫(1 + Σ w_i u_i²) dt on nearopt's knots.

    Objectives ``[copp.objective.Time(1), copp.objective.ThermalEnergy(1, normalize=√w)]``
    (ThermalEnergy is w_e ∫ Σ (u_i ν_i)² dt). Caveat: copp's COPP2 quadrature takes the torque
    at the start of each segment only, J_th = Σ_k Δt_k Σ_i (ν_i u_i(σ_k⁺))², whereas nearopt
    averages both ends, Σ_k Δt_k ½[f(σ_k⁺) + f(σ_{k+1}⁻)]: the two discrete optima differ at
    O(Δσ), and ``objective`` is copp's own value (``Copp2SocpResult.objective_value``).
    With all weights 0 only ``Time(1)`` is passed: the time-optimal SOCP on the same rows as
    TOPP2-RA (a check of RA's optimality).

    A bug in copp-py 0.2.3: the ThermalEnergy cone (``clarabel_objective_thermal_energy_copp2``)
    enters the gravity term with the wrong sign, so Clarabel minimises Σ Δt Σ ν²(m a + c b − g)²
    while ``objective_value`` reports the true J (measured: Clarabel's ``obj_val`` equals the
    flipped J of copp's profile to 1e-9, and nearopt's profile has a lower true J in copp's own
    quadrature: 22.28 vs 23.24 on ur5). With ``fix_gravity_sign`` (default) the torque limits
    are built with the true callback, then the callback is swapped
    (``Robot.set_inverse_dynamics``) for ID − 2g, which the objective (built inside the solve)
    reads as m, c and −g: its cone then holds (m a + c b + g)², the true torque. ``objective``
    is then Clarabel's ``obj_val`` (``objective_value`` would use the swapped callback).
    Note that the objective's callbacks run inside ``solve`` (part of ``solve_time``).
    """
    t0 = time.perf_counter()
    w = np.broadcast_to(np.asarray(weights, dtype=float), (robot.n,))
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError(f"weights must be finite and ≥ 0, got {w.tolist()}")
    sigma = _check(robot, sigma, torque or bool(np.any(w > 0)))  # the energy uses the torque
    crobot = _copp_robot(
        robot,
        path,
        sigma,
        velocity=velocity,
        torque=torque,
        acceleration=acceleration,
        callback=True,
    )
    objectives = [copp.objective.Time(1.0)]
    fixed = False
    if np.any(w > 0):
        objectives.append(copp.objective.ThermalEnergy(1.0, np.sqrt(w)))
        if fix_gravity_sign:
            model = robot.model
            data = model.createData()

            def shifted(q, dq, ddq):  # ID − 2g: the objective's cone then holds +g (see above)
                return pin.rnea(model, data, q, dq, ddq) - 2.0 * pin.computeGeneralizedGravity(
                    model, data, q
                )

            crobot.set_inverse_dynamics(shifted)
            fixed = True
    problem = copp.solver.copp2_socp.Problem(
        crobot, objectives, idx_s_interval=(0, sigma.size - 1), a_boundary=(0.0, 0.0)
    )
    t1 = time.perf_counter()
    result = copp.solver.copp2_socp.solve_expert(problem, copp.solver.copp2_socp.Options())
    t2 = time.perf_counter()
    if result.a is None:
        raise RuntimeError(f"COPP2-SOCP did not solve: {result.solver_status}")
    b = np.maximum(np.asarray(result.a), 0.0)
    return PeerResult(
        duration_from_b(sigma, b),
        t2 - t0,
        t2 - t1,
        b,
        f"copp-py {copp.version()} COPP2-SOCP (Clarabel, default options), "
        f"{' + '.join(type(o).__name__ for o in objectives)}"
        f"{' (gravity-sign workaround)' if fixed else ''}, "
        f"status {result.solver_status}, "
        f"{result.iterations} iterations, Clarabel {1e3 * result.solve_time:.2f} ms",
        objective=float(result.obj_val if fixed else result.objective_value),
    )


# ---------------------------------------------------------------- TOPP-RA
def _version(dist: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return "?"


def _toppra_path(path):
    """nearopt's θ(s) as a toppra path θ(σ), σ ∈ [0, 1] (derivatives with respect to σ)."""

    class SigmaPath(ta.interpolator.AbstractGeometricPath):
        def __call__(self, sigma, order=0):
            sigma = np.asarray(sigma, dtype=float)
            out = path(np.atleast_1d(sigma) * path.s_end, order) * path.s_end**order
            return out[0] if sigma.ndim == 0 else out

        @property
        def dof(self):
            return path.dof

        @property
        def path_interval(self):
            return np.array([0.0, 1.0])

    return SigmaPath()


def toppra_duration(
    robot, path, sigma, *, velocity=True, torque=True, acceleration=None
) -> PeerResult:
    """TOPP-RA (``toppra.algorithm.TOPPRA``, default solver wrapper: seidel) on nearopt's knots.

    ``JointVelocityConstraint``, ``JointAccelerationConstraint`` and ``JointTorqueConstraint``
    (a ``pin.rnea`` callback, no friction), the last two with
    ``DiscretizationType.Interpolation``; ``TOPPRA(constraints, path, gridpoints=σ)`` (which
    evaluates the callbacks) and ``compute_parameterization(0, 0)`` (the solve). The path is
    nearopt's own, wrapped as θ(σ).
    """
    t0 = time.perf_counter()
    sigma = _check(robot, sigma, torque)
    lim = robot.limits
    scheme = ta.constraint.DiscretizationType.Interpolation
    constraints = []
    if velocity:
        v = np.asarray(lim.velocity, dtype=float)
        constraints.append(ta.constraint.JointVelocityConstraint(np.column_stack([-v, v])))
    if acceleration is not None:
        acc = np.broadcast_to(np.asarray(acceleration, dtype=float), (robot.n,))
        constraints.append(
            ta.constraint.JointAccelerationConstraint(
                np.column_stack([-acc, acc]), discretization_scheme=scheme
            )
        )
    if torque:
        constraints.append(
            ta.constraint.JointTorqueConstraint(
                _inverse_dynamics(robot),
                np.column_stack([lim.effort_lower, lim.effort_upper]),
                np.zeros(robot.n),
                discretization_scheme=scheme,
            )
        )
    algo = ta.algorithm.TOPPRA(constraints, _toppra_path(path), gridpoints=sigma)
    t1 = time.perf_counter()
    _, sd, _ = algo.compute_parameterization(0.0, 0.0)
    t2 = time.perf_counter()
    if sd is None:
        raise RuntimeError(f"TOPP-RA failed: {algo.problem_data.return_code}")
    b = np.asarray(sd, dtype=float) ** 2
    return PeerResult(
        duration_from_b(sigma, b),
        t2 - t0,
        t2 - t1,
        b,
        f"toppra {_version('toppra')} TOPPRA ({type(algo.solver_wrapper).__name__}), "
        "gridpoints = nearopt's knots, Interpolation",
    )


# ---------------------------------------------------------------- self-test
def _spline(robot, seed: int):
    import nearopt

    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    return nearopt.SplinePath(np.linspace(0.0, 1.0, 6), rng.uniform(lo, hi, size=(6, robot.n)))


def _nearopt(robot, path, grid: int, cost):
    """nearopt's stage 1 with the limits at the knots only: (problem, solution, t_e, wall)."""
    import dataclasses

    from nearopt.timing import build_timing_problem, solve_timing
    from nearopt.trajectory import segment_times

    t0 = time.perf_counter()
    problem = build_timing_problem(robot, path, grid=grid)
    problem = dataclasses.replace(problem, interior_speed=None, interior=None)
    sol = solve_timing(problem, cost)
    wall = time.perf_counter() - t0
    return problem, sol, float(segment_times(problem.sigma, sol.b).sum()), wall


def _self_test() -> None:
    import nearopt
    from nearopt.cost import TimeCost, TorqueCost
    from nearopt.timing import Discretisation

    accel = 10.0
    cases = [
        ("torque+speed", True, None),
        (f"speed+acc{accel:g}", False, accel),
        (f"all+acc{accel:g}", True, accel),
    ]
    print(
        "time-optimal, limits at the knots only; te [s]; rel = x/nearopt − 1; "
        "SOCP = copp COPP2-SOCP Time(1) on the TOPP2-RA rows; ms = wall/solve"
    )
    print(
        f"{'robot':<6}{'case':<13}{'N':>5}{'copp RA':>13}{'toppra':>13}{'nearopt':>13}"
        f"{'SOCP':>13}{'rel RA':>10}{'rel tpra':>10}{'rel SOCP':>10}"
        f"{'copp RA ms':>14}{'toppra ms':>13}{'SOCP ms':>15}{'near ms':>8}"
    )
    for name in ("panda", "ur5"):
        robot = nearopt.Robot.from_name(name).with_limits(damping=0.0)
        path = _spline(robot, seed=7)
        for label, torque, acc in cases:
            arm = robot if acc is None else robot.with_limits(acceleration=acc)
            if not torque:  # nearopt always has torque rows: make them slack (1e9 upsets Clarabel)
                arm = arm.with_limits(effort=1e4)
            for grid in (200, 1000):
                sigma = nearopt.timing.build_timing_problem(arm, path, grid=grid).sigma
                try:
                    _, _, te_near, wall_near = _nearopt(arm, path, grid, TimeCost())
                except nearopt.SolverError as err:  # e.g. Clarabel's InsufficientProgress
                    te_near, wall_near = np.nan, np.nan
                    print(f"  (nearopt failed: {err})")
                acc_vec = None if acc is None else np.full(robot.n, acc)
                cp = copp_topp2_ra(arm, path, sigma, torque=torque, acceleration=acc_vec)
                tp = toppra_duration(arm, path, sigma, torque=torque, acceleration=acc_vec)
                sc = copp_copp2_socp_energy(
                    arm, path, sigma, np.zeros(robot.n), torque=torque, acceleration=acc_vec
                )
                rel = [x.duration / te_near - 1 for x in (cp, tp, sc)]
                ms = [f"{1e3 * x.wall_time:.1f}/{1e3 * x.solve_time:.2f}" for x in (cp, tp, sc)]
                print(
                    f"{name:<6}{label:<13}{grid:>5}{cp.duration:>13.9f}{tp.duration:>13.9f}"
                    f"{te_near:>13.9f}{sc.duration:>13.9f}"
                    + "".join(f"{r:>10.1e}" for r in rel)
                    + f"{ms[0]:>14}{ms[1]:>13}{ms[2]:>15}{1e3 * wall_near:>8.0f}"
                )

    # the energy cost J = ∫(1 + Σ w u²) dt. copp's quadrature takes the torque at each segment's
    # start, nearopt's both ends: "J own" is each solver's own value, "J_near(b)" nearopt's
    # discretised J at that solver's profile (≥ nearopt's optimum); "raw" = copp without the
    # gravity-sign workaround
    print("\nJ = ∫(1 + β Σu²) dt, β = 1e-3 (copp: COPP2-SOCP Time + ThermalEnergy)")
    print(
        f"{'robot':<6}{'N':>5}{'J near':>11}{'J copp own':>12}"
        f"{'J_near(copp)':>13}{'rel':>9}{'J_near(raw)':>12}{'rel':>9}{'te near':>9}"
        f"{'te copp':>9}{'te raw':>9}{'copp ms':>14}{'near ms':>9}"
    )
    for name in ("panda", "ur5"):
        robot = nearopt.Robot.from_name(name).with_limits(damping=0.0)
        path = _spline(robot, seed=7)
        beta = 1e-3
        cost = TorqueCost(beta)
        for grid in (200, 1000):
            problem, sol, te_near, wall_near = _nearopt(robot, path, grid, cost)
            w = np.full(robot.n, beta)
            disc = Discretisation(problem)
            fixed = copp_copp2_socp_energy(robot, path, problem.sigma, w)
            raw = copp_copp2_socp_energy(robot, path, problem.sigma, w, fix_gravity_sign=False)
            j_fix = disc.objective(fixed.b[1:-1], cost)[0]
            j_raw = disc.objective(raw.b[1:-1], cost)[0]
            print(
                f"{name:<6}{grid:>5}{sol.objective:>11.6f}{fixed.objective:>12.6f}"
                f"{j_fix:>13.6f}{j_fix / sol.objective - 1:>9.1e}{j_raw:>12.6f}"
                f"{j_raw / sol.objective - 1:>9.1e}{te_near:>9.5f}{fixed.duration:>9.5f}"
                f"{raw.duration:>9.5f}"
                f"{f'{1e3 * fixed.wall_time:.1f}/{1e3 * fixed.solve_time:.1f}':>14}"
                f"{1e3 * wall_near:>9.0f}"
            )


if __name__ == "__main__":
    _self_test()
