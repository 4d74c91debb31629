"""Checks that plugins keep their contracts; a broken plugin is named in the error."""
from __future__ import annotations

import numpy as np

from raysort.errors import PluginContractError
from raysort.rays import MAX_PACKET

__all__ = ["check_sort"]


def check_sort(name, result, n, packets):
    """Validate a sorter's ``(order, offsets)`` for ``n`` rays; returns them as int32 arrays.

    ``order`` must be a permutation of ``range(n)``; ``offsets`` must start at
    0, increase strictly, end at ``n``; each sub-packet must hold at most
    4096 rays, all from one large packet.
    """
    def fail(msg):
        raise PluginContractError(f"sorter {name!r} broke its contract: {msg}",
                                  kind="sorters", name=name)

    if not (isinstance(result, tuple) and len(result) == 2):
        fail(f"sort() must return (order, offsets), got {type(result).__name__}")
    try:
        order, offsets = (np.asarray(a) for a in result)
    except (TypeError, ValueError) as exc:
        fail(f"order and offsets must be 1-d integer arrays ({exc})")
    for label, arr in (("order", order), ("offsets", offsets)):
        if arr.ndim != 1 or not np.issubdtype(arr.dtype, np.integer):
            fail(f"{label} must be a 1-d integer array, got {arr.dtype} with shape {arr.shape}")
        if arr.size and arr.max() > np.iinfo(np.int32).max:
            fail(f"{label} holds values beyond the int32 range")
    order, offsets = order.astype(np.int64), offsets.astype(np.int64)
    if len(order) != n:
        fail(f"order has {len(order)} entries for {n} rays")
    if n and (order.min() < 0 or order.max() >= n
              or not (np.bincount(order, minlength=n) == 1).all()):
        fail("order is not a permutation of the batch (an index is missing or repeated)")
    if len(offsets) < 1 or offsets[0] != 0 or offsets[-1] != n:
        fail(f"offsets must run from 0 to {n}")
    sizes = np.diff(offsets)
    if (sizes <= 0).any():
        fail("offsets must increase strictly (no empty sub-packets)")
    if len(sizes) and sizes.max() > MAX_PACKET:
        fail(f"a sub-packet holds {sizes.max()} rays; the most a traversal takes is {MAX_PACKET}")
    if n:
        packet_of = np.searchsorted(np.asarray(packets), order, side="right") - 1
        starts = offsets[:-1]
        if not (np.minimum.reduceat(packet_of, starts)
                == np.maximum.reduceat(packet_of, starts)).all():
            fail("a sub-packet mixes rays of different large packets")
    return order.astype(np.int32, copy=False), offsets.astype(np.int32, copy=False)
