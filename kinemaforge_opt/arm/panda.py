"""The nominal Panda: the URDF shipped by the ``example-robot-data`` pip package (6.0.0).

The package has no Python module; the URDF is found through the installed distribution's files.
The gripper fingers (prismatic, one of them a mimic joint) are welded at q = 0, leaving the
7 arm joints ``panda_joint1`` … ``panda_joint7``.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata as md
from pathlib import Path

from ..errors import InputFileError
from ..model import ArticulatedModel, JointDynamics, read_urdf

PANDA_URDF_IN_DIST = "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"
PANDA_FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")


def panda_urdf_path() -> Path:
    """Path of ``panda.urdf`` inside the installed ``example-robot-data`` distribution."""
    try:
        path = Path(md.distribution("example-robot-data").locate_file(PANDA_URDF_IN_DIST))
    except md.PackageNotFoundError:
        raise InputFileError(
            "the Panda URDF comes from the pip package example-robot-data, which is not installed"
        ) from None
    if not path.is_file():
        raise InputFileError(f"example-robot-data is installed but {PANDA_URDF_IN_DIST} is missing")
    return path


def weld_joints(model: ArticulatedModel, names) -> ArticulatedModel:
    """A copy of ``model`` with joints ``names`` made fixed at q = 0 (their child links kept)."""
    out = model
    for name in names:
        out = out.with_joint(name, type="fixed", limits=None, dynamics=JointDynamics())
    return out


def load_panda() -> ArticulatedModel:
    """The nominal 7-joint Panda (fingers welded), read with :func:`kinemaforge_opt.model.read_urdf`."""
    model = weld_joints(read_urdf(panda_urdf_path()), PANDA_FINGER_JOINTS)
    return dataclasses.replace(model, name="panda")
