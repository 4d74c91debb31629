"""Hostile plugins of every kind end in a clear PluginContractError, never a signal.

The cases (``hostile_plugins.CASES``: wrong types, wrong lengths, out-of-range
indices, NaN, non-permutations, descending parents, huge values, raising)
run in child processes (``run_cases.py``), so a crash fails its case instead of
killing the test run.  The children run the cases one after another and say
which one they start; when one dies, the case it was running is recorded as
crashed and a new child takes the remaining ones.
"""
import json
import os
import signal
import subprocess
import sys

import pytest

from hostile_plugins import CASES

RUNNER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "run_cases.py")


def run_all(names):
    """Case name -> outcome dict (``{"outcome": "crashed", ...}`` for a dead child)."""
    outcomes, todo = {}, list(names)
    while todo:
        proc = subprocess.run([sys.executable, RUNNER, *todo], capture_output=True, text=True,
                              timeout=600)
        started = None
        for line in proc.stdout.splitlines():
            record = json.loads(line)
            if "start" in record:
                started = record["start"]
            else:
                outcomes[record["case"]] = record
                started = None
        if started is None and proc.returncode == 0:
            break
        if started is None:            # died between cases: blame the next one
            started = next(n for n in todo if n not in outcomes)
        code = proc.returncode
        outcomes[started] = {"case": started, "outcome": "crashed",
                             "message": (f"signal {signal.Signals(-code).name}" if code < 0
                                         else f"exit status {code}") + f"\n{proc.stderr[-3000:]}"}
        todo = [n for n in todo if n not in outcomes]
    return outcomes


@pytest.fixture(scope="module")
def outcomes():
    return run_all(list(CASES))


@pytest.mark.parametrize("name", list(CASES))
def test_hostile_plugin(name, outcomes):
    """The case ends as expected: a PluginContractError naming the plugin (its kind, its
    name, where it comes from), or, for odd but legal output, a finished render."""
    kind, _, expected = CASES[name]
    result = outcomes[name]
    assert result["outcome"] != "crashed", f"{name} crashed the interpreter: {result['message']}"
    if expected == "ok":
        assert result["outcome"] == "ok", result
        return
    assert result["outcome"] == "PluginContractError", result
    assert result["plugin"] == name and result["kind"] == kind, result
    message = result["message"]
    assert message.startswith(f"{kind[:-1]} {name!r} (registered in process) "), message
    assert "broke its contract: " in message or "failed: " in message, message
