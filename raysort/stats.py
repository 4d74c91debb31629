"""Work counters (the paper's Table I) and per-stage timings."""
from __future__ import annotations

import itertools
import operator
from dataclasses import dataclass, fields, replace

__all__ = ["Counters", "COUNTER_LABELS"]

#: Table I names of the counters, in the paper's order.
COUNTER_LABELS = {
    "ia": "N_IA",
    "box1": "scalar N_B",
    "box4": "SIMD N_B",
    "tri1": "scalar N_T",
    "tri4": "SIMD N_T",
}


@dataclass
class Counters:
    """Tests performed by a traversal, summed over a call or a render.

    ``rays`` is the number of (active) rays submitted; a SIMD test is one
    test of the traversal's width (4 lanes, or 8 in ``wide8``) whatever its
    active lanes.  ``available`` is False for
    traversals that cannot count (e.g. an external library).
    ``stream_tasks`` and ``stream_rays`` count the streams of rays a stream
    traversal visited nodes with and the rays they held (0 for the others):
    ``stream_rays / stream_tasks`` is the mean stream size.
    ``stream_level_rays`` splits ``stream_rays`` by the depth in the tree of
    the box each stream was popped at: entry ``d`` is the rays that entered
    boxes of level ``d`` together (0: the root; as long as the deepest level
    reached, ``()`` for the others); tuples of different lengths add up
    entry by entry.
    """

    rays: int = 0
    ia: int = 0
    box1: int = 0
    box4: int = 0
    tri1: int = 0
    tri4: int = 0
    stream_tasks: int = 0
    stream_rays: int = 0
    available: bool = True
    stream_level_rays: tuple = ()

    def __add__(self, other):
        if not isinstance(other, Counters):
            return NotImplemented
        out = replace(self)
        out += other
        return out

    def __iadd__(self, other):
        """Add ``other`` into this object (for a caller's own running total: one
        object per render, not one per batch)."""
        if not isinstance(other, Counters):
            return NotImplemented
        mine, theirs = self.__dict__, other.__dict__     # plain dataclass fields
        for name in WHOLE_NUMBERS:
            mine[name] += theirs[name]
        if other.stream_level_rays:
            self.stream_level_rays = _add_levels(self.stream_level_rays,
                                                 other.stream_level_rays)
        self.available = self.available and other.available
        return self

    def per_ray(self):
        """Each counter divided by the rays submitted (None when not available)."""
        if not self.available:
            return {key: None for key in COUNTER_LABELS}
        rays = max(self.rays, 1)
        return {key: getattr(self, key) / rays for key in COUNTER_LABELS}

    def as_dict(self):
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["stream_level_rays"] = list(self.stream_level_rays)
        return out


# the counters that are one whole number each (the rest: ``available``, ``stream_level_rays``)
WHOLE_NUMBERS = tuple(f.name for f in fields(Counters)
                      if f.name not in ("available", "stream_level_rays"))


def _add_levels(a, b):
    """Entry-by-entry sum of two per-level tuples, the shorter padded with zeros."""
    if len(a) == len(b):
        return tuple(map(operator.add, a, b))
    return tuple(x + y for x, y in itertools.zip_longest(a, b, fillvalue=0))
