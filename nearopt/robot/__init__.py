"""The arm: its dynamics (Pinocchio), its limits, its URDF and SRDF, its kinematics.

:class:`Robot` (``dynamics``: H, h, g, D, RNEA, ABA and their derivatives, the path form of
eq. 10, the limits as :class:`JointLimits`; the only maker of Pinocchio's work spaces,
:meth:`Robot.new_data`), ``urdf`` (reading and checking a URDF, SRDF groups and chains) and
``kinematics`` (tool poses, inverse kinematics).
"""

from .dynamics import NO_LIMIT, JointLimits, PathCoefficients, Robot, check_robot

__all__ = ["Robot", "JointLimits", "PathCoefficients", "NO_LIMIT", "check_robot"]
