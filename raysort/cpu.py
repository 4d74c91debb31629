"""Report the compiled SIMD path and the CPU's features.

raysort is built either with the SSE2 path of ``raysort/simd.h`` (x86-64) or
with its portable scalar path (``RAYSORT_NO_SIMD=1`` at install time, or any
other CPU).  Both give bit-identical results; only speed differs.
"""
from __future__ import annotations

import platform

from raysort import _cpu

__all__ = ["info"]


def info():
    """``{"compiled": ..., "active": ..., "cpu_features": [...], "machine": ...}``."""
    compiled = _cpu.compiled_path()
    features = _cpu.cpu_features()
    active = compiled if compiled == "scalar" or compiled in features else "unsupported"
    return {"compiled": compiled, "active": active, "cpu_features": features,
            "machine": platform.machine()}
