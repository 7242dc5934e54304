"""kinemaforge_opt: recordings of articulated objects -> simulation-ready URDFs whose physics
matches the recording.  See README.md and DESIGN.md (shared) for the data flow."""

from .errors import KinemaforgeError
from .model import ArticulatedModel, read_urdf, write_urdf

__version__ = "0.1.0"
__all__ = ["ArticulatedModel", "KinemaforgeError", "read_urdf", "write_urdf", "__version__"]
