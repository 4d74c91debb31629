"""The identity order: a sorter result that leaves rays where they are, known to the
contract without reading it."""
from __future__ import annotations

import threading

import numpy as np

__all__ = ["identity_order", "is_identity_order"]

class _FrozenPrefixes:
    """Prefixes of one block of immutable memory (a ``bytes`` object, which NumPy will not
    make writeable) that grows, doubling, to the longest prefix asked for: read-only
    arrays at no cost per call.  ``fill(size)`` makes a grown block's values; every block
    handed out is kept in ``blocks`` (the largest last), as views of it may be in use."""

    def __init__(self, fill):
        self._fill = fill
        self._lock = threading.Lock()
        self.blocks = [np.frombuffer(b"", dtype=fill(0).dtype)]

    def prefix(self, n):
        """The first ``n`` values, a read-only view."""
        block = self.blocks[-1]     # (another thread may append a larger one: keep this one)
        if len(block) < n:
            with self._lock:
                block = self.blocks[-1]
                if len(block) < n:
                    size = max(int(n), 2 * len(block))
                    block = np.frombuffer(self._fill(size).tobytes(), block.dtype)
                    self.blocks.append(block)
        return block[:n]


_IDENTITY = _FrozenPrefixes(lambda size: np.arange(size, dtype=np.int32))


def identity_order(n):
    """``np.arange(n, dtype=np.int32)``, read-only, at no cost per call: a view of one
    block of immutable memory (a ``bytes`` object, which NumPy will not make writeable)
    that grows, doubling, to the largest ``n`` asked for.  A sorter that keeps the
    rays' order returns it, and the pipeline's check of the sorter's result then knows
    the order for a permutation without a pass over it (:func:`is_identity_order`)."""
    return _IDENTITY.prefix(n)


def is_identity_order(order):
    """Whether ``order`` is a view of :func:`identity_order`'s memory from its start,
    one int32 after another: then it holds ``0, 1, ..., len(order) - 1``, as nothing
    can write that memory."""
    base = getattr(order, "base", None)
    return (type(order) is np.ndarray and order.dtype == np.int32 and order.ndim == 1
            and order.strides == (4,) and any(base is block for block in _IDENTITY.blocks)
            and order.ctypes.data == base.ctypes.data)
