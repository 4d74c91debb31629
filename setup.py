"""Build raysort's Cython extensions; all metadata lives in pyproject.toml.

Every .pyx becomes one extension built for the baseline (SSE2 on x86-64, the
portable scalar path elsewhere).  The kernel modules named in ISA_MODULES are
compiled again, from the same generated C, once per extra ISA into
``raysort._isa.<isa>.<module>``; ``raysort.isa`` picks the best one the CPU
supports at import (Embree's and NumPy's run-time dispatch).  On x86-64 the
baseline build *is* the ``sse2`` ISA.

Environment switches (read at build time):
  RAYSORT_BUILD_ISAS=scalar,avx2   which extra ISAs to build (default: every one
                                   the compiler supports but avx512emu; "none" for
                                   none; avx512emu, for tests only, is built only
                                   when named)
  RAYSORT_DEBUG_CYTHON=1           turn Cython bounds checking on
"""
import os
import platform
import runpy
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy
from Cython.Build import cythonize
from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

HERE = Path(__file__).parent
# raysort's C headers, and NumPy's (sorters._keysort calls NumPy's sort through its C API)
INCLUDES = ["raysort/include", numpy.get_include()]

# Kernel modules compiled once per ISA (dotted, relative to the raysort package).  A
# kernel module added here is called through raysort.isa.module("<name>"); see the
# README's "ISAs" section.
ISA_MODULES = [
    "_gather",
    "_contract",
    "sorters.nah",
    "sorters._keysort",
    "shaders.lambert",
    "shaders.ao",
    "traversals.single",
    "traversals.masked",
    "traversals.ranged",
    "traversals.partition",
    "traversals.wide",
    "traversals.wide8",
    "traversals.wide16",
    "traversals.stream",
    "traversals.frustum",
    "generators.pinhole",
]


def _flag(name):
    return os.environ.get(name, "").strip().lower() in ("1", "yes", "true", "on")


DEBUG = _flag("RAYSORT_DEBUG_CYTHON")
X86 = platform.machine().lower() in ("x86_64", "amd64")
MSVC = os.name == "nt"
# -fno-math-errno: errno is never read, so sqrt is one instruction (IEEE, correctly
# rounded either way) and loops that take square roots can be vectorised.
BASE_ARGS = ["/O2", "/fp:precise"] if MSVC else ["-O3", "-ffp-contract=off", "-fno-math-errno"]
MACROS = [("NPY_NO_DEPRECATED_API", "NPY_1_7_API_VERSION")] \
    + ([("RAYSORT_DEBUG_CYTHON", "1")] if DEBUG else [])     # _contract._bounds_probe

# The extra ISAs: (macros, flags).  No -mfma, and contraction stays off (AVX-512F
# implies FMA): every ISA performs the same IEEE operations per lane.
ISAS = {
    "scalar": ([("RAYSORT_NO_SIMD", "1")], []),
    "avx2": ([], ["/arch:AVX2"] if MSVC else ["-mavx2"]),
    "avx512": ([], ["/arch:AVX512"] if MSVC else
               ["-mavx512f", "-mavx512vl", "-mavx512bw", "-mavx512dq"]),
    # the avx512 build's code for an AVX2 CPU, its AVX-512 intrinsics emulated in C
    # (raysort/include/raysort/avx512_emu.h): slow, for testing that code where no CPU
    # runs AVX-512; built only when RAYSORT_BUILD_ISAS names it
    "avx512emu": ([("RAYSORT_EMULATE_AVX512", "1")], ["/arch:AVX2"] if MSVC else ["-mavx2"]),
}
# The ISAs' names, and which are built only when named, have one owner, which imports
# nothing and is read here by path (this script cannot import the package it builds).
_TABLE = runpy.run_path(str(HERE / "raysort" / "_isa_table.py"))
ON_REQUEST = set(_TABLE["ON_REQUEST"])
if set(ISAS) | {"sse2"} != set(_TABLE["ISAS"]):
    sys.exit("setup.py: the ISAs with build flags (ISAS) and raysort/_isa_table.py's ISAS differ")


