"""``none``: fixed-size packets in input order (no sorting)."""
from __future__ import annotations

import numpy as np

from raysort.sdk import MAX_PACKET, Sorter, fixed_packets, integer

__all__ = ["NoneSorter"]


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
        """``order`` is a read-only view of one ``arange`` that grows to the largest batch
        (writing a new one per batch cost the frame a pass over memory)."""
        return _identity(len(rays)), fixed_packets(packets, self.packet_size)


_IDENTITY = np.zeros(0, dtype=np.int32)


def _identity(n):
    """``np.arange(n, dtype=np.int32)``, read-only, sharing its memory with every call's."""
    global _IDENTITY
    identity = _IDENTITY            # (another thread may replace it: keep this one)
    if len(identity) < n:
        identity = np.arange(n, dtype=np.int32)
        identity.flags.writeable = False
        _IDENTITY = identity
    return identity[:n]
