"""``none``: fixed-size packets in input order (no sorting)."""
from __future__ import annotations

import numpy as np

from raysort._validate import integer
from raysort.plugin import Sorter
from raysort.rays import MAX_PACKET

__all__ = ["NoneSorter", "fixed_packets"]


def fixed_packets(packets, size):
    """Offsets that cut every large packet ``[packets[i], packets[i+1])`` into pieces of ``size``."""
    packets = np.asarray(packets, dtype=np.int64)
    lengths = np.diff(packets)
    pieces = (lengths + size - 1) // size
    first = np.repeat(packets[:-1], pieces)
    k = np.arange(int(pieces.sum())) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    return np.append(first + k * size, packets[-1]).astype(np.int32)


class NoneSorter(Sorter):
    """Rays stay in the order they were made, cut into fixed-size sub-packets.

    The baseline of the paper: primary rays come from the generator in Morton
    (Z) order inside each tile, so ``packet_size=64`` gives Manta's 8x8 square
    packets and ``1024`` a whole 32x32 tile.  A sub-packet never crosses a
    large-packet boundary; the last one of a large packet may be shorter.

    ===========  ======  =======  ==========================================
    parameter    type    default  meaning
    ===========  ======  =======  ==========================================
    packet_size  int     64       rays per sub-packet (1 .. 4096)
    ===========  ======  =======  ==========================================
    """

    trusted = True

    def __init__(self, *, packet_size=64):
        self.packet_size = integer("packet_size", packet_size, 1, MAX_PACKET)

    def sort(self, rays, packets, bounds):
        order = np.arange(len(rays), dtype=np.int32)
        return order, fixed_packets(packets, self.packet_size)
