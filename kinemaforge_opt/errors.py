"""Exceptions raised by kinemaforge_opt.

Every error raised for bad input derives from :class:`KinemaforgeError` and its message says
what was expected, what was found, and where (file, field, joint or link).  A solve that does
not converge is *not* an error: it is a state of the solver's result object.
"""

from __future__ import annotations

from collections.abc import Iterable


class KinemaforgeError(Exception):
    """Base class of every error raised by kinemaforge_opt for bad input or bad use."""


class InputFileError(KinemaforgeError):
    """A file is missing, unreadable or malformed; the message names the file and field."""


class ModelError(KinemaforgeError):
    """An articulated model is inconsistent (loop, unknown link, bad axis, …)."""


class UnknownNameError(KinemaforgeError, KeyError):
    """A joint, link or parameter name that does not exist; the message lists valid names."""

    def __init__(self, kind: str, name: str, available: Iterable[str]):
        names = sorted(available)
        shown = ", ".join(repr(n) for n in names[:20]) + (" …" if len(names) > 20 else "")
        super().__init__(f"{kind} {name!r} does not exist; available: {shown or '(none)'}")
        self.kind, self.name, self.available = kind, name, tuple(names)

    def __str__(self) -> str:  # KeyError would otherwise quote the whole message
        return self.args[0]


class MissingDynamicsError(ModelError):
    """Dynamics were asked of a model whose moving bodies lack inertial data."""


class NativeBridgeError(KinemaforgeError):
    """The compiled Pinocchio→CasADi bridge is missing or rejected its input."""


class DataError(KinemaforgeError):
    """Array data with the wrong shape, NaNs, or degenerate content (e.g. no motion)."""


def require_finite(name: str, array, where: str = "") -> None:
    """Raise :class:`DataError` naming ``name`` if ``array`` holds NaN or inf values."""
    import numpy as np

    a = np.asarray(array, dtype=float)
    if not np.all(np.isfinite(a)):
        bad = int(np.size(a) - np.count_nonzero(np.isfinite(a)))
        loc = f" in {where}" if where else ""
        raise DataError(f"{name}{loc} holds {bad} non-finite value(s) (NaN or inf)")


def require_shape(name: str, array, shape: tuple, where: str = "") -> None:
    """Raise :class:`DataError` unless ``array`` has ``shape`` (None = any size on that axis)."""
    import numpy as np

    a = np.asarray(array)
    ok = a.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, a.shape))
    if not ok:
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        loc = f" in {where}" if where else ""
        raise DataError(f"{name}{loc} must have shape {want}, got {a.shape}")
