"""``morton``: a raysort sorter that orders rays by a Morton code (pure NumPy).

A complete third-party sorter plugin in one module: a :class:`raysort.Sorter`
subclass, registered by the entry point in ``pyproject.toml``.  Vectorised
over the whole batch: no Python loop over rays or packets.
"""
from __future__ import annotations

import numpy as np

from raysort.sdk import MAX_PACKET, Sorter, fixed_packets, integer

__all__ = ["MortonSorter", "morton_keys"]
__version__ = "0.1.0"


def morton_keys(rays, bounds, bits):
    """A uint64 key per ray: the 6-D Morton code of its origin and direction.

    The six coordinates ox, oy, oz (mapped from the scene box ``bounds`` to
    [0, 1]; 0 on an axis where the box is flat) and dx, dy, dz (mapped from
    [-1, 1] to [0, 1]) are clamped to [0, 1] (NaN -> 0), quantised to ``bits``
    bits each, and interleaved: bit ``b`` of coordinate ``k`` (0..5 in that
    order) is bit ``6 * b + k`` of the key.
    """
    lo, hi = np.asarray(bounds, dtype=np.float64)
    flat = ~(hi > lo)
    extent = np.where(flat, 1.0, hi - lo)
    origin = (rays.origins.astype(np.float64) - lo[:, None]) / extent[:, None]
    origin[flat] = 0.0                                   # a flat scene axis carries no order
    direction = (rays.directions.astype(np.float64) + 1.0) / 2.0
    unit = np.nan_to_num(np.concatenate([origin, direction]), nan=0.0, posinf=1.0, neginf=0.0)
    cells = 1 << bits
    q = np.minimum(np.clip(unit, 0.0, 1.0) * cells, cells - 1).astype(np.uint64)   # (6, n)
    place = np.arange(6, dtype=np.uint64)[:, None]
    key = np.zeros(q.shape[1], dtype=np.uint64)
    for b in range(bits):                                # a loop over bits, not rays
        bit = (q >> np.uint64(b)) & np.uint64(1)
        key |= np.bitwise_or.reduce(bit << (place + np.uint64(6 * b)), axis=0)
    return key


class MortonSorter(Sorter):
    """Rays of each large packet in the order of a 6-D Morton code of origin and direction.

    The key interleaves the origin (x, y, z, normalised to the scene box) and
    the direction (x, y, z, normalised from [-1, 1]), ``bits`` bits each (see
    :func:`morton_keys`).  A stable sort by (large packet, key) keeps every
    large packet together; each is then cut into sub-packets of
    ``packet_size`` rays (the last one may be shorter).

    ===========  ======  =======  ==========================================
    parameter    type    default  meaning
    ===========  ======  =======  ==========================================
    bits         int     4        bits per coordinate of the key (1 .. 10)
    packet_size  int     64       rays per sub-packet (1 .. 4096)
    ===========  ======  =======  ==========================================
    """

    def __init__(self, *, bits=4, packet_size=64):
        self.bits = integer("bits", bits, 1, 10)
        self.packet_size = integer("packet_size", packet_size, 1, MAX_PACKET)

    def sort(self, rays, packets, bounds):
        packets = np.asarray(packets, dtype=np.int64)
        key = morton_keys(rays, bounds, self.bits)
        packet = np.repeat(np.arange(len(packets) - 1), np.diff(packets))  # each ray's packet
        order = np.argsort(key, kind="stable")
        order = order[np.argsort(packet[order], kind="stable")]          # by packet, then key
        return order.astype(np.int32), fixed_packets(packets, self.packet_size)
