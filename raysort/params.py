"""Parameter checks shared by plugins and the pipeline (bools are not integers here)."""
from __future__ import annotations

import numbers

from raysort.errors import ConfigError

import numpy as np

__all__ = ["integer", "number", "boolean", "vector3"]


def integer(name, value, lo, hi=None):
    """``value`` as an int in [lo, hi]; ConfigError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo \
            or (hi is not None and value > hi):
        rng = f"in {lo}..{hi}" if hi is not None else f">= {lo}"
        raise ConfigError(f"{name} must be an integer {rng}, got {value!r}")
    return int(value)


def number(name, value, lo, hi=None, *, lo_open=False, hi_open=False):
    """``value`` as a float in [lo, hi] (open ends with lo_open / hi_open)."""
    ok = (not isinstance(value, bool) and isinstance(value, numbers.Real) and value == value
          and (value > lo if lo_open else value >= lo)
          and (hi is None or (value < hi if hi_open else value <= hi)))
    if not ok:
        left, right = "(" if lo_open else "[", ")" if hi_open else "]"
        rng = (f"in {left}{lo}, {hi}{right}" if hi is not None
               else f"{'>' if lo_open else '>='} {lo}")
        raise ConfigError(f"{name} must be a number {rng}, got {value!r}")
    return float(value)


def vector3(name, value):
    """``value`` as 3 finite floats (a float64 array); ConfigError naming ``name``."""
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be 3 numbers, got {value!r}") from None
    if not np.isfinite(arr).all():
        raise ConfigError(f"{name} must be finite, got {value!r}")
    return arr


def boolean(name, value, *, allow_none=False):
    if isinstance(value, bool) or (allow_none and value is None):
        return value
    raise ConfigError(f"{name} must be true or false{' or None' if allow_none else ''}, "
                      f"got {value!r}")
