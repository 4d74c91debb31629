"""Ray batches, hit records and gathered sub-packets (structure of arrays).

Three containers move rays through the pipeline:

:class:`RayBatch`
    rays in the order a generator or shader made them: one float32 array of
    rows ``ox oy oz dx dy dz tmin tmax``.  This is what sorters read.
:class:`Packets`
    the same rays gathered by the framework into sub-packets, in a sorter's
    order, each sub-packet starting at a multiple of 4 (16-byte aligned), with
    inverse directions computed on the way.  This is what traversals read and
    write.  Padding lanes and invalid rays (NaN, infinite, ``tmin < 0`` or
    ``tmin >= tmax``) are stored inactive.
:class:`Hits`
    the closest hit of every ray, scattered back to the batch order:
    ``t`` (+inf on a miss), ``prim`` (-1 on a miss), ``u``, ``v``.

Every row is 16-byte aligned and the capacity is a multiple of 4, so a kernel
can use aligned 4-wide loads on lanes ``[4k, 4k + 4)``.
"""
from __future__ import annotations

import math
import numbers
import sys
import threading

import numpy as np

from raysort import isa
from raysort._layout import MAX_PACKET, PacketRow, RayRow
from raysort.errors import ConfigError

__all__ = ["RayBatch", "Packets", "Hits", "RayRow", "PacketRow", "MAX_PACKET", "aligned_empty",
           "gather", "scatter", "scatter_occluded", "add_unoccluded"]

#: row names of a ray batch and of gathered packets, in row order (types.h's enums)
RAY_ROWS = tuple(row.name for row in RayRow)
PACKET_ROWS = tuple(row.name for row in PacketRow)
ALIGN = 16
_O, _D, _TMIN, _TMAX = int(RayRow.ox), int(RayRow.dx), int(RayRow.tmin), int(RayRow.tmax)
_P_O, _P_D, _P_I = int(PacketRow.ox), int(PacketRow.dx), int(PacketRow.ix)
_P_TMIN, _P_T = int(PacketRow.tmin), int(PacketRow.t)
#: most rays in one batch: ray indices, offsets and packet boundaries are int32, and the
#: capacity (rounded up to a multiple of 4) must fit too
MAX_RAYS = 2**31 - 4


