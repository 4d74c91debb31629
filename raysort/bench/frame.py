"""The frame benchmark: the paper's experiment (Fig. 2 and Table I), whole frames.

Every configuration renders the same frame (the ``[render]`` shader of
configs.toml, jittered samples, one seed) once per round; see
:mod:`raysort.bench.rounds` for the method.  Every exact configuration must
give a bit-identical image in every round; an inexact one (an outside
library's triangle test) reports its largest difference over all rounds.
"""
from __future__ import annotations

import numpy as np

from raysort import registry
from raysort.bench.report import bvh_settings, group_report, load_average, machine_info
from raysort.bench.rounds import run_checked
from raysort.errors import ConfigError, RaysortError
from raysort.pipeline import Pipeline
from raysort.scene import load_scene

__all__ = ["run_frames"]


class _Frame:
    """One configuration's pipeline, called once per round.  Each image is compared
    with the reference image as it comes: bitwise, and the largest difference."""

    def __init__(self, pipe, size, spp, seed):
        self.pipe, self.size, self.spp, self.seed = pipe, size, spp, seed
        self.exact = bool(type(pipe.traversal).exact)
        self.reference = None
        self.stats = []
        self.identical, self.max_difference = True, 0.0

    def render(self):
        return self.pipe.render(*self.size, self.spp, self.seed)

    def result(self):
        """The image, as the reference the other configurations are checked against."""
        return self.render().image

    def __call__(self):
        out = self.render()
        self.stats.append(out.stats)
        ref = self.reference
        self.identical = self.identical and np.array_equal(out.image.view(np.uint32),
                                                           ref.view(np.uint32))
        self.max_difference = max(self.max_difference,
                                  float(np.nanmax(np.abs(out.image - ref))))
        return out.stats.wall_seconds


def _shader(table, depth):
    """The ``[render]`` shader with ``depth`` set as its ``depth_parameter``; checked
    before any scene is loaded: ConfigError naming the file of the value that is wrong."""
    shader = dict(table.render.get("shader", {}))
    key = table.render.get("depth_parameter")
    if not shader:
        return {key: depth} if key else {}
    source = table.where("render.shader")
    _check_shader(shader, f"{source} [render]: ")
    if key:
        shader[key] = depth
        where = table.where("render.depth_parameter")
        _check_shader(shader, f"{where} [render]: depth_parameter {key!r}: ",
                      "" if where == source else f"; the shader is set in {source}")
    return shader


def _check_shader(shader, before, after=""):
    try:
        registry.create("shaders", shader)
    except RaysortError as exc:
        raise ConfigError(f"{before}{exc}{after}") from None


def run_frames(scene_specs, configs, table, *, width=256, height=256, spp=4, depth=2, seed=0,
               threads=1, repeat=3, order_seed=0, bvh=None, warmup=True, progress=None):
    """Run every configuration on every scene; returns a JSON-ready dict."""
    shader = _shader(table, depth)
    report = {"kind": "frame", "machine": machine_info(), "load": {"before": load_average()},
              "settings": {"width": width, "height": height, "spp": spp, "depth": depth,
                           "seed": seed, "threads": threads, "repeat": repeat,
                           "order_seed": order_seed, "warmup": warmup, "shader": shader,
                           **bvh_settings(bvh)},
              "groups": {}}
    scenes = [load_scene(spec) for spec in scene_specs]     # every mesh read before timing
    for s, scene in enumerate(scenes):
        built = scene.bvh(**(bvh or {}))          # built once, outside the timings
        frames = [_Frame(Pipeline(scene, shader=shader, threads=threads, bvh=bvh,
                                  traversal=c.traversal, sorter=c.sorter),
                         (width, height), spp, seed) for c in configs]

        seconds, orders = run_checked(configs, frames, repeat, seed=order_seed + s,
                                      warmup=warmup, progress=progress, group=s,
                                      groups=len(scene_specs))
        rows = []
        for f in frames:
            timed = f.stats[len(f.stats) - repeat:]
            rows.append({
                "exact_traversal": f.exact, "identical_image": f.identical,
                "max_image_difference": f.max_difference,
                "rays": timed[0].total_rays,
                "counters": timed[0].closest_hit_counters(),
                "stage_seconds": [st.stage_seconds for st in timed],
            })
        group = group_report(configs, seconds, orders, rows,
                             [tuple(pair) for pair in table.render.get("compare", [])])
        group.update(scene=scene.name, triangles=scene.n_triangles, bvh=built.stats())
        report["groups"][scene.name] = group
    report["load"]["after"] = load_average()
    return report
