"""The bounds-checked build (``RAYSORT_DEBUG_CYTHON=1 pip install .``) checks bounds.

A kernel given an input array shorter than the others raises IndexError in that
build (the normal build would read past the array, so the probe runs in a child
process).  The test runs when ``RAYSORT_DEBUG_CYTHON`` says the installed build
is the checked one, as in the second half of ``.ci/run``.
"""
import os
import subprocess
import sys

import pytest

DEBUG = os.environ.get("RAYSORT_DEBUG_CYTHON", "").strip().lower() in ("1", "yes", "true", "on")

PROBE = """
import numpy as np
from raysort import _gather
prim = np.zeros(2, np.int32)                  # lanes 2 and 3 have no prim
index = np.array([0, 1, 2, 3], np.int32)
out = np.zeros(4, np.uint8)
try:
    _gather.scatter_occluded(prim, index, out)
    print("no error")
except IndexError as exc:
    print("IndexError:", exc)
"""


@pytest.mark.skipif(not DEBUG, reason="the installed build is not the bounds-checked one")
def test_an_out_of_bounds_index_raises_index_error(tmp_path):
    # from another directory: `python -c` in the checkout would import the source tree
    proc = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("IndexError:"), proc.stdout
