"""The bounds-checked build (``RAYSORT_DEBUG_CYTHON=1 pip install .``) checks bounds.

An index outside an array raises IndexError in that build (the probe, a read through
Cython's indexing, runs in a child process).  The test runs when ``RAYSORT_DEBUG_CYTHON``
says the installed build is the checked one, as in the second half of ``.ci/run``; in
the normal build the probe refuses the index itself.
"""
import os
import subprocess
import sys

import pytest

DEBUG = os.environ.get("RAYSORT_DEBUG_CYTHON", "").strip().lower() in ("1", "yes", "true", "on")

# _contract._bounds_probe reads values[i] through Cython's indexing: the checked build
# stops it with IndexError, the normal build (which compiles no check) with a ValueError
# of its own
PROBE = """
import numpy as np
from raysort import _contract
try:
    _contract._bounds_probe(np.zeros(4, np.int32), 4)
    print("no error")
except (IndexError, ValueError) as exc:
    print(f"{type(exc).__name__}:", exc)
"""


def _probe(tmp_path):
    # from another directory: `python -c` in the checkout would import the source tree
    proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


@pytest.mark.skipif(not DEBUG, reason="the installed build is not the bounds-checked one")
def test_an_out_of_bounds_index_raises_index_error(tmp_path):
    assert _probe(tmp_path).startswith("IndexError:")


@pytest.mark.skipif(DEBUG, reason="the installed build is the bounds-checked one")
def test_the_normal_build_refuses_the_probe_without_reading(tmp_path):
    assert _probe(tmp_path).startswith("ValueError: _bounds_probe: index 4")
