"""Stage 2 and the planner (Sections 5-6): improve the path itself, re-timing it by stage 1.

``records`` holds what a plan returns, ``sensitivity`` the gradient of stage 1's optimum with
respect to the path, ``paper`` the paper's own update (torque gradient, improved torques,
boundary-value problem) and ``planner`` the loop of Section 6, :func:`plan`.
"""

from .paper import boundary_value_path, nominal_motion, paper_iterations, torque_gradient
from .planner import METHODS, plan
from .records import Iteration, PlanResult
from .sensitivity import PathSensitivity, timing_sensitivity

__all__ = [
    "plan",
    "METHODS",
    "Iteration",
    "PlanResult",
    "PathSensitivity",
    "timing_sensitivity",
    "torque_gradient",
    "nominal_motion",
    "boundary_value_path",
    "paper_iterations",
]
