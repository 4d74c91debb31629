"""``two_point``: the two-point key of Meister, Bokšanský, Guthe and Bittner, "On Ray
Reordering Techniques for Faster GPU Ray Tracing", I3D 2020 (doi
10.1145/3384382.3384534; the TWO_POINT kernel of their hippie framework).

A ray is described by two points: its origin ``a = o`` and an estimated end point
``b = o + L * d / |d|``, both normalised to the scene box.  The key is the 6-D Morton
code of ``ax ay az bx by bz``, so rays that start *and* end close together sort
together even when their directions differ a little.  The length ``L`` is
``length`` times the scene box's diagonal, clamped to the ray's ``tmax`` and to the
distance at which the ray leaves the scene box (shrunk by 0.1 %, as hippie does).
As ``L`` goes to 0 the key degrades to the origin-only Morton key.
"""
from __future__ import annotations

from raysort.sdk import number
from raysort.sorters._keysort import COORD_BITS, KeySorter, scene_diagonal

__all__ = ["TwoPointSorter"]

#: origin and end point, interleaved level by level
TWO_POINT_LEVELS = [(0, 1, 2, 3, 4, 5)] * COORD_BITS


class TwoPointSorter(KeySorter):
    """Rays sorted by the 6-D Morton code of origin and estimated end point (Meister 2020).

    ===========  ======  =======  ==========================================
    parameter    type    default  meaning
    ===========  ======  =======  ==========================================
    length       float   0.25     estimated ray length, as a fraction of the
                                  scene box's diagonal (hippie's default)
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
    coordinates = "end_point"

    def __init__(self, *, length=0.25, bits=24, packet_size=64, split_bits=0, octant=True):
        self.length = number("length", length, 0)
        self._setup(TWO_POINT_LEVELS, bits, packet_size, split_bits, octant)

    def end_length(self, rays, bounds):
        return self.length * scene_diagonal(bounds), None, 1.0
