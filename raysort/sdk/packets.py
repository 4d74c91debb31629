"""Sub-packet helpers for sorters."""
from __future__ import annotations

import numpy as np

__all__ = ["fixed_packets", "plain_packets"]


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


def plain_packets(packets, n):
    """Whether large-packet boundaries for ``n`` rays can go to a kernel as they are: a
    contiguous int32 array ending at ``n``, as the pipeline passes them, so that only
    their start at 0 and their order are left to check (cheaply, in the kernel).  Other
    packets go through :func:`~raysort.sdk.check_packets` first, and where the kernel
    rejects plain ones, ``check_packets`` raises the error that names what is wrong."""
    return (type(packets) is np.ndarray and packets.dtype == np.int32 and packets.ndim == 1
            and len(packets) > 0 and packets.flags.c_contiguous and packets[-1] == n)
