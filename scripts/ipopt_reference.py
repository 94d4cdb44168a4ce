"""Reference solver: direct transcription of the free-final-time problem with CasADi + IPOPT.

Used only by tests and benchmark scripts, never by the :mod:`nearopt` package. It solves the full
optimal control problem (not nearopt's path-then-timing decomposition)

    min over te, u(t)   J = ∫₀^te f0 dt,   f0 = 1 + Σ_i w_i u_i²,
    s.t.  H(θ)θ̈ + h(θ, θ̇) + g(θ) + Dθ̇ = u             (eq. 1),
          u_min ≤ u ≤ u_max,   [|θ̇| ≤ v_max],   [θ_min ≤ θ ≤ θ_max],
          θ(0) = θ0, θ̇(0) = 0, θ(te) = θe, θ̇(te) = 0,

by multiple shooting: K equal intervals of length h = te/K (te a decision variable), one
piecewise-constant torque u_k per interval, the state x = (θ, θ̇) at the K + 1 nodes, and
``substeps`` classical RK4 steps per interval as the shooting map (one SX ``ca.Function`` mapped
over the intervals). Speed and position limits are box bounds on the node states and, unless
``inner_limits=False``, constraints on the states between the RK4 substeps (the midpoint of every
interval for ``substeps`` = 2); the dense re-simulation reports by how much they are exceeded
anywhere. The cost of piecewise-constant torques is exact: J = Σ_k h (1 + Σ_i w_i u_ki²).

The forward dynamics are the Articulated-Body Algorithm (Featherstone) written here in CasADi SX
from the data of the ``pinocchio.Model`` (joint tree, joint placements, inertias, gravity, joint
axes) with the arm's viscous damping, θ̈ = ABA(θ, θ̇, u − Dθ̇); :func:`check_dynamics` compares it
with ``pinocchio.aba`` before an arm is first solved.

The NLP is built once per (arm, K, substeps, tol, max_iter) and cached: start and goal, weights,
every limit and the initial guess are inputs of the cached solver, so the multi-start and later
calls only pay IPOPT's iterations. IPOPT gets the exact Hessian of the Lagrangian. Its cost
dominates: the Hessian of one RK4 interval is ~80 × the interval's own operations (19 × 19 dense
for a 6-DOF arm), so an iteration takes ~10 ms for the two-link arm and ~0.5-1 s for ur5 or panda
at K = 100 (CasADi's virtual machine; compiling the 1-million-operation Hessian to C was measured
not to be faster). Each candidate solution is re-simulated with ``pinocchio.aba`` and SciPy's DOP853
(see :func:`resimulate`).

    python scripts/ipopt_reference.py [--K 100] [--substeps 2] [--starts 4] [--robots ur5 panda]

prints J, te, wall time, starts solved and the re-simulation errors of the paper's two-link example
and of ur5 and panda motions from 30 % to 70 % of every joint's range, with and without speed
limits.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp

import nearopt
from nearopt.paper_example import BETA, THETA_0, THETA_E

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ReferenceSolution",
    "ResimulationResult",
    "solve_reference",
    "check_dynamics",
    "aba_casadi",
    "resimulate",
    "format_row",
    "HEADER",
]

TE_BOUNDS = (1e-3, 100.0)  # bounds of the final time [s]
RESIM_TOL = 1e-4  # largest end-position error [rad] of an accepted solution's re-simulation
WINDOW = 0.25  # length [s] of the windows of the windowed re-simulation
DENSE = 20  # re-simulation samples per interval
DYNAMICS_TOL = 1e-9  # largest acceptable |ABA here − pinocchio.aba| [rad/s²]
ACCEPTED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
_TE_EXPONENTS = (0.0, 1.0, -1.0, 0.5, -0.5, 1.5, -1.5, 0.25, -0.25, 0.75, -0.75)  # te guess 2^e

_ALIGNED_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


# ---------------------------------------------------------------------------------- results
@dataclass(frozen=True)
class ReferenceSolution:
    """The best solution found by :func:`solve_reference`.

    Attributes
    ----------
    J
        ∫ f0 dt of the returned motion; with piecewise-constant torques exactly
        Σ_k h (1 + Σ_i w_i u_ki²) [s].
    te
        Final time [s].
    t
        Node times, shape (K + 1,) [s].
    q
        Node positions from IPOPT, shape (K + 1, n) [rad or m].
    qd
        Node speeds from IPOPT, shape (K + 1, n) [rad/s or m/s].
    u
        Piecewise-constant torques, u[k] on [t[k], t[k+1]), shape (K, n) [N·m or N].
    status
        IPOPT's return status of the returned (best) start.
    starts
        Starts tried.
    solved
        Starts that IPOPT reported as solved (``Solve_Succeeded`` or
        ``Solved_To_Acceptable_Level``).
    wall_time
        Wall time of the whole call: dynamics check and NLP build when not cached yet, every start,
        the re-simulations [s].
    resim_end_position
        max_i |θ_i(te) − θe_i| of the open-loop re-simulation of ``u`` from (θ0, 0) with
        ``pinocchio.aba`` [rad or m].
    resim_end_speed
        max_i |θ̇_i(te)| of that re-simulation [rad/s or m/s].
    resim_speed_excess
        max over the dense windowed re-simulation (``DENSE`` = 20 samples per interval) and the
        joints with a speed limit of |θ̇_i| / v_i − 1 (≤ 0: inside the limits); −inf if no joint
        has one or speed limits were not imposed.
    resim_position_excess
        max over the dense windowed re-simulation of the distance outside the position limits,
        max(θ_min − θ, θ − θ_max) (≤ 0: inside) [rad or m]; −inf if there are none or they were not
        imposed.
    resim_window_position
        The windowed re-simulation restarts from IPOPT's node state every ``WINDOW`` = 0.25 s (at
        the first node at or after each multiple of 0.25 s); this is the largest |θ − θ_node| at
        the end of a window, the last one ending at te [rad or m]. It measures the transcription's
        integration error without the amplification of unstable (gravity) modes that dominates
        the open-loop error of a motion of a few seconds (see :func:`resimulate`). For
        te ≤ 0.25 s it is the open-loop re-simulation: equal to ``resim_end_position``.
    resim_window_speed
        Likewise the largest |θ̇ − θ̇_node| at a window end [rad/s or m/s].
    start_costs
        J of every start in order (NaN where IPOPT did not solve it) [s].
    start_te
        te of every start in order (NaN where not solved) [s].
    start_statuses
        IPOPT's return status of every start, in order.
    iterations
        IPOPT iterations of the returned start.
    rejected
        Starts that IPOPT solved with a lower J than the returned one but whose re-simulation
        missed θe by more than ``RESIM_TOL`` (both open loop and windowed): a sign that K or
        ``substeps`` are too small for the motion.
    """

    J: float
    te: float
    t: NDArray[np.float64]
    q: NDArray[np.float64]
    qd: NDArray[np.float64]
    u: NDArray[np.float64]
    status: str
    starts: int
    solved: int
    wall_time: float
    resim_end_position: float
    resim_end_speed: float
    resim_speed_excess: float
    resim_position_excess: float
    resim_window_position: float = math.nan
    resim_window_speed: float = math.nan
    start_costs: tuple[float, ...] = ()
    start_te: tuple[float, ...] = ()
    start_statuses: tuple[str, ...] = ()
    iterations: int = 0
    rejected: int = 0


@dataclass(frozen=True)
class ResimulationResult:
    """What :func:`resimulate` measures.

    Attributes
    ----------
    end_position, end_speed
        Open loop from (θ0, 0): max |θ(te) − θe| [rad] and max |θ̇(te)| [rad/s].
    speed_excess
        Worst max(|θ̇_i| / v_i) − 1 on the dense windowed re-simulation (−inf without limits).
    position_excess
        Worst excess over the position limits on it [rad] (−inf without limits).
    window_position, window_speed
        Windowed re-simulation (restart from the node state every ``window`` seconds): worst
        |θ − θ_node| [rad] and |θ̇ − θ̇_node| [rad/s] at the window ends.
    t, q, qd
        The dense windowed re-simulation: times (M,) [s], positions and speeds (M, n).
    """

    end_position: float
    end_speed: float
    speed_excess: float
    position_excess: float
    window_position: float
    window_speed: float
    t: NDArray[np.float64]
    q: NDArray[np.float64]
    qd: NDArray[np.float64]


@dataclass(frozen=True)
class _Start:
    """One IPOPT run of the multi-start (internal)."""

    index: int
    status: str
    J: float
    iterations: int
    w: NDArray[np.float64]


@dataclass
class _Transcription:
    """A built NLP and how to pack / unpack its decision vector (internal)."""

    model: pin.Model
    n: int
    K: int
    solver: ca.Function
    build_time: float

    def unpack(
        self, w: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
        """Split a decision vector into X (2n, K+1), U (n, K) and te."""
        n2, K = 2 * self.n, self.K
        nx = n2 * (K + 1)
        X = w[:nx].reshape((n2, K + 1), order="F")
        U = w[nx : nx + self.n * K].reshape((self.n, K), order="F")
        return X, U, float(w[-1])

    @staticmethod
    def pack(X: NDArray[np.float64], U: NDArray[np.float64], te: float) -> NDArray[np.float64]:
        """The decision vector of X (2n, K+1), U (n, K) and te."""
        return np.concatenate([X.ravel(order="F"), U.ravel(order="F"), [te]])


# ---------------------------------------------------------------------------------- dynamics
def _const(a: ArrayLike) -> ca.SX:
    """A numeric matrix as a sparse SX constant, entries within 1e-14 of 0 or ±1 snapped to them.

    The snapping (e.g. of the 6e-17 left by an URDF ``rpy`` of π/2) keeps the joint placements'
    zeros structural, which keeps the ABA expression and its derivatives smaller.
    """
    a = np.array(a, dtype=float, ndmin=2)
    for v in (0.0, 1.0, -1.0):
        a[np.abs(a - v) < 1e-14] = v
    return ca.SX(ca.sparsify(ca.DM(a)))


def _skew_np(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """The 3×3 matrix p̂ with p̂ x = p × x."""
    return np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]], [-p[1], p[0], 0.0]])


def _motion_act_inv(rotation: NDArray[np.float64], translation: NDArray[np.float64]) -> ca.SX:
    """The 6×6 motion transform (linear; angular) of M⁻¹ for M = (R, p): parent → child."""
    rt = rotation.T
    return _const(np.block([[rt, -rt @ _skew_np(translation)], [np.zeros((3, 3)), rt]]))


def _joint_axis(model: pin.Model, jid: int) -> tuple[bool, NDArray[np.float64]]:
    """(is_revolute, axis in the joint frame) of a one-DOF joint of a Pinocchio model.

    Raises
    ------
    ValueError
        For a joint that is not one-DOF revolute or prismatic, or a revolute axis not of unit
        length.
    """
    joint = model.joints[jid]
    name = joint.shortname()
    for prefix, revolute in (("JointModelR", True), ("JointModelP", False)):
        suffix = name[len(prefix) :]
        if name.startswith(prefix) and suffix in _ALIGNED_AXES:
            return revolute, np.array(_ALIGNED_AXES[suffix])
    if name in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
        axis = np.array(joint.extract().axis, dtype=float)
        revolute = name.startswith("JointModelR")
        # Pinocchio uses the axis as given (S = axis); a prismatic axis of another length only
        # rescales θ, but a revolute one would make its rotation matrix improper
        if revolute and abs(np.linalg.norm(axis) - 1.0) > 1e-12:
            raise ValueError(
                f"joint {model.names[jid]!r} has a revolute axis of length "
                f"{np.linalg.norm(axis):.6g}, not 1"
            )
        return revolute, axis
    raise ValueError(
        f"joint {model.names[jid]!r} is a {name}: only one-DOF revolute and prismatic joints "
        "are supported"
    )


def _symmetric(m: Any) -> Any:
    """The symmetric matrix of the upper triangle of m (the lower one is never evaluated)."""
    upper = ca.triu(m)
    return upper + ca.triu(m, False).T


def aba_casadi(model: pin.Model, damping: ArrayLike, q: Any, qd: Any, u: Any) -> Any:
    """θ̈ = ABA(θ, θ̇, u − Dθ̇), Featherstone's Articulated-Body Algorithm in CasADi SX.

    Spatial vectors are in Pinocchio's order (linear; angular), every quantity of body i in the
    frame of joint i (after its motion); gravity enters as the base's acceleration −g. The motion
    transform from the parent's frame to joint i's is split into the constant one of the joint
    placement and the joint's own (a rotation about, or a translation along, its axis), so that
    the constant's zeros stay structural. Works on any kinematic tree (``model.parents``) of
    one-DOF revolute / prismatic joints with any axis.

    Parameters
    ----------
    model
        The Pinocchio model (nq = nv = n); its gravity, joint placements and inertias are read.
    damping
        Viscous damping d_i [N·m·s/rad or N·s/m], shape (n,).
    q, qd, u
        θ [rad or m], θ̇ [rad/s or m/s] and the torques [N·m or N], SX columns of length n.

    Returns
    -------
    Any
        θ̈ [rad/s² or m/s²], an SX column of length n.
    """
    n, nj = model.nv, model.njoints
    d = np.asarray(damping, dtype=float)
    tau = u - d * qd if np.any(d != 0.0) else u
    parents = list(model.parents)
    zero3 = ca.SX(3, 3)

    x_place: list[Any] = [None] * nj  # actInv of the joint placement, constant 6×6
    x_joint: list[Any] = [None] * nj  # actInv of the joint's motion, 6×6
    vel: list[Any] = [None] * nj  # spatial velocity of body i in frame i
    bias_acc: list[Any] = [None] * nj  # c_i = v_i × (S_i θ̇_i)
    ia: list[Any] = [None] * nj  # articulated inertia, 6×6
    pa: list[Any] = [None] * nj  # articulated bias force
    sub: list[Any] = [None] * nj  # motion subspace S_i, 6×1
    iv = [0] * nj
    vel[0] = ca.SX(6, 1)

    # pass 1: velocities, velocity-product accelerations and bias forces, root to leaves
    for i in range(1, nj):
        revolute, axis = _joint_axis(model, i)
        k = iv[i] = model.joints[i].idx_v
        placement = model.jointPlacements[i]
        x_place[i] = _motion_act_inv(
            np.asarray(placement.rotation, dtype=float),
            np.asarray(placement.translation, dtype=float),
        )
        if revolute:
            c, s = ca.cos(q[k]), ca.sin(q[k])
            kx = _skew_np(axis)
            # Rodrigues: R_j = I + s K + (1 − c) K², R_jᵀ = I − s K + (1 − c) K²
            rjt = _const(np.eye(3)) - s * _const(kx) + (1 - c) * _const(kx @ kx)
            x_joint[i] = ca.blockcat([[rjt, zero3], [zero3, rjt]])
            sub[i] = _const(np.r_[np.zeros(3), axis].reshape(6, 1))
        else:
            eye = _const(np.eye(3))
            x_joint[i] = ca.blockcat([[eye, -q[k] * _const(_skew_np(axis))], [zero3, eye]])
            sub[i] = _const(np.r_[axis, np.zeros(3)].reshape(6, 1))
        vj = sub[i] * qd[k]
        v_i = ca.mtimes(x_joint[i], ca.mtimes(x_place[i], vel[parents[i]])) + vj
        vel[i] = v_i
        v_lin, v_ang = v_i[:3], v_i[3:]
        bias_acc[i] = ca.vertcat(
            ca.cross(v_ang, vj[:3]) + ca.cross(v_lin, vj[3:]), ca.cross(v_ang, vj[3:])
        )
        inertia = _const(np.asarray(model.inertias[i].matrix(), dtype=float))
        ia[i] = inertia
        momentum = ca.mtimes(inertia, v_i)
        f_lin, f_ang = momentum[:3], momentum[3:]
        pa[i] = ca.vertcat(ca.cross(v_ang, f_lin), ca.cross(v_ang, f_ang) + ca.cross(v_lin, f_lin))

    # pass 2: articulated inertias and bias forces, leaves to root
    big_u: list[Any] = [None] * nj
    big_d: list[Any] = [None] * nj
    small_u: list[Any] = [None] * nj
    for i in range(nj - 1, 0, -1):
        big_u[i] = ca.mtimes(ia[i], sub[i])
        big_d[i] = ca.mtimes(sub[i].T, big_u[i])
        small_u[i] = tau[iv[i]] - ca.mtimes(sub[i].T, pa[i])
        lam = parents[i]
        if lam == 0:
            continue
        i_a = ia[i] - _symmetric(ca.mtimes(big_u[i], big_u[i].T) / big_d[i])
        p_a = pa[i] + ca.mtimes(i_a, bias_acc[i]) + big_u[i] * (small_u[i] / big_d[i])
        xj, xp = x_joint[i], x_place[i]
        in_joint = _symmetric(ca.mtimes([xj.T, i_a, xj]))
        ia[lam] = ia[lam] + _symmetric(ca.mtimes([xp.T, in_joint, xp]))
        pa[lam] = pa[lam] + ca.mtimes(xp.T, ca.mtimes(xj.T, p_a))

    # pass 3: accelerations, root to leaves
    g = model.gravity
    acc: list[Any] = [None] * nj
    acc[0] = -_const(np.r_[g.linear, g.angular].reshape(6, 1))
    qdd: list[Any] = [None] * n
    for i in range(1, nj):
        a_i = ca.mtimes(x_joint[i], ca.mtimes(x_place[i], acc[parents[i]])) + bias_acc[i]
        qdd_i = (small_u[i] - ca.mtimes(big_u[i].T, a_i)) / big_d[i]
        qdd[iv[i]] = qdd_i
        acc[i] = a_i + sub[i] * qdd_i
    return ca.vertcat(*qdd)


def _dynamics_function(model: pin.Model, damping: ArrayLike) -> ca.Function:
    """The SX function (θ, θ̇, u) ↦ θ̈ of :func:`aba_casadi`."""
    n = model.nv
    q, qd, u = ca.SX.sym("q", n), ca.SX.sym("qd", n), ca.SX.sym("u", n)
    return ca.Function("aba", [q, qd, u], [aba_casadi(model, damping, q, qd, u)])


def _sample_box(
    rng: np.random.Generator, lo: NDArray[np.float64], hi: NDArray[np.float64], default: float
) -> NDArray[np.float64]:
    """Uniform samples in [lo, hi], with ±default where a bound is infinite."""
    return rng.uniform(np.maximum(lo, -default), np.minimum(hi, default))


def check_dynamics(robot: nearopt.Robot, samples: int = 20, seed: int = 0) -> float:
    """Largest |θ̈ of :func:`aba_casadi` − θ̈ of ``pinocchio.aba``| at seeded random states.

    θ within the position limits (clipped to ±π), |θ̇| ≤ min(v_max, 3) and u within the effort
    limits, drawn by NumPy's default generator; Pinocchio's side is
    ``pinocchio.aba(model, data, θ, θ̇, u − Dθ̇)``.

    Parameters
    ----------
    robot
        The arm.
    samples
        Number of random (θ, θ̇, u).
    seed
        Seed of the generator.

    Returns
    -------
    float
        The largest absolute difference [rad/s² or m/s²].
    """
    model = robot.model
    data = model.createData()
    fd = _dynamics_function(model, robot.damping)
    lim = robot.limits
    rng = np.random.default_rng(seed)
    speed = np.minimum(lim.velocity, 3.0)
    worst = 0.0
    for _ in range(samples):
        q = _sample_box(rng, lim.position_lower, lim.position_upper, np.pi)
        qd = rng.uniform(-speed, speed)
        u = _sample_box(rng, lim.effort_lower, lim.effort_upper, 10.0)
        ours = np.asarray(fd(q, qd, u)).ravel()
        theirs = np.asarray(pin.aba(model, data, q, qd, u - robot.damping * qd)).ravel()
        worst = max(worst, float(np.max(np.abs(ours - theirs))))
    return worst


_CHECKED: dict[tuple[int, bytes], tuple[pin.Model, float]] = {}


def _checked_dynamics(robot: nearopt.Robot) -> float:
    """:func:`check_dynamics` once per (model, damping); raise if it exceeds ``DYNAMICS_TOL``."""
    key = (id(robot.model), np.asarray(robot.damping, dtype=float).tobytes())
    if key not in _CHECKED:
        _CHECKED[key] = (robot.model, check_dynamics(robot))
    err = _CHECKED[key][1]
    if not err <= DYNAMICS_TOL:
        raise RuntimeError(
            f"the CasADi ABA of {robot.name} and pinocchio.aba disagree by {err:.3g} rad/s²"
        )
    return err


# ---------------------------------------------------------------------------------- transcription
def _rk4_function(model: pin.Model, damping: ArrayLike, substeps: int) -> ca.Function:
    """The shooting map of one interval of length h [s]: ``substeps`` RK4 steps of h / substeps.

    (x, u, h) ↦ (x at the end, the states after the first substeps − 1 steps as the columns of a
    (2n, substeps − 1) matrix), x = (θ, θ̇), u constant.
    """
    n = model.nv
    x, u, h = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n), ca.SX.sym("h")
    fd = _dynamics_function(model, damping)

    def rhs(z: Any) -> Any:
        return ca.vertcat(z[n:], fd(z[:n], z[n:], u))

    dt = h / substeps
    z, inner = x, []
    for j in range(substeps):
        k1 = rhs(z)
        k2 = rhs(z + dt / 2 * k1)
        k3 = rhs(z + dt / 2 * k2)
        k4 = rhs(z + dt * k3)
        z = z + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if j < substeps - 1:
            inner.append(z)
    return ca.Function("rk4", [x, u, h], [z, ca.horzcat(ca.SX(2 * n, 0), *inner)])


_NLPS: dict[tuple[Any, ...], _Transcription] = {}


def _assemble(shape: tuple[int, int], rows: Any, cols: Any, sources: Any, values: Any) -> Any:
    """The sparse MX matrix with entry (rows[e], cols[e]) = values[sources[e]] (no duplicates)."""
    rows, cols, sources = (np.asarray(a, dtype=np.int64) for a in (rows, cols, sources))
    order = np.lexsort((rows, cols))
    colind = np.searchsorted(cols[order], np.arange(shape[1] + 1)).tolist()
    pattern = ca.Sparsity(shape[0], shape[1], colind, rows[order].tolist())
    return ca.MX(pattern, values[sources[order].tolist()])


@dataclass(frozen=True)
class _IntervalFunctions:
    """Per-interval SX functions of z = (x_k, u_k, h), h = te/K the interval length (internal).

    Their output y = (x at the interval's end (2n), then the checked inner states: the selected
    rows of each state between two RK4 substeps, substep after substep).

    Attributes
    ----------
    out
        (x, u, h) ↦ y.
    jac
        (x, u, h) ↦ (y, ∂y/∂z), the Jacobian dense (len(y), 3n + 1).
    hess
        (x, u, h, λ, σ, w) ↦ the upper triangle of ∇²_z (λᵀ y + σ h Σ_i w_i u_i²) as a column
        of its nonzeros in column-major order.
    inner_rows
        The rows of x (0..2n−1) checked at the inner substep states.
    """

    out: ca.Function
    jac: ca.Function
    hess: ca.Function
    inner_rows: tuple[int, ...]


def _upper_triangle(size: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Row and column indices of the upper triangle of a size × size matrix, column-major."""
    rows, cols = np.triu_indices(size)
    order = np.lexsort((rows, cols))
    return rows[order], cols[order]


