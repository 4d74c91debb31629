"""``nah_numpy``: the Nah et al. sorter written in plain NumPy.

The reference for the Cython ``nah`` sorter (tests check that both put every
ray in the same bucket and cell and give the same order), and an example of a
complete sorter plugin with no compiled code.  Vectorised over all large
packets at once: no Python loop over rays or packets.
"""
from __future__ import annotations

import numpy as np

from raysort.sorters.nah import NahSorter

__all__ = ["NahNumpySorter"]


class NahNumpySorter(NahSorter):
    """The ``nah`` algorithm in NumPy (same parameters, same output, slower).

    ===========  ======  =======  ==========================================
    parameter    type    default  meaning
    ===========  ======  =======  ==========================================
    threshold    float   0.25     as for ``nah``
    max_cells    int     8        as for ``nah``
    packet_size  int     64       as for ``nah``
    large_packet int     None     as for ``nah``
    ===========  ======  =======  ==========================================
    """

    trusted = False

    def classify(self, rays, packets, bounds):
        return self._classes(rays, self._packets(packets, len(rays)), bounds)

    def _classes(self, rays, packets, bounds):
        """:meth:`classify` of large packets already checked and cut (``_packets``)."""
        f32 = np.float32
        o, d = rays.origins, rays.directions
        n = len(rays)
        # 24 direction buckets: octant (bit k = component k negative) x major axis
        octant = ((d[0] < 0).astype(np.int64) | (d[1] < 0) << 1 | (d[2] < 0) << 2)
        ad = np.abs(d)
        major = np.zeros(n, dtype=np.int64)
        best = ad[0].copy()
        for axis in (1, 2):                     # the same comparisons as the kernel
            bigger = ad[axis] > best
            major[bigger] = axis
            best[bigger] = ad[axis][bigger]
        bucket = octant * 3 + major
        # per (large packet, bucket) origin bounds, NaN-ignoring like rs_minf/rs_maxf
        packet = np.repeat(np.arange(len(packets) - 1), np.diff(packets))
        group = packet * 24 + bucket
        n_groups = (len(packets) - 1) * 24
        lo = np.full((n_groups, 3), np.inf, dtype=f32)
        hi = np.full((n_groups, 3), -np.inf, dtype=f32)
        for axis in range(3):                   # ufunc.at: C loops, NaN-ignoring fmin/fmax
            np.fmin.at(lo[:, axis], group, o[axis])
            np.fmax.at(hi[:, axis], group, o[axis])
        # origin grid: which axes split, ranked by relative extent
        root = np.asarray(bounds, dtype=f32)
        root_ext = (root[1] - root[0]).astype(f32)
        with np.errstate(invalid="ignore", over="ignore"):
            ext = (hi - lo).astype(f32)
            wide = ext > f32(self.threshold) * root_ext
            mid = (f32(0.5) * lo + f32(0.5) * hi).astype(f32)
            rank = np.zeros((n_groups, 3), dtype=np.int64)
            for a in range(3):
                for b in range(3):
                    if a == b:
                        continue
                    lhs, rhs = ext[:, b] * root_ext[a], ext[:, a] * root_ext[b]
                    rank[:, a] += wide[:, b] & ((lhs > rhs) | ((lhs == rhs) & (b < a)))
            split = wide & (rank < self.max_cells.bit_length() - 1)
            # cell: one bit per split axis, in axis order
            bit = np.cumsum(split, axis=1) - split
            above = o.T >= mid[group]
        cell = ((above & split[group]).astype(np.int64) << bit[group]).sum(axis=1)
        return bucket.astype(np.uint8), cell.astype(np.uint8)

    def sort(self, rays, packets, bounds):
        packets = self._packets(packets, len(rays))
        bucket, cell = self._classes(rays, packets, bounds)
        packet = np.repeat(np.arange(len(packets) - 1), np.diff(packets))
        key = packet * 192 + bucket.astype(np.int64) * 8 + cell
        order = np.argsort(key, kind="stable").astype(np.int32)
        sorted_key = key[order]
        group_start = np.flatnonzero(np.diff(sorted_key, prepend=-1))
        # cut each (packet, bucket, cell) group into pieces of packet_size rays
        rank = np.arange(len(rays)) - np.repeat(group_start, np.diff(
            np.append(group_start, len(rays))))
        starts = np.flatnonzero(np.diff(sorted_key, prepend=-1) | (rank % self.packet_size == 0))
        return order, np.append(starts, len(rays)).astype(np.int32)
