"""Build the one Cython module against raysort: its C headers (``raysort.get_include()``)
and its ``.pxd`` files (found next to the installed ``raysort`` package, also when raysort
is installed in editable mode, where it is not on ``sys.path`` itself).

Use the same floating-point flags as raysort (no fused multiply-add) so that the shared
kernels give the same hits, bit for bit, as raysort's own traversals.
"""
from pathlib import Path

from Cython.Build import cythonize
from setuptools import Extension, setup

import raysort

extension = Extension(
    "stack_traversal",
    ["stack_traversal.pyx"],
    include_dirs=[raysort.get_include()],
    extra_compile_args=["-O2", "-ffp-contract=off"],
)
setup(ext_modules=cythonize(
    [extension],
    include_path=[str(Path(raysort.__file__).parents[1])],
    compiler_directives={"language_level": 3, "boundscheck": False, "wraparound": False},
))
