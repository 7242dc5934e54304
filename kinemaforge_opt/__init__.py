"""kinemaforge_opt: recordings of articulated objects -> simulation-ready URDFs whose physics
matches the recording.  See README.md and DESIGN.md (shared) for the data flow."""

from .calibration import Calibration, calibrate
from .errors import KinemaforgeError
from .model import ArticulatedModel, read_urdf, write_urdf

__version__ = "0.1.0"
__all__ = ["ArticulatedModel", "Calibration", "KinemaforgeError", "calibrate", "read_urdf", "write_urdf", "__version__"]
