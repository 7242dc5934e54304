"""Loader of the compiled Pinocchio→CasADi bridge (``_kfbridge*.so``, built by ``setup.py``).

The library exposes a C ABI (``api.cpp``); it links ``libcasadi`` by soname, so the copy that
ships with the installed ``casadi`` wheel is loaded first (RTLD_GLOBAL) and the bridge binds to
it.  Build and runtime versions must match; ``pyproject.toml`` pins them.
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os

import casadi

from ..errors import NativeBridgeError

_HERE = os.path.dirname(os.path.abspath(__file__))


@functools.lru_cache(maxsize=1)
def library() -> ctypes.CDLL:
    """The loaded bridge library; raises :class:`NativeBridgeError` if it was not built."""
    candidates = sorted(glob.glob(os.path.join(_HERE, "_kfbridge*.so")))
    if not candidates:
        raise NativeBridgeError(
            f"the native bridge is not built (no _kfbridge*.so in {_HERE}); "
            "install the package with `pip install -e .` (or run `make test`), which compiles it"
        )
    casadi_dir = os.path.dirname(casadi.__file__)
    for name in sorted(glob.glob(os.path.join(casadi_dir, "libcasadi.so*"))):
        ctypes.CDLL(name, mode=ctypes.RTLD_GLOBAL)
        break
    lib = ctypes.CDLL(candidates[0])
    lib.kf_build.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_void_p), ctypes.POINTER(ctypes.c_size_t)]
    lib.kf_build.restype = ctypes.c_int
    lib.kf_free.argtypes = [ctypes.c_void_p]
    lib.kf_versions.restype = ctypes.c_char_p
    built = lib.kf_versions().decode()
    if f"casadi {casadi.__version__}," not in built:
        raise NativeBridgeError(
            f"the native bridge was built against {built} but casadi {casadi.__version__} is installed; "
            "reinstall the package so the bridge is rebuilt"
        )
    return lib


def build_functions(spec: str) -> list[casadi.Function]:
    """Run the bridge on a topology spec; returns [aba, rnea, crba, kinetic_energy,
    potential_energy, link_poses] over the full parameter vector P."""
    lib = library()
    out = ctypes.c_void_p()
    n = ctypes.c_size_t()
    rc = lib.kf_build(spec.encode(), ctypes.byref(out), ctypes.byref(n))
    try:
        blob = ctypes.string_at(out, n.value)
    finally:
        lib.kf_free(out)
    if rc != 0:
        raise NativeBridgeError(f"native bridge rejected the model: {blob.decode(errors='replace')}")
    functions, i = [], 0
    while i < len(blob):
        j = blob.index(b"\n", i)
        size = int(blob[i:j])
        functions.append(casadi.Function.deserialize(blob[j + 1 : j + 1 + size].decode()))
        i = j + 1 + size
    return functions
