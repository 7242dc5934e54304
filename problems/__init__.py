"""The benchmark catalogue as code: each case makes its own data (``kinemaforge synth CASE -o DIR``)
and states what a correct pipeline should recover.  See :mod:`problems.catalogue`."""

from .catalogue import CASES, get_case

__all__ = ["CASES", "get_case"]
