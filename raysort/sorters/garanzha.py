"""``garanzha``: the ray hash and compress-sort-decompress of Garanzha and Loop, "Fast
Ray Sorting and Breadth-First Packet Traversal for GPU Ray Tracing", Computer
Graphics Forum 29(2) (Eurographics 2010).

Every ray gets a hash: the cell of its origin in a uniform grid over the scene box
(``origin_bits`` bits per axis, cells in Morton order) followed by the cell of its
direction in a grid over the octahedral map of the sphere (``direction_bits`` bits
per axis).  Per large packet the rays are then

1. compressed: each run of consecutive rays with equal hash becomes one chunk
   (camera rays in tile order and the bounce rays of one surface come in runs);
2. sorted: the chunks by hash (a stable sort, see :mod:`raysort.sorters._keysort`);
3. decompressed: each chunk's rays, in input order, go to its sorted place.

The result is a stable sort of the rays by hash; a large packet whose runs are
short (more than half as many chunks as rays, as for diffuse bounce rays) is
sorted without steps 1 and 3, which give the same order but would cost more
than they save.

The paper's abstract names these steps but not the bit split of the hash; the grid
sizes and the octahedral direction map are raysort's choice.  Sub-packets are cut
from the sorted rays at ``packet_size`` and, with ``split``, wherever the hash
changes (a packet then holds rays of one origin cell and one direction cell).
"""
from __future__ import annotations

from raysort.sdk import boolean, integer
from raysort.sorters._keysort import KeySorter

__all__ = ["GaranzhaSorter"]


class GaranzhaSorter(KeySorter):
    """Rays sorted by a hash of origin cell and direction cell (Garanzha & Loop 2010).

    ==============  ======  =======  =======================================
    parameter       type    default  meaning
    ==============  ======  =======  =======================================
    origin_bits     int     5        origin grid: 2**origin_bits cells per
                                     axis of the scene box (1 .. 16)
    direction_bits  int     3        direction grid: 2**direction_bits cells
                                     per axis of the octahedral map (1 .. 8)
    packet_size     int     64       most rays per sub-packet (1 .. 4096)
    split           bool    False    also start a sub-packet wherever the
                                     hash changes
    ==============  ======  =======  =======================================
    """

    trusted = True
    compress = True
    coordinates = "octahedral"

    def __init__(self, *, origin_bits=5, direction_bits=3, packet_size=64, split=False):
        self.origin_bits = integer("origin_bits", origin_bits, 1, 16)
        self.direction_bits = integer("direction_bits", direction_bits, 1, 8)
        self.split = boolean("split", split)
        levels = [(0, 1, 2)] * self.origin_bits + [(3, 4)] * self.direction_bits
        hash_bits = 3 * self.origin_bits + 2 * self.direction_bits
        self._setup(levels, hash_bits, packet_size, hash_bits if self.split else 0)
