"""The robot layer: a URDF arm on Pinocchio, with the quantities of the paper's eq. (1).

Notation (used throughout nearopt):

- θ ∈ ℝⁿ joint positions [rad or m], θ̇, θ̈ their time derivatives;
- u ∈ ℝⁿ actuator torques / forces [N·m or N];
- the dynamics of eq. (1), H(θ)θ̈ + h(θ, θ̇) + g(θ) + Dθ̇ = u, with H the joint-space inertia
  matrix, h the Coriolis and centrifugal terms, g the gravity torques and D = diag(d) the viscous
  damping of the URDF's ``<dynamics damping>``;
- the state x = (θ, θ̇) ∈ ℝ²ⁿ and the forward dynamics ẋ = f(x, u) of eq. (20), with Jacobians
  A = ∂f/∂x and B = ∂f/∂u (eqs. 24-26);
- along a path θ(s) with λ(s) = ds/dt (eq. 5), primes are s-derivatives, and eq. (10) gives
  u(s) = λ²[Hθ'' + h(θ, θ')] + λ[λ'Hθ' + Dθ'] + g, or with b = λ² and a = ½ db/ds = λλ',
  u = m·a + c·b + d·λ + g (the coefficient form a timing optimiser uses).

This is the only module of nearopt that calls Pinocchio's dynamics. Pinocchio's ABA and RNEA know no
joint damping, so Dθ̇ is added here, to the derivatives too.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import pinocchio as pin

from .. import catalog
from ..errors import ConfigurationError, URDFError
from .urdf import RateLimits, read_urdf

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, NDArray

__all__ = ["Robot", "JointLimits", "PathCoefficients", "NO_LIMIT", "check_robot"]

_ONE_DOF_JOINTS = (
    "JointModelRX",
    "JointModelRY",
    "JointModelRZ",
    "JointModelRevoluteUnaligned",
    "JointModelPX",
    "JointModelPY",
    "JointModelPZ",
    "JointModelPrismaticUnaligned",
)


def _check_no_nul(urdf: object, srdf: object) -> None:
    """A URDFError where a path holds a NUL character (the OS would raise a bare ValueError)."""
    for given, what in ((urdf, "URDF"), (srdf, "SRDF")):
        if given is not None and "\0" in str(given):
            raise URDFError(f"a path holds no NUL character: the {what} {str(given)!r:.80}")


def _readonly(x: ArrayLike) -> NDArray[np.float64]:
    a = np.array(x, dtype=float)
    a.setflags(write=False)
    return a


NO_LIMIT = 1e100
"""A speed or acceleration limit this large is none (inf); a larger effort limit is taken as this
(it cannot bind, and its square would overflow)."""


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits, read-only arrays of shape (n,).

    Attributes
    ----------
    position_lower, position_upper
        Joint position limits [rad or m]; ±inf where a joint has none (continuous joints).
    velocity
        Joint speed limits |θ̇_i| ≤ velocity_i [rad/s or m/s]; inf where none is declared.
    effort_lower, effort_upper
        Actuator limits u_min ≤ u ≤ u_max of eq. (2) [N·m or N].
    acceleration
        Joint acceleration limits |θ̈_i| ≤ acceleration_i [rad/s² or m/s²]; inf where none: from
        a URDF 1.2 ``<limit acceleration=… deceleration=…>`` (the smaller of the two: nearopt's
        limit holds for speeding up and slowing down alike), a MoveIt ``joint_limits.yaml``
        (:meth:`Robot.with_joint_limits`) or :meth:`Robot.with_limits`.
    names
        The joints' names, for messages (a :class:`Robot`'s limits carry its joints').
    jerk
        Joint jerk limits |θ⃛_i| ≤ jerk_i [rad/s³ or m/s³] the robot's files declare (URDF 1.2
        ``<limit jerk=…>``, ``joint_limits.yaml``) or :meth:`Robot.with_limits`; inf where none
        (the default). Where any is finite, :func:`~nearopt.plan` times the path it finds under
        them (:func:`~nearopt.timing.time_with_jerk_limits`).
    torque_rate
        Actuator torque-rate limits |u̇_i| ≤ torque_rate_i [N·m/s or N/s] (an actuator's
        bandwidth; no robot file declares one: :meth:`Robot.with_limits`); inf where none (the
        default). Where any is finite, :func:`~nearopt.plan` times the path it finds with a C¹
        timing that holds them (:mod:`nearopt.timing.rates`), as for jerk limits.

    Every array is made read-only; they must have one shape (n,), no NaN, and each lower limit at
    most its upper one (a :class:`~nearopt.ConfigurationError` otherwise).
    """

    position_lower: NDArray[np.float64]
    position_upper: NDArray[np.float64]
    velocity: NDArray[np.float64]
    effort_lower: NDArray[np.float64]
    effort_upper: NDArray[np.float64]
    acceleration: NDArray[np.float64]
    names: tuple[str, ...] = ()
    jerk: NDArray[np.float64] | None = None
    torque_rate: NDArray[np.float64] | None = None

    _ARRAYS = (
        "position_lower",
        "position_upper",
        "velocity",
        "effort_lower",
        "effort_upper",
        "acceleration",
        "jerk",
        "torque_rate",
    )

    def __post_init__(self) -> None:
        for key in ("jerk", "torque_rate"):
            if getattr(self, key) is None:
                object.__setattr__(self, key, np.full(np.shape(self.position_lower), np.inf))
        for key in self._ARRAYS:
            object.__setattr__(self, key, _readonly(getattr(self, key)))
        n = self.position_lower.shape
        if len(n) != 1 or any(getattr(self, key).shape != n for key in self._ARRAYS):
            raise ConfigurationError(
                "joint limits must all have one shape (n,), got "
                + ", ".join(f"{key} {getattr(self, key).shape}" for key in self._ARRAYS)
            )
        object.__setattr__(self, "names", tuple(self.names))
        if self.names and len(self.names) != n[0]:
            raise ConfigurationError(f"{len(self.names)} joint names for {n[0]} joints")
        for key in self._ARRAYS:
            if np.any(np.isnan(getattr(self, key))):
                i = int(np.argmax(np.isnan(getattr(self, key))))
                raise ConfigurationError(
                    f"{key} of joint {self._name(i)} is NaN", joint=self._joint(i)
                )
        for what, lo, hi in (
            ("position", self.position_lower, self.position_upper),
            ("effort", self.effort_lower, self.effort_upper),
        ):
            if np.any(lo > hi):
                i = int(np.argmax(lo > hi))
                raise ConfigurationError(
                    f"{what} limits of joint {self._name(i)}: lower {lo[i]:g} is above upper "
                    f"{hi[i]:g}",
                    joint=self._joint(i),
                )

    @property
    def smooth(self) -> bool:
        """Whether a jerk or torque-rate limit is finite: a motion then needs θ̈ continuous
        (a C¹ timing, :mod:`nearopt.timing.jerk`)."""
        return bool(np.any(np.isfinite(self.jerk)) or np.any(np.isfinite(self.torque_rate)))

    def _name(self, i: int) -> str:
        return repr(self.names[i]) if self.names else str(i)

    def _joint(self, i: int) -> str | None:
        return self.names[i] if self.names else None

    def check_within(
        self,
        q: ArrayLike,
        what: str = "q",
        degrees: bool = False,
        prismatic: ArrayLike | None = None,
    ) -> None:
        """Raise a :class:`~nearopt.ConfigurationError` naming the first joint of ``q`` (n,)
        outside its position limits, its value and the limits (a revolute joint's in degrees
        with ``degrees``: a request given in them; a ``prismatic`` joint's in m)."""
        q = np.asarray(q, dtype=float)
        outside = ~((self.position_lower <= q) & (q <= self.position_upper))
        if np.any(outside):
            i = int(np.argmax(outside))
            linear = prismatic is not None and bool(np.asarray(prismatic)[i])
            unit, suffix = ("deg", " deg") if degrees and not linear else ("rad", "")
            if linear:
                unit, suffix = "m", " m"
            value, low, high = (q[i], self.position_lower[i], self.position_upper[i])
            if degrees and not linear:
                value, low, high = np.rad2deg([value, low, high])
            raise ConfigurationError(
                f"{what}[{i}] = {value:.6g} {unit} is outside the position limits "
                f"[{low:.6g}, {high:.6g}]{suffix} of joint {self._name(i)}",
                joint=self._joint(i),
            )

    def sampling_box(self, span: float = np.pi) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The position limits with ±``span`` [rad] where a joint has none: a box to draw
        configurations from."""
        return (
            np.where(np.isfinite(self.position_lower), self.position_lower, -span),
            np.where(np.isfinite(self.position_upper), self.position_upper, span),
        )


class PathCoefficients(NamedTuple):
    """Coefficients of eq. (10) along a sampled path, each of shape (N, n).

    u = m·a + c·b + d·λ + g with b = λ², a = ½ db/ds, where m = Hθ', c = Hθ'' + h(θ, θ'),
    d = Dθ', g = g(θ).
    """

    m: NDArray[np.float64]
    c: NDArray[np.float64]
    d: NDArray[np.float64]
    g: NDArray[np.float64]


def _rate_arrays(
    rates: dict[str, RateLimits], names: list[str]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The joints' acceleration limits (the smaller of a URDF 1.2 acceleration and
    deceleration: nearopt's limit is one for both) and jerk limits, inf where none."""
    found = [rates.get(name) or RateLimits() for name in names]
    return (
        np.array([min(r.acceleration, r.deceleration) for r in found], dtype=float),
        np.array([r.jerk for r in found], dtype=float),
    )


