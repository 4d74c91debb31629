"""Standard ray batches for benchmarks and tests: camera rays and diffuse bounces.

Both come in large packets exactly as a render makes them (one tile sample
pass per large packet, Morton order inside a tile), so a sorter or traversal
measured on them sees what it sees inside :meth:`raysort.Pipeline.render`.
"""
from __future__ import annotations

import numpy as np

from raysort import registry
from raysort.paths import Paths
from raysort.pipeline import Pipeline
from raysort.rays import RayBatch

__all__ = ["Workload", "camera_rays", "bounce_rays", "workload"]


class Workload:
    """A ray batch with its large-packet boundaries and a label."""

    __slots__ = ("rays", "packets", "label")

    def __init__(self, rays, packets, label=""):
        self.rays, self.packets, self.label = rays, np.asarray(packets, np.int32), label

    def __len__(self):
        return len(self.rays)

    def __repr__(self):
        return f"Workload({self.label!r}, rays={len(self.rays)}, packets={len(self.packets) - 1})"


def _tiles(width, height, tile):
    return [(x, y) for y in range(0, height, tile) for x in range(0, width, tile)]


def camera_rays(scene, width=256, height=256, spp=1, seed=0, tile=32, generator="pinhole"):
    """Primary rays of every tile and sample, one large packet per tile pass."""
    from raysort.pipeline import morton_order

    gen = registry.create("generators", generator)
    batches, counts, pixel, sample = [], [], [], []
    samples = np.arange(spp, dtype=np.int32)
    for x0, y0 in _tiles(width, height, tile):
        w, h = min(tile, width - x0), min(tile, height - y0)
        local = morton_order(w, h)
        pixels = ((y0 + local // w) * width + x0 + local % w).astype(np.int32)
        batches.append(gen.generate(scene.camera, pixels, samples, width, height, spp, seed))
        counts.append(np.full(spp, len(pixels)))
        pixel.append(np.tile(pixels, spp))
        sample.append(np.repeat(samples, len(pixels)))
    rays = _concat(batches)
    packets = np.concatenate([[0], np.cumsum(np.concatenate(counts))])
    pixel, sample = np.concatenate(pixel), np.concatenate(sample)
    return (Workload(rays, packets, f"{scene.name} primary"),
            Paths(pixel, sample, np.zeros_like(pixel)))


def bounce_rays(scene, width=256, height=256, spp=1, seed=0, depth=1, tile=32):
    """Diffuse rays of bounce ``depth`` (1 = first bounce), large packets as in a render."""
    pipe = Pipeline(scene, sorter="none", traversal="single",
                    shader={"type": "lambert", "max_depth": depth, "shadow_rays": False},
                    tile=tile)
    work, paths = camera_rays(scene, width, height, spp, seed, tile)
    rays, packets = work.rays, work.packets
    radiance = np.zeros((len(rays), 3))
    pipe.shader.prepare(scene)
    for d in range(depth):
        hits, _ = pipe.trace(rays, packets)
        bounce = pipe.shader.shade(scene, rays, hits, paths, d, seed, radiance)
        packets = np.searchsorted(bounce.parent, packets).astype(np.int32)
        paths = paths.take(bounce.parent, bounce.throughput)
        rays = bounce.rays
    return Workload(rays, packets, f"{scene.name} diffuse depth {depth}")


def workload(scene, kind, **kw):
    """``kind`` "primary" or "diffuse" (first bounce): a :class:`Workload`."""
    if kind == "primary":
        return camera_rays(scene, **kw)[0]
    if kind == "diffuse":
        return bounce_rays(scene, **kw)
    raise ValueError(f"workload kind must be 'primary' or 'diffuse', got {kind!r}")


def _concat(batches):
    out = RayBatch(sum(len(b) for b in batches))
    out.data[:, :len(out)] = np.concatenate([b.data[:, :len(b)] for b in batches], axis=1)
    return out
