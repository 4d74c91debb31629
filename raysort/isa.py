"""Run-time ISA dispatch: the kernels are built for several ISAs, the best one runs.

The kernel modules (traversals, the sorters' kernels, gather, the ``pinhole``
generator, the ``lambert`` and ``ao`` shaders; setup.py's ``ISA_MODULES``) are
compiled from the same source once per ISA: ``scalar`` (the portable C path of
``simd.h``), ``sse2`` (the baseline build on x86-64), ``avx2`` and ``avx512``.
At first use raysort picks the best ISA that is both compiled and supported by
this CPU, as Embree and NumPy do; every ISA performs the same IEEE operations
per lane (no FMA contraction), so hits and images are bit-identical whichever
runs.  ``RAYSORT_ISA=scalar|sse2|avx2|avx512`` forces one; asking for an ISA
that is not compiled or not supported is a ConfigError.

``avx512emu`` is for tests only, and built only on request
(``RAYSORT_BUILD_ISAS=avx512emu``): the avx512 build's 16-lane code compiled for
an AVX2 CPU, with its AVX-512 intrinsics emulated lane by lane in C
(``raysort/include/raysort/avx512_emu.h``), so that the suite can check that code
where no CPU runs AVX-512.  It is slow and never chosen unless asked for.

Framework code and plugins call a kernel through :func:`module`::

    isa.module("traversals.single").trace(bvh, packets, any_hit)
"""
from __future__ import annotations

import importlib
import importlib.util
import os
import platform
import threading

from raysort import _cpuid
from raysort._isa_table import ISAS, NEEDS as _NEEDS, ON_REQUEST
from raysort.errors import ConfigError

__all__ = ["ISAS", "baseline", "compiled", "supported", "available", "active", "use",
           "module", "info"]

_X86 = platform.machine().lower() in ("x86_64", "amd64", "i386", "i686", "x86")
#: a kernel module every ISA build holds (its presence says the ISA was built)
_PROBE = "_gather"

_lock = threading.Lock()
_active = None
_modules = {}


def baseline():
    """The ISA of the baseline build, which every CPU of this architecture runs."""
    return "sse2" if _X86 else "scalar"


def _module_name(isa, name):
    return f"raysort.{name}" if isa == baseline() else f"raysort._isa.{isa}.{name}"


def _built(isa):
    try:
        return importlib.util.find_spec(_module_name(isa, _PROBE)) is not None
    except ModuleNotFoundError:     # no raysort._isa at all (RAYSORT_BUILD_ISAS=none)
        return False


def compiled():
    """The ISAs this installation holds kernels for, lowest first."""
    return [isa for isa in ISAS if isa == baseline() or _built(isa)]


def supported():
    """The ISAs this CPU (and its OS) can run, lowest first."""
    features = set(_cpuid.features())
    return [isa for isa in ISAS if isa == "scalar" or isa == baseline()
            or (_X86 and all(f in features for f in _NEEDS[isa]))]


def available():
    """The ISAs that are both compiled and supported, lowest first."""
    runnable = supported()
    return [isa for isa in compiled() if isa in runnable]


def _check(isa, source):
    if isa not in ISAS:
        raise ConfigError(f"{source}: unknown ISA {isa!r} (known: {', '.join(ISAS)})")
    if isa not in compiled():
        raise ConfigError(f"{source}: ISA {isa!r} was not compiled into this installation "
                          f"(compiled: {', '.join(compiled())}; see RAYSORT_BUILD_ISAS)")
    if isa not in supported():
        raise ConfigError(f"{source}: this CPU cannot run ISA {isa!r} "
                          f"(supported: {', '.join(supported())})")


def active():
    """The ISA whose kernels run now: ``RAYSORT_ISA`` if set, else the best available
    (an emulated one only if asked for)."""
    global _active
    if _active is None:
        with _lock:
            if _active is None:
                forced = os.environ.get("RAYSORT_ISA", "").strip().lower()
                if forced:
                    _check(forced, "RAYSORT_ISA")
                    _active = forced
                else:
                    _active = [i for i in available() if i not in ON_REQUEST][-1]
    return _active


def use(isa):
    """Switch every kernel to ``isa`` from the next call on; returns the previous ISA.

    For tests and benchmarks that compare ISAs in one process; not meant to be
    called while another thread traces.
    """
    global _active
    previous = active()
    _check(isa, "raysort.isa.use")
    with _lock:
        _active = isa
        _modules.clear()
    return previous


def module(name):
    """The active ISA's build of kernel module ``name`` (e.g. ``"traversals.single"``)."""
    isa = _active if _active is not None else active()
    try:
        return _modules[name]
    except KeyError:
        pass
    # the baseline first: Cython's module init registers an ISA build under the baseline's
    # name in sys.modules when that name is still free
    mod = importlib.import_module(f"raysort.{name}")
    if isa != baseline():
        mod = importlib.import_module(_module_name(isa, name))
    with _lock:
        if _active == isa:
            _modules[name] = mod
    return mod


def info():
    """``{"active", "baseline", "compiled", "supported", "available", "cpu_features",
    "machine"}``: what raysort can run here and what it runs (for reports)."""
    return {"active": active(), "baseline": baseline(), "compiled": compiled(),
            "supported": supported(), "available": available(),
            "cpu_features": _cpuid.features(), "machine": platform.machine()}
