"""Signed distances between the robot's links and the obstacles of a scene, their gradients in
θ, and a certified check of a whole path.

The robot's bodies are the URDF's ``<collision>`` geometry (Pinocchio's ``GeometryModel``), each
mesh taken as its convex hull so that coal's GJK/EPA gives a signed distance d (negative: the
penetration depth) and its nearest points p1, p2 with the unit normal n from the first body to the
second. The checked pairs are

* every link with every obstacle, except bodies fixed to the base (they cannot move; the table
  the base stands on touches it);
* every two links, except those on the same joint or on adjacent joints (parent and child), the
  SRDF's ``<disable_collisions>`` pairs, and the pairs already in contact at the neutral
  configuration (0 within the limits; MoveIt's setup assistant's "default" rule, which the SRDFs
  of kinova and z1 lack).

The gradient of d (Pinocchio and coal give none) comes from the nearest points and the joint
Jacobians: ∂d/∂θ = nᵀ (J₂(p2) − J₁(p1)), J_k(p) the Jacobian of the point p fixed to body k.

**Between checked points** (:meth:`CollisionModel.path_clearance`): the distance of a pair can
change no faster than the speed of its bodies' points relative to each other, and for a path θ(s)

    |d(s) − d(s_a)| ≤ Σ_j |θ'_j|max · R_j · |s − s_a|,

the sum over the joints between the two bodies in the kinematic tree, R_j a bound on the
distance of the moving body's points from joint j's axis (chain lengths plus the body's
bounding-sphere radius; 1 for a prismatic joint). An interval [s_a, s_b] is therefore certified
at level m when d(s_a) + d(s_b) − 2m ≥ L (s_b − s_a) (Schwarzer, Saha and Latombe, "Exact
collision checking of robot paths", 2002), and bisected until it is or a point closer than m is
found. |θ'_j|max is exact per polynomial piece of the path (θ' is piecewise quadratic for
nearopt's paths), so the certificate is a proof, not a sample.
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import coal
import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull, QhullError

from ..errors import CollisionError, ConfigurationError, SceneError, URDFError
from ..path import BSplinePath, SplinePath, StraightPath
from ..robot import check_robot
from ..validate import is_number
from .scene import Box, Capsule, Cylinder, HalfSpace, Mesh, Scene, Sphere

if TYPE_CHECKING:
    from collections.abc import Callable

    from numpy.typing import ArrayLike, NDArray

    from ..path import Path as JointPath
    from ..robot import Robot

__all__ = ["CollisionModel", "Contact", "Clearance", "Pair", "collisions_for"]


@dataclass(frozen=True)
class Pair:
    """A checked pair of bodies: robot links (by link name) or obstacles (by obstacle name)."""

    first: str
    second: str

    def __str__(self) -> str:
        return f"{self.first} ↔ {self.second}"


@dataclass(frozen=True)
class Contact:
    """The closest pair at one configuration.

    Attributes
    ----------
    pair
        The two bodies.
    distance
        Their signed distance [m] (negative: penetration depth).
    points
        The nearest points on the first and on the second body, in the base frame [m],
        shape (2, 3).
    index
        The pair's index in :attr:`CollisionModel.pairs` (−1 when nothing is checked).
    """

    pair: Pair
    distance: float
    points: NDArray[np.float64]
    index: int = -1


@dataclass(frozen=True)
class Clearance:
    """The result of checking a whole path.

    Attributes
    ----------
    certified
        True when every pair keeps a distance ≥ ``level`` at every s (proved between the checked
        points by the bound of the module docstring).
    level
        The distance certified [m].
    closest
        The closest pair found at a checked point, and where.
    s
        The path parameter of ``closest``.
    checks
        Distance evaluations (configurations × pairs) the certificate took.
    """

    certified: bool
    level: float
    closest: Contact
    s: float
    checks: int


class _Verdict(NamedTuple):
    """A path's certificate (:meth:`CollisionModel.path_clearance`): whether it holds, the
    least distance found [m], its s, its pair's index and configuration (None: θ(s))."""

    certified: bool
    distance: float
    s: float
    pair: int
    at: NDArray[np.float64] | None
    checks: int


