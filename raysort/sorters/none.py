"""``none``: fixed-size packets in input order (no sorting)."""
from __future__ import annotations

from raysort.sdk import MAX_PACKET, Sorter, fixed_packets, identity_order, integer

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
        """``order`` is :func:`raysort.sdk.identity_order` (writing a new ``arange`` per
        batch, and checking it, cost the frame two passes over memory)."""
        return identity_order(len(rays)), fixed_packets(packets, self.packet_size)
