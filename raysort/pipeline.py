"""The render pipeline: generate -> sort -> gather -> traverse -> scatter -> shade.

A :class:`Pipeline` is composed from four plugins chosen by name or dict
config.  :meth:`Pipeline.trace` runs the middle of the frame on any ray batch
(useful on its own for benchmarks); :meth:`Pipeline.render` renders an image
in tiles.

How a render is organised (and why it is deterministic):

* The image is cut into square tiles (``tile`` = 32: 32x32 pixels).  One
  sample pass over a tile is one *large packet* of up to 1024 rays, made in
  Morton order so that any power-of-4 run of rays is a square of pixels.
* A tile's passes are processed in batches of about ``batch_rays`` rays; each
  batch goes through every bounce before the next batch starts, so memory is
  bounded by the batch, never by image size x spp.
* Tiles are spread over ``threads`` worker threads; all kernels release the
  GIL.  A tile accumulates its radiance in its own buffer in a fixed order
  (batch, bounce, ray index), and hits are scattered back to generation
  order before shading, so the image is bit-identical for every sorter,
  traversal and thread count at a fixed seed.
"""
from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np

from raysort import registry
from raysort.params import integer
from raysort.contract import check_sort
from raysort.errors import ConfigError, PluginContractError
from raysort.paths import Bounce, Paths
from raysort.progress import with_rays
from raysort.rays import Hits, RayBatch, gather, scatter, scatter_occluded
from raysort.scene import Scene, load_scene
from raysort.stats import Counters

__all__ = ["Pipeline", "RenderResult", "RenderStats", "Traced", "STAGES", "morton_order"]

#: stage names used in timings, in pipeline order
STAGES = ("generate", "sort", "check", "gather", "traverse", "scatter", "shade")


def morton_order(width, height):
    """Local pixel indices ``y * width + x`` of a tile, in Morton (Z) order."""
    y, x = np.divmod(np.arange(width * height, dtype=np.int64), width)
    code = np.zeros_like(x)
    for bit in range(7):
        code |= ((x >> bit) & 1) << (2 * bit) | ((y >> bit) & 1) << (2 * bit + 1)
    return np.argsort(code, kind="stable").astype(np.int32)