_INTERVALS: dict[tuple[Any, ...], tuple[pin.Model, _IntervalFunctions]] = {}


def _interval_functions(
    robot: nearopt.Robot, substeps: int, inner_rows: tuple[int, ...]
) -> _IntervalFunctions:
    """The cached :class:`_IntervalFunctions` of an arm (independent of K)."""
    key = (id(robot.model), np.asarray(robot.damping, dtype=float).tobytes(), substeps, inner_rows)
    if key in _INTERVALS:
        return _INTERVALS[key][1]
    n = robot.n
    step = _rk4_function(robot.model, robot.damping, substeps)
    x, u, h = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n), ca.SX.sym("h")
    z = ca.vertcat(x, u, h)
    end, inner = step(x, u, h)
    y = ca.vertcat(end, ca.vec(inner[list(inner_rows), :])) if inner_rows else end
    lam, sigma, w = ca.SX.sym("lam", y.numel()), ca.SX.sym("sigma"), ca.SX.sym("w", n)
    tag = f"{robot.name}_{substeps}"
    f_out = ca.Function(f"out_{tag}", [x, u, h], [y])
    f_jac = ca.Function(f"jac_{tag}", [x, u, h], [y, ca.densify(ca.jacobian(y, z))])
    lagrangian = ca.dot(lam, y) + sigma * h * ca.dot(w, u**2)
    hess = ca.densify(ca.hessian(lagrangian, z)[0])
    rows, cols = _upper_triangle(z.numel())
    entries = ca.vertcat(*[hess[int(i), int(j)] for i, j in zip(rows, cols, strict=True)])
    f_hess = ca.Function(f"hess_{tag}", [x, u, h, lam, sigma, w], [entries])
    funcs = _IntervalFunctions(f_out, f_jac, f_hess, inner_rows)
    _INTERVALS[key] = (robot.model, funcs)
    return funcs


