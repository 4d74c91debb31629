"""The bounds-checked build (``RAYSORT_DEBUG_CYTHON=1 pip install .``) checks bounds.

A kernel given an input array its caller promised to be longer raises IndexError in
that build (the probe runs in a child process).  The test runs when
``RAYSORT_DEBUG_CYTHON`` says the installed build is the checked one, as in the second
half of ``.ci/run``.
"""
import os
import subprocess
import sys

import pytest

DEBUG = os.environ.get("RAYSORT_DEBUG_CYTHON", "").strip().lower() in ("1", "yes", "true", "on")

# _contract.sort_result's caller promises at least one offset; without one, the checked
# build stops at the first index into the empty array (the normal build takes the
# pointer to its start without reading it, and the kernel reports bad offsets)
PROBE = """
import numpy as np
from raysort import _contract
order, offsets = np.zeros(4, np.int32), np.zeros(0, np.int32)
try:
    _contract.sort_result(order, offsets, np.array([0, 4], np.int32), 4, 4096)
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
