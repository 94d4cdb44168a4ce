"""nearopt: near-optimum trajectory planning for URDF robot arms.

The package follows the paper "Near-Optimum Trajectory Planning for Robot Manipulators":
``robot`` (URDF → Pinocchio: H, h, g, D, limits, derivatives) → ``path`` (θ(s)) → ``timing``
(stage 1, λ(s)) → ``trajectory`` (θ(t)) → ``path optimisation`` (stage 2) → ``plan``.
"""

from .catalog import available_robots
from .errors import (
    ConfigurationError,
    InfeasiblePathError,
    NearoptError,
    RobotNotFoundError,
    SolverError,
    URDFError,
)
from .robot import JointLimits, PathCoefficients, Robot

__all__ = [
    "Robot",
    "JointLimits",
    "PathCoefficients",
    "available_robots",
    "NearoptError",
    "URDFError",
    "RobotNotFoundError",
    "ConfigurationError",
    "InfeasiblePathError",
    "SolverError",
]

__version__ = "0.1.0"