@dataclass
class RenderStats:
    """Where the time went and how much work the traversal did.

    ``stage_seconds`` are summed over worker threads (CPU seconds per stage);
    ``wall_seconds`` is the elapsed time of the whole render.
    """

    wall_seconds: float = 0.0
    stage_seconds: dict = field(default_factory=lambda: dict.fromkeys(STAGES, 0.0))
    rays: dict = field(default_factory=dict)          # depth -> closest-hit rays traced
    counters: dict = field(default_factory=dict)      # depth -> Counters
    shadow_rays: int = 0
    shadow_counters: Counters = field(default_factory=Counters)
    threads: int = 1

    def merge(self, other):
        for k, v in other.stage_seconds.items():
            self.stage_seconds[k] = self.stage_seconds.get(k, 0.0) + v
        for d, n in other.rays.items():
            self.rays[d] = self.rays.get(d, 0) + n
        for d, c in other.counters.items():
            self.counters[d] = self.counters.get(d, Counters()) + c
        self.shadow_rays += other.shadow_rays
        self.shadow_counters = self.shadow_counters + other.shadow_counters

    @property
    def total_rays(self):
        """Every ray traced: closest-hit rays of all depths plus shadow rays."""
        return sum(self.rays.values()) + self.shadow_rays

    @property
    def mrays_per_second(self):
        return self.total_rays / max(self.wall_seconds, 1e-12) / 1e6

    def closest_hit_counters(self):
        """Counters summed over all depths (the paper's per-frame Table I figures)."""
        total = Counters()
        for c in self.counters.values():
            total = total + c
        return total

    def stage_shares(self):
        """Each stage's share of the summed stage seconds (0..1), largest first."""
        total = sum(self.stage_seconds.values()) or 1.0
        return dict(sorted(((k, v / total) for k, v in self.stage_seconds.items() if v > 0),
                           key=lambda item: -item[1]))

    def _summary(self):
        """(label, text) rows shared by the text and HTML views."""
        from raysort.stats import COUNTER_LABELS

        depths = ", ".join(f"depth {d}: {n:,}" for d, n in sorted(self.rays.items()))
        per_ray = self.closest_hit_counters().per_ray()
        counters = ("not counted by this traversal" if None in per_ray.values() else
                    ", ".join(f"{COUNTER_LABELS[k]} {v:.2f}" for k, v in per_ray.items()))
        return [
            ("time", f"{self.wall_seconds:.3f} s wall, {self.threads} "
                     f"thread{'s' if self.threads != 1 else ''}"),
            ("throughput", f"{self.mrays_per_second:.3f} Mrays/s"),
            ("rays", f"{self.total_rays:,} ({depths}; shadow: {self.shadow_rays:,})"),
            ("stages", ", ".join(f"{k} {share:.0%}" for k, share in
                                 self.stage_shares().items()) or "none"),
            ("work per ray", counters),
        ]

    def __repr__(self):
        rows = "\n".join(f"  {label + ':':<14}{text}" for label, text in self._summary())
        return f"RenderStats(\n{rows}\n)"

    def _repr_html_(self):
        from html import escape

        rows = "".join(f"<tr><th style='text-align:left'>{escape(label)}</th>"
                       f"<td style='text-align:left'>{escape(text)}</td></tr>"
                       for label, text in self._summary())
        return f"<table><caption>RenderStats</caption>{rows}</table>"

    def as_dict(self):
        return {
            "wall_seconds": self.wall_seconds,
            "stage_seconds": dict(self.stage_seconds),
            "rays_per_depth": {str(d): n for d, n in sorted(self.rays.items())},
            "shadow_rays": self.shadow_rays,
            "mrays_per_second": self.mrays_per_second,
            "counters_per_depth": {str(d): c.as_dict() for d, c in sorted(self.counters.items())},
            "counters": self.closest_hit_counters().as_dict(),
            "counters_per_ray": self.closest_hit_counters().per_ray(),
            "shadow_counters": self.shadow_counters.as_dict(),
            "threads": self.threads,
        }


@dataclass(frozen=True)
class Traced:
    """One batch of rays a render traced, as a ``tap`` of :meth:`Pipeline.render` sees it.

    ``shadow`` is False for closest-hit rays (the primary rays at ``depth`` 0, then each
    bounce) and True for the any-hit rays (shadow or AO rays) a shader made at ``depth``.
    ``packets`` are the large-packet boundaries the render traced them with; ``hits`` is
    a :class:`~raysort.rays.Hits`, or the bool ``occluded`` array of any-hit rays;
    ``paths`` (closest-hit rays only) holds each ray's pixel, sample and tile slot.
    Everything is in generation order and must be treated as read-only.
    """

    tile: tuple
    depth: int
    shadow: bool
    rays: RayBatch
    packets: np.ndarray
    hits: object
    paths: Paths | None = None


@dataclass
class RenderResult:
    """A rendered image (float32 linear RGB, (height, width, 3)) with its stats, and the
    AOV layers asked for (name -> (height, width[, 3]) array, see :mod:`raysort.aov`)."""

    image: np.ndarray
    stats: RenderStats
    settings: dict
    aov: dict = field(default_factory=dict)

    def __repr__(self):
        s = self.settings
        return (f"RenderResult({s.get('scene')}, {s.get('width')}x{s.get('height')}, "
                f"{s.get('spp')} spp, sorter {s.get('sorter')}, traversal "
                f"{s.get('traversal')}: {self.stats.wall_seconds:.3f} s, "
                f"{self.stats.mrays_per_second:.3f} Mrays/s)")

    def _repr_png_(self):
        """Jupyter shows the image, tone mapped as the PNG preview is (exposure 0)."""
        from raysort import output

        return output.png_bytes(self.image)

    def write(self, path, *, png=True, exposure=0.0):
        """Write the EXR (and a PNG preview next to it, of the same render); each file appears
        whole or not at all (see :func:`raysort.output.write_render`).  AOV layers go into
        the EXR as extra named channels (``depth.Z``, ``normal.X``, ...)."""
        from raysort import output

        path = os.fspath(path)
        if not path.lower().endswith(".exr"):
            return output.write_image(path, self.image, exposure=exposure)
        meta = {f"raysort.{k}": str(v) for k, v in self.settings.items()}
        from raysort.aov import exr_channels

        output.write_render(path, self.image, metadata=meta, exposure=exposure, png=png,
                            channels=exr_channels(self.aov))


