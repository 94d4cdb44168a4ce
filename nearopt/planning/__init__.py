"""Stage 2 and the planner (Sections 5-6): improve the path itself, re-timing it by stage 1.

``records`` holds the methods, their options and what a plan returns; ``linearisation`` stage 1's
rows as functions of the path; ``scp`` the default path update (sequential convex programming);
``paper`` the paper's own update (torque gradient, improved torques, boundary-value problem);
``smooth`` the path improved for its J under jerk (torque-rate) limits, after stage 2;
``planner`` the loop of Section 6, :func:`plan`; ``task`` a sequence of targets, :func:`plan_task`.
"""

from .linearisation import PathBasis, path_basis, row_path_jacobian
from .paper import boundary_value_path, nominal_motion, paper_iterations, torque_gradient
from .planner import MAX_CONTROL_POINTS, METHODS, plan
from .records import (
    Iteration,
    Method,
    MethodOutcome,
    PaperOptions,
    Plan,
    PlanResult,
    PlanSettings,
    Run,
    SCPOptions,
    StopReason,
)
from .scp import sequential_convex
from .smooth import SmoothOutcome, jerk_rows, smooth_iterations
from .task import Target, Task, TaskResult, check_plan, plan_task

__all__ = [
    "check_plan",
    "plan",
    "plan_task",
    "Target",
    "Task",
    "TaskResult",
    "METHODS",
    "MAX_CONTROL_POINTS",
    "Method",
    "StopReason",
    "SCPOptions",
    "PaperOptions",
    "PlanSettings",
    "Iteration",
    "MethodOutcome",
    "PlanResult",
    "Plan",
    "Run",
    "PathBasis",
    "path_basis",
    "row_path_jacobian",
    "sequential_convex",
    "smooth_iterations",
    "SmoothOutcome",
    "jerk_rows",
    "torque_gradient",
    "nominal_motion",
    "boundary_value_path",
    "paper_iterations",
]