def _real(name, value):
    """``value`` as a float32 array, if it holds real numbers (ConfigError otherwise)."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name} must be an array of numbers ({exc})") from None
    if arr.dtype.kind not in "iuf":
        raise ConfigError(f"{name} must be numbers, got an array of {arr.dtype}")
    with np.errstate(over="ignore"):        # beyond float32: +-inf, an invalid ray
        return arr.astype(np.float32)


def _round4(n):
    return (int(n) + 3) & ~3


def _row_lanes(lanes):
    """Lanes per row of a block of rows holding ``lanes`` values each: a multiple of 4
    (at least 4) and, from 1024 lanes (4 kB) up, one cache line past a multiple of 1024.
    Rows a power-of-two multiple of 4 kB apart (a 256x256 batch: 256 kB) map a kernel's
    loads and stores at one lane to the same sets of the L1 and L2 caches, which then
    evict each other's lines: the gather of 65,536 rays took 0.25 ms with rows
    65,536 lanes apart and 0.16 ms with 65,552 (Zen 3, AVX2)."""
    lanes = max(_round4(lanes), 4)
    if lanes < 1024 or lanes > MAX_RAYS - 1024:
        return lanes
    return -(-(lanes - 16) // 1024) * 1024 + 16


def aligned_empty(shape, dtype, align=ALIGN):
    """An uninitialised C-contiguous array whose data starts ``align``-aligned."""
    dtype = np.dtype(dtype)
    nbytes = math.prod(shape) * dtype.itemsize
    raw = np.empty(nbytes + align, dtype=np.uint8)
    start = (-raw.ctypes.data) % align
    return raw[start:start + nbytes].view(dtype).reshape(shape)


def _sole_count():
    """What ``sys.getrefcount(blocks[i][0])`` says of an object only the pair in the list
    ``blocks`` holds."""
    blocks = [(object(), 0)]
    return sys.getrefcount(blocks[0][0])


class _Recycler(threading.local):
    """Each thread's few most recent blocks of memory for :class:`RayBatch` and
    :class:`Packets`.

    A batch's rays and packets are large (92 bytes per ray) and short-lived: fresh
    arrays would fault in their pages on first touch, batch after batch.  A block is
    handed out again only when nothing but this pool refers to it, i.e. when every
    array viewing it (a :class:`Packets`' rows, a caller's ray batch) is gone, so a
    result never shares memory with a later batch's while anyone can still read it.
    (Hits, 16 bytes per ray, come from the heap: recycling them did not pay.)
    """

    SOLE = _sole_count()
    KEEP = 12           # blocks kept per thread, least recently used dropped first ...
    BUDGET = 1 << 26    # ... and while they hold more bytes than this (64 MiB)
    GRAIN = 1 << 16     # smaller blocks are not kept; sizes are rounded up to a multiple

    def __init__(self):
        self.blocks = []    # (uint8 array, offset of its first ALIGN-aligned byte), oldest first

    def take(self, nbytes):
        """An uninitialised ALIGN-aligned uint8 array of ``nbytes`` bytes."""
        if nbytes < self.GRAIN:         # small: the heap has it at hand anyway
            return aligned_empty((nbytes,), np.uint8)
        blocks = self.blocks
        want = nbytes + ALIGN
        for i in range(len(blocks) - 1, -1, -1):
            if want <= blocks[i][0].nbytes <= 2 * want + self.GRAIN \
                    and sys.getrefcount(blocks[i][0]) == self.SOLE:
                raw, start = blocks.pop(i)
                break
        else:
            raw = np.empty(-(-want // self.GRAIN) * self.GRAIN, np.uint8)
            start = (-raw.ctypes.data) % ALIGN
            held = raw.nbytes + sum(block.nbytes for block, _ in blocks)
            while blocks and (len(blocks) >= self.KEEP or held > self.BUDGET):
                held -= blocks.pop(0)[0].nbytes
        blocks.append((raw, start))
        return raw[start:start + nbytes]


_recycler = _Recycler()
LINE = 64   # bytes of a cache line


def _carve(*sizes):
    """uint8 arrays of ``sizes`` bytes in one recycled block, each starting on a cache
    line one line further round the cache than the one before, so that arrays of the
    same length do not compete for the same cache sets when a kernel streams them
    together (a length of a multiple of 4 kB would make them)."""
    starts, end = [], 0
    for size in sizes:
        starts.append(end)
        end += -(-size // LINE) * LINE + LINE
    block = _recycler.take(end)
    return [block[start:start + size] for start, size in zip(starts, sizes)]


class RayBatch:
    """``n`` rays as float32 rows ``ox oy oz dx dy dz tmin tmax`` (:class:`RayRow`).

    ``data`` has shape ``(len(RayRow), capacity)``; lanes past ``n`` are padding and
    inactive.  The row views (``origins``, ``directions``, ``tmin``, ``tmax``)
    cover the first ``n`` lanes only.

    ``prev_t`` is None or float32 ``(n,)``: for a bounce ray, the hit distance of
    the ray its path continues (the pipeline sets it after shading), which sorters
    may use to estimate where the ray ends; NaN or inf where unknown.  It never
    affects hits.
    """

    __slots__ = ("data", "n", "prev_t")

    def __init__(self, n):
        if isinstance(n, bool) or not isinstance(n, numbers.Integral) or not 0 <= n <= MAX_RAYS:
            raise ConfigError(f"a ray batch holds 0..{MAX_RAYS} rays, got {n!r}")
        self._allocate(int(n))
        self.data[:, :n] = 0.0

    def _allocate(self, n):
        """Rows for ``n`` rays: lanes ``[0, n)`` uninitialised, the padding set."""
        self.n = n
        self.prev_t = None
        capacity = _row_lanes(n)
        self.data = _recycler.take(len(RAY_ROWS) * capacity * 4).view(np.float32).reshape(
            len(RAY_ROWS), capacity)
        self.data[:, n:] = 0.0
        self.data[_TMIN, n:] = np.inf
        self.data[_TMAX, n:] = -np.inf

    @classmethod
    def _unfilled(cls, n):
        """A batch of ``n`` rays whose rows are not initialised: for a kernel that writes
        every row of the rays it makes and then truncates the batch to them (the
        built-in shaders), so their memory is written once.  ``n`` is trusted."""
        batch = object.__new__(cls)
        batch._allocate(n)
        return batch

    @classmethod
    def from_arrays(cls, origins, directions, tmin=0.0, tmax=np.inf):
        """Rays from ``(n, 3)`` origins and directions; tmin/tmax scalar or ``(n,)``.

        Any real values are accepted (a ray that is not finite, or has not
        ``0 <= tmin < tmax``, is invalid and never hits); the arrays must be
        numbers of matching shapes (ConfigError otherwise).
        """
        origins = _real("origins", origins)
        directions = _real("directions", directions)
        if origins.ndim != 2 or origins.shape[1] != 3 or directions.shape != origins.shape:
            raise ConfigError(
                f"origins and directions must both have shape (n, 3), got "
                f"{origins.shape} and {directions.shape}")
        n = len(origins)
        if n > MAX_RAYS:
            raise ConfigError(f"a batch holds at most {MAX_RAYS} rays (int32 indices), got {n}")
        tmin, tmax = _real("tmin", tmin), _real("tmax", tmax)
        for name, value in (("tmin", tmin), ("tmax", tmax)):
            if value.shape not in ((), (n,)):
                raise ConfigError(f"{name} must be one number or one per ray ({n}), got shape "
                                  f"{value.shape}")
        batch = cls(n)
        batch.origins[:] = origins.T
        batch.directions[:] = directions.T
        batch.tmin[:] = tmin
        batch.tmax[:] = tmax
        return batch

    def __len__(self):
        return self.n

    def __repr__(self):
        return f"RayBatch(n={self.n})"

    @property
    def origins(self):
        """``(3, n)`` view of the origins."""
        return self.data[_O:_O + 3, :self.n]

    @property
    def directions(self):
        """``(3, n)`` view of the directions."""
        return self.data[_D:_D + 3, :self.n]

    @property
    def tmin(self):
        """``(n,)`` view of tmin: a hit needs ``t > tmin``."""
        return self.data[_TMIN, :self.n]

    @property
    def tmax(self):
        """``(n,)`` view of tmax: a hit needs ``t < tmax``."""
        return self.data[_TMAX, :self.n]

    def truncate(self, n):
        """Keep the first ``n`` rays (in place; the rest become inactive padding); returns self."""
        if not 0 <= n <= self.n:
            raise ValueError(f"cannot truncate {self.n} rays to {n}")
        if n < self.n:      # lanes no longer rays: padding (lanes past self.n are already)
            isa.module("_gather").pad_rays(self.data, n, self.n)
        self.n = int(n)
        if self.prev_t is not None:
            self.prev_t = self.prev_t[:n]
        return self

    def take(self, index):
        """A new batch holding the rays ``index`` (an integer array), in that order."""
        index = np.asarray(index, dtype=np.intp)
        out = RayBatch(len(index))
        out.data[:, :len(index)] = self.data[:, index]
        if self.prev_t is not None:
            out.prev_t = self.prev_t[index]
        return out


class Hits:
    """Closest hits in batch order: ``t`` (+inf on a miss), ``prim`` (-1), ``u``, ``v``."""

    __slots__ = ("t", "prim", "u", "v")

    def __init__(self, n, _prim=-1):
        self.t = np.full(n, np.inf, dtype=np.float32)
        self.prim = np.full(n, _prim, dtype=np.int32)
        self.u = np.zeros(n, dtype=np.float32)
        self.v = np.zeros(n, dtype=np.float32)

    @classmethod
    def _of_block(cls, block):
        """Hits viewing a float32 (4, n) block of the rows t, prim (int32 bits), u, v."""
        hits = object.__new__(cls)
        hits.t, hits.u, hits.v = block[0], block[2], block[3]
        hits.prim = block[1].view(np.int32)
        return hits

    def __len__(self):
        return len(self.t)

    def __repr__(self):
        return f"Hits(n={len(self)}, hit={int((self.prim >= 0).sum())})"


class Packets:
    """Rays gathered into 16-byte aligned sub-packets, ready for a traversal.

    Attributes
    ----------
    rows : float32 (len(PacketRow), capacity)
        ``ox oy oz dx dy dz ix iy iz tmin t`` (:class:`PacketRow`; also as the
        views ``origins``, ``directions``, ``inverse_directions``, ``tmin``,
        ``t``); ``t`` starts at the ray's tmax and is lowered by the traversal
        as it finds closer hits.
    prim, u, v : (capacity,)
        hit record being built by the traversal (prim -1 = none yet).
    starts, counts : int32 (n_packets,)
        sub-packet k occupies lanes ``[starts[k], starts[k] + counts[k])``;
        every start is a multiple of 4 and lanes up to the next multiple of 4
        are inactive padding.
    index : int32 (capacity,)
        the batch index of the ray in each lane, -1 for padding.
    """

    __slots__ = ("rows", "prim", "u", "v", "starts", "counts", "index", "_extra")

    def __init__(self, counts, _extra_rows=0):
        counts = np.ascontiguousarray(counts, dtype=np.int32)
        starts = np.empty(len(counts), dtype=np.int32)
        self._allocate(counts, starts, isa.module("_gather").layout(counts, starts),
                       _extra_rows)

    @classmethod
    def _laid_out(cls, counts, starts, lanes, extra_rows=0):
        """Packets of int32 ``counts`` already laid out (``starts``, ``lanes``: what
        ``_gather.layout`` gives), rows not initialised."""
        packets = object.__new__(cls)
        packets._allocate(counts, starts, lanes, extra_rows)
        return packets

    def _allocate(self, counts, starts, lanes, _extra_rows):
        self.counts, self.starts = counts, starts
        capacity = _row_lanes(lanes)
        # one block: the packet rows, then prim, u, v, index (and the caller's extra rows)
        lane_bytes = capacity * 4
        rows, prim, u, v, index, *extra = _carve(len(PACKET_ROWS) * lane_bytes,
                                                 *[lane_bytes] * (4 + _extra_rows))
        self.rows = rows.view(np.float32).reshape(len(PACKET_ROWS), capacity)
        self.prim, self.index = prim.view(np.int32), index.view(np.int32)
        self.u, self.v = u.view(np.float32), v.view(np.float32)
        self._extra = [row.view(np.float32) for row in extra]

    def slice(self, first, last):
        """A view of sub-packets ``[first, last)`` sharing this batch's rows and hits
        (for splitting one traversal call over threads)."""
        view = object.__new__(Packets)
        for name in ("rows", "prim", "u", "v", "index", "_extra"):
            setattr(view, name, getattr(self, name))
        view.starts, view.counts = self.starts[first:last], self.counts[first:last]
        return view

    @property
    def n_packets(self):
        return len(self.counts)

    @property
    def capacity(self):
        return self.rows.shape[1]

    @property
    def origins(self):
        """``(3, capacity)`` view of the origins."""
        return self.rows[_P_O:_P_O + 3]

    @property
    def directions(self):
        """``(3, capacity)`` view of the directions."""
        return self.rows[_P_D:_P_D + 3]

    @property
    def inverse_directions(self):
        """``(3, capacity)`` view of ``1 / direction`` (computed by the gather)."""
        return self.rows[_P_I:_P_I + 3]

    @property
    def tmin(self):
        """``(capacity,)`` view of tmin (+inf on an inactive lane)."""
        return self.rows[_P_TMIN]

    @property
    def t(self):
        """``(capacity,)`` view of t: the ray's tmax, lowered to the closest hit found
        (-inf on an inactive lane; an any-hit query sets -inf on a hit)."""
        return self.rows[_P_T]

    def active(self):
        """A bool ``(capacity,)`` array, True on lanes a traversal must trace
        (``tmin < t``)."""
        return self.rows[_P_TMIN] < self.rows[_P_T]

    def __repr__(self):
        return f"Packets(n_packets={self.n_packets}, rays={int(self.counts.sum())})"


def gather(rays, order, offsets):
    """Gather ``rays`` into aligned sub-packets.

    Sub-packet k holds the rays ``order[offsets[k]:offsets[k + 1]]``.  The
    copy runs four rays at a time with SIMD stores and computes the inverse
    directions.  ``order`` must be a permutation of the batch and ``offsets``
    run from 0 to ``len(rays)`` in sub-packets of at least one ray (checked
    first; ValueError otherwise).  A traversal takes sub-packets of at most
    ``MAX_PACKET`` rays; larger ones suit a reference that loops over rays.
    """
    n = len(rays)
    order = np.ascontiguousarray(order, dtype=np.int32)
    offsets = np.ascontiguousarray(offsets, dtype=np.int32)
    one_packet = np.array([0, n], np.int32)
    if len(order) != n or len(offsets) < 1 or isa.module("_contract").sort_result(
            order, offsets, one_packet, n, max(n, 1))[0]:
        raise ValueError(f"gather: order must be a permutation of the {n} rays and offsets "
                         f"run from 0 to {n} in non-empty sub-packets "
                         f"(raysort.contract.check_sort says what is wrong)")
    return gather_checked(rays, order, offsets, one_packet, check_order=False,
                          max_packet=max(n, 1))[0]


def gather_checked(rays, order, offsets, packets, keep_tmax=False, check_order=True,
                   max_packet=MAX_PACKET):
    """:func:`gather` checking a sorter's result against the large packets ``packets``
    (unless ``check_order`` is False: a trusted sorter's) and the rays against the ray
    contract on the way, for the pipeline.

    ``order`` and ``offsets`` are int32 arrays with ``len(order) == len(rays)``;
    ``packets`` valid boundaries; sub-packets hold 1..``max_packet`` rays.

    Returns ``(Packets, tmax, bad_ray)``: ``(None, None, -1)`` if the offsets break
    their contract or a sub-packet holds a ray beyond its large packet
    (:func:`raysort.contract.check_sort` says how; a ray that comes twice is found by
    :func:`scatter_checked`); ``tmax`` (with ``keep_tmax``; otherwise None) each
    lane's t as gathered, which :func:`scatter_checked` needs for closest hits;
    ``bad_ray`` a ray that is active yet not finite or with tmin < 0 (traced as
    invalid), or -1.
    """
    kernels = isa.module("_gather")
    layout = kernels.sub_packets(offsets, len(rays), max_packet)
    if layout is None or len(order) != len(rays):
        return None, None, -1
    batch = Packets._laid_out(*layout, int(keep_tmax))
    tmax = batch._extra[0] if keep_tmax else None
    order_ok, bad_ray = kernels.gather(rays.data, order, offsets, batch.starts, batch.rows,
                                       batch.prim, batch.u, batch.v, batch.index, packets,
                                       tmax, check_order)
    return (batch, tmax, bad_ray) if order_ok else (None, None, -1)


def scatter(packets, n, hits=None):
    """Copy the closest hits of ``packets`` back to batch order (a new or given :class:`Hits`)."""
    hits, ok = _scatter(packets, n, False, hits=hits)
    if not ok:
        raise ValueError(f"scatter: packets.index holds a ray beyond the {len(hits)} hits")
    return hits


def scatter_occluded(packets, n):
    """For an any-hit query: a bool array, True where the ray found any hit."""
    occluded, ok = _scatter(packets, n, True)
    if not ok:
        raise ValueError(f"scatter_occluded: packets.index holds a ray beyond the {n} rays")
    return occluded


def _scatter(packets, n, any_hit, hits=None):
    """The hits (a :class:`Hits`, or a bool array with ``any_hit``) of ``packets``'s lanes
    in batch order (a ray no lane holds: a miss), and False if a lane's index lies
    beyond ``n``."""
    kernels = isa.module("_gather")
    if any_hit:
        out = np.zeros(n, dtype=np.uint8)
        ok = kernels.scatter_occluded(packets.prim, packets.index, out)
        return out.view(bool), ok
    out = Hits(n) if hits is None else hits
    ok = kernels.scatter(packets.rows, packets.prim, packets.u, packets.v, packets.index,
                         out.t, out.prim, out.u, out.v)
    return out, ok


def scatter_checked(packets, order, offsets, tmax, n_prim, any_hit, *, check_hits=True,
                    check_order=True):
    """Scatter the hits a traversal wrote into :func:`gather_checked`'s ``packets``,
    checking them first (``check_hits``: the rules of
    :func:`raysort.contract.check_hits`, for the arrays being the ones gathered; a pass
    over lanes in order, which vectorises) and that every ray got one lane
    (``check_order``: the rest of the sorter's contract, found from rays the scatter
    left unwritten).  ``tmax`` (each lane's t as gathered) is needed for closest hits
    with ``check_hits``.

    Returns ``(out, fault)``: the :class:`Hits` (with ``any_hit``, the bool array of
    occluded rays) and None, or None and ``"hits"`` (the traversal broke its contract)
    or ``"order"`` (the sorter's order is not a permutation)."""
    n = len(order)
    if check_hits:
        try:
            code, _ = isa.module("_contract").hits(
                packets.rows, packets.t if tmax is None else tmax, packets.prim, packets.u,
                packets.v, packets.index, packets.starts, packets.counts, order, offsets,
                n_prim, any_hit)
        except (TypeError, ValueError):         # an array retyped in place
            code = 1
        if code:
            return None, "hits"
    if not check_order:
        out, ok = _scatter(packets, n, any_hit)
        return (out, None) if ok else (None, "hits")    # not ok: an index beyond the batch
    # every ray written once, in one pass that finds a ray left out (another came twice)
    out, fault = isa.module("_gather").scatter_each(packets.rows, packets.prim, packets.u,
                                                    packets.v, packets.index, n, any_hit)
    if fault:
        return None, ("hits", "order")[fault - 1]
    return (out.view(bool) if any_hit else Hits._of_block(out)), None


def add_unoccluded(radiance, slot, contribution, occluded):
    """``radiance[slot[i]] += contribution[:, i]`` (float64 sums, in ray order) for every
    shadow ray ``i`` that is not ``occluded``: ``np.add.at``'s result, without its cost."""
    isa.module("_gather").add_unoccluded(
        radiance, np.ascontiguousarray(slot, dtype=np.int32),
        np.asarray(contribution, dtype=np.float32), np.asarray(occluded).view(np.uint8))
