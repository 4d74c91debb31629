"""A traversal called from a script with gathered packets whose values were then
overwritten with anything (``packet_values_cases.py``) comes back without a crash or a
hang: a traversal skips an empty child slot (child 0, ``types.h``) whatever its box
test says, so no value sends a ray back to the root through an empty slot.  What it
says of such rays is unspecified.  The cases run in a child process per traversal, so a
crash or a hang fails the test instead of the test run."""
import json
import os
import subprocess
import sys

import pytest

import raysort

from _helpers import child_records

HERE = os.path.dirname(os.path.abspath(__file__))
BUILT_IN = [name for name in raysort.available("traversals")
            if type(raysort.create("traversals", name)).__module__.startswith("raysort.")]


@pytest.mark.parametrize("name", BUILT_IN)
def test_packets_of_any_values_come_back(name):
    try:
        proc = subprocess.run([sys.executable, os.path.join(HERE, "packet_values_cases.py"),
                               name], capture_output=True, text=True, check=False,
                              timeout=120)
    except subprocess.TimeoutExpired as exc:
        started = [json.loads(line) for line in (exc.stdout or b"").decode().splitlines()]
        pytest.fail(f"{name} hung on the case {started[-1] if started else None!r}")
    records = child_records(proc, name)
    done = [r["case"] for r in records if "case" in r]
    assert len(done) == 25 and done[0] == "the looping lane"