def _transcription(
    robot: nearopt.Robot,
    K: int,
    substeps: int,
    tol: float,
    max_iter: int,
    *,
    inner_rows: tuple[int, ...] = (),
    threads: int | None = None,
    expand: bool = False,
) -> _Transcription:
    """The cached multiple-shooting NLP of an arm: weights its parameter, limits and guess inputs.

    Decision vector w = (vec X, vec U, te), X (2n, K+1) the node states, U (n, K) the torques;
    objective te + te/K Σ_k Σ_i w_i U_ik². Constraints, interval after interval: the continuity
    y_end(x_k, u_k, te/K) − x_{k+1} = 0 of the RK4 map (mapped over the K intervals), then the
    ``inner_rows`` of the states between its substeps (to be bounded by the limits).

    The constraint Jacobian and the Hessian of the Lagrangian are assembled here from the
    per-interval SX derivatives of :func:`_interval_functions`, mapped over the intervals (on
    ``threads`` threads; default 2 for n ≥ 4), and passed to IPOPT as ``jac_g`` and ``hess_lag``.
    With ``expand=True`` CasADi derives them from the NLP expanded to SX instead: the same numbers,
    but its build time grows with K × the size of the interval's Hessian (100 s for ur5 at
    K = 100, against 0.6 s here).
    """
    model = robot.model
    if threads is None:
        threads = min(2, os.cpu_count() or 1) if robot.n >= 4 else 1
    key = (
        id(model),
        np.asarray(robot.damping, dtype=float).tobytes(),
        K,
        substeps,
        tol,
        max_iter,
        inner_rows,
        threads,
        expand,
    )
    if key in _NLPS:
        return _NLPS[key]
    t0 = time.perf_counter()
    n, nz = robot.n, 3 * robot.n + 1
    n2 = 2 * n
    nx = n2 * (K + 1)
    nw = nx + n * K + 1
    funcs = _interval_functions(robot, substeps, inner_rows)
    ny = funcs.out.numel_out(0)  # constraints per interval
    X, U, te = ca.MX.sym("X", n2, K + 1), ca.MX.sym("U", n, K), ca.MX.sym("te")
    weights = ca.MX.sym("w", n)
    decision = ca.veccat(X, U, te)
    options: dict[str, Any] = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": tol,
        "ipopt.max_iter": max_iter,
        "ipopt.mu_strategy": "adaptive",
    }
    h = te / K
    targets = ca.vertcat(X[:, 1:], ca.MX(ny - n2, K))
    if expand:
        options["expand"] = True
    else:
        mode = ("thread", threads) if threads > 1 else ("serial",)
        # global index of z_k = (x_k, u_k, te) for every interval k, shape (K, nz);
        # ∂/∂te = ∂/∂h / K
        k = np.arange(K)[:, None]
        zidx = np.hstack(
            [k * n2 + np.arange(n2), nx + k * n + np.arange(n), np.full((K, 1), nw - 1)]
        )
        zscale = np.r_[np.ones(nz - 1), 1.0 / K]

        # constraint Jacobian, rows k·ny + r: ∂y/∂z_k, and −I for x_{k+1}
        y_all, jac_all = funcs.jac.map(K, *mode)(X[:, :K], U, h)
        r, c = np.meshgrid(np.arange(ny), np.arange(nz), indexing="ij")
        kk, rr = np.meshgrid(np.arange(K), np.arange(n2), indexing="ij")
        rows = np.r_[(k[:, :, None] * ny + r[None]).ravel(), (kk * ny + rr).ravel()]
        cols = np.r_[zidx[:, c].ravel(), n2 + (kk * n2 + rr).ravel()]
        src = np.r_[
            ((k[:, :, None] * nz + c[None]) * ny + r[None]).ravel(), np.full(n2 * K, ny * nz * K)
        ]
        jac_scale = np.tile(np.repeat(zscale, ny), K)
        values = ca.vertcat(ca.vec(jac_all) * jac_scale, -1)
        jac = _assemble((ny * K, nw), rows, cols, src, values)

        # Hessian of the Lagrangian, upper triangle: per-interval blocks, (te, te) summed
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", ny * K)
        h_all = funcs.hess.map(K, *mode)(X[:, :K], U, h, ca.reshape(lam_g, ny, K), lam_f, weights)
        ia, ib = _upper_triangle(nz)
        m = len(ia)
        tt = m - 1  # (te, te) is the last entry in column-major order
        keep = np.arange(m - 1)
        rows = np.r_[zidx[:, ia[keep]].ravel(), nw - 1]
        cols = np.r_[zidx[:, ib[keep]].ravel(), nw - 1]
        src = np.r_[(k * m + keep[None]).ravel(), m * K]
        h_scaled = h_all * (zscale[ia] * zscale[ib])
        values = ca.vertcat(ca.vec(h_scaled), ca.sum2(h_scaled[tt, :]))
        hess = _assemble((nw, nw), rows, cols, src, values)

        options["jac_g"] = ca.Function(
            "nlp_jac_g",
            [decision, weights],
            [ca.vec(y_all - targets), jac],
            ["x", "p"],
            ["g", "jac_g_x"],
        )
        options["hess_lag"] = ca.Function(
            "nlp_hess_l",
            [decision, weights, lam_f, lam_g],
            [hess],
            ["x", "p", "lam_f", "lam_g"],
            ["triu_hess_gamma_x_x"],
        )
    nlp = {
        "x": decision,
        "p": weights,
        "f": te + h * ca.dot(weights, ca.sum2(U**2)),
        "g": ca.vec(funcs.out.map(K)(X[:, :K], U, h) - targets),
    }
    solver = ca.nlpsol(f"reference_{robot.name}_{K}", "ipopt", nlp, options)
    built = _Transcription(model, n, K, solver, time.perf_counter() - t0)
    _NLPS[key] = built
    return built


