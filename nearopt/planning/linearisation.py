"""Stage 1's rows as functions of the path: what stage 2 differentiates.

For a path θ(σ) = Σ_j B_j(σ) c_j whose control points c_j are moved by stage 2 (the interior ones,
flattened into p with index j·n + i for joint i of interior point j), every row of
:class:`~nearopt.timing.Discretisation` depends on the path through θ, θ', θ'' where it lies:

* torque u_i = ID_i(θ, λθ', bθ'' + aθ') + D_i λ θ'_i at sample r (knot k, segment s):
  ∂u/∂θ = ∂ID/∂θ, ∂u/∂θ' = λ ∂ID/∂θ̇ + a H, ∂u/∂θ'' = b H (Pinocchio's RNEA derivatives, the
  damping D included in ∂ID/∂θ̇);
* joint acceleration θ̈_i = θ'_i a + θ''_i b: ∂/∂θ'_i = a, ∂/∂θ''_i = b;
* joint speed b θ'_i² (at knots and inside segments): ∂/∂θ'_i = 2 b θ'_i;
* the rows between the samples (the bounds of the motion between them): interpolated linearly
  between the same quantity's derivatives at the two ends of their segment.

With ∂θ^(o)(σ)/∂c_j = B_j^(o)(σ), :func:`row_path_jacobian` gives ∂(rows)/∂p at a timing b; the
rows are then linear in b (for a fixed path) and, to first order, in p: the convex model of
stage 2's sequential convex programming.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.sparse as sp

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from ..path import BSplinePath
    from ..robot import Robot
    from ..timing import Discretisation

__all__ = ["PathBasis", "path_basis", "row_path_jacobian"]


class PathBasis(NamedTuple):
    """∂θ^(o)(σ)/∂c_j of the interior control points j where the rows lie.

    Attributes
    ----------
    knots
        B, B', B'' (derivatives with respect to σ) at the grid knots, each (N+1, K).
    interior
        B' at the points inside segments where speed rows lie, (P, K).
    first, local
        The same at the knots on the few consecutive control points whose basis is nonzero
        there: the first one's index per knot, (N+1,), and B, B', B'' from it on, each
        (N+1, w) (w = 4 for a cubic B-spline; zeros past the last control point).
    """

    knots: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]
    interior: NDArray[np.float64]
    first: NDArray[np.int64]
    local: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]


def path_basis(path: BSplinePath, disc: Discretisation, end: bool = False) -> PathBasis:
    """The basis of a B-spline path's interior control points (and of its end point, with
    ``end``: a goal that moves) at a discretisation's rows."""
    sigma = disc.problem.sigma
    cols = slice(1, None if end else -1)
    knots = tuple(path.basis(sigma, order)[:, cols] for order in (0, 1, 2))
    inside = disc.problem.interior_speed
    at = np.zeros(0) if inside is None else inside.sigma
    nonzero = (knots[0] != 0.0) | (knots[1] != 0.0) | (knots[2] != 0.0)
    count = knots[0].shape[1]
    first = np.where(nonzero.any(axis=1), nonzero.argmax(axis=1), 0)
    last = np.where(nonzero.any(axis=1), count - 1 - nonzero[:, ::-1].argmax(axis=1), 0)
    width = int(np.max(last - first + 1, initial=1))
    take = first[:, None] + np.arange(width)[None, :]
    inside_range = take < count
    local = tuple(
        np.where(inside_range, np.take_along_axis(b, np.minimum(take, count - 1), axis=1), 0.0)
        for b in knots
    )
    return PathBasis(knots, path.basis(at, 1)[:, cols], first, local)  # type: ignore[arg-type]


