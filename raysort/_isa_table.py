"""The ISAs raysort's kernels are built for: the one owner of their names, the CPU
features each needs, and which are built only on request.

:mod:`raysort.isa` imports it; ``setup.py``, which cannot import the package it
builds, reads this file by path.  It imports nothing, so that it can.
"""

#: every ISA, lowest first ("sse2" is the baseline build on x86-64)
ISAS = ("scalar", "sse2", "avx2", "avx512", "avx512emu")

#: the CPU features (raysort._cpuid's names) an ISA needs
NEEDS = {"scalar": (), "sse2": ("sse2",), "avx2": ("avx2",),
         "avx512": ("avx512f", "avx512vl", "avx512bw", "avx512dq"), "avx512emu": ("avx2",)}

#: ISAs for tests: built only when RAYSORT_BUILD_ISAS names them, and never chosen
#: unless RAYSORT_ISA (or raysort.isa.use) asks for them
ON_REQUEST = ("avx512emu",)