class Robot:
    """A fixed-base arm loaded from a URDF into Pinocchio.

    Build one with :meth:`from_urdf` or :meth:`from_name`; it is immutable (use :meth:`with_limits`
    for a copy with other limits). Methods take one configuration as an array of shape (n,).

    Parameters
    ----------
    model
        The Pinocchio model of the arm, every joint one-dimensional (nq = nv = n).
    limits
        The limits the planner enforces.
    damping
        Viscous damping d_i of each joint, D = diag(d) in eq. (1) [N·m·s/rad or N·s/m], shape (n,).
    name
        A name for messages and outputs.
    tip
        The frame traced as the end effector.
    urdf_xml
        The URDF text the model was built from (for visual geometry), if any.
    urdf_path
        The URDF file, if any (mesh URIs are resolved relative to it).
    locked_joints
        The joints of the URDF held fixed at their reference value.
    lock
        The locked joints' names in ``urdf_xml`` and the configuration of the full model they are
        held at (internal: how :meth:`visual_model` reduces the visuals like the model).
    srdf
        The SRDF whose ``<disable_collisions>`` pairs are not checked for self-collision
        (:class:`~nearopt.collision.CollisionModel`), if any.
    """

    def __init__(
        self,
        model: pin.Model,
        *,
        limits: JointLimits,
        damping: ArrayLike,
        name: str,
        tip: str,
        urdf_xml: str | None = None,
        urdf_path: Path | None = None,
        locked_joints: tuple[str, ...] = (),
        lock: tuple[tuple[str, ...], NDArray[np.float64]] | None = None,
        srdf: Path | None = None,
    ) -> None:
        if model.nq != model.nv:
            raise URDFError(f"robot {name!r}: nq = {model.nq} ≠ nv = {model.nv}")
        self._model = model
        self._data = model.createData()
        self._pool: pin.ModelPool | None = None  # for batches of RNEA, made on first use
        self.name = name
        self.tip = tip
        names = tuple(model.names)[1:]
        self.limits = limits if limits.names == names else replace(limits, names=names)
        self.damping = _readonly(damping)
        self.urdf_xml = urdf_xml
        self.urdf_path = urdf_path
        self.locked_joints = tuple(locked_joints)
        self._lock = lock  # the locked joints' names in urdf_xml and the full model's q there
        self.srdf = srdf
        self._tip_id = _frame_id(model, tip, name)
        self._has_damping = bool(np.any(self.damping != 0.0))
        self._visuals: pin.GeometryModel | None = None  # loaded on first use (visual_model)

    def __getstate__(self) -> dict:
        """What pickling keeps (a Dask worker's copy): all but the RNEA pool and the visuals,
        made again there."""
        state = self.__dict__.copy()
        state["_pool"] = None
        state["_visuals"] = None
        return state

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_urdf(
        cls,
        path: str | Path,
        *,
        locked_joints: str | tuple[str, ...] | list[str] = (),
        tip: str | None = None,
        base: str | None = None,
        srdf: str | Path | None = None,
        group: str | None = None,
        lock_at: dict[str, float] | None = None,
        name: str | None = None,
        effort_limit: ArrayLike | tuple[ArrayLike, ArrayLike] | None = None,
        velocity_limit: ArrayLike | None = None,
        position_limits: tuple[ArrayLike, ArrayLike] | None = None,
        damping: ArrayLike | None = None,
        acceleration_limit: ArrayLike | None = None,
    ) -> Robot:
        """Load an arm from a URDF file.

        Parameters
        ----------
        path
            The URDF file.
        locked_joints
            Joints to hold fixed at their reference value (0 clipped to their limits, or
            ``lock_at``), e.g. the fingers of a gripper (a name or a list of names); duplicates
            and fixed joints are ignored.
        tip
            A link: the arm is the chain of joints from ``base`` to it (every other moving joint
            is locked, like ``locked_joints``), and it is the end effector the figures and the
            viewer trace. By default no joint is locked for it and the end effector is the last
            body frame on the last joint.
        base
            The link the chain to ``tip`` starts from (default: the URDF's root link).
        srdf
            An SRDF file of the URDF: its ``<disable_collisions>`` pairs are not checked for
            self-collision (default for a named robot: the one example-robot-data ships).
        group
            A group of ``srdf``: the arm is the group's joints (its chains, joints and
            subgroups); every other moving joint is locked.
        lock_at
            Values [rad or m] at which locked joints are held, by joint name.
        name
            Name of the robot; by default the URDF's ``<robot name>``.
        effort_limit, velocity_limit, position_limits, damping, acceleration_limit
            Overrides of the URDF's values; see :meth:`with_limits`. ``damping`` [N·m·s/rad], (n,).

        Raises
        ------
        URDFError
            Missing or malformed file, non-physical values (see :mod:`nearopt.urdf`), floating
            base, mimic or unsupported joints, a moving joint without inertia below it, or a
            joint without an effort limit and no override.
        ConfigurationError
            A ``lock_at`` joint that is not locked, or a value outside its limits.
        """
        if not isinstance(path, str | os.PathLike) or not str(path):
            raise URDFError(f"a URDF is given by its file's path, got {path!r:.60}")
        _check_no_nul(path, srdf)
        path = Path(path).expanduser().resolve()
        if group is not None and srdf is None:
            raise ConfigurationError("a group needs its SRDF (srdf=...): the group is read from it")
        srdf = None if srdf is None else Path(srdf).expanduser().resolve()
        if srdf is not None and not srdf.is_file():
            raise URDFError(f"the SRDF {srdf} does not exist", path=str(srdf))
        if isinstance(locked_joints, str):  # one joint's name, not its letters
            locked_joints = (locked_joints,)
        arm = read_urdf(path, tuple(locked_joints), tip, base, srdf if group else None, group)
        robot_name, xml, continuous, no_effort, locked = (
            arm.name,
            arm.xml,
            arm.continuous,
            arm.no_effort,
            arm.locked,
        )
        if no_effort and effort_limit is None:
            raise URDFError(
                f"joint {no_effort[0]!r} of {path} declares no effort limit (its <limit "
                "effort> is missing or 0); set the actuator limits with effort_limit=... "
                "(--effort-limit)",
                path=str(path),
            )
        try:
            full = pin.buildModelFromXML(xml)
        except (RuntimeError, ValueError) as exc:
            raise URDFError(f"Pinocchio cannot load {path}: {exc}", path=str(path)) from exc
        for jid in range(1, full.njoints):
            shortname = full.joints[jid].shortname()
            if shortname not in _ONE_DOF_JOINTS:
                raise URDFError(
                    f"joint {full.names[jid]!r} of {path} is a {shortname}: only one-axis "
                    "revolute and prismatic joints are supported",
                    path=str(path),
                )
        q_ref = _lock_reference(
            full, path, dict(zip(arm.locked, arm.locked_in_xml, strict=True)), lock_at or {}
        )
        ids = [full.getJointId(j) for j in arm.locked_in_xml]
        model = pin.buildReducedModel(full, ids, q_ref) if ids else full
        names = list(model.names)[1:]
        n = model.nv
        if n == 0:
            raise URDFError(f"{path} has no moving joint", path=str(path))

        lower = np.array(model.lowerPositionLimit, dtype=float)
        upper = np.array(model.upperPositionLimit, dtype=float)
        for i, jn in enumerate(names):
            if jn in continuous or lower[i] == upper[i]:
                lower[i], upper[i] = -np.inf, np.inf
        velocity = np.array(model.velocityLimit, dtype=float)
        velocity[(velocity <= 0.0) | (velocity >= NO_LIMIT)] = np.inf  # as with_limits
        effort_upper = np.minimum(model.upperEffortLimit, NO_LIMIT)  # (a larger one: NO_LIMIT)
        effort_lower = np.maximum(model.lowerEffortLimit, -NO_LIMIT)  # as with_limits takes it
        acceleration, jerk = _rate_arrays(arm.rates, names)
        robot = cls(
            model,
            limits=JointLimits(
                lower, upper, velocity, effort_lower, effort_upper, acceleration, jerk=jerk
            ),
            damping=np.array(model.damping, dtype=float),
            name=name or robot_name,
            tip=tip or _default_tip(model),
            urdf_xml=xml,
            urdf_path=path,
            locked_joints=locked,
            lock=(arm.locked_in_xml, q_ref),
            srdf=srdf,
        )
        robot._check_inertia()
        overrides = (effort_limit, velocity_limit, position_limits, damping, acceleration_limit)
        if any(x is not None for x in overrides):
            robot = robot.with_limits(
                effort=effort_limit,
                velocity=velocity_limit,
                position=position_limits,
                damping=damping,
                acceleration=acceleration_limit,
            )
        return robot

    @classmethod
    def from_name(cls, name: str, **overrides: object) -> Robot:
        """Load a known arm by name (see :func:`nearopt.available_robots`).

        Parameters
        ----------
        name
            ``two_link`` (the paper's arm, bundled) or an example-robot-data arm such as ``ur5``,
            ``panda`` (fingers locked), ``xarm7``, ``z1`` (gripper locked), ``kinova``.
        **overrides
            Keyword arguments of :meth:`from_urdf` (limits, damping).

        Raises
        ------
        RobotNotFoundError
            For an unknown name; the message lists the known ones.
        """
        entry = catalog.robot_entry(name)
        kwargs = {
            "tip": entry.tip,
            "locked_joints": entry.locked_joints,
            "name": entry.name,
            "srdf": entry.srdf,
        }
        kwargs.update(overrides)
        return cls.from_urdf(entry.urdf, **kwargs)  # type: ignore[arg-type]

    def with_joint_limits(self, path: str | os.PathLike[str]) -> Robot:
        """A copy of this robot with the limits of a MoveIt ``joint_limits.yaml`` (see
        :mod:`nearopt.robot.joint_limits_file`): each declared velocity, acceleration (the
        smaller of acceleration and deceleration), jerk, effort (symmetric) and position range
        replaces this robot's; joints it locks are skipped.

        Raises
        ------
        ConfigurationError
            An unreadable or malformed file, a joint the URDF does not have, a value that is
            not a positive number (naming the file, joint and key).
        """
        from .joint_limits_file import read_joint_limits

        declared = read_joint_limits(path)
        known = set(self.joint_names) | set(self.locked_joints) | self._urdf_joint_names()
        unknown = [name for name in declared if name not in known]
        if unknown:
            raise ConfigurationError(
                f"{path} limits joint {unknown[0]!r}, which {self.name} does not have (its "
                f"joints: {', '.join(self.joint_names)})",
                joint=unknown[0],
            )
        lim = self.limits
        arrays = {
            "velocity": lim.velocity.copy(),
            "acceleration": lim.acceleration.copy(),
            "jerk": lim.jerk.copy(),
        }
        e_lo, e_hi = lim.effort_lower.copy(), lim.effort_upper.copy()
        p_lo, p_hi = lim.position_lower.copy(), lim.position_upper.copy()
        for i, jn in enumerate(self.joint_names):
            entry = declared.get(jn)
            if entry is None:
                continue
            for key in ("velocity", "jerk"):
                if getattr(entry, key) is not None:
                    arrays[key][i] = getattr(entry, key)
            given = [v for v in (entry.acceleration, entry.deceleration) if v is not None]
            if given:
                arrays["acceleration"][i] = min(given)
            if entry.effort is not None:
                e_lo[i], e_hi[i] = -entry.effort, entry.effort
            if entry.position is not None:
                p_lo[i], p_hi[i] = entry.position
        return self.with_limits(effort=(e_lo, e_hi), position=(p_lo, p_hi), **arrays)

    def _urdf_joint_names(self) -> set[str]:
        """Every joint name of the URDF (fixed and locked ones too); none without a URDF."""
        if self.urdf_xml is None:
            return set()
        import xml.etree.ElementTree as ET

        return {j.get("name", "") for j in ET.fromstring(self.urdf_xml).iter("joint")}

    def with_limits(
        self,
        *,
        effort: ArrayLike | tuple[ArrayLike, ArrayLike] | None = None,
        velocity: ArrayLike | None = None,
        position: tuple[ArrayLike, ArrayLike] | None = None,
        damping: ArrayLike | None = None,
        acceleration: ArrayLike | None = None,
        jerk: ArrayLike | None = None,
        torque_rate: ArrayLike | None = None,
    ) -> Robot:
        """A copy of this robot with some limits (or the damping) replaced.

        Parameters
        ----------
        effort
            Symmetric limits |u_i| ≤ effort_i as a scalar or (n,) array, or a pair
            (u_min, u_max) of (n,) arrays [N·m or N].
        velocity
            Speed limits [rad/s or m/s], scalar or (n,); ``np.inf`` removes them.
        position
            A pair (lower, upper) of (n,) arrays [rad or m]; ``±np.inf`` removes them.
        damping
            Viscous damping d_i [N·m·s/rad or N·s/m], scalar or (n,).
        acceleration
            Joint acceleration limits |θ̈_i| ≤ a_i [rad/s² or m/s²], scalar or (n,); ``np.inf``
            removes them (the default where the URDF declares none).
        jerk
            Joint jerk limits |θ⃛_i| ≤ j_i [rad/s³ or m/s³], scalar or (n,); ``np.inf`` removes
            them (the default). :func:`~nearopt.plan` holds them for all t.
        torque_rate
            Torque-rate limits |u̇_i| ≤ r_i [N·m/s or N/s], scalar or (n,); ``np.inf`` removes
            them (the default). :func:`~nearopt.plan` holds them (see
            :attr:`JointLimits.torque_rate`).

        Raises
        ------
        ConfigurationError
            Wrong shape, NaN, or a lower limit above an upper limit; the message names the joint.
        """
        lim = self.limits
        e_lo, e_hi = lim.effort_lower, lim.effort_upper
        if effort is not None:
            if isinstance(effort, tuple) and len(effort) != 2:
                raise ConfigurationError(
                    "effort is a limit per joint, or a tuple (lower, upper) of them, got "
                    f"a tuple of {len(effort)}"
                )
            if isinstance(effort, tuple):
                e_lo = self._joint_array(effort[0], "lower effort limit")
                e_hi = self._joint_array(effort[1], "upper effort limit")
            else:
                e_hi = self._joint_array(effort, "effort limit")
                self._check_positive(e_hi, "effort limit")
                e_lo = -e_hi
            self._check_order(e_lo, e_hi, "effort", strict=True)
            # beyond NO_LIMIT an effort limit cannot bind: taken as NO_LIMIT (no overflow)
            e_lo, e_hi = np.maximum(e_lo, -NO_LIMIT), np.minimum(e_hi, NO_LIMIT)
        vel = lim.velocity
        if velocity is not None:
            vel = self._joint_array(velocity, "velocity limit", allow_inf=True)
            self._check_positive(vel, "velocity limit")
            vel = np.where(vel >= NO_LIMIT, np.inf, vel)  # none: its square would overflow
        p_lo, p_hi = lim.position_lower, lim.position_upper
        if position is not None:
            p_lo = self._joint_array(position[0], "lower position limit", allow_inf=True)
            p_hi = self._joint_array(position[1], "upper position limit", allow_inf=True)
            self._check_order(p_lo, p_hi, "position", strict=False)
        acc = lim.acceleration
        if acceleration is not None:
            acc = self._joint_array(acceleration, "acceleration limit", allow_inf=True)
            self._check_positive(acc, "acceleration limit")
            acc = np.where(acc >= NO_LIMIT, np.inf, acc)
        jerks = lim.jerk
        if jerk is not None:
            jerks = self._joint_array(jerk, "jerk limit", allow_inf=True)
            self._check_positive(jerks, "jerk limit")
            jerks = np.where(jerks >= NO_LIMIT, np.inf, jerks)
        rates = lim.torque_rate
        if torque_rate is not None:
            rates = self._joint_array(torque_rate, "torque-rate limit", allow_inf=True)
            self._check_positive(rates, "torque-rate limit")
            rates = np.where(rates >= NO_LIMIT, np.inf, rates)
        damp = self.damping
        if damping is not None:
            damp = self._joint_array(damping, "damping")
            if np.any(damp < 0):
                i = int(np.argmax(damp < 0))
                raise ConfigurationError(
                    f"damping of joint {self.joint_names[i]!r} is {damp[i]:g} < 0",
                    joint=self.joint_names[i],
                )
        return Robot(
            self._model,
            limits=JointLimits(
                p_lo,
                p_hi,
                vel,
                e_lo,
                e_hi,
                acc,
                jerk=jerks,
                torque_rate=rates,
            ),
            damping=damp,
            name=self.name,
            tip=self.tip,
            urdf_xml=self.urdf_xml,
            urdf_path=self.urdf_path,
            srdf=self.srdf,
            locked_joints=self.locked_joints,
            lock=self._lock,
        )

    # ------------------------------------------------------------------ description
    @property
    def n(self) -> int:
        """Number of joints (degrees of freedom)."""
        return self._model.nv

    @property
    def joint_names(self) -> list[str]:
        """Names of the n joints, in the order of every joint vector."""
        return list(self._model.names)[1:]

    @property
    def prismatic(self) -> NDArray[np.bool_]:
        """Which joints are prismatic (their units are m, m/s, N instead of rad, rad/s, N·m),
        shape (n,)."""
        kinds = [self._model.joints[j].shortname() for j in range(1, self._model.njoints)]
        return np.array([k.startswith("JointModelP") for k in kinds][: self.n], dtype=bool)

    @property
    def gravity(self) -> NDArray[np.float64]:
        """Gravity acceleration vector of the world frame [m/s²], shape (3,)."""
        return np.array(self._model.gravity.linear)

    @property
    def model(self) -> pin.Model:
        """The Pinocchio model (read it; do not modify it)."""
        return self._model

    def new_data(self) -> pin.Data:
        """A fresh Pinocchio data of the model: the work space of one caller at a time (a data
        must not be shared between threads). Every part of nearopt gets its data here."""
        return self._model.createData()

    def new_pool(self) -> pin.ModelPool:
        """A fresh pool of one model and its data, for Pinocchio's batched algorithms
        (``pin.rneaInParallel``, ``pin.abaInParallel``) on one thread."""
        return pin.ModelPool(self._model, 1)

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, n={self.n}, joints={self.joint_names})"

    def summary(self) -> str:
        """A table of the joints with their limits and damping, for people to read."""
        lim = self.limits
        rows = [
            f"{self.name}: {self.n} joints, tip frame {self.tip!r}, "
            f"gravity {np.round(self.gravity, 4).tolist()} m/s²",
            f"{'joint':<28}{'position [lo, hi]':>24}{'|velocity|':>12}"
            f"{'effort [lo, hi]':>22}{'damping':>10}{'|accel.|':>10}",
        ]
        jerk = np.any(np.isfinite(lim.jerk))  # a column where any joint has a jerk limit
        rate = np.any(np.isfinite(lim.torque_rate))
        if jerk:
            rows[-1] += f"{'|jerk|':>10}"
        if rate:
            rows[-1] += f"{'|du/dt|':>10}"
        for i, jn in enumerate(self.joint_names):
            rows.append(
                f"{jn:<28}{f'[{lim.position_lower[i]:.4g}, {lim.position_upper[i]:.4g}]':>24}"
                f"{lim.velocity[i]:>12.4g}"
                f"{f'[{lim.effort_lower[i]:.4g}, {lim.effort_upper[i]:.4g}]':>22}"
                f"{self.damping[i]:>10.4g}{lim.acceleration[i]:>10.4g}"
                + (f"{lim.jerk[i]:>10.4g}" if jerk else "")
                + (f"{lim.torque_rate[i]:>10.4g}" if rate else "")
            )
        return "\n".join(rows)

    # ------------------------------------------------------------------ dynamics (eq. 1)
    def mass_matrix(self, q: ArrayLike) -> NDArray[np.float64]:
        """H(θ), the joint-space inertia matrix of eq. (1), shape (n, n)."""
        q = self.check_configuration(q)
        return np.array(pin.crba(self._model, self._data, q))

    def gravity_torque(self, q: ArrayLike) -> NDArray[np.float64]:
        """g(θ), the gravity torques of eq. (1) [N·m or N], shape (n,)."""
        q = self.check_configuration(q)
        return np.array(pin.computeGeneralizedGravity(self._model, self._data, q))

    def coriolis(self, q: ArrayLike, qd: ArrayLike) -> NDArray[np.float64]:
        """h(θ, θ̇), the Coriolis and centrifugal torques of eq. (1), shape (n,)."""
        q = self.check_configuration(q)
        qd = self._joint_array(qd, "velocity")
        return np.array(pin.nonLinearEffects(self._model, self._data, q, qd)) - np.array(
            pin.computeGeneralizedGravity(self._model, self._data, q)
        )

    def inverse_dynamics(self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike) -> NDArray[np.float64]:
        """u = H(θ)θ̈ + h(θ, θ̇) + g(θ) + Dθ̇ (eq. 1), shape (n,).

        Parameters
        ----------
        q, qd, qdd
            θ [rad], θ̇ [rad/s], θ̈ [rad/s²], each of shape (n,).
        """
        q = self.check_configuration(q)
        qd = self._joint_array(qd, "velocity")
        qdd = self._joint_array(qdd, "acceleration")
        return np.array(pin.rnea(self._model, self._data, q, qd, qdd)) + self.damping * qd

    def inverse_dynamics_batch(
        self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike
    ) -> NDArray[np.float64]:
        """Eq. (1) at N samples: arrays of shape (N, n) in, torques of shape (N, n) out."""
        q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
        self._check_batch(q, qd, qdd)
        return self._rnea_columns(q, qd, qdd) + self.damping * qd

    def _rnea_columns(
        self, q: NDArray[np.float64], qd: NDArray[np.float64], qdd: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Pinocchio's RNEA (no damping) at N samples in one call, (N, n) in and out.

        ``pin.rneaInParallel`` on one thread over a model pool of this robot: the loop runs in C++
        (about 2× faster than a Python loop over ``pin.rnea`` on a 7-joint arm), with the same
        numbers.
        """
        count = q.shape[0]
        if count == 0:
            return np.zeros((0, self.n))
        if self._pool is None:
            self._pool = self.new_pool()
        tau = np.zeros((self.n, count), order="F")
        pin.rneaInParallel(
            1,
            self._pool,
            np.asfortranarray(q.T),
            np.asfortranarray(qd.T),
            np.asfortranarray(qdd.T),
            tau,
        )
        return tau.T

    def forward_dynamics(self, q: ArrayLike, qd: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """θ̈ = H⁻¹(u − h − g − Dθ̇), the acceleration part of ẋ = f(x, u) (eq. 20), shape (n,)."""
        q = self.check_configuration(q)
        qd = self._joint_array(qd, "velocity")
        u = self._joint_array(u, "torque")
        return np.array(pin.aba(self._model, self._data, q, qd, u - self.damping * qd))

    def state_derivative(self, x: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """ẋ = f(x, u) of eq. (20) with x = (θ, θ̇), shape (2n,)."""
        x = np.asarray(x, dtype=float)
        n = self.n
        if x.shape != (2 * n,):
            raise ConfigurationError(f"state must have shape ({2 * n},), got {x.shape}")
        return np.concatenate([x[n:], self.forward_dynamics(x[:n], x[n:], u)])

    def dynamics_jacobians(
        self, q: ArrayLike, qd: ArrayLike, u: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """A = ∂f/∂x (2n, 2n) and B = ∂f/∂u (2n, n) of ẋ = f(x, u) (eqs. 24-26).

        From Pinocchio's analytic ABA derivatives, evaluated at the effective torque u − Dθ̇,
        with the damping's −H⁻¹D added to ∂θ̈/∂θ̇.
        """
        q = self.check_configuration(q)
        qd = self._joint_array(qd, "velocity")
        u = self._joint_array(u, "torque")
        n = self.n
        ddq_dq, ddq_dv, minv = pin.computeABADerivatives(
            self._model, self._data, q, qd, u - self.damping * qd
        )
        minv = np.array(minv)
        a = np.zeros((2 * n, 2 * n))
        a[:n, n:] = np.eye(n)
        a[n:, :n] = ddq_dq
        a[n:, n:] = np.array(ddq_dv) - minv * self.damping[None, :]
        b = np.zeros((2 * n, n))
        b[n:, :] = minv
        return a, b

    # ------------------------------------------------------------------ path form (eq. 10)
    def path_coefficients(
        self, theta: ArrayLike, dtheta: ArrayLike, ddtheta: ArrayLike
    ) -> PathCoefficients:
        """The coefficients m, c, d, g of eq. (10) at N path samples.

        Parameters
        ----------
        theta, dtheta, ddtheta
            θ(s_k), θ'(s_k), θ''(s_k) at N samples, each of shape (N, n) [rad, rad/unit s, …].

        Returns
        -------
        PathCoefficients
            m = Hθ', c = Hθ'' + h(θ, θ'), d = Dθ', g = g(θ), each (N, n), such that
            u = m·a + c·b + d·λ + g with b = λ², a = λλ'.
        """
        theta, dtheta, ddtheta = (
            np.atleast_2d(np.asarray(x, dtype=float)) for x in (theta, dtheta, ddtheta)
        )
        self._check_batch(theta, dtheta, ddtheta)
        zero = np.zeros_like(dtheta)
        g, c, m = np.split(
            self._rnea_columns(
                np.vstack([theta, theta, theta]),
                np.vstack([zero, dtheta, zero]),
                np.vstack([zero, ddtheta, dtheta]),
            ),
            3,
        )
        return PathCoefficients(m - g, c - g, self.damping * dtheta, g)

    def path_torque(
        self,
        theta: ArrayLike,
        dtheta: ArrayLike,
        ddtheta: ArrayLike,
        lam: ArrayLike,
        dlam: ArrayLike,
    ) -> NDArray[np.float64]:
        """u(s) of eq. (10) at N path samples, shape (N, n).

        Parameters
        ----------
        theta, dtheta, ddtheta
            θ(s), θ'(s), θ''(s), each (N, n).
        lam, dlam
            λ(s) = ds/dt [unit s / s] and λ'(s) = dλ/ds [1/s], each (N,).
        """
        coef = self.path_coefficients(theta, dtheta, ddtheta)
        lam = np.asarray(lam, dtype=float).reshape(-1, 1)
        dlam = np.asarray(dlam, dtype=float).reshape(-1, 1)
        return coef.m * (lam * dlam) + coef.c * lam**2 + coef.d * lam + coef.g

    def inverse_dynamics_derivatives(
        self, q: ArrayLike, qd: ArrayLike, qdd: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """∂u/∂θ, ∂u/∂θ̇ (damping included) and ∂u/∂θ̈ = H of u = ID(θ, θ̇, θ̈) at N samples.

        From Pinocchio's analytic RNEA derivatives; q, qd, qdd of shape (N, n); each output is
        (N, n, n) with [k, i, j] = ∂u_i/∂x_j at sample k.
        """
        q, qd, qdd = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, qd, qdd))
        self._check_batch(q, qd, qdd)
        count, n = q.shape
        du_dq, du_dv, h = (np.empty((count, n, n)) for _ in range(3))
        for k in range(count):
            du_dq[k], du_dv[k], h[k] = pin.computeRNEADerivatives(
                self._model, self._data, q[k], qd[k], qdd[k]
            )
        du_dv += np.diag(self.damping)
        return du_dq, du_dv, h

    # ------------------------------------------------------------------ kinematics
    def frame_id(self, frame: str | None = None) -> int:
        """Pinocchio's id of a frame by name (default: the tip).

        Raises
        ------
        ConfigurationError
            For an unknown frame; the message lists the robot's link frames.
        """
        return self._tip_id if frame is None else _frame_id(self._model, frame, self.name)

    def frame_placement(self, q: ArrayLike, frame: str | None = None) -> pin.SE3:
        """Placement of a frame (default: the tip) in the base frame at θ, shape (n,)."""
        q = self.check_configuration(q)
        fid = self.frame_id(frame)
        pin.framesForwardKinematics(self._model, self._data, q)
        return pin.SE3(self._data.oMf[fid])

    def frame_position(self, q: ArrayLike, frame: str | None = None) -> NDArray[np.float64]:
        """World position of a frame (default: the tip) [m]; q of shape (n,) or (N, n)."""
        q = np.asarray(q, dtype=float)
        fid = self._tip_id if frame is None else _frame_id(self._model, frame, self.name)
        model, data = self._model, self._data
        out = []
        for qk in np.atleast_2d(q):
            qk = self.check_configuration(qk)
            pin.forwardKinematics(model, data, qk)
            out.append(np.array(pin.updateFramePlacement(model, data, fid).translation))
        return out[0] if q.ndim == 1 else np.array(out)

    def link_placements(self, q: ArrayLike) -> dict[str, NDArray[np.float64]]:
        """World placements of every link (body frame) as 4×4 homogeneous matrices."""
        q = self.check_configuration(q)
        pin.framesForwardKinematics(self._model, self._data, q)
        return {
            f.name: np.array(self._data.oMf[i].homogeneous)
            for i, f in enumerate(self._model.frames)
            if f.type == pin.FrameType.BODY
        }

    def visual_model(self) -> pin.GeometryModel:
        """The URDF's visual geometry with ``package://`` mesh URIs resolved to files.

        Raises
        ------
        URDFError
            If the robot was not built from a URDF, or a mesh cannot be found.
        """
        if self._visuals is None:  # loaded once (0.35 s on panda): the command line loads
            self._visuals = self._geometry(pin.GeometryType.VISUAL)  # them before planning too
        return self._visuals.copy()

    def collision_geometry(self) -> pin.GeometryModel:
        """The URDF's ``<collision>`` geometry (meshes as coal's triangle models), attached to
        this model's joints like the visuals (locked joints' links on their parent's joint).

        Raises
        ------
        URDFError
            If the robot was not built from a URDF, or a mesh cannot be found.
        """
        return self._geometry(pin.GeometryType.COLLISION)

    def package_dirs(self) -> list[Path]:
        """The folders in which a ``package://NAME/…`` mesh URI of this robot's URDF is
        resolved (as ``folder/NAME/…``), in Pinocchio's order: the URDF's own folder, the known
        robots' (example-robot-data), then those of ``ROS_PACKAGE_PATH``."""
        dirs = [] if self.urdf_path is None else [Path(self.urdf_path).parent]
        try:
            dirs += catalog.package_dirs()
        except URDFError:
            pass
        ros = os.environ.get("ROS_PACKAGE_PATH", "")
        return dirs + [Path(d) for d in ros.split(os.pathsep) if d]

    def _geometry(self, kind: pin.GeometryType) -> pin.GeometryModel:
        what = "visuals" if kind == pin.GeometryType.VISUAL else "collision geometry"
        if self.urdf_xml is None or self.urdf_path is None:
            raise URDFError(f"robot {self.name!r} was not built from a URDF; it has no {what}")
        dirs = [str(d) for d in self.package_dirs()]
        full = pin.buildModelFromXML(self.urdf_xml)
        try:
            geom = pin.buildGeomFromUrdfString(full, self.urdf_xml, kind, package_dirs=dirs)
        except (RuntimeError, ValueError) as exc:
            raise URDFError(f"cannot load the {what} of {self.urdf_path}: {exc}") from exc
        if self._lock is not None and self._lock[0]:
            names, q_ref = self._lock
            _, geom = pin.buildReducedModel(full, geom, [full.getJointId(j) for j in names], q_ref)
        return geom

    # ------------------------------------------------------------------ checks
    def check_configuration(self, q: ArrayLike, what: str = "configuration") -> NDArray[np.float64]:
        """Return q as a float array of shape (n,), or raise a :class:`ConfigurationError` (a
        single number is refused: a configuration has a value per joint)."""
        if isinstance(q, dict):  # (np.ndim of a dict is 0: it was called a single number)
            raise ConfigurationError(
                f"{what} is a list of {self.n} values in the joints' order "
                f"({', '.join(self.joint_names)}), not a dict"
            )
        if self.n > 1 and np.ndim(q) == 0 and q is not None and not isinstance(q, str):
            raise ConfigurationError(
                f"{what} must have {self.n} values (one per joint of {self.name}: "
                f"{', '.join(self.joint_names)}), got the single number {q!r}"
            )
        return self._joint_array(q, what)

    def _joint_array(
        self, x: ArrayLike, what: str, *, allow_inf: bool = False
    ) -> NDArray[np.float64]:
        if x is None:
            raise ConfigurationError(
                f"{what} is missing: give {self.n} values (one per joint of {self.name}: "
                f"{', '.join(self.joint_names)})"
            )
        try:
            a = np.asarray(x, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ConfigurationError(f"{what} is not numeric: {x!r}") from exc
        if a.ndim == 0:
            a = np.full(self.n, float(a))
        if a.shape != (self.n,):
            raise ConfigurationError(
                f"{what} must have {self.n} values (one per joint of {self.name}: "
                f"{', '.join(self.joint_names)}), got shape {a.shape}"
            )
        bad = np.isnan(a) if allow_inf else ~np.isfinite(a)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise ConfigurationError(
                f"{what} of joint {self.joint_names[i]!r} is {a[i]}", joint=self.joint_names[i]
            )
        return a

    def _check_batch(self, *arrays: NDArray[np.float64]) -> None:
        shape = arrays[0].shape
        for a in arrays:
            if a.ndim != 2 or a.shape[1] != self.n or a.shape != shape:
                raise ConfigurationError(
                    f"expected arrays of shape (N, {self.n}) for {self.name}, got "
                    f"{[x.shape for x in arrays]}"
                )
            if not np.all(np.isfinite(a)):
                k, i = np.argwhere(~np.isfinite(a))[0]
                raise ConfigurationError(
                    f"sample {k} of joint {self.joint_names[i]!r} is {a[k, i]}",
                    joint=self.joint_names[i],
                )

    def _check_order(
        self, lo: NDArray[np.float64], hi: NDArray[np.float64], what: str, *, strict: bool
    ) -> None:
        bad = lo >= hi if strict else lo > hi
        if np.any(bad):
            i = int(np.argmax(bad))
            raise ConfigurationError(
                f"{what} limits of joint {self.joint_names[i]!r}: lower {lo[i]:g} is not below "
                f"upper {hi[i]:g}",
                joint=self.joint_names[i],
            )

    def _check_positive(self, x: NDArray[np.float64], what: str) -> None:
        if np.any(x <= 0):
            i = int(np.argmax(x <= 0))
            raise ConfigurationError(
                f"{what} of joint {self.joint_names[i]!r} is {x[i]:g}, must be > 0",
                joint=self.joint_names[i],
            )

    def _check_inertia(self) -> None:
        """Every joint must move some inertia, or H(θ) is singular and eq. (16) undefined."""
        lim = self.limits
        q = np.clip(np.zeros(self.n), lim.position_lower, lim.position_upper)
        h = self.mass_matrix(q)
        for i, jn in enumerate(self.joint_names):
            if not h[i, i] > 1e-12:
                raise URDFError(
                    f"joint {jn!r} of {self.urdf_path} moves no inertia (H[{i},{i}] = "
                    f"{h[i, i]:g}): the links below it carry no mass or inertia (no <inertial>, "
                    "or mass and inertia 0)",
                    path=str(self.urdf_path),
                )
        if np.linalg.eigvalsh(h)[0] <= 0.0:
            raise URDFError(f"the inertia matrix of {self.name} is not positive definite")


def _lock_reference(
    full: pin.Model, path: Path, locked: dict[str, str], values: dict[str, float]
) -> NDArray[np.float64]:
    """The full model's configuration at which the locked joints are held: 0 within their
    limits, or the given values (by the joints' URDF names)."""
    q_ref = np.clip(np.zeros(full.nq), full.lowerPositionLimit, full.upperPositionLimit)
    for name, value in values.items():
        if name not in locked:
            raise ConfigurationError(
                f"lock_at names joint {name!r}, which is not locked (locked: "
                f"{', '.join(locked) or 'none'})",
                joint=name,
            )
        jid = full.getJointId(locked[name])
        k = full.idx_qs[jid]
        lo, hi = full.lowerPositionLimit[k], full.upperPositionLimit[k]
        if not np.isfinite(value) or (lo < hi and not lo <= value <= hi):
            raise ConfigurationError(
                f"joint {name!r} cannot be locked at {value}: its limits are [{lo:g}, {hi:g}]",
                joint=name,
            )
        q_ref[k] = value
    return q_ref


def _frame_id(model: pin.Model, frame: str, robot: str) -> int:
    """Id of a frame by name, the body frame where a joint frame bears the same name."""
    for ftype in (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT):
        if model.existFrame(frame, ftype):
            return model.getFrameId(frame, ftype)
    if model.existFrame(frame):
        return model.getFrameId(frame)
    links = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
    raise ConfigurationError(
        f"robot {robot!r} has no frame {frame!r}; its links: {', '.join(links)}"
    )


def _default_tip(model: pin.Model) -> str:
    last = model.njoints - 1
    body = pin.FrameType.BODY
    bodies = [f.name for f in model.frames if f.type == body and f.parentJoint == last]
    return bodies[-1] if bodies else model.frames[-1].name


def check_robot(robot: object, what: str = "robot") -> None:
    """That ``robot`` is a :class:`Robot`.

    Raises
    ------
    ConfigurationError
        Naming the argument and what it got.
    """
    if not isinstance(robot, Robot):
        raise ConfigurationError(
            f"{what} must be a nearopt.Robot (e.g. Robot.from_name('two_link') or "
            f"Robot.from_urdf(path)), got {type(robot).__name__} {robot!r:.60}"
        )
