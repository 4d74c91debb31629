"""Work counters (the paper's Table I) and per-stage timings."""
from __future__ import annotations

from dataclasses import dataclass, fields

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
    4-wide test whatever its active lanes.  ``available`` is False for
    traversals that cannot count (e.g. an external library).
    ``stream_tasks`` and ``stream_rays`` count the streams of rays a stream
    traversal visited nodes with and the rays they held (0 for the others):
    ``stream_rays / stream_tasks`` is the mean stream size.
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

    def __add__(self, other):
        if not isinstance(other, Counters):
            return NotImplemented
        out = Counters(**{f.name: getattr(self, f.name) + getattr(other, f.name)
                          for f in fields(self) if f.name != "available"})
        out.available = self.available and other.available
        return out

    def per_ray(self):
        """Each counter divided by the rays submitted (None when not available)."""
        if not self.available:
            return {key: None for key in COUNTER_LABELS}
        rays = max(self.rays, 1)
        return {key: getattr(self, key) / rays for key in COUNTER_LABELS}

    def as_dict(self):
        return {f.name: getattr(self, f.name) for f in fields(self)}
