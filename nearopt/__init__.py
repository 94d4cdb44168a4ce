"""nearopt: near-optimum trajectory planning for URDF robot arms.

The package follows the paper "Near-Optimum Trajectory Planning for Robot Manipulators":
``robot`` (URDF → Pinocchio: H, h, g, D, limits, derivatives) → ``path`` (θ(s)) → ``timing``
(stage 1, λ(s)) → ``trajectory`` (θ(t)) → ``planning`` (stage 2, tasks) → ``verify``; ``viz``
to look at it, ``export`` to write it; ``api`` (one request), ``batch`` and ``cli`` on top.

Glossary (the names the code uses, and their symbols):

=====================  =======================================================================
n, ``dof``             joints (degrees of freedom)
θ, ``q``               joint positions [rad or m], shape (n,) or (samples, n); θ0 ``q0``, θe ``qe``
θ̇, θ̈, ``qd``, ``qdd``   joint speeds and accelerations
u, ``tau``, effort     joint torques (forces) of eq. (1) [N·m or N]; ``effort`` for their limits
s                      the path's own parameter, θ(s) on [0, s_e] (``Path.s_end``)
σ, ``sigma``           s / s_e ∈ [0, 1], stage 1's grid (knots σ_k, N = ``grid`` segments)
λ, ``lam``             ds/dt, the timing (eq. 5); b = λ² and a = λλ' = ½ db/ds, linear in u
t_e, ``duration``      the motion's duration [s]
f0, J                  the running cost and J = ∫ f0 dt (eq. 3); ``cost`` is an f0
stage 1, ``timing``    the optimal λ(s) of a fixed path; stage 2, ``planning``: the path's update
α, ``step``            stage 2's step length along its direction
``status``             why a planner stopped (``StopReason``); ``message`` the same in words
=====================  =======================================================================
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
from .path import BSplinePath, Path, SplinePath, StraightPath
from .planning import (
    Iteration,
    Method,
    PaperOptions,
    Plan,
    PlanResult,
    PlanSettings,
    SCPOptions,
    StopReason,
    Target,
    Task,
    TaskResult,
    plan,
    plan_task,
)
from .robot import JointLimits, PathCoefficients, Robot
from .robot.kinematics import ToolPose, inverse_kinematics
from .timing import TimingResult, optimal_timing
from .trajectory import ChainedTrajectory, Samples, Trajectory
from .verify import VerificationError, VerificationReport, Waypoint, verify, verify_plan

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
    "PlanSettings",
    "TimingResult",
    "Trajectory",
    "ChainedTrajectory",
    "Samples",
    "verify",
    "verify_plan",
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
