"""Per-path state carried from one bounce to the next, and what a shader returns."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from raysort._gather import sample_paths
from raysort.orders import _FrozenPrefixes
from raysort.rays import RayBatch, _carve

__all__ = ["Paths", "Bounce", "ShadowRays", "unit_throughput"]

_ONES = _FrozenPrefixes(lambda size: np.ones(size, dtype=np.float32))


def unit_throughput(n):
    """A throughput of ones for ``n`` paths, float32 ``(3, n)``, C-contiguous and
    read-only, at no cost per call: a view of one block of immutable memory that grows,
    doubling, to the largest ``n`` asked for, as :func:`raysort.orders.identity_order`
    does for the identity order.  A generated batch's paths start with it, so a batch's
    throughput is neither written nor, read by a shader, fetched from far memory."""
    return _ONES.prefix(3 * n).reshape(3, n)


class Paths:
    """One entry per ray of the current batch (structure of arrays).

    ``pixel`` and ``sample`` key the random numbers; ``slot`` is the row of
    the tile's radiance accumulator the path adds to; ``throughput`` (3, n)
    is the path weight so far.
    """

    __slots__ = ("pixel", "sample", "slot", "throughput")

    def __init__(self, pixel, sample, slot, throughput=None):
        self.pixel = np.ascontiguousarray(pixel, dtype=np.int32)
        self.sample = np.ascontiguousarray(sample, dtype=np.int32)
        self.slot = np.ascontiguousarray(slot, dtype=np.int32)
        if throughput is None:
            throughput = np.ones((3, len(self.pixel)), dtype=np.float32)
        self.throughput = np.ascontiguousarray(throughput, dtype=np.float32)

    @classmethod
    def _of_samples(cls, pixels, slots, samples):
        """The paths of a batch that holds, sample by sample, a pass over ``pixels`` (int32,
        each with its accumulator row in ``slots``) for each of ``samples`` (int32): pixel,
        sample and slot written in one pass into one recycled block, whose pages are not
        faulted in again batch after batch, and :func:`unit_throughput` (a generator's
        batch, in the pipeline)."""
        n = len(pixels) * len(samples)
        paths = object.__new__(cls)
        paths.pixel, paths.sample, paths.slot = (a.view(np.int32)
                                                 for a in _carve(4 * n, 4 * n, 4 * n))
        paths.throughput = unit_throughput(n)
        sample_paths(pixels, slots, samples, paths.pixel, paths.sample, paths.slot)
        return paths

    def __len__(self):
        return len(self.pixel)

    def take(self, index, throughput=None):
        """The paths ``index`` (in that order), optionally with a new throughput."""
        return Paths(self.pixel[index], self.sample[index], self.slot[index],
                     self.throughput[:, index] if throughput is None else throughput)


@dataclass
class ShadowRays:
    """Shadow rays and what each adds to its path's slot when unoccluded."""

    rays: RayBatch
    parent: np.ndarray          # int32, index of the shaded ray each came from
    slot: np.ndarray            # int32, accumulator row
    contribution: np.ndarray    # float32 (3, m)


@dataclass
class Bounce:
    """A shader's output: the next rays (``parent`` = index of the ray each
    continues, ascending), their throughput, and optional shadow rays."""

    rays: RayBatch
    parent: np.ndarray
    throughput: np.ndarray
    shadow: ShadowRays | None = None
