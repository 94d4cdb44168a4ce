"""nearopt: near-optimum trajectory planning for URDF robot arms.

The package follows the paper "Near-Optimum Trajectory Planning for Robot Manipulators":
``robot`` (URDF → Pinocchio: H, h, g, D, limits, derivatives) → ``path`` (θ(s)) → ``timing``
(stage 1, λ(s)) → ``trajectory`` (θ(t)) → ``path optimisation`` (stage 2) → ``plan`` →
``verify``; ``viewer`` and ``figures`` to look at it, ``export`` to write it.
"""

from .batch import MotionOutcome, MotionRequest, plan_many
from .catalog import available_robots
from .collision import CollisionModel, Obstacle, Scene
from .cost import CallableCost, Cost, TimeCost, TorqueCost
from .errors import (
    CollisionError,
    ConfigurationError,
    InfeasiblePathError,
    NearoptError,
    RobotNotFoundError,
    SamplingWarning,
    SceneError,
    SolverError,
    TaskError,
    UnreachablePoseError,
    URDFError,
)
from .kinematics import ToolPose, inverse_kinematics
from .path import BSplinePath, Path, SplinePath, StraightPath
from .planning import (
    Iteration,
    Method,
    PaperOptions,
    Plan,
    PlanResult,
    SCPOptions,
    StopReason,
    Target,
    Task,
    TaskResult,
    plan,
    plan_task,
)
from .robot import JointLimits, PathCoefficients, Robot
from .timing import TimingResult, optimal_timing
from .trajectory import ChainedTrajectory, Samples, Trajectory
from .verify import VerificationError, VerificationReport, Waypoint, verify

__all__ = [
    "Robot",
    "Path",
    "StraightPath",
    "BSplinePath",
    "SplinePath",
    "Cost",
    "TimeCost",
    "TorqueCost",
    "CallableCost",
    "optimal_timing",
    "plan",
    "PlanResult",
    "Plan",
    "plan_task",
    "plan_many",
    "MotionRequest",
    "MotionOutcome",
    "Target",
    "Task",
    "TaskResult",
    "Iteration",
    "Method",
    "StopReason",
    "SCPOptions",
    "PaperOptions",
    "TimingResult",
    "Trajectory",
    "ChainedTrajectory",
    "Samples",
    "verify",
    "VerificationReport",
    "VerificationError",
    "Waypoint",
    "JointLimits",
    "PathCoefficients",
    "available_robots",
    "Scene",
    "Obstacle",
    "CollisionModel",
    "ToolPose",
    "inverse_kinematics",
    "NearoptError",
    "URDFError",
    "RobotNotFoundError",
    "ConfigurationError",
    "InfeasiblePathError",
    "SolverError",
    "CollisionError",
    "SceneError",
    "TaskError",
    "UnreachablePoseError",
    "SamplingWarning",
]

__version__ = "0.1.0"