class CollisionModel:
    """The robot's collision bodies and a scene's obstacles, with the pairs that are checked.

    Parameters
    ----------
    robot
        The arm (its URDF's ``<collision>`` elements).
    scene
        The obstacles (default: none, self-collision only).
    srdf
        An SRDF whose ``<disable_collisions>`` pairs are not checked (default: the robot's,
        :attr:`Robot.srdf`).
    margin
        The clearance kept [m] (default: the scene's, whose default is
        :data:`~nearopt.collision.DEFAULT_MARGIN`).
    self_collision
        Check pairs of the robot's own links.

    Raises
    ------
    URDFError
        A collision mesh cannot be loaded, or a bad SRDF.
    SceneError
        An obstacle's mesh cannot be loaded.
    """

    def __init__(
        self,
        robot: Robot,
        scene: Scene | None = None,
        *,
        srdf: str | Path | None = None,
        margin: float | None = None,
        self_collision: bool = True,
    ) -> None:
        check_robot(robot)
        self._arguments = (robot, scene, srdf, margin, self_collision)
        self.robot = robot
        self.scene = Scene() if scene is None else scene
        if not isinstance(self.scene, Scene):
            raise SceneError(f"scene must be a nearopt Scene, got {type(scene).__name__}")
        margin = self.scene.margin if margin is None else margin
        if not (is_number(margin) and np.isfinite(margin) and margin >= 0.0):
            raise ConfigurationError(f"margin must be a distance ≥ 0 [m], got {margin!r}")
        self.margin = float(margin)
        model = robot.model
        geom = robot.collision_geometry() if robot.urdf_xml is not None else pin.GeometryModel()
        self._robot_geoms = geom.ngeoms
        for obj in geom.geometryObjects:
            obj.geometry = _convex(obj.geometry, obj.name)
        for ob in self.scene.obstacles:
            try:
                shape = _coal_shape(ob.shape, ob.name)
            except SceneError as exc:  # which file it came from
                if self.scene.source is None:
                    raise
                raise SceneError(
                    f"{self.scene.source}: {exc}", obstacle=ob.name, field="mesh"
                ) from None
            placement = pin.SE3(ob.rotation(), np.asarray(ob.position, dtype=float))
            geom.addGeometryObject(
                pin.GeometryObject(f"obstacle:{ob.name}", 0, 0, placement, shape)
            )
        self.geometry = geom
        self._names = [self._body(i) for i in range(geom.ngeoms)]
        links = set(self._names[: self._robot_geoms])
        for ob in self.scene.obstacles:
            if ob.name in links:
                raise SceneError(
                    f"obstacle {ob.name!r} has the name of a link of {robot.name}: a contact "
                    "between them could not be told apart; rename the obstacle",
                    obstacle=ob.name,
                    field="name",
                )
        self._joint = np.array([o.parentJoint for o in geom.geometryObjects], dtype=int)
        self._moved_by = np.zeros((model.njoints, model.nv))
        """1 where a velocity coordinate moves the joint's body (the joints that support it)."""
        for j in range(1, model.njoints):
            for k in model.supports[j].tolist()[1:]:
                joint = model.joints[k]
                self._moved_by[j, joint.idx_v : joint.idx_v + joint.nv] = 1.0
        srdf_path = robot.srdf if srdf is None else Path(srdf).expanduser().resolve()
        disabled = _srdf_disabled(srdf_path) if srdf_path is not None else set()
        pairs: list[tuple[int, int]] = []
        for b in range(self._robot_geoms, geom.ngeoms):  # links with obstacles
            pairs += [(a, b) for a in range(self._robot_geoms) if self._joint[a] != 0]
        if self_collision:
            parents = list(model.parents)
            for a in range(self._robot_geoms):
                for b in range(a + 1, self._robot_geoms):
                    ja, jb = int(self._joint[a]), int(self._joint[b])
                    if ja == jb or parents[ja] == jb or parents[jb] == ja:
                        continue
                    if frozenset((self._names[a], self._names[b])) in disabled:
                        continue
                    pairs.append((a, b))
        for a, b in pairs:
            geom.addCollisionPair(pin.CollisionPair(int(a), int(b)))
        self.seconds = 0.0
        """Time spent computing distances (all pairs at a configuration) so far [s]."""
        self._data = robot.new_data()
        self._gdata = pin.GeometryData(geom)
        self._configure()
        if self_collision and pairs:  # MoveIt's "default" rule (kinova's, z1's SRDFs lack it)
            q = np.clip(
                np.zeros(model.nq), robot.limits.position_lower, robot.limits.position_upper
            )
            d = self._all(q)
            keep = [k for k, (a, b) in enumerate(pairs) if b >= self._robot_geoms or d[k] > 0.0]
            if len(keep) < len(pairs):
                geom.removeAllCollisionPairs()
                pairs = [pairs[k] for k in keep]
                for a, b in pairs:
                    geom.addCollisionPair(pin.CollisionPair(int(a), int(b)))
                self._gdata = pin.GeometryData(geom)
                self._configure()
        self._pairs = np.array(pairs, dtype=int).reshape(-1, 2)
        self.pairs = tuple(Pair(self._names[a], self._names[b]) for a, b in self._pairs)
        self.motion_rates = self._motion_rates()
        """R_j of every pair: how fast its distance can change per unit of θ'_j [m/rad or
        m/m], shape (len(pairs), n) (see the module docstring)."""
        self._boxes = _local_boxes(geom)

    # ------------------------------------------------------------------ queries
    def __repr__(self) -> str:
        return (
            f"CollisionModel({self.robot.name!r}, {len(self.scene.obstacles)} obstacles, "
            f"{len(self.pairs)} pairs, margin {self.margin:g} m)"
        )

    def distances(self, q: ArrayLike) -> NDArray[np.float64]:
        """Signed distance of every checked pair at θ [m], shape (len(pairs),)."""
        return self._all(self.robot.check_configuration(q))

    def distances_along(
        self, qs: ArrayLike, below: float | ArrayLike = np.inf
    ) -> NDArray[np.float64]:
        """Signed distances of every checked pair at each θ of ``qs`` [m], shape
        (len(qs), len(pairs)): exact where they are at most ``below`` (one level, or one per
        pair [m]); elsewhere a lower bound above ``below``, the distance between the two bodies'
        bounding boxes (coal is asked only for the pairs whose boxes are that close: a broad
        phase).

        Parameters
        ----------
        qs
            Configurations θ [rad or m], shape (S, n).
        below
            The level up to which distances are exact (default inf: all of them).
        """
        values, _ = self._bounded(self._configurations(qs), below)
        return values

    def closest_along(self, qs: ArrayLike) -> tuple[int, int, float]:
        """The closest pair over the configurations ``qs`` (shape (S, n)): the configuration's
        index, the pair's index in :attr:`pairs` and their signed distance [m] (coal's; the
        other pairs bounded from below by their bodies' boxes first, as
        :meth:`distances_along`). (−1, −1, inf) when nothing is checked."""
        qs = self._configurations(qs)
        if len(self._pairs) == 0 or len(qs) == 0:
            return -1, -1, np.inf
        dist, exact = self._bounded(qs, self.margin)
        t0 = time.perf_counter()
        self._least(qs, dist, exact)
        self.seconds += time.perf_counter() - t0
        k_t, k_p = np.unravel_index(int(np.argmin(dist)), dist.shape)
        return int(k_t), int(k_p), float(dist[k_t, k_p])

    def closest(self, q: ArrayLike) -> Contact:
        """The closest checked pair at θ (``distance`` inf when nothing is checked)."""
        d = self.distances(q)
        if d.size == 0:
            return Contact(Pair("", ""), np.inf, np.full((2, 3), np.nan))
        k = int(np.argmin(d))
        r = self._results[k]
        return Contact(
            self.pairs[k], float(d[k]), np.array([r.getNearestPoint1(), r.getNearestPoint2()]), k
        )

    def check_configuration(self, q: ArrayLike, what: str = "configuration") -> None:
        """Raise a :class:`CollisionError` if a checked pair at θ is closer than the margin."""
        c = self.closest(q)
        if c.distance < self.margin:
            state = (
                (
                    f"penetrates by {-c.distance * 1e3:.1f} mm"
                    if np.isfinite(c.distance)
                    else "penetrates deeply (beyond what coal's depth search resolves)"
                )
                if c.distance < 0
                else f"is {c.distance * 1e3:.1f} mm apart, closer than the margin "
                f"{self.margin * 1e3:.1f} mm"
            )
            raise CollisionError(
                f"the {what} collides: {c.pair} {state}",
                pair=(c.pair.first, c.pair.second),
                distance=c.distance,
            )

    def distance_gradients(
        self, q: ArrayLike, pairs: ArrayLike | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Signed distances d [m] and their gradients ∂d/∂θ [m/rad or m/m] at θ.

        Parameters
        ----------
        q
            θ, shape (n,).
        pairs
            Indices into :attr:`pairs` (default: all).

        Returns
        -------
        d, G
            Shapes (m,) and (m, n).
        """
        q = self.robot.check_configuration(q)
        if pairs is None:
            index = np.arange(len(self.pairs))
            d = self._all(q)
        else:  # those pairs only
            index = np.asarray(pairs, dtype=int)
            d = self._some(q, index)
        model, data = self.robot.model, self._data
        grads = np.zeros((index.size, model.nv))
        if index.size == 0:
            return d, grads
        pin.computeJointJacobians(model, data, q)  # [v; ω] of every joint at the world origin
        jv, jw = data.J[:3], data.J[3:]
        results = [self._results[int(k)] for k in index]
        normal = np.array([r.normal for r in results])  # (m, 3), from the first to the second
        for side, sign in ((0, -1.0), (1, 1.0)):
            points = np.array(
                [r.getNearestPoint1() if side == 0 else r.getNearestPoint2() for r in results]
            )
            moved = self._moved_by[self._joint[self._pairs[index, side]]]  # (m, nv)
            # a point p of the body: nᵀ(v + ω × p) = nᵀv + (p × n)ᵀω over the joints moving it
            grads += sign * moved * (normal @ jv + _cross(points, normal) @ jw)
        return d, grads

    # ------------------------------------------------------------------ paths
    def path_clearance(
        self,
        path: JointPath,
        level: float | None = None,
        *,
        samples: int = 64,
        max_checks: int = 2_000_000,
        distances: NDArray[np.float64] | None = None,
        exact_below: float = -np.inf,
    ) -> Clearance:
        """Check a whole path: is every pair at least ``level`` apart at every s?

        Parameters
        ----------
        path
            A :class:`~nearopt.StraightPath`, :class:`~nearopt.BSplinePath` or
            :class:`~nearopt.SplinePath` (θ' piecewise quadratic, so its bound is exact).
        level
            The distance to certify [m] (default: the margin).
        samples
            Uniform intervals checked first; each is bisected until certified.
        max_checks
            Budget of pair distance evaluations; past it the path is not certified.
        distances
            The pairs' distances at the ``samples + 1`` uniform s computed before, shape
            (samples + 1, len(pairs)) [m] (:meth:`distances_along`: exact where at most
            ``exact_below``, lower bounds elsewhere): the first pass starts from them instead of
            computing its own (e.g. a planner's clearance rows at the same points); NaN where
            one is not known.
        exact_below
            The level up to which ``distances`` are exact [m].
        """
        level = self.margin if level is None else float(level)
        if len(self._pairs) == 0:
            return Clearance(True, level, self.closest(path(np.zeros(1))[0]), 0.0, 0)
        v = self._certify(path, level, samples, max_checks, distances, exact_below)
        self._all(path([v.s])[0] if v.at is None else v.at)
        r = self._results[v.pair]
        closest = Contact(
            self.pairs[v.pair],
            v.distance,
            np.array([r.getNearestPoint1(), r.getNearestPoint2()]),
            v.pair,
        )
        return Clearance(v.certified, level, closest, v.s, v.checks)

    def path_is_clear(
        self,
        path: JointPath,
        level: float | None = None,
        *,
        samples: int = 64,
        max_checks: int = 2_000_000,
        distances: NDArray[np.float64] | None = None,
        exact_below: float = -np.inf,
    ) -> bool:
        """:meth:`path_clearance`'s certificate alone (the same arguments and answer, without
        the closest pair's nearest points, which cost one more query): e.g. OMPL's motion
        checks."""
        level = self.margin if level is None else float(level)
        if len(self._pairs) == 0:
            return True
        return self._certify(path, level, samples, max_checks, distances, exact_below).certified

    def _certify(
        self,
        path: JointPath,
        level: float,
        samples: int,
        max_checks: int,
        distances: NDArray[np.float64] | None,
        exact_below: float,
    ) -> _Verdict:
        """:meth:`path_clearance`'s certificate (some pairs checked)."""
        s_end = path.s_end
        s = np.linspace(0.0, s_end, samples + 1)
        q = path(s)
        if distances is not None:
            distances = np.asarray(distances, dtype=float)
            if distances.shape != (samples + 1, len(self._pairs)):
                raise ConfigurationError(
                    f"distances must have shape ({samples + 1}, {len(self._pairs)}) (samples + 1, "
                    f"pairs), got {distances.shape}"
                )
        known = None
        if distances is not None:  # NaN: not known (computed, as a bound below every value)
            unknown = np.isnan(distances)
            known = (np.where(unknown, -np.inf, distances), ~unknown & (distances <= exact_below))
        dist, bound, slope = self._first_pass(path, s, q, level, known)  # (S, P), (S − 1, P)
        k_min = np.unravel_index(int(np.argmin(dist)), dist.shape)
        checks = dist.size
        worst = (float(dist[k_min]), float(s[k_min[0]]), int(k_min[1]))
        if worst[0] < level:
            return _Verdict(False, worst[0], worst[1], worst[2], q[k_min[0]], checks)
        if slope is None:  # a path the bound does not cover: its error
            slope = _slope_bound(path)
        rate = self.motion_rates  # (P, n): R_j of each pair's moving bodies
        open_ = np.argwhere(dist[:-1] + dist[1:] - 2.0 * level < bound)
        # the open intervals, bisected level by level: each level's midpoints evaluated
        # together (the path in one call, the kinematics once per distinct midpoint, shared by
        # the pairs open there); every interval is bisected exactly as it would be alone
        i, k = open_.T if open_.size else (np.zeros(0, dtype=int), np.zeros(0, dtype=int))
        a, b, da, db, k = s[i], s[i + 1], dist[i, k], dist[i + 1, k], k.astype(int)
        model, data, geom, gdata = self.robot.model, self._data, self.geometry, self._gdata
        while a.size:
            short = np.flatnonzero(b - a < 1e-9 * s_end)
            if checks > max_checks or short.size:
                j = int(short[0]) if short.size else 0
                at = float(a[j])
                return _Verdict(False, min(da[j], db[j]), at, int(k[j]), None, checks)
            m = 0.5 * (a + b)
            points, where = np.unique(m, return_inverse=True)
            qm = path(points)
            dm = np.empty(m.size)
            order = np.argsort(where, kind="stable")
            bounds = np.searchsorted(where[order], np.arange(points.size + 1))
            for u in range(points.size):
                pin.forwardKinematics(model, data, qm[u])
                pin.updateGeometryPlacements(model, data, geom, gdata)
                for j in order[bounds[u] : bounds[u + 1]]:
                    dm[j] = pin.computeDistance(geom, gdata, int(k[j])).min_distance
            checks += m.size
            j = int(np.argmin(dm))
            if dm[j] < worst[0]:
                worst = (float(dm[j]), float(m[j]), int(k[j]))
            close = np.flatnonzero(dm < level)
            if close.size:
                j = int(close[0])
                return _Verdict(False, dm[j], float(m[j]), int(k[j]), qm[where[j]], checks)
            halves = (a, m, da, dm), (m, b, dm, db)
            lo, hi, dl, dh = (np.concatenate(pair) for pair in zip(*halves, strict=True))
            kk = np.concatenate([k, k])
            v = np.einsum("ij,ij->i", slope(lo, hi), rate[kk]) * (hi - lo)
            keep = dl + dh - 2.0 * level < v
            a, b, da, db, k = lo[keep], hi[keep], dl[keep], dh[keep], kk[keep]
        return _Verdict(True, worst[0], worst[1], worst[2], None, checks)

    # ------------------------------------------------------------------ internals
    def _first_pass(
        self,
        path: JointPath,
        s: NDArray[np.float64],
        q: NDArray[np.float64],
        level: float,
        known: tuple[NDArray[np.float64], NDArray[np.bool_]] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, Callable | None]:
        """:meth:`path_clearance`'s uniform samples: the distances (S, P), exact wherever the
        certificate looks at them (the smallest, and both ends of every interval it cannot
        certify from them), lower bounds elsewhere; the bound L (s_b − s_a) of every
        interval and pair (S − 1, P) and the path's slope bound (:func:`_slope_bound`); both
        None for a path the bound does not cover. ``known``: distances computed before and
        where they are exact (taken, and completed where needed, instead of computed)."""
        try:
            slope = _slope_bound(path)
        except ConfigurationError:  # raised again where the certificate needs the bound
            slope = bound = None
        else:
            bound = slope(s[:-1], s[1:]) @ self.motion_rates.T * np.diff(s)[:, None]
        dist, exact = self._bounded(q, level) if known is None else known
        t0 = time.perf_counter()
        self._least(q, dist, exact)
        if bound is not None and dist.min() >= level:  # (else not certified: no need)
            # the intervals the bounds alone leave open: their ends exactly
            open_ = dist[:-1] + dist[1:] - 2.0 * level < bound
            ends = np.zeros(exact.shape, dtype=bool)
            ends[:-1] |= open_
            ends[1:] |= open_
            ends &= ~exact
            self._exactly(q, ends, dist)
        self.seconds += time.perf_counter() - t0
        return dist, bound, slope

    def __reduce__(self) -> tuple[object, ...]:
        """Pickled as its arguments (coal's shapes are not picklable): rebuilt where it is
        unpickled, e.g. a plan sent back from a Dask worker."""
        robot, scene, srdf, margin, self_collision = self._arguments
        return (_rebuild, (robot, scene, srdf, margin, self_collision))

    def _configure(self) -> None:
        # GJK stops on an absolute duality gap: distances to ~1e-8 m on finely faceted hulls
        # (the default relative criterion leaves ~1e-6 m of noise on kinova's links)
        for req in self._gdata.distanceRequests:
            req.enable_signed_distance = True
            req.gjk_convergence_criterion = coal.GJKConvergenceCriterion.DualityGap
            req.gjk_convergence_criterion_type = coal.GJKConvergenceCriterionType.Absolute
            req.gjk_tolerance = 1e-10
            req.epa_tolerance = 1e-10
        # the results' Python handles, taken once: they refer to the results coal fills at
        # every query (taking them anew from the vector costs as much as the query itself)
        self._results = list(self._gdata.distanceResults)

    def _some(self, q: NDArray[np.float64], index: NDArray[np.int64]) -> NDArray[np.float64]:
        """The distances of the pairs ``index`` only, at θ."""
        t0 = time.perf_counter()
        pin.updateGeometryPlacements(self.robot.model, self._data, self.geometry, self._gdata, q)
        for k in index:
            pin.computeDistance(self.geometry, self._gdata, int(k))
        d = np.array([self._results[int(k)].min_distance for k in index])
        self.seconds += time.perf_counter() - t0
        return d

    def _configurations(self, qs: ArrayLike) -> NDArray[np.float64]:
        """qs as a float array of shape (S, n), or the error of its first bad row."""
        a = np.asarray(qs, dtype=float)
        n = self.robot.n
        if a.ndim != 2 or a.shape[1] != n or not np.all(np.isfinite(a)):
            for row in a.reshape(-1, a.shape[-1]) if a.ndim >= 1 else [a]:
                self.robot.check_configuration(row)
            raise ConfigurationError(f"configurations must have shape (S, {n}), got {a.shape}")
        return a

    def _bounded(
        self, qs: NDArray[np.float64], below: float | ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """:meth:`distances_along` and where its values are exact, shape (S, P) each."""
        count = len(self._pairs)
        below = np.broadcast_to(np.asarray(below, dtype=float), (count,))
        if min(count, len(qs)) < BROAD_PHASE or not np.any(np.isfinite(below)):
            values = np.array([self._all(q) for q in qs]).reshape(len(qs), count)
            return values, np.ones(values.shape, dtype=bool)
        t0 = time.perf_counter()
        model, data, boxes = self.robot.model, self._data, self._boxes
        centre = np.broadcast_to(boxes.centre, (len(qs), *boxes.centre.shape)).copy()  # (S, G, 3)
        extent = np.broadcast_to(boxes.half, centre.shape).copy()
        if boxes.joints.size:
            frames = np.empty((len(qs), boxes.joints.size, 4, 4))
            for i, q in enumerate(qs):
                pin.forwardKinematics(model, data, q)
                frames[i] = [data.oMi[int(j)].homogeneous for j in boxes.joints]
            moving = boxes.moving
            frame = frames[:, boxes.frame[moving]]  # (S, G', 4, 4)
            rotation, translation = frame[..., :3, :3], frame[..., :3, 3]
            with np.errstate(invalid="ignore"):  # an unbounded body: inf · 0
                centre[:, moving] = np.einsum("sgij,gj->sgi", rotation, boxes.centre[moving])
                centre[:, moving] += translation
                extent[:, moving] = np.einsum("sgij,gj->sgi", np.abs(rotation), boxes.half[moving])
        a, b = self._pairs[:, 0], self._pairs[:, 1]
        with np.errstate(invalid="ignore"):
            gap = np.abs(centre[:, a] - centre[:, b]) - extent[:, a] - extent[:, b]  # (S, P, 3)
        # boxes apart bound the distance from below; overlapping ones (or unbounded) do not
        apart = np.all(np.isfinite(gap), axis=2) & np.any(gap > 0.0, axis=2)
        values = np.where(apart, np.linalg.norm(np.maximum(gap, 0.0), axis=2), -np.inf)
        exact = values <= below
        self._exactly(qs, exact, values)
        self.seconds += time.perf_counter() - t0
        return values, exact

    def _least(
        self, qs: NDArray[np.float64], dist: NDArray[np.float64], exact: NDArray[np.bool_]
    ) -> None:
        """Make the least of ``dist`` (S, P) exact (in place, ``exact`` updated): coal's
        distance wherever a lower bound lies below the least one known."""
        while True:
            low = ~exact & (dist < np.min(dist, where=exact, initial=np.inf))
            if not low.any():
                return
            if not exact.any():  # nothing known yet: the least bound first
                low = np.zeros(exact.shape, dtype=bool)
                low.flat[int(np.argmin(dist))] = True
            self._exactly(qs, low, dist)
            exact |= low

    def _exactly(
        self, qs: NDArray[np.float64], where: NDArray[np.bool_], values: NDArray[np.float64]
    ) -> None:
        """coal's distances into ``values`` (S, P) where ``where``: at each configuration the
        pairs asked for only, the others deactivated for the time of the query."""
        rows = np.flatnonzero(where.any(axis=1))
        if rows.size == 0:
            return
        model, data, geom, gdata = self.robot.model, self._data, self.geometry, self._gdata
        a, b = self._pairs[:, 0], self._pairs[:, 1]
        chosen = np.zeros((geom.ngeoms, geom.ngeoms), dtype=bool)
        try:
            for i in rows:
                ks = np.flatnonzero(where[i])
                chosen[:] = False
                chosen[a[ks], b[ks]] = True
                gdata.setActiveCollisionPairs(geom, chosen, True)
                pin.computeDistances(model, data, geom, gdata, qs[i])
                values[i, ks] = [self._results[k].min_distance for k in ks]
        finally:
            gdata.setActiveCollisionPairs(geom, np.ones(chosen.shape, dtype=bool), True)

    def _all(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        if not self.geometry.collisionPairs:
            return np.zeros(0)
        t0 = time.perf_counter()
        pin.computeDistances(self.robot.model, self._data, self.geometry, self._gdata, q)
        d = np.array([r.min_distance for r in self._results])
        self.seconds += time.perf_counter() - t0
        return d

    def _body(self, i: int) -> str:
        obj = self.geometry.geometryObjects[i]
        if i >= self._robot_geoms:
            return obj.name.removeprefix("obstacle:")
        return self.robot.model.frames[obj.parentFrame].name

    def _motion_rates(self) -> NDArray[np.float64]:
        """R_j per pair and joint: how fast the pair's distance can change per unit of θ'_j
        [m/rad or m/m], shape (P, n) (see the module docstring)."""
        model, robot = self.robot.model, self.robot
        n = model.nv
        support = [set(model.supports[j].tolist()) - {0} for j in range(model.njoints)]
        radius = np.zeros(self.geometry.ngeoms)
        for i, obj in enumerate(self.geometry.geometryObjects):
            g = obj.geometry
            if isinstance(g, coal.Halfspace):
                continue
            g.computeLocalAABB()
            centre = obj.placement.act(np.asarray(g.aabb_center))
            radius[i] = np.linalg.norm(centre) + g.aabb_radius
        prismatic = robot.prismatic
        travel = np.where(
            prismatic,
            np.maximum(np.abs(robot.limits.position_lower), np.abs(robot.limits.position_upper)),
            0.0,
        )
        travel = np.where(np.isfinite(travel), travel, 10.0)
        offsets = np.array(
            [0.0]
            + [
                np.linalg.norm(model.jointPlacements[j].translation) + travel[j - 1]
                for j in range(1, model.njoints)
            ]
        )

        def reach(j: int, body: int) -> float:
            """Bound on the distance of the body's points from joint j's axis [m]."""
            jb = int(self._joint[body])
            chain = [i for i in sorted(support[jb]) if i > j]  # joints after j up to the body
            return float(offsets[chain].sum() + radius[body])

        rates = np.zeros((len(self._pairs), n))
        for k, (a, b) in enumerate(self._pairs):
            sa, sb = support[self._joint[a]], support[self._joint[b]]
            for j in sa ^ sb:
                body = a if j in sa else b
                rates[k, j - 1] = 1.0 if prismatic[j - 1] else reach(j, body)
        return rates


BROAD_PHASE = 16
"""Configurations and pairs from which :meth:`CollisionModel.distances_along` bounds the pairs
by their bodies' boxes first (fewer of either: every pair exactly, which costs less than the
boxes' set-up)."""


@dataclass(frozen=True)
class _Boxes:
    """Every body's bounding box for the broad phase of :meth:`CollisionModel.distances_along`.

    Attributes
    ----------
    joints
        The joints the moving bodies are fixed to, shape (J,).
    moving
        The bodies on a joint, shape (G',).
    frame
        Each body's joint as an index into ``joints`` (−1: fixed to the base), shape (G,).
    centre, half
        Each box's centre and half-extents [m], in its joint's frame (the base's for a fixed
        body), axis-aligned there; infinite half-extents for a half-space, or where coal gives
        no finite box; shape (G, 3) each.
    """

    joints: NDArray[np.int64]
    moving: NDArray[np.int64]
    frame: NDArray[np.int64]
    centre: NDArray[np.float64]
    half: NDArray[np.float64]


def _local_boxes(geom: pin.GeometryModel) -> _Boxes:
    """The bodies' boxes (coal's local boxes, each placed in its joint's frame)."""
    count = geom.ngeoms
    centre, half = np.zeros((count, 3)), np.full((count, 3), np.inf)
    parent = np.array([o.parentJoint for o in geom.geometryObjects], dtype=int)
    for i, obj in enumerate(geom.geometryObjects):
        g = obj.geometry
        if isinstance(g, coal.Halfspace | coal.Plane):
            continue
        g.computeLocalAABB()
        lo, hi = np.asarray(g.aabb_local.min_), np.asarray(g.aabb_local.max_)
        if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)):
            m = obj.placement  # the body in its joint's frame
            centre[i] = m.rotation @ (0.5 * (lo + hi)) + m.translation
            half[i] = np.abs(m.rotation) @ (0.5 * (hi - lo))
    joints = np.unique(parent[parent != 0])
    frame = np.where(parent != 0, np.searchsorted(joints, parent), -1)
    return _Boxes(joints, np.flatnonzero(parent != 0), frame, centre, half)


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """a × b row by row, shapes (m, 3) (NumPy's ``cross`` costs ~30 µs at these sizes)."""
    return np.column_stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ]
    )


def _slope_bound(path: JointPath):  # noqa: ANN202
    """A function (a, b) → max |θ'_j| over [a, b] per joint, for intervals given as arrays,
    exact per polynomial piece (θ' is quadratic between the path's breakpoints)."""
    if isinstance(path, StraightPath):
        slope = np.abs(path(np.zeros(1), 1)[0])
        return lambda a, b: np.broadcast_to(slope, (np.size(a), slope.size))
    if not isinstance(path, BSplinePath | SplinePath):
        raise ConfigurationError(
            f"a certified collision check needs a StraightPath, BSplinePath or SplinePath, got "
            f"{type(path).__name__}"
        )
    edges = np.concatenate([[0.0], np.asarray(path.breakpoints, dtype=float), [path.s_end]])
    lo, hi = edges[:-1], edges[1:]
    mid = 0.5 * (lo + hi)
    f0, fm, f1 = path(lo, 1), path(mid, 1), path(hi, 1)  # (P, n) each: a quadratic per piece
    # q(x) on x ∈ [−1, 1]: q = fm + βx + αx², β = (f1 − f0)/2, α = (f1 + f0)/2 − fm
    beta, alpha = 0.5 * (f1 - f0), 0.5 * (f1 + f0) - fm
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(alpha != 0.0, -beta / (2.0 * alpha), 0.0)
    inside = np.abs(x) < 1.0
    vertex = np.where(inside, np.abs(fm + beta * x + alpha * x * x), 0.0)
    piece = np.maximum.reduce([np.abs(f0), np.abs(f1), vertex])  # (P, n)

    def bound(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        first = np.clip(np.searchsorted(edges, a, side="right") - 1, 0, lo.size - 1)
        last = np.clip(np.searchsorted(edges, b, side="left") - 1, 0, lo.size - 1)
        out = piece[first]  # an interval within one piece: that piece's bound
        for i in np.flatnonzero(last > first):
            out[i] = piece[first[i] : last[i] + 1].max(axis=0)
        return out

    return bound


def _convex(geometry: coal.CollisionGeometry, name: str) -> coal.CollisionGeometry:
    """A mesh as its convex hull (coal's GJK/EPA then gives signed distances).

    The hull is qhull's (SciPy) on the mesh's vertices, handed to coal with its hull vertices
    only: coal's own ``buildConvexRepresentation`` keeps every vertex, and GJK's support search
    on that graph stops at interior points (distances then depend on the previous query).
    """
    if not isinstance(geometry, coal.BVHModelBase):
        return geometry
    points = np.asarray(geometry.vertices(), dtype=float).reshape(-1, 3)
    if not np.all(np.isfinite(points)):
        raise URDFError(f"the mesh of {name!r} has vertices that are not finite numbers")
    if points.shape[0] < 4 or np.ptp(points, axis=0).max() < 1e-6:
        raise URDFError(f"the mesh of {name!r} has no volume (smaller than 1 µm)")
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError) as exc:
        raise URDFError(f"the mesh of {name!r} has no volume: {exc}") from None
    return coal.Convex.convexHull(list(points[hull.vertices]), False, None)


def _loader_reason(exc: Exception) -> str:
    """What a mesh loader's error says, without its C++ file and function (assimp via coal)."""
    text = " ".join(str(exc).split())
    reason = text.rsplit(" in function: ", 1)[-1]
    reason = reason.split(")", 1)[-1] if reason != text else reason
    reason = reason.split(" Hint:", 1)[0].strip(" :")
    if "No suitable reader" in text:
        return "not a mesh file coal's loader reads (STL, OBJ, DAE, …)"
    if "File is empty" in text:
        return "the file is empty"
    return reason or text


def _coal_shape(shape: object, name: str) -> coal.CollisionGeometry:
    if isinstance(shape, Box):
        return coal.Box(*shape.size)
    if isinstance(shape, Sphere):
        return coal.Sphere(shape.radius)
    if isinstance(shape, Cylinder):
        return coal.Cylinder(shape.radius, shape.length)
    if isinstance(shape, Capsule):
        return coal.Capsule(shape.radius, shape.length)
    if isinstance(shape, HalfSpace):
        return coal.Halfspace(np.asarray(shape.normal, dtype=float), shape.offset)
    if isinstance(shape, Mesh):
        try:
            bvh = coal.MeshLoader().load(str(shape.path), np.full(3, shape.scale))
        except (RuntimeError, ValueError) as exc:
            raise SceneError(
                f"obstacle {name!r}: cannot load the mesh {shape.path}: {_loader_reason(exc)}",
                obstacle=name,
                field="mesh",
            ) from None
        try:
            return _convex(bvh, name)
        except URDFError as exc:
            raise SceneError(
                f"obstacle {name!r}: {shape.path}: {exc}", obstacle=name, field="mesh"
            ) from None
    raise SceneError(f"obstacle {name!r}: unknown shape {type(shape).__name__}", obstacle=name)


def _srdf_disabled(path: Path) -> set[frozenset[str]]:
    """The SRDF's ``<disable_collisions link1= link2=>`` pairs."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise URDFError(f"cannot read the SRDF {path}: {exc}", path=str(path)) from None
    return {
        frozenset((e.get("link1", ""), e.get("link2", ""))) for e in root.iter("disable_collisions")
    }


def _rebuild(
    robot: Robot,
    scene: Scene | None,
    srdf: str | Path | None,
    margin: float | None,
    self_collision: bool,
) -> CollisionModel:
    return CollisionModel(robot, scene, srdf=srdf, margin=margin, self_collision=self_collision)


def collisions_for(
    robot: Robot,
    scene: Scene | CollisionModel | None,
    margin: float | None,
    self_collision: bool | None,
) -> CollisionModel | None:
    """The collision model a plan keeps, or None when nothing is checked: ``scene`` itself if it
    is a model already (built for this robot), else one built from the scene (None: no
    obstacles) with the margin [m] and self-collision (None: with a scene) asked for."""
    if isinstance(scene, CollisionModel):
        if scene.robot is not robot:
            raise ConfigurationError("the collision model was built for another Robot object")
        if margin is not None or self_collision is not None:
            raise ConfigurationError(
                "give margin and self_collision when building the CollisionModel, not to plan()"
            )
        return scene
    if scene is not None and not isinstance(scene, Scene):
        raise ConfigurationError(
            f"scene must be a nearopt.collision.Scene (Scene.from_file(path)) or a "
            f"CollisionModel, got {type(scene).__name__}"
        )
    if self_collision is None:
        self_collision = scene is not None
    if scene is None and not self_collision:
        if margin is not None:
            raise ConfigurationError("margin applies with a scene or self_collision=True")
        return None
    return CollisionModel(robot, scene, margin=margin, self_collision=bool(self_collision))
