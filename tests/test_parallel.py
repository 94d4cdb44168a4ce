"""in_parallel: forked tasks give the results of the same tasks run here, in order."""

from __future__ import annotations

import os

import numpy as np
import pytest

import nearopt
from nearopt.parallel import cores, in_child, in_parallel


def test_forked_tasks_give_the_same_results_in_order() -> None:
    """Stage 1 on three paths: the same numbers, to the last bit, as one after the other here;
    with two cores or more the second and third ran in other processes."""
    robot = nearopt.Robot.from_name("two_link")
    q0 = np.array([0.7, -1.5])
    paths = [nearopt.StraightPath(q0, q0 + d) for d in ([1.0, 0.5], [-0.8, 1.2], [0.3, -0.9])]

    def timed(path: nearopt.Path) -> tuple[int, np.ndarray, float]:
        timing = nearopt.optimal_timing(robot, path, nearopt.TorqueCost(0.03), grid=60)
        return os.getpid(), timing.b, timing.J

    here = [timed(p) for p in paths]
    forked = in_parallel([lambda p=p: timed(p) for p in paths])
    for (_, b_here, j_here), (_, b_forked, j_forked) in zip(here, forked, strict=True):
        np.testing.assert_array_equal(b_here, b_forked)
        assert j_here == j_forked
    pids = [pid for pid, _, _ in forked]
    assert pids[0] == os.getpid()
    if cores() >= 2:
        assert len(set(pids)) == 3


@pytest.mark.skipif(cores() < 2, reason="on one core the tasks run here, their errors as they are")
def test_an_error_in_a_child_is_named_here() -> None:
    def fails() -> None:
        raise ValueError("no such thing")

    with pytest.raises(nearopt.SolverError, match="ValueError: no such thing"):
        in_parallel([lambda: 1, fails])
    assert in_parallel([lambda: 1]) == [1]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="without fork the task runs here")
def test_a_nearopt_error_in_a_child_comes_back_as_it_was() -> None:
    """A child's nearopt error is raised here with its type and its values; the result of a
    task that succeeds comes back from another process."""

    def collides() -> None:
        raise nearopt.CollisionError("too close", pair=("link", "post"), distance=-0.002)

    with pytest.raises(nearopt.CollisionError, match="too close") as caught:
        in_child(collides)
    assert caught.value.pair == ("link", "post") and caught.value.distance == -0.002
    assert in_child(os.getpid) != os.getpid()
