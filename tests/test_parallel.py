"""in_parallel: forked tasks give the results of the same tasks run here, in order."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

import nearopt
from nearopt.parallel import beside, cores, in_child, in_children, in_parallel


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


@pytest.mark.skipif(cores() < 2, reason="on one core the second task runs here after the first")
def test_beside_runs_the_second_task_at_the_same_time_and_ends_it_when_unwanted() -> None:
    """here in this process, there in another at the same time (two tasks of 0.3 s take ~0.3 s);
    where here's result is not wanted, there's child is ended without waiting for it."""
    began = time.perf_counter()
    mine, theirs = beside(
        lambda: (time.sleep(0.3), os.getpid())[1],
        lambda: (time.sleep(0.3), os.getpid())[1],
        lambda _: True,
    )
    assert mine == os.getpid() and theirs not in (None, os.getpid())
    assert time.perf_counter() - began < 0.55
    began = time.perf_counter()
    mine, theirs = beside(lambda: 1, lambda: time.sleep(30.0), lambda _: False)
    assert (mine, theirs) == (1, None) and time.perf_counter() - began < 5.0

    def fails() -> None:
        raise ValueError("no such thing")

    with pytest.raises(nearopt.SolverError, match="the second run failed: ValueError"):
        beside(lambda: 1, fails, lambda _: True, "the second run")


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


@pytest.mark.skipif(not hasattr(os, "fork"), reason="without fork the tasks run here")
def test_in_children_runs_every_task_in_a_process_of_its_own() -> None:
    """Results in order, each from another process than this one and than the others; an
    error in one child is raised here (the others ended)."""
    answers = in_children([lambda k=k: (k, os.getpid()) for k in range(3)])
    assert [k for k, _ in answers] == [0, 1, 2]
    pids = {pid for _, pid in answers}
    assert len(pids) == 3 and os.getpid() not in pids

    def fails() -> None:
        raise ValueError("no such thing")

    with pytest.raises(nearopt.SolverError, match="the OMPL search failed: ValueError"):
        in_children([os.getpid, fails, os.getpid], "the OMPL search")


def test_ompl_attempts_in_children_give_the_same_paths_as_one_after_the_other() -> None:
    """The cell's OMPL searches at the same time, each in its own child seeded with its own
    number, give the paths the same searches give one after the other (each in a child of its
    own): the same request gives the same paths however the processes share the cores."""
    from nearopt.collision import Box, CollisionModel, Obstacle, Scene
    from nearopt.collision.sampling import OMPL_SEED, collision_free_path, search_paths

    robot = nearopt.Robot.from_name("ur5")
    scene = Scene((Obstacle("box", Box((0.2, 0.2, 0.6)), (0.45, 0.0, 0.3)),), margin=0.01)
    model = CollisionModel(robot, scene)
    q0 = np.array([-0.8, -1.2, 1.2, -1.5, -1.57, 0.0])
    qe = np.array([0.8, -1.2, 1.2, -1.5, -1.57, 0.0])
    assert not model.path_clearance(nearopt.StraightPath(q0, qe)).certified
    together = collision_free_path(
        model, q0, qe, control_points=12, breaks=None, time_limit=20.0, attempts=3
    )

    def alone(seed: int) -> list[np.ndarray]:
        found = search_paths(
            model, q0, qe, control_points=12, breaks=None, time_limit=20.0, attempts=1, seed=seed
        )
        return [p.control_points for p in found]

    one_by_one = [c for k in range(3) for c in in_child(lambda k=k: alone(OMPL_SEED + k))]
    assert len(together) == len(one_by_one) >= 2
    for path, points in zip(together, one_by_one, strict=True):
        np.testing.assert_array_equal(path.control_points, points)
    # searches numbered from 1 on: the same paths as those searches among the first three
    later = collision_free_path(
        model, q0, qe, control_points=12, breaks=None, time_limit=20.0, attempts=2, first=1
    )
    assert len(later) == 2
    for path, points in zip(later, one_by_one[-2:], strict=True):
        np.testing.assert_array_equal(path.control_points, points)
