"""A base class for traversals that hand rays to an outside ray tracer (Embree, Mitsuba, ...).

Such libraries trace arrays of rays ``(origin, direction, far)`` from ``t = 0`` and
count a hit at ``t = 0``; raysort's contract counts only hits with ``tmin < t``.  The
base class shifts each ray's origin to its ``tmin``, asks the library, traces again
from a little further along any ray whose hit lies at ``t <= 0`` (a ray starting in a
triangle's plane), and writes the hits into the packets.  A subclass supplies only the
library's scene and query.
"""
from __future__ import annotations

import numpy as np

from raysort.plugin import Traversal
from raysort.stats import Counters

__all__ = ["LibraryTraversal"]


class LibraryTraversal(Traversal):
    """A traversal answered by an outside library; subclasses define :meth:`scene` and
    :meth:`query`.  Hits agree with brute force up to the library's rounding, so
    ``exact = False``; the library's work is not counted (``Counters.available`` is
    False).

    A hit at ``t <= 0`` from the shifted origin is traced again from further along the
    ray, up to :attr:`NUDGES` times, the first step :attr:`NUDGE` times the origin's
    magnitude, doubled each time; a ray still hitting at ``t <= 0`` after that misses.
    """

    exact = False
    #: retraces of a ray whose hit lies at t <= 0, and the first step (relative)
    NUDGES, NUDGE = 4, 2.0 ** -20

    def scene(self, bvh):
        """The library's scene for ``bvh`` (build it on first use and cache it)."""
        raise NotImplementedError

    def query(self, scene, origins, directions, far, any_hit):
        """Trace rays ``(n, 3)`` float32 ``origins`` and ``directions`` up to ``far``
        (n,) float32; return ``(t, prim, u, v)`` with ``t`` from the origin (inf and -1
        on a miss; ``u``, ``v`` may be None for ``any_hit``)."""
        raise NotImplementedError

    def intersect(self, bvh, packets, any_hit=False):
        lanes = np.flatnonzero((packets.index >= 0) & packets.active())
        if len(lanes) == 0:
            return Counters(available=False)
        tmin, tmax = packets.tmin[lanes], packets.t[lanes]
        start = np.where(tmin > 0, tmin, np.float32(0)).astype(np.float32)
        dirs = packets.directions[:, lanes]
        d = np.ascontiguousarray(dirs.T)
        o = np.ascontiguousarray((packets.origins[:, lanes] + start * dirs).T)
        far = np.ascontiguousarray(np.minimum(tmax - start, np.float32(1e37)), np.float32)
        scene = self.scene(bvh)
        t, prim, u, v = self.query(scene, o, d, far, any_hit)
        if not any_hit:
            self._retrace_start_hits(scene, o, d, far, t, prim, u, v)
        hit = prim >= 0
        got = lanes[hit]
        if any_hit:
            packets.prim[got] = 0
            packets.t[got] = -np.inf
        else:
            packets.prim[got] = prim[hit]
            packets.t[got] = t[hit] + start[hit]
            packets.u[got] = u[hit]
            packets.v[got] = v[hit]
        return Counters(rays=len(lanes), available=False)

    def _retrace_start_hits(self, scene, o, d, far, t, prim, u, v):
        """Trace rays whose hit lies at t <= 0 again from further along (in place)."""
        again = np.flatnonzero((prim >= 0) & (t <= 0))
        step = self.NUDGE * (np.abs(o).max(axis=1) + 1) / np.maximum(
            np.linalg.norm(d, axis=1), np.float32(1e-30))
        for _ in range(self.NUDGES):
            if len(again) == 0:
                break
            shift = step[again].astype(np.float32)
            o2 = np.ascontiguousarray(o[again] + shift[:, None] * d[again], np.float32)
            f2 = np.ascontiguousarray(far[again] - shift, np.float32)
            t2, p2, u2, v2 = self.query(scene, o2, np.ascontiguousarray(d[again]), f2, False)
            t[again], prim[again], u[again], v[again] = t2 + shift, p2, u2, v2
            step[again] *= 2
            again = again[(p2 >= 0) & (t2 <= 0)]
        prim[again] = -1                # still in the plane: not a hit past tmin
