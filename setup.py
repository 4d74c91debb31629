"""Build raysort's Cython extensions; all metadata lives in pyproject.toml.

Environment switches (read at build time):
  RAYSORT_NO_SIMD=1        build the portable scalar path of raysort/simd.h
  RAYSORT_DEBUG_CYTHON=1   turn Cython bounds checking on
"""
import os
import platform
from pathlib import Path

from Cython.Build import cythonize
from setuptools import Extension, setup

HERE = Path(__file__).parent
INCLUDE = "raysort/include"


def _flag(name):
    return os.environ.get(name, "").strip().lower() in ("1", "yes", "true", "on")


def _compile_args():
    if os.name == "nt":
        return ["/O2", "/fp:precise"]
    args = ["-O3", "-ffp-contract=off"]
    if platform.machine().lower() in ("x86_64", "amd64") and not _flag("RAYSORT_NO_SIMD"):
        args.append("-msse2")
    return args


def _extensions():
    macros = [("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")]
    if _flag("RAYSORT_NO_SIMD"):
        macros.append(("RAYSORT_NO_SIMD", "1"))
    sources = sorted(HERE.glob("raysort/**/*.pyx"))
    return [
        Extension(
            ".".join(src.relative_to(HERE).with_suffix("").parts),
            [str(src.relative_to(HERE))],
            include_dirs=[INCLUDE],
            define_macros=macros,
            extra_compile_args=_compile_args(),
        )
        for src in sources
    ]


directives = {
    "language_level": 3,
    "boundscheck": _flag("RAYSORT_DEBUG_CYTHON"),
    "wraparound": False,
    "cdivision": True,
    "initializedcheck": False,
    "embedsignature": True,
}

JOBS = os.cpu_count() or 1

setup(
    ext_modules=cythonize(_extensions(), compiler_directives=directives, include_path=["."],
                          quiet=True, nthreads=JOBS if JOBS > 1 else 0),
    options={"build_ext": {"parallel": JOBS}},
)
