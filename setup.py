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
from setuptools.command.build_ext import build_ext

HERE = Path(__file__).parent
INCLUDE = "raysort/include"


def _flag(name):
    return os.environ.get(name, "").strip().lower() in ("1", "yes", "true", "on")


DEBUG = _flag("RAYSORT_DEBUG_CYTHON")


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


# The only place Cython directives are set: a `# cython:` header in a .pyx would
# override these and silently disable the bounds-checked build.
directives = {
    "language_level": 3,
    "boundscheck": DEBUG,
    "wraparound": False,
    "cdivision": True,
    "initializedcheck": DEBUG,
    "embedsignature": True,
}

JOBS = os.cpu_count() or 1
MODE = "scalar" if _flag("RAYSORT_NO_SIMD") else "simd"


def _directives_changed():
    """cythonize regenerates a .c file only when its .pyx is newer and cannot see that the
    directives changed (a bounds-checked build would reuse unchecked C): regenerate every
    file when they differ from those of the last build here."""
    stamp = HERE / "build" / "cython-directives"
    changed = not stamp.exists() or stamp.read_text() != repr(sorted(directives.items()))
    stamp.parent.mkdir(exist_ok=True)
    stamp.write_text(repr(sorted(directives.items())))
    return changed


class BuildExt(build_ext):
    """Keep the SIMD and scalar builds apart.

    setuptools rebuilds by timestamp and cannot see that RAYSORT_NO_SIMD
    changed, so each mode keeps its own object files and every extension is
    rebuilt when the ones already built were built in the other mode.
    """

    def run(self):
        stamp = Path(self.build_temp).parent / "raysort-simd-mode"
        if stamp.exists() and stamp.read_text() != MODE:
            self.force = True
        super().run()
        stamp.write_text(MODE)


setup(
    ext_modules=cythonize(_extensions(), compiler_directives=directives, include_path=["."],
                          quiet=True, nthreads=JOBS if JOBS > 1 else 0,
                          force=_directives_changed()),
    cmdclass={"build_ext": BuildExt},
    options={"build_ext": {"parallel": JOBS,
                           "build_temp": f"build/temp-{MODE}{'-debug' if DEBUG else ''}"}},
)
