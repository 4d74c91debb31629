"""A traversal called from a script with packets whose arrays do not fit together
(``packets_cases.py``: a sub-packet outside the lanes, arrays too short or missing rows)
raises a ValueError that says so, never a crash: every built-in traversal checks them
before its kernel reads a lane (``raysort.sdk.driver.check_packet_layout``).  The cases run in
a child process per traversal, so a crash fails the test instead of the test run."""
import os
import subprocess
import sys

import pytest

import raysort

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from packets_cases import CASES      # noqa: E402

from _helpers import child_records   # noqa: E402

BUILT_IN = [name for name in raysort.available("traversals")
            if type(raysort.create("traversals", name)).__module__.startswith("raysort.")]


@pytest.mark.parametrize("name", BUILT_IN)
def test_broken_packets_raise_a_value_error(name):
    proc = subprocess.run([sys.executable, os.path.join(HERE, "packets_cases.py"), name],
                          capture_output=True, text=True, timeout=300)
    records = child_records(proc, name)
    outcomes = {r["case"]: r for r in records if "case" in r}
    assert outcomes.pop("unbroken")["outcome"] == "ok"
    assert set(outcomes) == set(CASES)
    for case, result in outcomes.items():
        assert result["outcome"] == "ValueError", (case, result)
        assert "packets" in result["message"], (case, result)
