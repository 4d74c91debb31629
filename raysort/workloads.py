"""Standard ray batches for benchmarks and tests: the ray kinds traversal studies measure.

Ray-tracing papers and libraries measure traversal on a standard set of ray kinds (Aila
and Laine 2009 and most ray-sorting work since).  :func:`workload` makes each of them::

    workload(scene, "primary")              # camera rays
    workload(scene, "ao:samples=4")         # ambient-occlusion rays of the primary hits
    workload(scene, "diffuse:depth=2")      # diffuse rays of the second bounce
    workload(scene, "shadow")               # shadow rays to the point lights

========  ==================  ==============================================  ========
kind      parameters          the rays                                        any-hit
========  ==================  ==============================================  ========
primary                       pinhole camera rays, jittered                   no
ao        samples, distance   the ``ao`` shader's rays from each primary hit  yes
diffuse   depth (1)           ``lambert``'s cosine-weighted rays of bounce    no
                              ``depth`` (1: the first bounce)
shadow    depth (0)           ``lambert``'s shadow rays to the scene's point  yes
                              lights from the hits of depth ``depth``
========  ==================  ==============================================  ========

Every workload is taken from a real render: :meth:`raysort.Pipeline.render` runs with a
``tap`` that keeps the rays of the wanted kind, so they come in exactly the large packets,
order and numbers a render makes (one tile sample pass per large packet, Morton order
inside a tile, a bounce's rays in their parents' large packet), and a sorter or traversal
measured on them sees what it sees inside a render.  Trace them the way the render does:
``pipe.trace(work.rays, work.packets, any_hit=work.any_hit)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Callable

import numpy as np

from raysort.errors import ConfigError
from raysort.params import integer
from raysort.paths import Paths
from raysort.pipeline import Pipeline
from raysort.rays import RayBatch
from raysort.registry import parse_spec

__all__ = ["Workload", "KINDS", "workload", "camera_rays", "bounce_rays"]


class Workload:
    """A ray batch with its large-packet boundaries, a label, and whether a render traces
    it as an any-hit (occlusion) query."""

    __slots__ = ("rays", "packets", "label", "any_hit")

    def __init__(self, rays, packets, label="", any_hit=False):
        self.rays, self.packets, self.label = rays, np.asarray(packets, np.int32), label
        self.any_hit = bool(any_hit)

    def __len__(self):
        return len(self.rays)

    def __repr__(self):
        return (f"Workload({self.label!r}, rays={len(self.rays)}, "
                f"packets={len(self.packets) - 1}, any_hit={self.any_hit})")


def _lambert(shadow_rays):
    """The lambert shader config of a render that reaches ``depth``."""
    return lambda params: {"type": "lambert", "max_depth": params.get("depth", 0),
                           "shadow_rays": shadow_rays}


def _ao(params):
    """The ao shader config, leaving unset parameters to the shader's defaults."""
    return {"type": "ao", **{k: v for k, v in params.items() if v is not None}}


@dataclass(frozen=True)
class Kind:
    """How one kind of workload is made: the shader of the render it is taken from, and
    which of the rays it traces are kept (closest-hit or any-hit rays, of which depth)."""

    name: str
    any_hit: bool
    shader: Callable                            # checked parameters -> shader config
    params: dict = field(default_factory=dict)  # parameter -> default (None: the shader's)
    min_depth: int = 0
    needs_lights: bool = False

    def check(self, spec, scene):
        """The parameters of ``spec`` (a dict from :func:`raysort.registry.parse_spec`)
        with defaults filled in; ConfigError naming what is wrong."""
        unknown = sorted(set(spec) - {"type"} - set(self.params))
        if unknown:
            takes = ", ".join(self.params) or "no parameters"
            raise ConfigError(f"workload {self.name!r} does not take {unknown[0]!r} "
                              f"(it takes: {takes})")
        params = {k: spec.get(k, default) for k, default in self.params.items()}
        if "depth" in params:
            params["depth"] = integer("depth", params["depth"], self.min_depth, 64)
        if self.needs_lights and not scene.lights:
            raise ConfigError(f"workload {self.name!r}: scene {scene.name!r} has no point "
                              f"lights to aim shadow rays at (a scene file adds them with "
                              f"[[light]])")
        return params


