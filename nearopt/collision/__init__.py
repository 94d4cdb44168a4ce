"""Collisions: the robot's links with each other and with the obstacles of a work cell.

:class:`Scene` (obstacles, read from TOML or built in Python) → :class:`CollisionModel` (the checked
pairs, signed distances, their gradients in θ, a certified check of a whole path) →
:func:`collision_free_path` (a first path around the obstacles, from OMPL).
"""

from .model import Clearance, CollisionModel, Contact, Pair, collisions_for
from .scene import (
    DEFAULT_MARGIN,
    Box,
    Capsule,
    Cylinder,
    HalfSpace,
    Mesh,
    Obstacle,
    Scene,
    Shape,
    Sphere,
)

__all__ = [
    "collisions_for",
    "Scene",
    "Obstacle",
    "Shape",
    "Box",
    "Sphere",
    "Cylinder",
    "Capsule",
    "HalfSpace",
    "Mesh",
    "DEFAULT_MARGIN",
    "CollisionModel",
    "Pair",
    "Contact",
    "Clearance",
]
