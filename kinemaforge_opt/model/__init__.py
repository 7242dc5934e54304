"""Articulated models: dataclasses, URDF I/O and the numeric Pinocchio builder."""

from .articulated import (
    JOINT_TYPES,
    ArticulatedModel,
    Geometry,
    Inertial,
    Joint,
    JointDynamics,
    JointLimits,
    Link,
)
from .urdf import parse_urdf, read_urdf, urdf_string, write_urdf

__all__ = [
    "JOINT_TYPES",
    "ArticulatedModel",
    "Geometry",
    "Inertial",
    "Joint",
    "JointDynamics",
    "JointLimits",
    "Link",
    "parse_urdf",
    "read_urdf",
    "urdf_string",
    "write_urdf",
]
