"""Base classes of the four plugin kinds.

A plugin is a class registered under a name in one of the entry-point groups
``raysort.generators``, ``raysort.sorters``, ``raysort.traversals`` and
``raysort.shaders`` (or in-process with :func:`raysort.register`).  Its
parameters are the keyword arguments of its ``__init__``; it keeps each one as
an attribute of the same name, so :meth:`Plugin.params` can report them.  A
configuration that passes a parameter the ``__init__`` does not take is an
error (see :func:`raysort.registry.create`).

Every stage works on whole batches: a plugin method is called once for many
rays, never once per ray.
"""
from __future__ import annotations

import inspect

__all__ = ["Plugin", "Generator", "Sorter", "Traversal", "Shader", "KINDS"]


class Plugin:
    """Common behaviour: a name, parameters, and a readable repr."""

    #: entry-point group suffix, e.g. "sorters"
    kind = ""
    #: the registered name, set by the registry when the class is loaded
    name = ""
    #: raysort's own plugins set this to skip the checks of their results when
    #: ``Pipeline(check_plugins=False)``; it is not inherited and has no effect on
    #: plugins from other packages, which are always checked (raysort.contract)
    trusted = False

    @classmethod
    def parameter_names(cls):
        """Names of the keyword parameters ``__init__`` accepts."""
        sig = inspect.signature(cls.__init__)
        return [p.name for p in list(sig.parameters.values())[1:]
                if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)]

    def params(self):
        """The plugin's parameters and their current values."""
        return {name: getattr(self, name, None) for name in self.parameter_names()}

    def spec(self):
        """``name:key=value,...``: a spec string that recreates this plugin."""
        args = ",".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{self.name or type(self).__name__}{':' + args if args else ''}"

    def __repr__(self):
        args = ", ".join(f"{k}={v!r}" for k, v in self.params().items())
        return f"{type(self).__name__}({args})"


class Generator(Plugin):
    """Makes primary rays.

    ``generate`` must be deterministic for (seed, pixel, sample): the same
    inputs give bit-identical rays whatever else is in the batch.
    """

    kind = "generators"

    def generate(self, camera, pixels, samples, width, height, spp, seed):
        """Rays for every pixel of ``pixels`` and every sample of ``samples``.

        Parameters
        ----------
        camera : raysort.camera.Camera
        pixels : int32 array
            flat pixel indices ``y * width + x`` of one tile, in tile order.
        samples : int32 array
            sample indices, one pass each.
        width, height, spp, seed : int

        Returns
        -------
        raysort.rays.RayBatch
            ``len(samples) * len(pixels)`` rays, pass major: ray
            ``s * len(pixels) + p`` is sample ``samples[s]`` of ``pixels[p]``.
        """
        raise NotImplementedError


class Sorter(Plugin):
    """Orders rays into coherent sub-packets; never moves ray data itself.

    ``sort`` returns ``(order, offsets)``: ``order`` is an int32 permutation
    of ``range(len(rays))`` and ``offsets`` int32 sub-packet boundaries
    (``offsets[0] == 0``, strictly increasing, ``offsets[-1] == len(rays)``);
    sub-packet k is ``order[offsets[k]:offsets[k+1]]`` and its rays must all
    come from one large packet.  The framework checks this contract
    (:func:`raysort.contract.check_sort`).
    """

    kind = "sorters"

    def sort(self, rays, packets, bounds):
        """Order a batch.

        Parameters
        ----------
        rays : raysort.rays.RayBatch
        packets : int32 array
            large-packet boundaries ``[0, ..., len(rays)]``.
        bounds : float32 array (2, 3)
            the scene's bounding box (min, max).
        """
        raise NotImplementedError


class Traversal(Plugin):
    """Finds the closest hit (or any hit) of gathered sub-packets in a BVH.

    ``intersect`` writes into ``packets`` (``t``, ``prim``, ``u``, ``v``) and
    returns :class:`raysort.stats.Counters`.  It must return exactly the hits
    brute force returns (bitwise t; ties to the lower primitive index).
    """

    kind = "traversals"
    #: True when hits equal brute force bit for bit (every built-in).  An
    #: external library with its own triangle test (e.g. Embree) sets False:
    #: tests then compare its hits within a tolerance, and ``raysort bench``
    #: does not expect its image to be bit-identical.
    exact = True

    def intersect(self, bvh, packets, any_hit=False):
        """Trace every sub-packet; write hits into ``packets``; return Counters.

        ``bvh.vertices`` and ``bvh.faces`` give the mesh for traversals that
        build their own structure (cache it per ``bvh``).
        """
        raise NotImplementedError


class Shader(Plugin):
    """Turns hits into radiance and the next bounce's rays.

    It sees rays and hits in the order the generator made them (the framework
    scatters hits back), so no sorter can change the image.  ``shade`` may be
    called from several threads at once for different tiles.
    """

    kind = "shaders"

    def prepare(self, scene):
        """Precompute per-scene data once before a render (optional)."""

    def shade(self, scene, rays, hits, paths, depth, seed, radiance):
        """Add the radiance found at ``depth`` and return the next bounce.

        Parameters
        ----------
        scene : raysort.scene.Scene
        rays : raysort.rays.RayBatch;  hits : raysort.rays.Hits (same order)
        paths : raysort.paths.Paths (same order)
        depth : int, 0 for primary rays
        seed : int
        radiance : float64 (pixels, 3) accumulator of the tile, indexed by ``paths.slot``

        Returns
        -------
        raysort.paths.Bounce
        """
        raise NotImplementedError


KINDS = {cls.kind: cls for cls in (Generator, Sorter, Traversal, Shader)}
