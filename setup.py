"""Builds the native Pinocchio->CasADi bridge as part of `pip install`.

The bridge (kinemaforge_opt/native/*.cpp) is plain C++ against the headers shipped in the
`libpinocchio` wheel (cmeel.prefix/include) and the `casadi` wheel (casadi/include, Eigen), linked
to the wheel's libcasadi; it exposes a C ABI loaded with ctypes.  Each translation unit
instantiates Pinocchio on casadi::SX (heavy: ~1-2.5 GB and up to ~2 min each), so they are
compiled in parallel, one per core.
"""

import os
import subprocess
import sys
import sysconfig
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

SOURCES = ["model.cpp", "aba.cpp", "rnea.cpp", "crba.cpp", "energy.cpp", "api.cpp"]
NATIVE = Path(__file__).parent / "kinemaforge_opt" / "native"
DEFINES = [
    "-DNDEBUG",  # Pinocchio's isUnitary asserts cannot evaluate symbolic axes
    "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
    "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
    "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
    "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",  # RNEA's joint visitor takes 7 arguments
    "-DFUSION_MAX_VECTOR_SIZE=20",
]


def _site_dirs():
    import casadi  # noqa: F401  (present in the build environment: build-system.requires)

    casadi_dir = Path(casadi.__file__).parent
    for p in map(Path, sys.path):
        inc = p / "cmeel.prefix" / "include"
        if (inc / "pinocchio" / "autodiff" / "casadi.hpp").is_file():
            return casadi_dir, inc
    raise RuntimeError("libpinocchio headers (cmeel.prefix/include/pinocchio) not found on sys.path")


class BuildBridge(build_ext):
    def build_extension(self, ext):
        casadi_dir, pin_inc = _site_dirs()
        out = Path(self.get_ext_fullpath(ext.name))
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(self.build_temp) / "kfbridge"
        tmp.mkdir(parents=True, exist_ok=True)
        flags = [
            "-std=c++17", "-O1", "-fPIC", "-w", *DEFINES,
            f"-I{pin_inc}", f"-I{casadi_dir / 'include'}", f"-I{casadi_dir / 'include' / 'eigen3'}",
        ]
        cxx = os.environ.get("CXX", "g++")
        start = time.time()

        def compile_one(src):
            obj = tmp / (src + ".o")
            cmd = [cxx, *flags, "-c", str(NATIVE / src), "-o", str(obj)]
            res = subprocess.run(cmd, capture_output=True, text=True)
            if res.returncode != 0:
                raise RuntimeError(f"compiling {src} failed:\n{res.stderr[-4000:]}")
            return obj

        jobs = int(os.environ.get("KF_BUILD_JOBS", os.cpu_count() or 2))
        print(f"kinemaforge: compiling the Pinocchio->CasADi bridge ({len(SOURCES)} units, {jobs} jobs)", flush=True)
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            objects = list(pool.map(compile_one, SOURCES))
        link = [cxx, "-shared", *map(str, objects), f"-L{casadi_dir}", "-lcasadi", "-o", str(out)]
        subprocess.run(link, check=True)
        print(f"kinemaforge: bridge built in {time.time() - start:.0f} s -> {out}", flush=True)


setup(
    ext_modules=[Extension("kinemaforge_opt.native._kfbridge", sources=[])],
    cmdclass={"build_ext": BuildBridge},
)
