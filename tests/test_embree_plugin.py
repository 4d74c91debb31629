"""The raysort-embree plugin: installed from plugins/, found by name, hits within tolerance.

Installs ``plugins/raysort-embree`` into a temporary directory (no
dependencies: embreex must already be importable, otherwise the tests skip)
and checks Embree's hits against brute force, allowing Embree's own rounding
and tie-breaking: the same primitive, or a hit at the same distance (a tie or
a shared edge).
"""
import importlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import raysort
from raysort.rays import gather, scatter, scatter_occluded
from raysort.reference import brute_force

PLUGIN = Path(__file__).resolve().parents[1] / "plugins" / "raysort-embree"
pytest.importorskip("embreex")
pytestmark = pytest.mark.skipif(not PLUGIN.is_dir(), reason="needs the source checkout")


@pytest.fixture(scope="module")
def embree_installed(tmp_path_factory):
    target = tmp_path_factory.mktemp("embree_plugin")
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                    "--no-build-isolation", "--target", str(target), str(PLUGIN)], check=True)
    sys.path.insert(0, str(target))
    importlib.invalidate_caches()
    raysort.refresh()
    try:
        yield target
    finally:
        sys.path.remove(str(target))
        sys.modules.pop("raysort_embree", None)
        raysort.refresh()


def _trace(bvh, work, any_hit=False):
    n = len(work)
    order = np.arange(n, dtype=np.int32)
    offsets = np.append(np.arange(0, n, 64), n).astype(np.int32)
    packets = gather(work.rays, order, offsets)
    counters = raysort.create("traversals", "embree").intersect(bvh, packets, any_hit)
    return (scatter_occluded(packets, n) if any_hit else scatter(packets, n)), counters


def test_found_by_name(embree_installed):
    info = {i.name: i for i in raysort.list_plugins("traversals", load=True)}
    assert info["embree"].distribution == "raysort-embree"
    assert info["embree"].status == "ok"
    assert raysort.load("traversals", "embree").exact is False


@pytest.mark.parametrize("kind", ["primary", "diffuse"])
def test_hits_match_brute_force_within_tolerance(embree_installed, real_scene, workloads, kind):
    work = workloads(real_scene, kind)
    bvh = real_scene.bvh()
    hits, counters = _trace(bvh, work)
    ref = brute_force(real_scene.vertices, real_scene.faces, work.rays)
    assert not counters.available and counters.rays == len(work)
    assert np.array_equal(hits.prim >= 0, ref.prim >= 0) or \
        (np.mean((hits.prim >= 0) != (ref.prim >= 0)) < 1e-3)
    both = (hits.prim >= 0) & (ref.prim >= 0)
    rel = np.abs(hits.t[both] - ref.t[both]) / ref.t[both]
    assert rel.max() < 1e-4
    other = both & (hits.prim != ref.prim)
    # a different primitive only where the two are at (numerically) the same distance
    assert other.mean() < 0.01
    assert (np.abs(hits.t[other] - ref.t[other]) / ref.t[other] < 1e-4).all()


def test_any_hit_matches_brute_force(embree_installed, sibenik, workloads):
    from raysort.workloads import Workload

    diffuse = workloads(sibenik, "diffuse")
    work = Workload(diffuse.rays.take(np.arange(len(diffuse))), diffuse.packets)
    work.rays.tmax[:] = 2.0           # shadow-ray style: only nearby occluders count
    occluded, _ = _trace(sibenik.bvh(), work, any_hit=True)
    ref = brute_force(sibenik.vertices, sibenik.faces, work.rays, any_hit=True)
    assert 0.05 < ref.mean() < 0.95
    assert np.mean(occluded != ref) < 1e-3


def test_render_and_bench_include_embree(embree_installed, sibenik):
    from raysort.bench import load_table
    from raysort.bench.configs import select
    from raysort.bench.frame import run_frames

    result = raysort.Pipeline(sibenik, traversal="embree").render(24, 16, 1)
    ours = raysort.Pipeline(sibenik, traversal="ranged").render(24, 16, 1)
    assert np.abs(result.image - ours.image).mean() < 0.02 * ours.image.mean()
    table = load_table()
    configs = select(table.frame_configs(), ["ranged (8x8)", "embree"])
    report = run_frames(["sibenik"], configs, table, width=16, height=16, spp=1, repeat=1)
    rows = {r["label"]: r for r in report["groups"]["sibenik"]["configs"]}
    assert rows["embree"]["counters_available"] is False
    assert rows["embree"]["exact_traversal"] is False
    assert rows["embree"]["mrays_per_second"] > 0
