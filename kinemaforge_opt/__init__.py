"""kinemaforge_opt: recordings of articulated objects -> simulation-ready URDFs whose physics
matches the recording.  See README.md and DESIGN.md (shared) for the data flow."""

from importlib import import_module

from .errors import KinemaforgeError

__version__ = "0.1.0"
__all__ = ["ArticulatedModel", "Calibration", "KinemaforgeError", "calibrate", "read_urdf", "write_urdf", "__version__"]

# The public names below load their modules (CasADi and the native bridge, yourdfpy and trimesh)
# on first use (PEP 562), so importing a light submodule — the command line's parser, errors —
# does not pay for them.
_LAZY = {"Calibration": ".calibration", "calibrate": ".calibration", "ArticulatedModel": ".model",
         "read_urdf": ".model", "write_urdf": ".model"}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