#: the workload kinds by name
KINDS = {k.name: k for k in (
    Kind("primary", False, _lambert(False)),
    Kind("ao", True, _ao, {"samples": None, "distance": None}),
    Kind("diffuse", False, _lambert(False), {"depth": 1}, min_depth=1),
    Kind("shadow", True, _lambert(True), {"depth": 0}, needs_lights=True),
)}


def workload(scene, kind, *, width=256, height=256, spp=1, seed=0, tile=32,
             generator="pinhole", threads=1):
    """The rays of one kind that a render of ``scene`` traces, as a :class:`Workload`.

    Parameters
    ----------
    scene : Scene
    kind : str or dict
        ``"primary"``, ``"ao"``, ``"diffuse"`` or ``"shadow"``, with parameters as
        ``"name:key=value,..."`` or a dict with a ``"type"`` key (see the module doc).
    width, height, spp, seed, tile : int
        the render the rays are taken from.
    generator : str or dict
        the primary-ray generator plugin.
    threads : int
        render threads; the workload is the same for any number.
    """
    return _collect(scene, kind, width=width, height=height, spp=spp, seed=seed, tile=tile,
                    generator=generator, threads=threads)[0]


def camera_rays(scene, width=256, height=256, spp=1, seed=0, tile=32, generator="pinhole"):
    """Primary rays of every tile and sample, one large packet per tile pass, and their
    :class:`~raysort.paths.Paths` (pixel, sample, tile slot)."""
    work, records = _collect(scene, "primary", width=width, height=height, spp=spp,
                             seed=seed, tile=tile, generator=generator)
    return work, Paths(*(np.concatenate([getattr(r.paths, f) for r in records])
                         for f in ("pixel", "sample", "slot")))


def bounce_rays(scene, width=256, height=256, spp=1, seed=0, depth=1, tile=32):
    """Diffuse rays of bounce ``depth`` (1 = first bounce), large packets as in a render."""
    return workload(scene, {"type": "diffuse", "depth": depth}, width=width, height=height,
                    spp=spp, seed=seed, tile=tile)


def check_kind(kind):
    """``kind`` (a name, ``"name:key=value,..."`` or a dict with a ``"type"``) as a spec
    dict whose kind exists; ConfigError otherwise.  Its parameters are checked against a
    scene when its rays are made."""
    spec = dict(kind) if isinstance(kind, dict) else parse_spec(str(kind))
    name = spec.get("type")
    if name not in KINDS:
        raise ConfigError(f"unknown workload kind {name!r}; kinds: {', '.join(KINDS)}")
    return spec


def _collect(scene, kind, *, width, height, spp, seed, tile, generator="pinhole", threads=1):
    """Render with a tap; returns the workload and the render's records it was made of."""
    spec = check_kind(kind)
    name = spec["type"]
    k = KINDS[name]
    params = k.check(spec, scene)
    depth = params.get("depth", 0)
    pipe = Pipeline(scene, generator=generator, sorter="none", shader=k.shader(params),
                    tile=tile, threads=threads)
    kept = []

    def tap(record):
        if record.shadow == k.any_hit and record.depth == depth:
            kept.append(record)

    pipe.render(width, height, spp, seed, tap=tap)
    # tiles in image order (rows of tiles, top to bottom), each tile's records in the
    # order it traced them: the same list whichever thread traced which tile
    kept.sort(key=lambda r: (r.tile[1], r.tile[0]))
    starts = np.cumsum([0] + [len(r.rays) for r in kept], dtype=np.int64)
    packets = np.concatenate([[0]] + [r.packets[1:] + s for r, s in zip(kept, starts)])
    given = ",".join(f"{p}={v}" for p, v in params.items() if v is not None)
    label = f"{scene.name} {name}" + (f":{given}" if given else "")
    return Workload(_concat([r.rays for r in kept]), packets, label, k.any_hit), kept


def _concat(batches):
    out = RayBatch(sum(len(b) for b in batches))
    if batches:
        out.data[:, :len(out)] = np.concatenate([b.data[:, :len(b)] for b in batches], axis=1)
        if all(b.prev_t is not None for b in batches):
            out.prev_t = np.concatenate([b.prev_t for b in batches])
    return out
