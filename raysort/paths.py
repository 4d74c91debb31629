"""Per-path state carried from one bounce to the next, and what a shader returns."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from raysort.rays import RayBatch

__all__ = ["Paths", "Bounce", "ShadowRays"]


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
