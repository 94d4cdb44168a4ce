"""Shared fixtures: every arm nearopt knows, loaded once per session, with readable ids."""

from __future__ import annotations

import functools

import numpy as np
import pytest

import nearopt

ROBOT_NAMES = nearopt.available_robots()


@functools.cache
def load(name: str) -> nearopt.Robot:
    """Load a known robot once per test session (a Robot is immutable)."""
    return nearopt.Robot.from_name(name)


@pytest.fixture(params=ROBOT_NAMES, ids=ROBOT_NAMES)
def robot(request: pytest.FixtureRequest) -> nearopt.Robot:
    """Each known arm in turn: the bundled ones and those of example-robot-data."""
    return load(request.param)


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator, so that every random test is reproducible."""
    return np.random.default_rng(20261122)


def random_configuration(robot: nearopt.Robot, rng: np.random.Generator) -> np.ndarray:
    """A configuration drawn uniformly within the position limits (±π where there are none)."""
    lo = np.maximum(robot.limits.position_lower, -np.pi)
    hi = np.minimum(robot.limits.position_upper, np.pi)
    return rng.uniform(lo, hi)
