"""A script that calls raysort's public functions with inconsistent arguments, or edits
what raysort hands it, gets a Python error that says what is wrong, never a signal.

Each case is a short script run in a child process (a crash fails its case, not the test
run); it prints the type and message of the exception it ends with.  Every case once
crashed the interpreter (a segmentation fault or glibc's abort).
"""
import json
import subprocess
import sys
import textwrap

import pytest

PRELUDE = """
import json, sys
import numpy as np
import raysort
from raysort.rays import gather
def rays(n):
    return raysort.RayBatch.from_arrays(np.zeros((n, 3)), np.ones((n, 3)))
def packets(n):
    return gather(rays(n), np.arange(n, dtype=np.int32), np.array([0, n], np.int32))
"""

CASES = {
    "nah given large packets past the batch": ("""
        raysort.create("sorters", "nah").sort(rays(8), np.array([0, 1 << 22], np.int32),
                                              np.array([[0, 0, 0], [1, 1, 1]], np.float32))
        """, "ConfigError", "must start at 0 and end at 8"),
    "nah's packet_size set to 0 after it was made": ("""
        pipe = raysort.Pipeline("cornell", sorter="nah", traversal="ranged")
        pipe.sorter.packet_size = 0
        pipe.render(16, 16, spp=1)
        """, "PluginContractError", "packet_size must be an integer"),
    "a tap that edits the packets it is shown": ("""
        pipe = raysort.Pipeline("cornell", sorter="nah:packet_size=1", traversal="ranged")
        def tap(rec):
            if rec.depth == 0 and not rec.shadow and rec.packets.flags.writeable:
                n = rec.packets[-1]
                rec.packets[:] = np.resize([0, n], len(rec.packets))
                rec.packets[-1] = n
        image = pipe.render(32, 32, spp=4, tap=tap).image
        assert np.array_equal(image, pipe.render(32, 32, spp=4).image)
        raise RuntimeError("rendered as without the tap")
        """, "RuntimeError", "rendered as without the tap"),
    "ao given a batch shorter than its hits": ("""
        scene = raysort.load_scene("cornell")
        from raysort.workloads import workload
        batch = workload(scene, "primary", width=64, height=64).rays
        hits = raysort.Pipeline(scene).trace(batch)[0]
        from raysort.paths import Paths
        n = len(batch)
        paths = Paths(np.zeros(n, np.int32), np.zeros(n, np.int32), np.zeros(n, np.int32),
                      np.ones((3, n), np.float32))
        batch.truncate(1)
        raysort.create("shaders", "ao").shade(scene, batch, hits, paths, 0, 1,
                                              np.zeros((1, 3)))
        """, "ValueError", "the batch of 1 rays must hold the 4096 rays"),
    "stream's tree set to 16 after it was made": ("""
        pipe = raysort.Pipeline("cornell", traversal="stream")
        pipe.traversal.tree = 16
        pipe.render(16, 16, spp=1)
        """, "PluginContractError", "tree must be 4 or 8"),
    "a BVH subclass that redefines the tree": ("""
        scene = raysort.load_scene("cornell")
        class Edited(raysort.BVH):
            @property
            def nodes(self):
                n = np.array(super().nodes)
                n["offset"] = 10**8
                return n
        bvh = Edited(scene.vertices, scene.faces)
        for name in ("single", "wide", "wide8", "wide16", "stream", "frustum"):
            try:
                raysort.create("traversals", name).intersect(bvh, packets(64), False)
            except raysort.ConfigError as exc:
                assert "redefines BVH.nodes" in str(exc), exc
            else:
                raise AssertionError(name)
        raise raysort.ConfigError("every traversal refused it")
        """, "ConfigError", "every traversal refused it"),
    "scatter into hits whose arrays differ in length": ("""
        p, hits = packets(64), raysort.Hits(0)
        hits.t = np.empty(1 << 24, np.float32)
        p.index[:64] = (1 << 24) - 1
        raysort.rays.scatter(p, 1 << 24, hits)
        """, "ValueError", "scatter: the packets' rows"),
    "scatter_occluded with more lanes of index than of prim": ("""
        p = packets(64)
        p.index = np.zeros(1 << 24, np.int32)
        raysort.rays.scatter_occluded(p, 64)
        """, "ValueError", "prim must hold every lane of index"),
    "check_hits given offsets outside the order": ("""
        from raysort.sdk import before_traversal, check_hits
        p = packets(4)
        check_hits("mine", p, before_traversal(p), np.arange(4, dtype=np.int32),
                   np.array([2**30, 2**30 + 4], np.int32), 1, False)
        """, "ConfigError", "offsets must run from 0 to len(order)"),
    "check_sort given large packets that do not bound the batch": ("""
        from raysort.sdk import check_sort
        order = np.array([0, -2**30, 1, 2, 3, 4, 5, 6], np.int32)
        check_sort("mine", (order, np.array([0, 8], np.int32)), 8,
                   np.array([-2**31 + 1, 2**31 - 1], np.int64))
        """, "ConfigError", "must start at 0 and end at 8"),
}

EPILOGUE = """
try:
    run()
except Exception as exc:
    print(json.dumps({"type": type(exc).__name__, "message": str(exc)}))
else:
    print(json.dumps({"type": None, "message": ""}))
"""


@pytest.mark.parametrize("name", list(CASES))
def test_a_caller_edit_is_an_error_not_a_crash(name, tmp_path):
    body, kind, fragment = CASES[name]
    script = PRELUDE + "def run():\n" + textwrap.indent(textwrap.dedent(body), "    ") + EPILOGUE
    # run from elsewhere than the checkout: `python -c` imports from its directory
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          check=False, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, f"{name}: exit {proc.returncode}\n{proc.stderr[-3000:]}"
    result = json.loads(proc.stdout.splitlines()[-1])
    assert result["type"] == kind and fragment in result["message"], (name, result)
