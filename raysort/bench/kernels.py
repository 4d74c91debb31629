"""``raysort bench --kernels``: traversal alone, on the rays a render traces.

For each scene and each workload kind (``[kernels] workloads`` in configs.toml,
or ``--workloads``: camera rays, first-bounce diffuse rays, ...; see
:mod:`raysort.workloads`), every installed traversal traces the same rays in
each packet layout of ``[kernels.packets]`` (8x8 and 32x32 packets in input
order, and ``nah``'s sorted sub-packets), one thread.  Only the traversal is
timed; sorting and gathering are timed apart (the ``sort`` column: their share
of the traversal time).  Every exact traversal must return the same hits (t
bit for bit and the primitive) as the reference configuration.
"""
from __future__ import annotations

import time

import numpy as np

from raysort import registry
from raysort.bench.report import bvh_settings, group_report, load_average, machine_info
from raysort.bench.rounds import run_checked
from raysort.rays import gather, scatter, scatter_occluded
from raysort.scene import load_scene
from raysort.workloads import workload

__all__ = ["run_kernels"]


class _Trace:
    """One configuration on one workload: sort + gather (timed apart), then traverse."""

    def __init__(self, config, bvh, work):
        self.sorter = registry.create("sorters", config.sorter)
        self.traversal = registry.create("traversals", config.traversal)
        self.exact = bool(type(self.traversal).exact)
        self.bvh, self.work = bvh, work
        self.sort_seconds = []
        self.reference, self.identical = None, True
        self.counters = None

    def result(self):
        """The hits, as the reference the other configurations are checked against."""
        w = self.work
        order, offsets = self.sorter.sort(w.rays, w.packets.copy(), self.bvh.bounds.copy())
        packets = gather(w.rays, order, offsets)
        self.traversal.intersect(self.bvh, packets, any_hit=w.any_hit)
        return scatter_occluded(packets, len(w)) if w.any_hit else scatter(packets, len(w))

    def __call__(self):
        w = self.work
        start = time.perf_counter()
        order, offsets = self.sorter.sort(w.rays, w.packets.copy(), self.bvh.bounds.copy())
        packets = gather(w.rays, order, offsets)
        mid = time.perf_counter()
        self.counters = self.traversal.intersect(self.bvh, packets, any_hit=w.any_hit)
        end = time.perf_counter()
        self.sort_seconds.append(mid - start)
        n = len(w)
        hits = scatter_occluded(packets, n) if w.any_hit else scatter(packets, n)
        self.identical = self.identical and _same(hits, self.reference)
        return end - mid


def _same(a, b):
    if isinstance(a, np.ndarray):
        return bool(np.array_equal(a, b))
    return bool(np.array_equal(a.t.view(np.uint32), b.t.view(np.uint32))
                and np.array_equal(a.prim, b.prim))


def run_kernels(scene_specs, configs, kinds, *, width=256, height=256, spp=1, seed=1,
                repeat=5, order_seed=0, bvh=None, warmup=True, progress=None):
    """Time every configuration on every (scene, workload kind); a JSON-ready dict."""
    report = {"kind": "kernels", "machine": machine_info(), "load": {"before": load_average()},
              "settings": {"width": width, "height": height, "spp": spp, "depth": None,
                           "seed": seed, "threads": 1, "repeat": repeat,
                           "order_seed": order_seed, "warmup": warmup,
                           "workloads": list(kinds), **bvh_settings(bvh)},
              "groups": {}}
    scenes = [load_scene(spec) for spec in scene_specs]     # every mesh read before timing
    jobs = [(scene, kind) for scene in scenes for kind in kinds]
    for j, (scene, kind) in enumerate(jobs):
        built = scene.bvh(**(bvh or {}))
        work = workload(scene, kind, width=width, height=height, spp=spp, seed=seed)
        traces = [_Trace(c, built, work) for c in configs]
        seconds, orders = run_checked(configs, traces, repeat, seed=order_seed + j,
                                      warmup=warmup, progress=progress, group=j,
                                      groups=len(jobs))
        rows = [{"exact_traversal": t.exact, "rays": len(work), "counters": t.counters,
                 "identical_hits": t.identical,
                 "sort_seconds": t.sort_seconds[len(t.sort_seconds) - repeat:]}
                for t in traces]
        group = group_report(configs, seconds, orders, rows)
        group.update(scene=scene.name, workload=work.label, any_hit=work.any_hit,
                     triangles=scene.n_triangles, bvh=built.stats())
        report["groups"][work.label] = group
    report["load"]["after"] = load_average()
    return report
