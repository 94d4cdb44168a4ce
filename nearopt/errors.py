"""Typed errors of nearopt.

Every failure nearopt raises on purpose derives from :class:`NearoptError`, so a caller can catch
one type; the subclasses say what kind of thing went wrong and carry the values that explain it
(the joint, the value, the limit).
"""

from __future__ import annotations

__all__ = [
    "NearoptError",
    "URDFError",
    "RobotNotFoundError",
    "SceneError",
    "CollisionError",
    "UnreachablePoseError",
    "ConfigurationError",
    "InfeasiblePathError",
    "SolverError",
    "VerificationError",
    "SamplingWarning",
]


class NearoptError(Exception):
    """Base class of every error nearopt raises on purpose."""


class URDFError(NearoptError):
    """A URDF that cannot be used: missing, malformed, or describing an unsupported robot.

    Parameters
    ----------
    message
        What is wrong, naming the file, joint or link.
    path
        The URDF file concerned, if any.
    """

    def __init__(self, message: str, *, path: str | None = None) -> None:
        super().__init__(message)
        self.path = path


class RobotNotFoundError(URDFError, KeyError):
    """A robot name that nearopt does not know.

    Parameters
    ----------
    name
        The name asked for.
    available
        The names nearopt knows.
    """

    def __init__(self, name: str, available: list[str]) -> None:
        self.name = name
        self.available = list(available)
        URDFError.__init__(
            self, f"unknown robot {name!r}; known robots: {', '.join(self.available)}"
        )

    def __str__(self) -> str:  # KeyError would otherwise quote the message
        return str(self.args[0])


class ConfigurationError(NearoptError, ValueError):
    """A joint vector (configuration, velocity, torque, limit) of the wrong shape or value.

    Parameters
    ----------
    message
        What is wrong, naming the joint and the value.
    joint
        The joint concerned, if one is.
    """

    def __init__(self, message: str, *, joint: str | None = None) -> None:
        super().__init__(message)
        self.joint = joint


class InfeasiblePathError(NearoptError):
    """No timing of the given path satisfies the limits.

    Parameters
    ----------
    message
        Where and why, naming the joint, the path parameter s, the configuration and the excess.
    joint
        The joint whose limit cannot be met.
    s
        The path parameter where it fails.
    excess
        By how much the limit is exceeded at the least, in the limit's unit.
    """

    def __init__(
        self,
        message: str,
        *,
        joint: str | None = None,
        s: float | None = None,
        excess: float | None = None,
    ) -> None:
        super().__init__(message)
        self.joint = joint
        self.s = s
        self.excess = excess


class SolverError(NearoptError):
    """A numerical solver did not reach a usable answer.

    Parameters
    ----------
    message
        Which solver, on what problem, and what it reported.
    status
        The solver's own status text or code.
    """

    def __init__(self, message: str, *, status: object = None) -> None:
        super().__init__(message)
        self.status = status


class SceneError(ConfigurationError):
    """A scene of obstacles that cannot be used: a bad file, field or value.

    Parameters
    ----------
    message
        What is wrong, naming the file, the obstacle and the field.
    obstacle
        The obstacle concerned, if one is.
    field
        The field concerned, if one is.
    """

    def __init__(
        self, message: str, *, obstacle: str | None = None, field: str | None = None
    ) -> None:
        super().__init__(message)
        self.obstacle = obstacle
        self.field = field


class TaskError(ConfigurationError):
    """A task file or task record that cannot be used: a bad file, target or field.

    Parameters
    ----------
    message
        What is wrong, naming the file, the target and the field.
    target
        The target concerned (its name, or ``target <k>``), if one is.
    field
        The field concerned, if one is.
    """

    def __init__(
        self, message: str, *, target: str | None = None, field: str | None = None
    ) -> None:
        super().__init__(message)
        self.target = target
        self.field = field


class CollisionError(NearoptError):
    """A configuration or motion that collides (or comes closer than the margin), or no
    collision-free path found.

    Parameters
    ----------
    message
        Where and why, naming the pair of bodies and their signed distance [m].
    pair
        The two bodies (robot links or obstacles), if one pair is concerned.
    distance
        Their signed distance [m] (negative: the penetration depth).
    """

    def __init__(
        self,
        message: str,
        *,
        pair: tuple[str, str] | None = None,
        distance: float | None = None,
    ) -> None:
        super().__init__(message)
        self.pair = pair
        self.distance = distance


class UnreachablePoseError(NearoptError):
    """A tool pose no configuration within the joint limits reaches.

    Parameters
    ----------
    message
        The target and how far the closest placement found is from it.
    distance, angle
        That distance [m] and angle [rad].
    """

    def __init__(self, message: str, *, distance: float, angle: float) -> None:
        super().__init__(message)
        self.distance = distance
        self.angle = angle


class VerificationError(NearoptError):
    """A motion failed verification; ``report`` (a :class:`~nearopt.VerificationReport`) says
    which checks and by how much."""

    def __init__(self, message: str, report: object) -> None:
        super().__init__(message)
        self.report = report


class SamplingWarning(UserWarning):
    """Samples of a motion at a rate too low to resolve it (a phase shorter than one period)."""
