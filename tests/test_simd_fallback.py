"""The portable scalar build of simd.h gives exactly the SSE build's hits and counters.

Builds raysort from this checkout with ``RAYSORT_NO_SIMD=1`` into a temporary
directory (needs the ``test`` extra's Cython and setuptools), traces the same
rays there in a subprocess with every traversal, and compares bit for bit with
this process's build.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import raysort
from raysort import cpu
from raysort.rays import gather, scatter
from raysort.workloads import workload

REPO = Path(__file__).resolve().parents[1]

TRACE_SCRIPT = r"""
import json, sys
import numpy as np
import raysort
from raysort import cpu
from raysort.rays import RayBatch, gather, scatter
data = np.load(sys.argv[1])
rays = RayBatch(int(data["n"]))
rays.data[:, :rays.n] = data["rays"]
scene = raysort.load_scene("sibenik")
out, counters = {}, {}
for name in data["traversals"]:
    name = str(name)
    for any_hit in (False, True):
        packets = gather(rays, data["order"], data["offsets"])
        c = raysort.create("traversals", name).intersect(scene.bvh(), packets, any_hit)
        key = f"{name}_{int(any_hit)}"
        hits = scatter(packets, rays.n)
        out[key + "_t"], out[key + "_prim"] = hits.t, hits.prim
        out[key + "_u"], out[key + "_v"] = hits.u, hits.v
        counters[key] = c.as_dict()
np.savez(sys.argv[2], **out)
print(json.dumps({"compiled": cpu.info()["compiled"], "counters": counters}))
"""


def _can_build():
    import importlib.util
    if importlib.util.find_spec("Cython") is None or importlib.util.find_spec("setuptools") is None:
        return False
    return (REPO / "setup.py").is_file()


@pytest.mark.slow
@pytest.mark.skipif(not _can_build(), reason="needs the source checkout, Cython and setuptools")
def test_scalar_build_matches_simd_build(tmp_path, sibenik):
    target = tmp_path / "scalar"
    # build from a clean copy: no object files or extensions of an earlier build
    source = tmp_path / "source"
    shutil.copytree(REPO, source, ignore=shutil.ignore_patterns(
        "build", ".venv", ".git", "*.so", "*.c", "*.egg-info", "__pycache__", ".benchmarks"))
    env = dict(os.environ, RAYSORT_NO_SIMD="1")
    build = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
         "--target", str(target), str(source)],
        env=env, capture_output=True, text=True)
    assert build.returncode == 0, build.stderr[-3000:]

    # diffuse rays in nah order: mixed packet sizes, heads, tails and SIMD groups
    work = workload(sibenik, "diffuse", width=48, height=32, spp=1, seed=2)
    order, offsets = raysort.create("sorters", "nah").sort(work.rays, work.packets,
                                                           sibenik.bvh().bounds)
    builtin = [info.name for info in raysort.list_plugins("traversals")
               if info.distribution == "raysort"]
    np.savez(tmp_path / "in.npz", rays=work.rays.data[:, :len(work)], n=len(work),
             order=order, offsets=offsets, traversals=np.array(builtin))
    script = tmp_path / "trace.py"
    script.write_text(TRACE_SCRIPT)
    run = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "in.npz"), str(tmp_path / "out.npz")],
        env=dict(os.environ, PYTHONPATH=str(target)), capture_output=True, text=True,
        cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["compiled"] == "scalar"
    theirs = np.load(tmp_path / "out.npz")

    for name in builtin:
        for any_hit in (False, True):
            packets = gather(work.rays, order, offsets)
            counters = raysort.create("traversals", name).intersect(sibenik.bvh(), packets,
                                                                    any_hit)
            hits = scatter(packets, len(work))
            key = f"{name}_{int(any_hit)}"
            for field in ("t", "prim", "u", "v"):
                ours = getattr(hits, field)
                assert np.array_equal(ours.view(np.uint32), theirs[f"{key}_{field}"]
                                      .view(np.uint32)), f"{key}: {field} differs"
            assert counters.as_dict() == report["counters"][key], key


def test_compiled_path_is_reported():
    info = cpu.info()
    assert info["compiled"] in ("sse2", "scalar")
    assert info["active"] == info["compiled"]
    if info["machine"] in ("x86_64", "AMD64") and not os.environ.get("RAYSORT_NO_SIMD"):
        assert "sse2" in info["cpu_features"]