def _te_estimate(
    robot: nearopt.Robot, q0: NDArray[np.float64], qe: NDArray[np.float64], velocity_limits: bool
) -> float:
    """A rough minimum time [s]: per joint bang-bang (speed-capped) at acceleration u_max/H_ii."""
    lim = robot.limits
    dist = np.abs(qe - q0)
    h = robot.mass_matrix(0.5 * (q0 + qe))
    g = robot.gravity_torque(0.5 * (q0 + qe))
    u_free = np.maximum(np.minimum(lim.effort_upper - g, g - lim.effort_lower), 1e-3)
    acc = u_free / np.maximum(np.diag(h), 1e-9)
    t = 2.0 * np.sqrt(dist / acc)
    if velocity_limits:
        v = lim.velocity
        capped = np.isfinite(v) & (dist > v**2 / acc)
        t = np.where(capped, dist / np.where(capped, v, 1.0) + v / acc, t)
    return float(max(np.max(t), 0.05))


def _initial_guess(
    robot: nearopt.Robot,
    q0: NDArray[np.float64],
    qe: NDArray[np.float64],
    K: int,
    te: float,
    bump: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    ends: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """Nodes on θ0 → θe (+ bump·sin(π s)), timed by s = 3τ² − 2τ³; u = gravity torque, clipped.

    Returns the decision vector (X, U, te) packed as :meth:`_Transcription.pack`.
    """
    tau = np.linspace(0.0, 1.0, K + 1)
    s, ds = 3 * tau**2 - 2 * tau**3, (6 * tau - 6 * tau**2) / te
    q = q0 + np.outer(s, qe - q0) + np.outer(np.sin(np.pi * s), bump)
    qd = np.outer(ds, qe - q0) + np.outer(np.pi * np.cos(np.pi * s) * ds, bump)
    q = np.clip(q, lo, hi)
    q[0], q[-1] = q0, qe
    qd[0], qd[-1] = (0.0, 0.0) if ends is None else ends
    mid = 0.5 * (q[:-1] + q[1:])
    lim = robot.limits
    u = np.array([robot.gravity_torque(m) for m in mid])
    u = np.clip(u, lim.effort_lower, lim.effort_upper)
    return _Transcription.pack(np.hstack([q, qd]).T, u.T, te)


def solve_reference(
    robot: nearopt.Robot,
    q0: ArrayLike,
    qe: ArrayLike,
    weights: ArrayLike,
    *,
    intervals: int = 100,
    substeps: int = 2,
    velocity_limits: bool = True,
    position_limits: bool = True,
    starts: int = 4,
    seed: int = 0,
    te_guess: float | None = None,
    tol: float = 1e-9,
    max_iter: int = 3000,
    inner_limits: bool = True,
    duration: float | None = None,
    qd0: ArrayLike | None = None,
    qde: ArrayLike | None = None,
    guesses: Sequence[Any] = (),
) -> ReferenceSolution:
    """Solve the free-final-time problem by RK4 multiple shooting and IPOPT, from several starts.

    Parameters
    ----------
    robot
        The arm; its effort limits always apply, its damping is part of the dynamics.
    q0, qe
        Start and goal configurations [rad or m], shape (n,); the arm rests at both.
    weights
        w_i ≥ 0 of f0 = 1 + Σ_i w_i u_i² [1/(N·m)²], scalar or (n,); 0 is time-optimal.
    intervals
        K, the number of equal shooting intervals (piecewise-constant torques).
    substeps
        RK4 steps per interval.
    velocity_limits, position_limits
        Bound |θ̇| ≤ v_max, respectively θ_min ≤ θ ≤ θ_max, at the nodes (box bounds) and, with
        ``inner_limits``, at the states between the RK4 substeps inside every interval.
    starts
        Initial guesses: all on the straight joint line θ0 → θe, with te guesses geometric around
        ``te_guess`` (factors 1, 2, 0.5, 1.41, 0.71, ...); starts 3, 4, ... add a seeded random
        bump b·sin(π s) (b ~ N(0, (0.25 |θe − θ0| + 0.1 rad)²) per joint) to the line.
    seed
        Seed of the bumps' generator.
    te_guess
        Centre of the te guesses [s]; by default a bang-bang estimate from the speed and torque
        limits.
    tol, max_iter
        IPOPT's ``tol`` and ``max_iter``.
    inner_limits
        Also bound the speeds and positions (of the joints that have limits) at the substeps'
        boundaries inside every interval (if ``substeps`` ≥ 2). Bounds at the nodes only let the
        optimum bulge over a speed limit between two nodes, by 0.9 % of the limit for ur5 at
        K = 20 and still at K = 100; with the midpoint of every interval bounded too
        (``substeps`` = 2) the excess measured on ur5 and panda was 1e-4 to 1.5e-3 of the limit.
        A joint can still bounce off a position limit between two bounded points (a ur5 wrist
        without speed limits by 3.5 mrad at K = 100).
    duration
        te fixed to this [s] (its bounds both set to it; the starts' te guesses then all T), or
        None: te free.
    qd0, qde
        θ̇ at the first and the last node [rad/s] (None: 0, at rest); the starts' guesses take
        them at their ends.
    guesses
        Further starts: motions (callables m(t, order) with ``duration``, and ``torque(t)``, as
        nearopt's), sampled at the K + 1 nodes and the intervals' midpoints.

    Returns
    -------
    ReferenceSolution
        The start of lowest J among those IPOPT solved whose open-loop re-simulation (or, for
        te > 0.25 s, windowed re-simulation) ends within ``RESIM_TOL`` = 1e-4 rad of θe
        (see :func:`resimulate`).

    Raises
    ------
    RuntimeError
        If no start is solved and passes the re-simulation, or if the CasADi dynamics disagree
        with Pinocchio's.
    """
    t_begin = time.perf_counter()
    n = robot.n
    q0 = np.asarray(q0, dtype=float).reshape(n)
    qe = np.asarray(qe, dtype=float).reshape(n)
    w = np.broadcast_to(np.asarray(weights, dtype=float), (n,)).copy()
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError(f"weights must be finite and ≥ 0, got {w}")
    if starts < 1 or intervals < 1 or substeps < 1:
        raise ValueError("starts, intervals and substeps must be ≥ 1")
    _checked_dynamics(robot)
    K = intervals
    lim = robot.limits
    q_lo = lim.position_lower if position_limits else np.full(n, -np.inf)
    q_hi = lim.position_upper if position_limits else np.full(n, np.inf)
    v_max = lim.velocity if velocity_limits else np.full(n, np.inf)
    inner_rows: tuple[int, ...] = ()
    if inner_limits and substeps > 1:
        checked = np.r_[np.isfinite(q_lo) | np.isfinite(q_hi), np.isfinite(v_max)]
        inner_rows = tuple(int(i) for i in np.flatnonzero(checked))
    nlp = _transcription(robot, K, substeps, tol, max_iter, inner_rows=inner_rows)
    rows = list(inner_rows)
    inner_lo = np.tile(np.r_[q_lo, -v_max][rows], substeps - 1) if rows else np.empty(0)
    inner_hi = np.tile(np.r_[q_hi, v_max][rows], substeps - 1) if rows else np.empty(0)
    lbg = np.tile(np.r_[np.zeros(2 * n), inner_lo], K)
    ubg = np.tile(np.r_[np.zeros(2 * n), inner_hi], K)
    x_lo = np.tile(np.r_[q_lo, -v_max][:, None], (1, K + 1))
    x_hi = np.tile(np.r_[q_hi, v_max][:, None], (1, K + 1))
    v0 = np.zeros(n) if qd0 is None else np.asarray(qd0, dtype=float).reshape(n)
    ve = np.zeros(n) if qde is None else np.asarray(qde, dtype=float).reshape(n)
    x_lo[:, 0] = x_hi[:, 0] = np.r_[q0, v0]
    x_lo[:, -1] = x_hi[:, -1] = np.r_[qe, ve]
    u_lo = np.tile(lim.effort_lower[:, None], (1, K))
    u_hi = np.tile(lim.effort_upper[:, None], (1, K))
    te_bounds = TE_BOUNDS if duration is None else (float(duration), float(duration))
    lbx = _Transcription.pack(x_lo, u_lo, te_bounds[0])
    ubx = _Transcription.pack(x_hi, u_hi, te_bounds[1])

    te0 = te_guess if te_guess is not None else _te_estimate(robot, q0, qe, velocity_limits)
    rng = np.random.default_rng(seed)
    scale = 0.25 * np.abs(qe - q0) + 0.1
    guess_lo, guess_hi = np.maximum(q_lo, -1e6), np.minimum(q_hi, 1e6)
    runs: list[_Start] = []
    for j in range(starts + len(guesses)):
        if j < starts:
            factor = 2.0 ** _TE_EXPONENTS[j % len(_TE_EXPONENTS)]
            te_j = float(np.clip(te0 * factor, 2 * TE_BOUNDS[0], 0.5 * TE_BOUNDS[1]))
            te_j = te_j if duration is None else float(duration)
            bump = rng.normal(0.0, scale) if j >= 2 else np.zeros(n)
            x0 = _initial_guess(robot, q0, qe, K, te_j, bump, guess_lo, guess_hi, (v0, ve))
        else:
            x0 = _motion_guess(guesses[j - starts], K, duration)
        sol = nlp.solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=w)
        stats = nlp.solver.stats()
        status = str(stats["return_status"])
        runs.append(
            _Start(
                j,
                status,
                float(sol["f"]),
                int(stats["iter_count"]),
                np.asarray(sol["x"], dtype=float).ravel(),
            )
        )

    solved = [r for r in runs if r.status in ACCEPTED]
    best: tuple[_Start, ResimulationResult] | None = None
    rejected: list[str] = []
    for run in sorted(solved, key=lambda r: r.J):
        X, U, te = nlp.unpack(run.w)
        check = resimulate(robot, X, U.T, te, v_max=v_max, q_lo=q_lo, q_hi=q_hi, qe=qe)
        if min(check.end_position, check.window_position) <= RESIM_TOL:
            best = (run, check)
            break
        rejected.append(
            f"start {run.index} (J={run.J:.6g}, te={te:.4g} s) re-simulates to "
            f"|Δθ(te)| = {check.end_position:.2e} rad, windowed {check.window_position:.2e} rad"
        )
    if best is None:
        statuses = ", ".join(f"{r.status} (J={r.J:.6g})" for r in runs)
        raise RuntimeError(
            f"IPOPT found no accepted solution for {robot.name} from {starts} starts: {statuses}"
            + ("; " + "; ".join(rejected) if rejected else "")
            + f" (tolerance {RESIM_TOL:g} rad; more intervals or substeps may help)"
        )
    run, check = best
    X, U, te = nlp.unpack(run.w)
    u = U.T.copy()
    h = te / K
    J = float(h * np.sum(1.0 + (u**2) @ w))
    return ReferenceSolution(
        J=J,
        te=te,
        t=np.linspace(0.0, te, K + 1),
        q=X[:n].T.copy(),
        qd=X[n:].T.copy(),
        u=u,
        status=run.status,
        starts=starts,
        solved=len(solved),
        wall_time=time.perf_counter() - t_begin,
        resim_end_position=check.end_position,
        resim_end_speed=check.end_speed,
        resim_speed_excess=check.speed_excess,
        resim_position_excess=check.position_excess,
        resim_window_position=check.window_position,
        resim_window_speed=check.window_speed,
        start_costs=tuple(r.J if r.status in ACCEPTED else math.nan for r in runs),
        start_te=tuple(float(r.w[-1]) if r.status in ACCEPTED else math.nan for r in runs),
        start_statuses=tuple(r.status for r in runs),
        iterations=run.iterations,
        rejected=len(rejected),
    )


