"""Each traversal on every Sibenik ray kind (camera, ambient-occlusion,
first-bounce diffuse and shadow rays; AO and shadow rays as any-hit queries, as
a render traces them), 8x8 and 32x32 packets, with and without the ``nah``
sorter (every installed traversal, yardsticks such as Embree included).  ``extra_info`` holds
Mrays/s and the five Table I counters per ray.  Only the traversal is timed:
the packets are gathered in the benchmark's setup."""
import pytest

import raysort
from raysort.rays import gather
from raysort.stats import COUNTER_LABELS
from raysort.workloads import KINDS

TRAVERSALS = raysort.available("traversals")
SORTERS = {"8x8": {"type": "none", "packet_size": 64},
           "32x32": {"type": "none", "packet_size": 1024},
           "nah": "nah"}


@pytest.mark.parametrize("sorter", list(SORTERS))
@pytest.mark.parametrize("traversal", TRAVERSALS)
@pytest.mark.parametrize("kind", list(KINDS))
def test_traversal(benchmark, scene_cache, workload_cache, kind, traversal, sorter):
    scene = scene_cache("sibenik")
    work = workload_cache("sibenik", kind)
    bvh = scene.bvh()
    order, offsets = raysort.create("sorters", SORTERS[sorter]).sort(work.rays, work.packets,
                                                                     bvh.bounds)
    trav = raysort.create("traversals", traversal)
    counters = []

    def setup():
        return (gather(work.rays, order, offsets),), {}

    def run(packets):
        counters.append(trav.intersect(bvh, packets, any_hit=work.any_hit))

    benchmark.group = f"sibenik {kind}: traversal"
    benchmark.pedantic(run, setup=setup, rounds=7, warmup_rounds=1)
    per_ray = counters[-1].per_ray()
    benchmark.extra_info.update(
        rays=len(work), sorter=sorter, traversal=traversal,
        mrays_per_second=len(work) / benchmark.stats.stats.min / 1e6,
        **{COUNTER_LABELS[k]: v for k, v in per_ray.items()})
