"""``termination``: the two-point key with the previous bounce's hit distance as the
length estimate -- the REAL_RAY_LENGTH variant of the TWO_POINT key of Meister,
Bokšanský, Guthe and Bittner, "On Ray Reordering Techniques for Faster GPU Ray
Tracing", I3D 2020 (doi 10.1145/3384382.3384534), with the estimate a render has.

hippie's REAL_RAY_LENGTH uses the ray's own hit distance, known only after tracing
(an oracle).  Here a bounce ray's end point is estimated from the hit distance of
the ray its path continues (``RayBatch.prev_t``, set by the pipeline after
shading): rays bouncing inside one part of a scene tend to travel as far as the
rays that brought them there.  Where that distance is unknown (camera rays, shadow
rays, a batch made by hand, a miss) the key falls back to the two-point key's
fixed ``length``.  The key layout, clamps and sort are those of ``two_point``.
"""
from __future__ import annotations

from raysort.sdk import number
from raysort.sorters._keysort import scene_diagonal
from raysort.sorters.two_point import TwoPointSorter

__all__ = ["TerminationSorter"]


class TerminationSorter(TwoPointSorter):
    """Two-point key with the end point from the previous bounce's hit distance.

    ===========  ======  =======  ==========================================
    parameter    type    default  meaning
    ===========  ======  =======  ==========================================
    scale        float   1.0      the length estimate is ``scale`` times the
                                  previous bounce's hit distance
    length       float   0.25     fallback length where that is unknown, as
                                  a fraction of the scene box's diagonal
    bits         int     24       key bits sorted (the top ones), 1 .. 64
    packet_size  int     64       most rays per sub-packet (1 .. 4096)
    split_bits   int     0        also start a sub-packet where the key's
                                  top ``split_bits`` bits change (0: never)
    octant       bool    True     prefix the key with the direction's octant
                                  and never mix octants in a sub-packet
                                  (False: the paper's key alone)
    ===========  ======  =======  ==========================================
    """

    trusted = True

    def __init__(self, *, scale=1.0, length=0.25, bits=24, packet_size=64, split_bits=0,
                 octant=True):
        self.scale = number("scale", scale, 0)
        super().__init__(length=length, bits=bits, packet_size=packet_size,
                         split_bits=split_bits, octant=octant)

    def end_length(self, rays, bounds):
        return self.length * scene_diagonal(bounds), getattr(rays, "prev_t", None), self.scale