def _motion_guess(motion: Any, K: int, duration: float | None) -> NDArray[np.float64]:
    """The decision vector of a motion sampled at K + 1 equal nodes (torques at the midpoints),
    te its duration (or ``duration``, the motion stretched to it)."""
    te = float(motion.duration)
    t = np.linspace(0.0, te, K + 1)
    mid = 0.5 * (t[:-1] + t[1:])
    stretch = 1.0 if duration is None else te / float(duration)
    q = np.asarray(motion(t, 0), dtype=float)
    qd = np.asarray(motion(t, 1), dtype=float) * stretch
    u = np.asarray(motion.torque(mid), dtype=float)
    return _Transcription.pack(np.hstack([q, qd]).T, u.T, te / stretch)


# ---------------------------------------------------------------------------------- re-simulation
def _integrate(
    robot: nearopt.Robot,
    x0: NDArray[np.float64],
    u: NDArray[np.float64],
    t: NDArray[np.float64],
    dense: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Integrate ẋ = (θ̇, aba(θ, θ̇, u_k − Dθ̇)) over the intervals [t_k, t_k+1], u_k constant.

    DOP853 with rtol 1e-10 and atol 1e-12, restarted at every interval boundary. Returns the state
    at every node (len(t), 2n) and ``dense`` samples per interval: times (M,), states (M, 2n).
    """
    model, data, damping, n = robot.model, robot.model.createData(), robot.damping, robot.n
    aba = pin.aba
    nodes = [np.asarray(x0, dtype=float)]
    times, states = [], []
    for k in range(len(t) - 1):
        uk = u[k]

        def rhs(_t: float, x: NDArray[np.float64], uk: NDArray[np.float64] = uk) -> Any:
            return np.concatenate([x[n:], aba(model, data, x[:n], x[n:], uk - damping * x[n:])])

        span = (float(t[k]), float(t[k + 1]))
        t_eval = np.linspace(span[0], span[1], dense + 1) if dense else None
        sol = solve_ivp(
            rhs, span, nodes[-1], method="DOP853", rtol=1e-10, atol=1e-12, t_eval=t_eval
        )
        if not sol.success:
            raise RuntimeError(f"re-simulation failed on interval {k}: {sol.message}")
        if dense:
            times.append(sol.t[:-1])
            states.append(sol.y[:, :-1].T)
        nodes.append(sol.y[:, -1])
    node_states = np.array(nodes)
    if dense:
        times.append(np.array([t[-1]]))
        states.append(node_states[-1:])
        return node_states, np.concatenate(times), np.vstack(states)
    return node_states, np.empty(0), np.empty((0, 2 * n))


def resimulate(
    robot: nearopt.Robot,
    X: NDArray[np.float64],
    u: NDArray[np.float64],
    te: float,
    *,
    v_max: NDArray[np.float64],
    q_lo: NDArray[np.float64],
    q_hi: NDArray[np.float64],
    qe: NDArray[np.float64],
    window: float = WINDOW,
    dense: int = DENSE,
) -> ResimulationResult:
    """Re-simulate piecewise-constant torques with ``pinocchio.aba`` and measure the errors.

    Two re-simulations, each by :func:`_integrate` (DOP853, rtol 1e-10, atol 1e-12, restarted at
    every interval boundary, θ̈ = aba(θ, θ̇, u − Dθ̇)):

    - open loop, from the first node (θ0, 0) over [0, te]: its end errors measure the whole motion,
      but over a long motion they include the amplification of the integration error by unstable
      modes (an arm falling under gravity), up to 10³ × over 3 s;
    - windowed, restarted from IPOPT's node state at the first node at or after every multiple of
      ``window`` seconds: its errors at the window ends measure the transcription's integration
      error itself. It is sampled ``dense`` times per interval, and the speed and position excess
      are measured on it. For te ≤ ``window`` it is the open-loop re-simulation.

    Parameters
    ----------
    robot
        The arm.
    X
        IPOPT's node states (θ; θ̇), shape (2n, K + 1) [rad, rad/s].
    u
        The torques, shape (K, n) [N·m].
    te
        Final time [s].
    v_max, q_lo, q_hi
        The speed [rad/s] and position [rad] limits to measure against (inf where none), (n,).
    qe
        The goal [rad], (n,).
    window
        Window length [s].
    dense
        Samples per interval.

    Returns
    -------
    ResimulationResult
        The errors and the dense windowed re-simulation.
    """
    n = robot.n
    K = u.shape[0]
    t = np.linspace(0.0, te, K + 1)
    marks = [0]
    for k in range(1, K + 1):
        if k == K or t[k] >= window * len(marks):
            marks.append(k)
    worst_q = worst_v = 0.0
    times, states = [], []
    for a, b in zip(marks[:-1], marks[1:], strict=True):
        seg, t_seg, x_seg = _integrate(robot, X[:, a], u[a:b], t[a : b + 1], dense)
        worst_q = max(worst_q, float(np.max(np.abs(seg[-1, :n] - X[:n, b]))))
        worst_v = max(worst_v, float(np.max(np.abs(seg[-1, n:] - X[n:, b]))))
        times.append(t_seg if b == K else t_seg[:-1])
        states.append(x_seg if b == K else x_seg[:-1])
    t_dense, x_dense = np.concatenate(times), np.vstack(states)
    if len(marks) > 2:
        nodes, _, _ = _integrate(robot, X[:, 0], u, t, 0)
        end = nodes[-1]
    else:
        end = x_dense[-1]
    end_position = float(np.max(np.abs(end[:n] - qe)))
    end_speed = float(np.max(np.abs(end[n:])))
    q_d, qd_d = x_dense[:, :n], x_dense[:, n:]
    limited = np.isfinite(v_max)
    speed_excess = (
        float(np.max(np.abs(qd_d[:, limited]) / v_max[limited]) - 1.0)
        if np.any(limited)
        else -math.inf
    )
    bounded = np.isfinite(q_lo) | np.isfinite(q_hi)
    position_excess = (
        float(np.max(np.maximum(q_lo - q_d, q_d - q_hi)[:, bounded]))
        if np.any(bounded)
        else -math.inf
    )
    return ResimulationResult(
        end_position, end_speed, speed_excess, position_excess, worst_q, worst_v, t_dense, q_d, qd_d
    )


# ---------------------------------------------------------------------------------- printing
HEADER = (
    f"{'case':<28}{'J':>11}{'te [s]':>9}{'wall [s]':>10}{'solved':>8}{'|Δθ(te)|':>10}"
    f"{'|θ̇(te)|':>10}{'win |Δθ|':>10}{'v excess':>10}{'θ excess':>10}  starts' J"
)


def format_row(name: str, sol: ReferenceSolution) -> str:
    """One line of the table of ``__main__`` (see :data:`HEADER`).

    Parameters
    ----------
    name
        The case's name.
    sol
        Its solution.

    Returns
    -------
    str
        J, te [s], wall time [s], starts solved / tried, the open-loop re-simulation's end errors
        [rad, rad/s], the windowed one's [rad], the dense speed excess [relative] and position
        excess [rad] (−inf: no limit), and every start's J (nan: not solved).
    """
    costs = " ".join(f"{c:.5g}" for c in sol.start_costs)
    return (
        f"{name:<28}{sol.J:>11.6f}{sol.te:>9.4f}{sol.wall_time:>10.1f}"
        f"{f'{sol.solved}/{sol.starts}':>8}{sol.resim_end_position:>10.1e}"
        f"{sol.resim_end_speed:>10.1e}{sol.resim_window_position:>10.1e}"
        f"{sol.resim_speed_excess:>10.1e}{sol.resim_position_excess:>10.1e}  {costs}"
    )


def range_pair(robot: nearopt.Robot) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """θ0 and θe at 30 % and 70 % of every joint's position range, the range clipped to ±π [rad].

    Parameters
    ----------
    robot
        The arm.

    Returns
    -------
    tuple of ndarray
        θ0 = lo + 0.3 (hi − lo) and θe = lo + 0.7 (hi − lo), each (n,).
    """
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    return lo + 0.3 * (hi - lo), lo + 0.7 * (hi - lo)


PAPER_Q0, PAPER_QE, PAPER_BETA = THETA_0, THETA_E, BETA  # the paper's example (Table 1, eq. 32)


def main() -> None:
    """Solve the paper's example and ur5 / panda motions; print :data:`HEADER` rows."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--K", type=int, default=100, help="shooting intervals")
    parser.add_argument("--substeps", type=int, default=2, help="RK4 steps per interval")
    parser.add_argument("--starts", type=int, default=4)
    parser.add_argument("--robots", nargs="*", default=["ur5", "panda"])
    parser.add_argument("--beta", type=float, default=PAPER_BETA, help="w_i of every joint")
    args = parser.parse_args()

    cases: list[tuple[str, nearopt.Robot, Any, Any, float, bool]] = [
        (
            "two_link paper example",
            nearopt.Robot.from_name("two_link"),
            PAPER_Q0,
            PAPER_QE,
            PAPER_BETA,
            True,
        ),
    ]
    for name in args.robots:
        robot = nearopt.Robot.from_name(name)
        q0, qe = range_pair(robot)
        cases.append((f"{name} 30→70 %, v limits", robot, q0, qe, args.beta, True))
        cases.append((f"{name} 30→70 %, no v limits", robot, q0, qe, args.beta, False))
    print(f"K = {args.K}, {args.substeps} RK4 steps per interval, {args.starts} starts")
    print(HEADER, flush=True)
    for label, robot, q0, qe, beta, speed in cases:
        check = _checked_dynamics(robot)
        try:
            sol = solve_reference(
                robot,
                q0,
                qe,
                beta,
                intervals=args.K,
                substeps=args.substeps,
                velocity_limits=speed,
                starts=args.starts,
            )
        except RuntimeError as exc:
            print(f"{label:<28}  failed: {exc}", flush=True)
            continue
        print(format_row(label, sol) + f"  (ABA check {check:.1e})", flush=True)


if __name__ == "__main__":
    main()
