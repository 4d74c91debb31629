"""``origin_direction``: Morton keys of the ray origin and direction, in the bit splits
evaluated by Meister, Bokšanský, Guthe and Bittner, "On Ray Reordering Techniques for
Faster GPU Ray Tracing", I3D 2020 (doi 10.1145/3384382.3384534).

The origin is normalised to the scene box; the direction is either its three unit
components mapped from [-1, 1] (``interleaved``) or its octahedral map to [0, 1]^2
(the other layouts; Meister's COSTA and REIS use spherical angles instead, which
need atan2/acos per ray and order the sphere the same way up to the map).  Each
layout is one bit split of a 64-bit key, most significant first:

================  ====================================================  ==============
layout            key bits, most significant first                      Meister's name
================  ====================================================  ==============
origin            3-D Morton code of the origin only                    ORIGIN
interleaved       ``lead`` origin levels (ox oy oz), then levels of     AILA (lead=3)
                  ox oy oz dx dy dz
octahedral        ``lead`` origin levels, then levels of ox oy oz u v   OCTAHEDRON
origin_first      ``lead`` origin levels, then a 2-D Morton code of     REIS
                  the direction (u v)
direction_first   ``lead`` levels of the direction (u v), then the      COSTA
                  3-D Morton code of the origin
================  ====================================================  ==============

``interleaved`` with ``lead=0`` is the plain 6-D origin-direction Morton code of
the outside example plugin ``raysort-morton`` (up to the order of the six
coordinates within a level).  Rays are sorted by the key's top ``bits`` bits within
each large packet (see :mod:`raysort.sorters._keysort`), then cut into sub-packets.
"""
from __future__ import annotations

from raysort.sdk import choice, integer
from raysort.sorters._keysort import COORD_BITS, KeySorter

__all__ = ["OriginDirectionSorter", "LAYOUTS"]

ORIGIN, DIRECTION3, DIRECTION2 = (0, 1, 2), (3, 4, 5), (3, 4)


def _levels(layout, lead):
    """The bit split of ``layout`` (levels of coordinates, most significant first)."""
    if layout == "origin":
        return [ORIGIN] * COORD_BITS
    if layout == "interleaved":
        return [ORIGIN] * lead + [ORIGIN + DIRECTION3] * (COORD_BITS - lead)
    if layout == "octahedral":
        return [ORIGIN] * lead + [ORIGIN + DIRECTION2] * (COORD_BITS - lead)
    if layout == "origin_first":
        return [ORIGIN] * lead + [DIRECTION2] * COORD_BITS + [ORIGIN] * (COORD_BITS - lead)
    # direction_first
    return [DIRECTION2] * lead + [ORIGIN] * COORD_BITS + [DIRECTION2] * (COORD_BITS - lead)


#: layout -> how the direction becomes coordinates
LAYOUTS = {"origin": "components", "interleaved": "components", "octahedral": "octahedral",
           "origin_first": "octahedral", "direction_first": "octahedral"}


class OriginDirectionSorter(KeySorter):
    """Rays sorted by a Morton key of origin and direction (Meister et al. 2020).

    ===========  ======  ============  ==========================================
    parameter    type    default       meaning
    ===========  ======  ============  ==========================================
    layout       str     interleaved   the bit split: origin, interleaved,
                                       octahedral, origin_first, direction_first
                                       (see the module docstring)
    lead         int     3             leading levels of origin bits (direction
                                       bits for direction_first), 0 .. 16
    bits         int     24            key bits sorted (the top ones; fewer
                                       bits, fewer radix passes), 1 .. 64
    packet_size  int     64            most rays per sub-packet (1 .. 4096)
    split_bits   int     0             also start a sub-packet where the key's
                                       top ``split_bits`` bits change (0: never)
    octant       bool    True          prefix the key with the direction's octant
                                       and never mix octants in a sub-packet
                                       (False: the paper's key alone)
    ===========  ======  ============  ==========================================
    """

    trusted = True

    def __init__(self, *, layout="interleaved", lead=3, bits=24, packet_size=64, split_bits=0,
                 octant=True):
        self.layout = choice("layout", layout, LAYOUTS)
        self.lead = integer("lead", lead, 0, COORD_BITS)
        self.coordinates = LAYOUTS[layout]
        self._setup(_levels(layout, self.lead), bits, packet_size, split_bits, octant)