def _compiler_accepts(flags):
    """Can the C compiler build a file with these flags (an old compiler may lack AVX-512)?"""
    if not flags or MSVC:
        return True
    cc = os.environ.get("CC", "cc").split()
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "probe.c"
        src.write_text("int main(void) { return 0; }\n")
        try:
            proc = subprocess.run(cc + flags + ["-c", str(src), "-o", str(Path(tmp) / "probe.o")],
                                  capture_output=True)
        except OSError:
            return False
        return proc.returncode == 0


def _selected_isas():
    wanted = os.environ.get("RAYSORT_BUILD_ISAS", "").strip().lower()
    if not X86 or wanted == "none":     # off x86 the baseline is the scalar path
        return []
    names = [n for n in ISAS if n not in ON_REQUEST] if not wanted or wanted == "all" else \
        [n.strip() for n in wanted.split(",") if n.strip() and n.strip() != "sse2"]
    unknown = sorted(set(names) - set(ISAS))
    if unknown:
        sys.exit(f"RAYSORT_BUILD_ISAS: unknown ISA {', '.join(unknown)} "
                 f"(known: sse2, {', '.join(ISAS)})")
    return [n for n in names if _compiler_accepts(ISAS[n][1])]


def _base_extensions():
    sources = sorted(HERE.glob("raysort/**/*.pyx"))
    return [
        Extension(
            ".".join(src.relative_to(HERE).with_suffix("").parts),
            [str(src.relative_to(HERE))],
            include_dirs=INCLUDES,
            define_macros=MACROS,
            extra_compile_args=BASE_ARGS + ([] if MSVC or not X86 else ["-msse2"]),
        )
        for src in sources
    ]


def _isa_extensions(isas):
    """Each kernel module once more per ISA, from the C file cythonize wrote for the
    baseline.  A one-line wrapper per ISA includes it (Embree's per-ISA dummy files), so
    every ISA gets its own object file."""
    wrappers = HERE / "build" / "isa-src"
    exts = []
    for isa in isas:
        macros, flags = ISAS[isa]
        for name in ISA_MODULES:
            c_file = (HERE / "raysort" / Path(*name.split("."))).with_suffix(".c")
            wrapper = wrappers / isa / Path(*name.split(".")).with_suffix(".c")
            wrapper.parent.mkdir(parents=True, exist_ok=True)
            text = f'/* {name} for the {isa} ISA (generated by setup.py) */\n' \
                   f'#include "{c_file.resolve().as_posix()}"\n'
            if not wrapper.exists() or wrapper.read_text() != text:
                wrapper.write_text(text)
            exts.append(Extension(
                f"raysort._isa.{isa}.{name}",
                [str(wrapper.relative_to(HERE))],
                include_dirs=INCLUDES,
                define_macros=MACROS + macros,
                extra_compile_args=BASE_ARGS + flags,
                depends=[str(c_file.relative_to(HERE))],     # rebuilt when the C changes
            ))
    return exts


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
MODE = "debug" if DEBUG else "release"


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
    """Keep the release and bounds-checked builds apart: each mode has its own object
    files (``build/temp-<mode>``), and a change of mode rebuilds every extension."""

    def run(self):
        self.force = self.force or _directives_changed_now
        super().run()

    def copy_extensions_to_source(self):
        # an editable install copies each extension next to its source; the per-ISA
        # folders raysort/_isa/<isa>/... hold no source, so make them first
        for ext in self.extensions:
            (HERE / Path(*ext.name.split(".")[:-1])).mkdir(parents=True, exist_ok=True)
        super().copy_extensions_to_source()


_directives_changed_now = _directives_changed()
_isas = _selected_isas()
setup(
    ext_modules=cythonize(_base_extensions(), compiler_directives=directives,
                          include_path=["."], quiet=True, nthreads=JOBS if JOBS > 1 else 0,
                          force=_directives_changed_now)
    + _isa_extensions(_isas),
    cmdclass={"build_ext": BuildExt},
    options={"build_ext": {"parallel": JOBS, "build_temp": f"build/temp-{MODE}"}},
)
