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
  bounded by the batch, never by image size x spp.  When one tile's passes
  are fewer rays than that (low spp), runs of tiles share batches
  (:meth:`Pipeline._tile_groups`): fewer, larger batches, the same pixels.
* Tiles are spread over ``threads`` worker threads (all kernels release the
  GIL), or over the workers of a Dask cluster (:mod:`raysort.distributed`).
  A tile accumulates its radiance in its own buffer in a fixed order
  (batch, bounce, ray index), and hits are scattered back to generation
  order before shading, so the image is bit-identical for every sorter,
  traversal and thread count at a fixed seed.
"""
from __future__ import annotations

import functools
import inspect
import operator
import os
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np

from raysort import contract, isa, registry
from raysort._gather import follow_paths as _follow_paths
from raysort.bvh import BVH
from raysort.errors import ConfigError
from raysort.orders import is_identity_order
from raysort.params import boolean, integer
from raysort.paths import Paths
from raysort.progress import with_rays
from raysort.rays import (MAX_PACKET, MAX_RAYS, Hits, RayBatch, add_unoccluded, gather_checked,
                          scatter_checked)
from raysort.scene import Scene, load_scene
from raysort.stats import Counters

__all__ = ["Pipeline", "RenderResult", "RenderStats", "Traced", "STAGES", "morton_order",
           "default_traversal"]

#: the stages a render's CPU time is split into, in pipeline order ("check": the contract
#: checks; "other": the bookkeeping between the stages: the batches' set-up, the counters'
#: running totals, the tiles put into the image)
STAGES = ("generate", "sort", "check", "gather", "traverse", "scatter", "shade", "other")
#: most random-number seeds: the counter-based generator keys on 32 bits
MAX_SEED = 2**32 - 1
#: pixel indices are int32
MAX_PIXELS = 2**31 - 1
#: a frame's tiles make at least this many runs that share batches (while there are
#: tiles enough), whatever ``batch_rays`` (``Pipeline._tile_groups``)
MIN_RUNS = 16
#: a path still bouncing after this many bounces means a shader that never ends its paths
MAX_BOUNCES = 1024
_BVH_PARAMETERS = tuple(p.name for p in inspect.signature(BVH).parameters.values()
                        if p.kind == p.KEYWORD_ONLY)


@functools.lru_cache(maxsize=16)
def morton_order(width, height):
    """Local pixel indices ``y * width + x`` of a tile, in Morton (Z) order (a read-only
    array, made once per tile size)."""
    y, x = np.divmod(np.arange(width * height, dtype=np.int64), width)
    code = np.zeros_like(x)
    for bit in range(7):
        code |= ((x >> bit) & 1) << (2 * bit) | ((y >> bit) & 1) << (2 * bit + 1)
    order = np.argsort(code, kind="stable").astype(np.int32)
    order.setflags(write=False)
    return order


@functools.lru_cache(maxsize=16)
def _tile_pixels(width, height, image_width):
    """The pixel indices of a tile at the image's origin, in :func:`morton_order` (add the
    index of the tile's corner for the others; read-only, made once per tile shape)."""
    local = morton_order(width, height)
    pixels = (local // width * image_width + local % width).astype(np.int32)
    pixels.setflags(write=False)
    return pixels


@dataclass
class RenderStats:
    """Where the time went and how much work the traversal did.

    ``stage_seconds`` are the CPU seconds of each stage (thread CPU time, summed
    over worker threads, so a thread waiting for the GIL or a core costs nothing;
    ``shade`` includes the paths' bookkeeping after the shader: the next packets,
    the paths taken, adding the unoccluded shadow rays; ``other`` is the rest of
    the render's CPU time: setting up batches, adding up counters, putting tiles
    into the image), so together they are all of a render's CPU time but its set-up
    (the BVH, the shader's ``prepare``);
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
            total = self.depth_counters(d)
            total += c
        self.shadow_rays += other.shadow_rays
        self.shadow_counters += other.shadow_counters

    def depth_counters(self, depth):
        """The running total of the counters of ``depth`` (created at 0)."""
        total = self.counters.get(depth)
        if total is None:
            total = self.counters[depth] = Counters()
        return total

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

    def write(self, path, *, png=True, exposure=0.0, sidecars=None):
        """Write the EXR (and a PNG preview next to it, of the same render); each file appears
        whole or not at all (see :func:`raysort.output.write_render`).  AOV layers go into
        the EXR as extra named channels (``depth.Z``, ``normal.X``, ...).  ``sidecars``
        (path -> text, e.g. the settings as JSON) are written with the EXR, all or none."""
        from raysort import output

        path = os.fspath(path)
        if not path.lower().endswith(".exr"):
            if sidecars:
                raise ValueError("RenderResult.write: sidecars are written with an .exr")
            return output.write_image(path, self.image, exposure=exposure)
        meta = {f"raysort.{k}": str(v) for k, v in self.settings.items()}
        from raysort.aov import exr_channels

        output.write_render(path, self.image, metadata=meta, exposure=exposure, png=png,
                            channels=exr_channels(self.aov), sidecars=sidecars)


class Pipeline:
    """generate -> sort -> gather -> traverse -> scatter -> shade, with plugins.

    Parameters
    ----------
    scene : Scene, or a scene name / path (see :func:`raysort.scene.load_scene`)
    generator, sorter, traversal, shader : str or dict or plugin instance
        a plugin name (``"nah"``), a spec (``"none:packet_size=1024"``) or a
        dict with a ``"type"`` key and parameters.  The defaults are the fastest
        exact combination measured (BENCHMARKS.md §1, §7): sorter ``none`` and
        traversal :func:`default_traversal` (``stream`` with AVX2 or AVX-512,
        ``wide8`` otherwise); the paper's method is ``sorter="nah",
        traversal="ranged"``.
    tile : int, default 32
        tile edge in pixels; one sample pass over a tile is a large packet.
    threads : int, default 1
        worker threads (tiles are shared out; the image does not change).
    batch_rays : int, default 131072
        about how many rays a worker keeps in flight (memory bound); fewer when a
        frame's tiles would otherwise make fewer than ``MIN_RUNS`` runs of tiles.
    check_plugins : bool, default True
        check every plugin result against its contract (:mod:`raysort.contract`);
        False skips the checks for raysort's own plugins marked trusted (plugins
        from other packages are always checked).
    bvh : dict, optional
        BVH build parameters (``preset``: ``"default"`` or ``"manta"`` for the paper's
        big leaves; ``max_leaf``, ``bins``, ``traversal_cost``; ``spatial_splits`` and
        ``split_alpha`` for an SBVH), see :class:`BVH`.
    """

    def __init__(self, scene=None, *, generator="pinhole", sorter="none", traversal=None,
                 shader="lambert", tile=32, threads=1, batch_rays=131072, check_plugins=True,
                 bvh=None):
        if not (scene is None or isinstance(scene, (Scene, str, os.PathLike))):
            raise ConfigError(f"scene must be a Scene, a packaged scene name or a path to a "
                              f".toml scene or mesh file, got {scene!r}")
        if not (bvh is None or isinstance(bvh, dict)):
            raise ConfigError(f"bvh must be a dict of BVH parameters, got {bvh!r}")
        unread = sorted(set(bvh or {}) - set(_BVH_PARAMETERS))
        if unread:
            raise ConfigError(f"bvh: unknown parameter {unread[0]!r} (BVH takes: "
                              f"{', '.join(_BVH_PARAMETERS)})")
        self.scene = scene if isinstance(scene, Scene) else load_scene(scene)
        self.generator = registry.create("generators", generator)
        self.sorter = registry.create("sorters", sorter)
        self.traversal = registry.create("traversals", default_traversal() if traversal is None
                                         else traversal)
        self.shader = registry.create("shaders", shader)
        self.tile = integer("tile", tile, 1, 64)
        self.threads = integer("threads", threads, 1)
        self.batch_rays = integer("batch_rays", batch_rays, 1, MAX_RAYS)
        self.check_plugins = boolean("check_plugins", check_plugins)
        self.bvh_params = dict(bvh or {})
        self._bvh = None

    # ------------------------------------------------------------------
    @property
    def bvh(self):
        if self._bvh is None:
            self._bvh = self.scene.bvh(**self.bvh_params)
        return self._bvh

    def _checked(self, plugin):
        """Whether the results of ``plugin`` are checked (always, unless trusted and
        ``check_plugins`` is off)."""
        return self.check_plugins or not _trusted(type(plugin))

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
        rays = contract.check_ray_batch(rays)
        n = len(rays)
        any_hit = boolean("any_hit", any_hit)
        threads = self.threads if threads is None else integer("threads", threads, 1)
        if not (timings is None or isinstance(timings, dict)):
            raise ConfigError(f"timings must be a dict or None, got {type(timings).__name__}")
        if packets is None:
            packets = np.append(np.arange(0, n, self.tile * self.tile), n)
        packets = contract.check_packets(packets, n)
        return self._trace(rays, packets, any_hit, timings, threads)

    def _trace(self, rays, packets, any_hit, timings, threads, maker=None):
        """:meth:`trace` of checked arguments.  ``maker``, ``(kind, plugin, label)``,
        names the plugin whose rays these are, which the ray contract then binds; a
        caller's rays may be anything (a ray that is not finite is invalid).

        The checks of the sorter's result, the rays and the traversal's hits run inside
        the gather and the scatter, which read those arrays anyway;
        :mod:`raysort.contract` is called only to say what is wrong."""
        n = len(rays)
        clock = _Clock(timings)
        if n == 0:
            return (np.zeros(0, bool) if any_hit else Hits(0)), Counters()
        result = contract.call_plugin("sorters", self.sorter, "sort", rays, packets.copy(),
                                      self.bvh.bounds.copy())
        clock.lap("sort")
        check_sort = self._checked(self.sorter)
        order, offsets = contract.sort_arrays(self.sorter, result, n) if check_sort else result
        clock.lap("check")
        if self._reads_batch():
            out, counters, bad_ray = self._trace_batch(rays, order, offsets, packets, any_hit,
                                                       check_sort, clock, timings, threads)
            if out is None:
                contract.check_sort(self.sorter, result, n, packets)
                raise AssertionError("the traversal rejected a sort result that check_sort "
                                     "passes")
            self._check_maker(maker, rays, bad_ray)
            return out, counters
        check_hits = self._checked(self.traversal)
        batch, tmax, bad_ray = gather_checked(rays, order, offsets, packets,
                                              keep_tmax=check_hits and not any_hit,
                                              check_order=check_sort)
        clock.lap("gather")
        if batch is None:
            contract.check_sort(self.sorter, result, n, packets)
            raise AssertionError("the gather rejected a sort result that check_sort passes")
        self._check_maker(maker, rays, bad_ray)
        arrays = contract.packet_arrays(batch) if check_hits else None
        counters = self._intersect(batch, any_hit, threads, timings)
        clock.lap("traverse")
        if check_hits and not all(map(operator.is_, contract.packet_arrays(batch), arrays)):
            contract.check_packet_arrays(self.traversal, batch, arrays)     # names it
        out, fault = scatter_checked(batch, order, offsets, tmax, len(self.bvh.faces), any_hit,
                                     check_hits=check_hits, check_order=check_sort)
        clock.lap("scatter")
        if fault == "hits":
            contract.check_hits(self.traversal, batch, (arrays or contract.packet_arrays(batch),
                                                        batch.t if tmax is None else tmax),
                                order, offsets, len(self.bvh.faces), any_hit)
            raise AssertionError("the scatter rejected hits that check_hits passes")
        if fault == "order":
            contract.check_sort(self.sorter, result, n, packets)
            raise AssertionError("the scatter left out a ray of an order check_sort passes")
        return out, counters

    def _check_maker(self, maker, rays, bad_ray):
        """Name the plugin whose ray ``bad_ray`` (-1: none) the gather found invalid."""
        if bad_ray >= 0 and maker is not None and self._checked(maker[1]):
            kind, plugin, label = maker
            contract.check_rays(kind, plugin, rays, label)
            raise AssertionError(f"the gather rejected ray {bad_ray}, which check_rays passes")

    def _reads_batch(self):
        """Whether the traversal reads the rays from the batch itself (raysort's own
        ``stream``: ``_intersect_batch``) rather than from gathered packets."""
        return (_trusted(type(self.traversal)) and len(self.bvh.triangles) > 0
                and hasattr(self.traversal, "_intersect_batch"))

    def _trace_batch(self, rays, order, offsets, packets, any_hit, check_sort, clock, timings,
                     threads):
        """:meth:`_trace` for a traversal that reads the batch in the sorter's order and
        writes the hits in batch order itself: no packets, no gather and no scatter (its
        own copy of each ray is the gather).  The sorter's result is checked first
        (unless trusted); the traversal checks each hit as it writes it.  Returns
        ``(hits, counters, bad_ray)``, or None for hits if the order is not valid."""
        n = len(rays)
        if check_sort and isa.module("_contract").sort_result(
                order, offsets, packets, n, MAX_PACKET, is_identity_order(order))[0]:
            return None, None, -1
        out = np.empty(n, np.uint8) if any_hit else np.empty((4, n), np.float32)
        clock.lap("check")

        def run(k0, k1):
            return contract.call_plugin("traversals", self.traversal, "_intersect_batch",
                                        self.bvh, rays.data, order, offsets, k0, k1, any_hit,
                                        out)

        parts = _in_threads(run, len(offsets) - 1, threads, timings)
        hits = out.view(bool) if any_hit else Hits._of_block(out)
        counters, bad = Counters(), []
        for part, bad_ray, bad_hit, order_ok in parts:
            if not order_ok:                    # an entry outside [0, n)
                return None, None, -1
            if bad_hit >= 0:
                contract.batch_hit_fault(self.traversal, rays, hits, len(self.bvh.faces),
                                         bad_hit)
            counters += contract.check_counters(self.traversal, part)
            if bad_ray >= 0:
                bad.append(bad_ray)
        clock.lap("traverse")
        return hits, counters, min(bad, default=-1)

    def _intersect(self, batch, any_hit, threads=1, timings=None):
        def run(k0, k1):
            part = batch if (k0, k1) == (0, batch.n_packets) else batch.slice(k0, k1)
            return contract.call_plugin("traversals", self.traversal, "intersect", self.bvh,
                                        part, any_hit)

        total = Counters()
        for counters in _in_threads(run, batch.n_packets, threads, timings):
            total += contract.check_counters(self.traversal, counters)
        return total

    # ------------------------------------------------------------------
    def render(self, width=256, height=256, spp=4, seed=0, *, progress=None, aov=(),
               tap=None, client=None):
        """Render the scene's camera view; returns a :class:`RenderResult`.

        ``progress(done_tiles, total_tiles)`` is called as tiles finish, with
        ``rays=`` the rays traced so far if it takes a ``rays`` argument.  ``aov`` names
        layers taken from each pixel's first primary hit (``depth``, ``normal``,
        ``albedo``, ``prim``; see :mod:`raysort.aov`) into ``result.aov``.
        ``tap(record)`` is called with a :class:`Traced` record for every batch of rays
        the render traces (from the worker threads when ``threads > 1``): the rays of a
        real render, e.g. for :mod:`raysort.workloads`.
        ``client``, a ``dask.distributed.Client``, renders the tiles as tasks on its
        workers instead of local threads (``threads`` does not apply; see
        :mod:`raysort.distributed`); the image is the same, bit for bit.  ``aov`` and
        ``tap`` need the rays in this process and are not available with ``client``.
        """
        width, height = integer("width", width, 1), integer("height", height, 1)
        spp, seed = integer("spp", spp, 1, MAX_RAYS), integer("seed", seed, 0, MAX_SEED)
        if not (progress is None or callable(progress)):
            raise ConfigError(f"progress must be a callable or None, got {progress!r}")
        _check_image_size(width, height)
        if client is not None and (aov or tap is not None):
            raise ConfigError("aov layers and tap need the rays in this process; they are not "
                              "available with client= (render locally for them)")
        collector = None
        if aov:
            from raysort.aov import AovCollector

            collector = AovCollector(aov, self.scene, width, height)
            tap = collector if tap is None else _both(collector, tap)
        start = time.perf_counter()
        tiles = [(x, y) for y in range(0, height, self.tile) for x in range(0, width, self.tile)]
        image = np.zeros((height, width, 3), dtype=np.float32)
        stats = RenderStats(threads=self.threads)
        progress = with_rays(progress, lambda: stats.total_rays)

        def finish(tile, result):
            started = time.thread_time()
            radiance, tile_stats = result
            x0, y0 = tile
            w, h = min(self.tile, width - x0), min(self.tile, height - y0)
            # the float64 mean rounded to float32, written in place
            np.divide(radiance.reshape(h, w, 3), spp, out=image[y0:y0 + h, x0:x0 + w],
                      casting="unsafe")
            if tile_stats is not None:
                stats.merge(tile_stats)
            stats.stage_seconds["other"] += time.thread_time() - started

        if client is not None:
            from raysort import distributed

            stats.threads = distributed.worker_threads(client)
            finished = distributed.render_tiles(self, client, self._tile_groups(tiles, spp),
                                                width, height, spp, seed)
        else:
            self.bvh  # noqa: B018 (build before the workers start)
            contract.call_plugin("shaders", self.shader, "prepare", self.scene)
            finished = self._local_tiles(self._tile_groups(tiles, spp, join=tap is None),
                                         width, height, spp, seed, tap)
        try:
            for done, (tile, result) in enumerate(finished, 1):
                finish(tile, result)
                if progress:
                    progress(done, len(tiles))
        finally:
            finished.close()
        stats.wall_seconds = time.perf_counter() - start
        # what determines the image (not how it was computed: threads live in stats)
        settings = dict(self.describe(), scene=self.scene.name, width=width, height=height,
                        spp=spp, seed=seed, tile=self.tile)
        return RenderResult(image, stats, settings, collector.layers() if collector else {})

    def _local_tiles(self, groups, width, height, spp, seed, tap=None):
        """``(tile, (radiance, stats))`` as the tiles of ``groups`` (see
        :meth:`_tile_groups`) finish on this process's threads."""
        if self.threads == 1:
            for group in groups:
                yield from self._render_tiles(group, width, height, spp, seed, tap)
            return
        with ThreadPoolExecutor(max_workers=self.threads) as pool:
            futures = [pool.submit(self._render_tiles, group, width, height, spp, seed, tap)
                       for group in groups]
            try:
                for future in as_completed(futures):
                    yield from future.result()
            finally:  # an error, or the caller stopped early: start no more tiles
                for f in futures:
                    f.cancel()

    def _tile_groups(self, tiles, spp, join=True):
        """``tiles`` in runs that share batches: at low spp one tile's passes make a
        small batch (the default 32x32 tiles at 4 spp: 4,096 rays), and every batch
        costs the same Python calls between the kernels, which hold the GIL; so as
        many tiles as their passes fill ``batch_rays`` are rendered together, but no
        more than leave ``MIN_RUNS`` runs, so that threads and Dask workers share a
        small frame.  The runs depend only on the frame and the pipeline, never on
        threads or workers (the traversal's counters depend on the batches).  ``join``
        False: one tile per run (a ``tap`` sees one tile per record)."""
        per_group = min(self.batch_rays // (self.tile * self.tile * spp),
                        -(-len(tiles) // MIN_RUNS))
        per_group = max(1, per_group) if join else 1
        return [tiles[i:i + per_group] for i in range(0, len(tiles), per_group)]

    def _render_tiles(self, group, width, height, spp, seed, tap=None):
        """Render the tiles of ``group`` in shared batches: ``[(tile, (radiance, stats))]``,
        ``radiance`` the tile's float64 sum of samples (row-major pixels); the group's
        stats go with its first tile, the others get None.

        A batch holds, sample by sample, each tile's pass (one large packet); every
        pixel's rays, random numbers and additions to its radiance are the same, in the
        same order, as when its tile is rendered alone, so the image does not depend
        on the grouping."""
        started = time.thread_time()
        starts, pixels, slots = [0], [], []
        for x0, y0 in group:
            w, h = min(self.tile, width - x0), min(self.tile, height - y0)
            pixels.append(_tile_pixels(w, h, width) + np.int32(y0 * width + x0))
            # accumulator rows: the tile's pixels after the tiles before it, row-major
            slots.append(morton_order(w, h) + np.int32(starts[-1]))
            starts.append(starts[-1] + w * h)
        pixels = np.concatenate(pixels) if len(group) > 1 else pixels[0]
        slots = np.concatenate(slots) if len(group) > 1 else slots[0]
        starts = np.asarray(starts[:-1], dtype=np.int32)
        n_pix = len(pixels)
        radiance = np.zeros((n_pix, 3), dtype=np.float64)
        tile = group[0]                 # the tile a tap's records name (a group of one then)
        stats = RenderStats()
        clock = _Clock(stats.stage_seconds)
        per_batch = max(1, self.batch_rays // n_pix)
        for s0 in range(0, spp, per_batch):
            samples = np.arange(s0, min(spp, s0 + per_batch), dtype=np.int32)
            clock.lap(None)
            rays = contract.call_plugin("generators", self.generator, "generate",
                                        self.scene.camera, pixels.copy(), samples.copy(), width,
                                        height, spp, seed)
            clock.lap("generate")
            if self._checked(self.generator):
                contract.check_generated(self.generator, rays, n_pix * len(samples),
                                         with_rays=False)     # the gather checks them
                clock.lap("check")
            paths = Paths._of_samples(pixels, slots, samples)
            packets = np.append((np.arange(0, len(rays), n_pix, dtype=np.int32)[:, None]
                                 + starts).ravel(), np.int32(len(rays)))
            depth, maker = 0, ("generators", self.generator, "generate() result")
            while len(rays):
                hits, counters = self._trace(rays, packets, False, stats.stage_seconds, 1, maker)
                stats.rays[depth] = stats.rays.get(depth, 0) + len(rays)
                total = stats.depth_counters(depth)
                total += counters
                if tap is not None:     # its own packets: the next bounce's come from these
                    tap(Traced(tile, depth, False, rays, packets.copy(), hits, paths))
                clock.lap(None)
                bounce = contract.call_plugin("shaders", self.shader, "shade", self.scene, rays,
                                              hits, paths, depth, seed, radiance)
                clock.lap("shade")
                if self._checked(self.shader):     # the rays: the gather checks them
                    bounce = contract.check_bounce(self.shader, bounce, len(rays), n_pix,
                                                   radiance, with_rays=False,
                                                   with_paths=not _checks_its_paths(self.shader))
                    clock.lap("check")
                if bounce.shadow is not None and len(bounce.shadow.rays):
                    self._trace_shadows(bounce.shadow, packets, radiance, stats, tap, tile,
                                        depth)
                clock.lap(None)             # the shadow rays' stages timed themselves
                packets = np.searchsorted(bounce.parent, packets).astype(np.int32)
                pixel, sample, slot, last_t = _follow_paths(
                    np.ascontiguousarray(bounce.parent, dtype=np.int32), paths.pixel,
                    paths.sample, paths.slot, hits.t)
                paths = Paths(pixel, sample, slot, bounce.throughput)
                rays, maker = bounce.rays, ("shaders", self.shader, "Bounce.rays")
                if rays.prev_t is None:     # each path's last hit distance, for sorters
                    rays.prev_t = last_t
                clock.lap("shade")          # the paths' bookkeeping counts as shading
                depth += 1
                if depth > MAX_BOUNCES and len(rays):
                    raise contract.plugin_error("shaders", self.shader, f"shade() still returns "
                                                f"rays after {MAX_BOUNCES} bounces")
        # the call's CPU time that no stage took is the bookkeeping between them
        seconds = stats.stage_seconds
        seconds["other"] += max(0.0, time.thread_time() - started - sum(seconds.values()))
        if len(group) == 1:
            return [(tile, (radiance, stats))]
        return [(t, (radiance[a:b], stats if i == 0 else None))
                for i, (t, a, b) in enumerate(zip(group, starts, [*starts[1:], n_pix]))]

    def _trace_shadows(self, shadow, packets, radiance, stats, tap=None, tile=None, depth=0):
        boundaries = np.searchsorted(shadow.parent, packets).astype(np.int32)
        occluded, counters = self._trace(shadow.rays, boundaries, True, stats.stage_seconds, 1,
                                         ("shaders", self.shader, "ShadowRays.rays"))
        if tap is not None:
            tap(Traced(tile, depth, True, shadow.rays, boundaries, occluded))
        stats.shadow_rays += len(shadow.rays)
        stats.shadow_counters += counters
        clock = _Clock(stats.stage_seconds)
        add_unoccluded(radiance, shadow.slot, shadow.contribution, occluded)
        clock.lap("shade")


def _in_threads(run, m, threads, timings):
    """``[run(k0, k1), ...]`` over ``[0, m)`` (sub-packets) cut into ``threads`` parts, run
    in that many threads (one part, in this thread, when ``threads`` or ``m`` is 1).  The
    workers' thread CPU is added to ``timings["traverse"]`` (the caller only waited)."""
    workers = max(1, min(threads, m))
    if workers == 1:
        return [run(0, m)]

    def timed(k0, k1):
        start = time.thread_time()
        return run(k0, k1), time.thread_time() - start

    cuts = [m * j // workers for j in range(workers + 1)]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(timed, cuts[:-1], cuts[1:]))
    if timings is not None:
        timings["traverse"] = timings.get("traverse", 0.0) + sum(s for _, s in results)
    return [result for result, _ in results]


def default_traversal():
    """The fastest exact traversal measured for the active ISA: ``stream`` where a
    stream test covers 8 or 16 rays (AVX2, AVX-512 and its emulation), ``wide8`` on SSE2
    and the scalar build, where ``stream`` is slower (BENCHMARKS.md §7).  Images do not
    depend on it."""
    return "wide8" if isa.active() in ("scalar", "sse2") else "stream"


def _both(first, second):
    """One tap that calls two."""
    def tap(record):
        first(record)
        second(record)
    return tap


def _trusted(cls):
    """Only raysort's own plugins that declare ``trusted = True`` themselves may skip
    the contract checks; a subclass from elsewhere never inherits that trust."""
    return vars(cls).get("trusted") is True and cls.__module__.split(".")[0] == "raysort"


def _checks_its_paths(shader):
    """Whether ``shader`` is one of raysort's own that checks the parents, weights and
    slots of the paths it makes as it writes them (``lambert``), by the rules of
    :func:`raysort.contract.check_bounce`, which need then not read them again."""
    return _trusted(type(shader)) and vars(type(shader)).get("_checks_its_paths") is True


def _check_image_size(width, height):
    """ConfigError, before anything is allocated, for an image whose pixel indices
    overflow int32 or whose float32 RGB buffer exceeds the machine's memory."""
    if width * height > MAX_PIXELS:
        raise ConfigError(f"an image of {width}x{height} has more than {MAX_PIXELS} pixels "
                          f"(pixel indices are int32)")
    need = width * height * 3 * np.dtype(np.float32).itemsize
    try:
        have = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):   # not on this platform
        return
    if need > have:
        raise ConfigError(f"an image of {width}x{height} needs {need / 2**30:.3g} GiB for its "
                          f"float32 RGB buffer, more than this machine's "
                          f"{have / 2**30:.3g} GiB of memory")


class _Clock:
    """Adds the calling thread's CPU time since the last lap to ``timings[stage]``."""

    __slots__ = ("timings", "last")

    def __init__(self, timings):
        self.timings = timings
        self.last = time.thread_time()

    def lap(self, stage):
        now = time.thread_time()
        if stage is not None and self.timings is not None:
            self.timings[stage] = self.timings.get(stage, 0.0) + now - self.last
        self.last = now
