"""Sub-packet helpers for sorters."""
from __future__ import annotations

import numpy as np

__all__ = ["fixed_packets"]


def fixed_packets(packets, size):
    """Offsets that cut every large packet ``[packets[i], packets[i+1])`` into pieces of
    ``size``."""
    if isinstance(packets, np.ndarray) and packets.dtype == np.int32:
        # the same offsets in one C pass: a frame's packets are int32
        from raysort._gather import fixed_offsets
        return fixed_offsets(np.ascontiguousarray(packets), size)
    packets = np.asarray(packets, dtype=np.int64)
    lengths = np.diff(packets)
    pieces = (lengths + size - 1) // size
    first = np.repeat(packets[:-1], pieces)
    k = np.arange(int(pieces.sum())) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    return np.append(first + k * size, packets[-1]).astype(np.int32)