def row_path_jacobian(
    robot: Robot,
    disc: Discretisation,
    z: NDArray[np.float64],
    basis: PathBasis,
    between: bool = True,
) -> sp.csr_matrix:
    """∂(rows)/∂p at the timing z: sparse, (R, K·n), columns j·n + i.

    Parameters
    ----------
    robot
        The arm the rows were built for.
    disc
        Stage 1's rows for the current path.
    z
        b at the free knots, shape (N−1,).
    basis
        The control points' basis where the rows lie (:func:`path_basis`).
    between
        Whether the rows between the samples get their derivatives; False: they are left
        empty (zero rows in their places), for a model that does not hold them (stage 2's).
    """
    p = disc.problem
    n, big_n = p.dof, p.segments
    k_count = basis.knots[0].shape[1]
    node, seg = disc.node, disc.seg
    b = disc.b(z)
    lam = np.sqrt(b)
    acc = (np.diff(b) / (2.0 * disc.ds))[seg]
    parts: list[sp.coo_matrix] = []

    # torque rows, joint-major (i·2N + r)
    th, dth = p.theta[node], p.dtheta[node]
    du_dq, du_dv, mass = robot.inverse_dynamics_derivatives(
        th, lam[node, None] * dth, b[node, None] * p.ddtheta[node] + acc[:, None] * dth
    )
    d_order = (
        du_dq,
        lam[node, None, None] * du_dv + acc[:, None, None] * mass,
        b[node, None, None] * mass,
    )
    if between:  # dense: the rows between the samples interpolate it
        torque = sum(
            np.einsum("rab,rj->arjb", d, basis.knots[o][node]) for o, d in enumerate(d_order)
        )
        torque = torque.reshape(n, 2 * big_n, k_count * n)
        parts.append(sp.coo_matrix(torque.reshape(n * 2 * big_n, k_count * n)))
    else:  # on the control points whose basis is nonzero at each sample's knot only
        parts.append(_local_torque(d_order, basis, node, n, k_count))

    def joint_rows(rows: slice, value: NDArray[np.float64], shape: NDArray[np.float64]) -> None:
        """Rows whose derivative is ``value`` × ``shape`` (a basis row) in their own joint."""
        count = rows.stop - rows.start
        joint = disc.joint[rows]
        data = value[:, None] * shape  # (count, K)
        r = np.repeat(np.arange(count), k_count)
        c = (np.arange(k_count)[None, :] * n + joint[:, None]).ravel()
        parts.append(sp.coo_matrix((data.ravel(), (r, c)), shape=(count, k_count * n)))

    rows = disc.blocks.acceleration
    sample, joint = disc.location[rows], disc.joint[rows]
    joint_rows(
        rows,
        np.ones(sample.size),
        acc[sample, None] * basis.knots[1][node[sample]]
        + b[node[sample], None] * basis.knots[2][node[sample]],
    )
    rows = disc.blocks.speed
    knot, joint = disc.location[rows], disc.joint[rows]
    joint_rows(rows, 2.0 * b[knot] * p.dtheta[knot, joint], basis.knots[1][knot])
    rows = disc.blocks.interior_speed
    if rows.stop > rows.start:
        inside = p.interior_speed
        point, joint = disc.location[rows], disc.joint[rows]
        k, w = inside.segment[point], inside.weight[point]
        b_at = (1.0 - w) * b[k] + w * b[k + 1]
        joint_rows(rows, 2.0 * b_at * inside.dtheta[point, joint], basis.interior[point])
    if not between:  # the rows between the samples are the last ones (Discretisation)
        tail = disc.offset.size - disc.blocks.torque_between.start
        parts.append(sp.csr_matrix((tail, k_count * n)))
        return _stacked(parts)
    # the rows between the samples: interpolated between the segment's two ends (their own
    # curvature terms, second differences along the segment, are left out: O(Δσ²) smaller)
    rows = disc.blocks.torque_between
    k, w, joint = disc.location[rows], disc.position[rows], disc.joint[rows]
    parts.append(
        sp.coo_matrix((1.0 - w)[:, None] * torque[joint, k] + w[:, None] * torque[joint, big_n + k])
    )
    rows = disc.blocks.acceleration_between
    k, w = disc.location[rows], disc.position[rows]
    a_k = (np.diff(b) / (2.0 * disc.ds))[k]  # the segment's path acceleration
    at_ends = [
        a_k[:, None] * basis.knots[1][knot] + b[knot, None] * basis.knots[2][knot]
        for knot in (k, k + 1)
    ]
    joint_rows(rows, np.ones(k.size), (1.0 - w)[:, None] * at_ends[0] + w[:, None] * at_ends[1])
    rows = disc.blocks.speed_between
    k, w, joint = disc.location[rows], disc.position[rows], disc.joint[rows]
    joint_rows(
        rows,
        np.ones(k.size),
        ((1.0 - w) * 2.0 * b[k] * p.dtheta[k, joint])[:, None] * basis.knots[1][k]
        + (w * 2.0 * b[k + 1] * p.dtheta[k + 1, joint])[:, None] * basis.knots[1][k + 1],
    )
    return _stacked(parts)


def _local_torque(
    d_order: tuple[NDArray[np.float64], ...],
    basis: PathBasis,
    node: NDArray[np.int64],
    n: int,
    k_count: int,
) -> sp.csr_matrix:
    """The torque rows' derivatives (joint-major, i·2N + r) as CSR, formed on the w control
    points whose basis is nonzero at each sample's knot: the same sums of the same products
    as the dense form, w/K of the work."""
    samples = node.size
    local = [b[node] for b in basis.local]  # (2N, w) each
    width = local[0].shape[1]
    block = sum(np.einsum("rab,rj->arjb", d, local[o]) for o, d in enumerate(d_order))
    point = basis.first[node][:, None] + np.arange(width)[None, :]  # (2N, w)
    columns = (point[:, :, None] * n + np.arange(n)[None, None, :]).reshape(samples, -1)
    keep = np.repeat(point < k_count, n, axis=1)  # past the last control point: none
    data = block.reshape(n, samples, width * n)[:, keep]
    indices = np.broadcast_to(columns[keep], (n, int(keep.sum())))
    counts = np.tile(keep.sum(axis=1), n)
    indptr = np.concatenate([[0], np.cumsum(counts)])
    return sp.csr_matrix((data.ravel(), indices.ravel(), indptr), shape=(n * samples, k_count * n))


def _stacked(parts: list[sp.spmatrix]) -> sp.csr_matrix:
    """The parts one under the other, without the zeros of the basis functions' supports."""
    out = sp.vstack(parts).tocsr()
    out.eliminate_zeros()
    return out
