"""Parameter checks shared by plugins, scenes and the pipeline (bools are not integers here).

Each raises :class:`~raysort.errors.ConfigError` naming the parameter and
what it accepts, and returns the value as a plain Python (or NumPy) value.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

from raysort.errors import ConfigError

__all__ = ["integer", "number", "boolean", "choice", "vector3", "FLOAT32_MAX"]

#: the largest finite float32: every coordinate and colour ends up in float32
FLOAT32_MAX = float(np.finfo(np.float32).max)


def integer(name, value, lo, hi=None):
    """``value`` as an int in [lo, hi]; ConfigError naming ``name`` otherwise."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral) \
            or value < lo or (hi is not None and value > hi):
        rng = f"in {lo}..{hi}" if hi is not None else f">= {lo}"
        raise ConfigError(f"{name} must be an integer {rng}, got {value!r}")
    return int(value)


def number(name, value, lo, hi=None, *, lo_open=False, hi_open=False, allow_inf=False):
    """``value`` as a finite float in [lo, hi] (open ends with lo_open / hi_open);
    ``allow_inf`` also accepts +inf when there is no upper bound."""
    ok = (not isinstance(value, (bool, np.bool_)) and isinstance(value, numbers.Real)
          and (math.isfinite(value) or (allow_inf and hi is None and value == math.inf))
          and (value > lo if lo_open else value >= lo)
          and (hi is None or (value < hi if hi_open else value <= hi)))
    if not ok:
        left, right = "(" if lo_open else "[", ")" if hi_open else "]"
        rng = (f"in {left}{lo}, {hi}{right}" if hi is not None
               else f"{'>' if lo_open else '>='} {lo}")
        kind = "a number (or inf)" if allow_inf and hi is None else "a finite number"
        raise ConfigError(f"{name} must be {kind} {rng}, got {value!r}")
    return float(value)


def vector3(name, value):
    """``value`` as 3 floats (a float64 array) that are finite in float32, where every
    coordinate ends up; ConfigError naming ``name``."""
    try:
        arr = np.asarray(value)
        if arr.dtype.kind not in "iuf":
            raise TypeError
        arr = arr.astype(np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be 3 numbers, got {value!r}") from None
    if not (np.abs(arr) <= FLOAT32_MAX).all():
        raise ConfigError(f"{name} must be finite numbers of magnitude at most "
                          f"{FLOAT32_MAX:.4g} (float32), got {value!r}")
    return arr


def boolean(name, value, *, allow_none=False):
    """``value`` as True or False (or None with ``allow_none``)."""
    if isinstance(value, (bool, np.bool_)) or (allow_none and value is None):
        return None if value is None else bool(value)
    raise ConfigError(f"{name} must be true or false{' or None' if allow_none else ''}, "
                      f"got {value!r}")


def choice(name, value, options):
    """``value`` if it is one of the strings ``options``; ConfigError naming ``name`` and
    the options otherwise (whatever its type)."""
    if not isinstance(value, str) or value not in options:
        raise ConfigError(f"{name} must be one of {', '.join(options)}; got {value!r}")
    return value