class Pipeline:
    """generate -> sort -> gather -> traverse -> scatter -> shade, with plugins.

    Parameters
    ----------
    scene : Scene, or a scene name / path (see :func:`raysort.scene.load_scene`)
    generator, sorter, traversal, shader : str or dict or plugin instance
        a plugin name (``"nah"``), a spec (``"none:packet_size=1024"``) or a
        dict with a ``"type"`` key and parameters.  The defaults, ``nah`` and
        ``wide``, are the fastest combination measured (BENCHMARKS.md).
    tile : int, default 32
        tile edge in pixels; one sample pass over a tile is a large packet.
    threads : int, default 1
        worker threads (tiles are shared out; the image does not change).
    batch_rays : int, default 16384
        about how many rays a worker keeps in flight (memory bound).
    check_sorters : bool, default True
        validate every sorter result; False skips the check for built-in
        sorters marked trusted (third-party sorters are always checked).
    bvh : dict, optional
        BVH build parameters (``max_leaf``, ``bins``, ``traversal_cost``).
    """

    def __init__(self, scene=None, *, generator="pinhole", sorter="nah", traversal="wide",
                 shader="lambert", tile=32, threads=1, batch_rays=16384, check_sorters=True,
                 bvh=None):
        self.scene = scene if isinstance(scene, Scene) else load_scene(scene)
        self.generator = registry.create("generators", generator)
        self.sorter = registry.create("sorters", sorter)
        self.traversal = registry.create("traversals", traversal)
        self.shader = registry.create("shaders", shader)
        self.tile = integer("tile", tile, 1, 64)
        self.threads = integer("threads", threads, 1)
        self.batch_rays = integer("batch_rays", batch_rays, 1)
        self.check_sorters = bool(check_sorters)
        self.bvh_params = dict(bvh or {})
        self._bvh = None

    # ------------------------------------------------------------------
    @property
    def bvh(self):
        if self._bvh is None:
            try:
                self._bvh = self.scene.bvh(**self.bvh_params)
            except TypeError as exc:
                raise ConfigError(f"bvh parameters: {exc}") from None
        return self._bvh

    def describe(self):
        """Plugin names and parameters, for reports and file metadata."""
        return {kind: p.spec() for kind, p in (
            ("generator", self.generator), ("sorter", self.sorter),
            ("traversal", self.traversal), ("shader", self.shader))}

    # ------------------------------------------------------------------
    def trace(self, rays, packets=None, *, any_hit=False, timings=None, threads=None):
        """Sort, gather, traverse and scatter one batch of rays.

        Parameters
        ----------
        rays : RayBatch
        packets : int array, optional
            large-packet boundaries; default: consecutive runs of
            ``tile * tile`` rays.
        any_hit : bool
            occlusion query: return a bool array instead of hits.
        timings : dict, optional
            stage name -> seconds, added to.
        threads : int, optional
            split the traversal over this many threads (default: the pipeline's
            ``threads``); sub-packets are shared out and every ray is traced by
            one thread, so the hits do not change.

        Returns
        -------
        (Hits or bool array, Counters)
        """
        n = len(rays)
        if packets is None:
            packets = np.append(np.arange(0, n, self.tile * self.tile), n)
        packets = np.asarray(packets, dtype=np.int32)
        clock = _Clock(timings)
        if n == 0:
            return (np.zeros(0, bool) if any_hit else Hits(0)), Counters()
        result = self.sorter.sort(rays, packets, self.bvh.bounds)
        clock.lap("sort")
        if self.check_sorters or not _trusted(type(self.sorter)):
            order, offsets = check_sort(self.sorter.name, result, n, packets)
            clock.lap("check")
        else:
            order, offsets = result
        batch = gather(rays, order, offsets)
        clock.lap("gather")
        counters = self._intersect(batch, any_hit, self.threads if threads is None else threads)
        clock.lap("traverse")
        out = scatter_occluded(batch, n) if any_hit else scatter(batch, n)
        clock.lap("scatter")
        return out, counters

    def _intersect(self, batch, any_hit, threads=1):
        if threads > 1 and batch.n_packets > 1:
            cuts = np.linspace(0, batch.n_packets, min(threads, batch.n_packets) + 1).astype(int)
            with ThreadPoolExecutor(max_workers=len(cuts) - 1) as pool:
                parts = list(pool.map(
                    lambda ab: self.traversal.intersect(self.bvh, batch.slice(*ab), any_hit),
                    zip(cuts[:-1], cuts[1:])))
        else:
            parts = [self.traversal.intersect(self.bvh, batch, any_hit)]
        total = Counters()
        for counters in parts:
            if not isinstance(counters, Counters):
                raise PluginContractError(
                    f"traversal {self.traversal.name!r} broke its contract: intersect() must "
                    f"return raysort.stats.Counters, got {type(counters).__name__}",
                    kind="traversals", name=self.traversal.name)
            total = total + counters
        return total

    # ------------------------------------------------------------------
    def render(self, width=256, height=256, spp=4, seed=0, *, progress=None, aov=(),
               tap=None):
        """Render the scene's camera view; returns a :class:`RenderResult`.

        ``progress(done_tiles, total_tiles)`` is called as tiles finish, with
        ``rays=`` the rays traced so far if it takes a ``rays`` argument.  ``aov`` names
        layers taken from each pixel's first primary hit (``depth``, ``normal``,
        ``albedo``, ``prim``; see :mod:`raysort.aov`) into ``result.aov``.
        ``tap(record)`` is called with a :class:`Traced` record for every batch of rays
        the render traces (from the worker threads when ``threads > 1``): the rays of a
        real render, e.g. for :mod:`raysort.workloads`.
        """
        width, height = integer("width", width, 1), integer("height", height, 1)
        spp, seed = integer("spp", spp, 1), integer("seed", seed, 0)
        collector = None
        if aov:
            from raysort.aov import AovCollector

            collector = AovCollector(aov, self.scene, width, height)
            tap = collector if tap is None else _both(collector, tap)
        start = time.perf_counter()
        self.bvh  # build before the workers start
        self.shader.prepare(self.scene)
        tiles = [(x, y) for y in range(0, height, self.tile) for x in range(0, width, self.tile)]
        image = np.zeros((height, width, 3), dtype=np.float32)
        stats = RenderStats(threads=self.threads)
        progress = with_rays(progress, lambda: stats.total_rays)

        def finish(tile, result):
            radiance, tile_stats = result
            x0, y0 = tile
            w, h = min(self.tile, width - x0), min(self.tile, height - y0)
            image[y0:y0 + h, x0:x0 + w] = (radiance / spp).reshape(h, w, 3).astype(np.float32)
            stats.merge(tile_stats)

        done = 0
        if self.threads == 1:
            for tile in tiles:
                finish(tile, self._render_tile(tile, width, height, spp, seed, tap))
                done += 1
                if progress:
                    progress(done, len(tiles))
        else:
            with ThreadPoolExecutor(max_workers=self.threads) as pool:
                futures = {pool.submit(self._render_tile, tile, width, height, spp, seed,
                                       tap): tile for tile in tiles}
                try:
                    for future in as_completed(futures):
                        finish(futures.pop(future), future.result())
                        done += 1
                        if progress:
                            progress(done, len(tiles))
                except BaseException:
                    for f in list(futures):
                        f.cancel()
                    raise
        stats.wall_seconds = time.perf_counter() - start
        # what determines the image (not how it was computed: threads live in stats)
        settings = dict(self.describe(), scene=self.scene.name, width=width, height=height,
                        spp=spp, seed=seed, tile=self.tile)
        return RenderResult(image, stats, settings, collector.layers() if collector else {})

    def _render_tile(self, tile, width, height, spp, seed, tap=None):
        x0, y0 = tile
        w, h = min(self.tile, width - x0), min(self.tile, height - y0)
        local = morton_order(w, h)
        pixels = ((y0 + local // w) * width + x0 + local % w).astype(np.int32)
        n_pix = len(pixels)
        slots = local                          # accumulator row = pixel's row-major index
        radiance = np.zeros((n_pix, 3), dtype=np.float64)
        stats = RenderStats()
        clock = _Clock(stats.stage_seconds)
        per_batch = max(1, self.batch_rays // n_pix)
        for s0 in range(0, spp, per_batch):
            samples = np.arange(s0, min(spp, s0 + per_batch), dtype=np.int32)
            clock.lap(None)
            rays = self.generator.generate(self.scene.camera, pixels, samples, width, height,
                                           spp, seed)
            clock.lap("generate")
            if not isinstance(rays, RayBatch) or len(rays) != n_pix * len(samples):
                raise PluginContractError(
                    f"generator {self.generator.name!r} broke its contract: expected a "
                    f"RayBatch of {n_pix * len(samples)} rays, got {rays!r}",
                    kind="generators", name=self.generator.name)
            paths = Paths(np.tile(pixels, len(samples)), np.repeat(samples, n_pix),
                          np.tile(slots, len(samples)))
            packets = np.arange(0, len(rays) + 1, n_pix, dtype=np.int32)
            depth = 0
            while len(rays):
                hits, counters = self.trace(rays, packets, timings=stats.stage_seconds, threads=1)
                stats.rays[depth] = stats.rays.get(depth, 0) + len(rays)
                stats.counters[depth] = stats.counters.get(depth, Counters()) + counters
                if tap is not None:
                    tap(Traced(tile, depth, False, rays, packets, hits, paths))
                clock.lap(None)
                bounce = self.shader.shade(self.scene, rays, hits, paths, depth, seed, radiance)
                clock.lap("shade")
                if not isinstance(bounce, Bounce):
                    raise PluginContractError(
                        f"shader {self.shader.name!r} broke its contract: shade() must return "
                        f"raysort.paths.Bounce, got {type(bounce).__name__}",
                        kind="shaders", name=self.shader.name)
                if bounce.shadow is not None and len(bounce.shadow.rays):
                    self._trace_shadows(bounce.shadow, packets, radiance, stats, tap, tile,
                                        depth)
                packets = np.searchsorted(bounce.parent, packets).astype(np.int32)
                paths = paths.take(bounce.parent, bounce.throughput)
                rays = bounce.rays
                depth += 1
        return radiance, stats

    def _trace_shadows(self, shadow, packets, radiance, stats, tap=None, tile=None, depth=0):
        boundaries = np.searchsorted(shadow.parent, packets).astype(np.int32)
        occluded, counters = self.trace(shadow.rays, boundaries, any_hit=True,
                                        timings=stats.stage_seconds, threads=1)
        if tap is not None:
            tap(Traced(tile, depth, True, shadow.rays, boundaries, occluded))
        stats.shadow_rays += len(shadow.rays)
        stats.shadow_counters = stats.shadow_counters + counters
        clock = _Clock(stats.stage_seconds)
        visible = ~occluded
        np.add.at(radiance, shadow.slot[visible], shadow.contribution[:, visible].T)
        clock.lap("shade")


def _both(first, second):
    """One tap that calls two."""
    def tap(record):
        first(record)
        second(record)
    return tap


def _trusted(cls):
    """Only raysort's own sorters that declare ``trusted = True`` themselves may skip
    the contract check; a subclass from elsewhere never inherits that trust."""
    return vars(cls).get("trusted") is True and cls.__module__.split(".")[0] == "raysort"


class _Clock:
    """Adds the time since the last lap to ``timings[stage]``."""

    __slots__ = ("timings", "last")

    def __init__(self, timings):
        self.timings = timings
        self.last = time.perf_counter()

    def lap(self, stage):
        now = time.perf_counter()
        if stage is not None and self.timings is not None:
            self.timings[stage] = self.timings.get(stage, 0.0) + now - self.last
        self.last = now
