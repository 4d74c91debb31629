"""Gathered packets whose row values a script then overwrote with anything (NaN, +-inf,
+-FLT_MAX, 1 / d that is not d's reciprocal, tmin < 0, t < tmin); run in a child process
by test_packet_values.py:

    python packet_values_cases.py TRAVERSAL

prints one JSON line per case, ``{"start": CASE}`` before it and ``{"case": CASE}`` after:
the traversal must come back (what it says of such rays is unspecified)."""
import json
import sys

import numpy as np

import raysort
from raysort.rays import PacketRow, gather

F32_MAX = float(np.finfo(np.float32).max)
JUNK = np.array([0.0, -0.0, 1.0, -1.0, F32_MAX, -F32_MAX, np.inf, -np.inf, np.nan, 1e-45,
                 -1e-45, 1e-30, 1e30], np.float32)
# one lane found to send the wide traversals back to the root through an empty slot
# (1 / d = 0 where d is not 0: an empty box's (inf - o) * 0 is NaN)
LOOPING_LANE = [1e-30, F32_MAX, F32_MAX, -F32_MAX, 0.0, 1e30, 0.0, -0.0, 0.0, -1.0, np.inf]


def cases(bvh, rng, trials):
    lo, hi = np.asarray(bvh.bounds, float)
    yield "the looping lane", gather(raysort.RayBatch.from_arrays([[0.5, 0.5, 0.5]],
                                                                  [[0, 0, 1.0]]),
                                     np.zeros(1, np.int32), np.array([0, 1], np.int32)), \
        lambda rows: rows.__setitem__((slice(None), 0), LOOPING_LANE)
    for trial in range(trials):
        n = int(rng.integers(1, 200))
        o = lo + rng.random((n, 3)) * (hi - lo)
        d = rng.normal(size=(n, 3))
        if trial % 3 == 0:      # coherent: the frustum walk's chunks
            d = np.tile(rng.normal(size=3), (n, 1)) + rng.normal(size=(n, 3)) * 0.01
        sizes = np.diff(np.unique(np.r_[0, rng.integers(1, n, size=n // 40), n]))
        offsets = np.r_[0, np.cumsum(sizes)].astype(np.int32)
        packets = gather(raysort.RayBatch.from_arrays(o, d), rng.permutation(n).astype(np.int32),
                         offsets)
        mode = trial % 4
        mask = rng.random(packets.rows.shape) < (0.3 if mode else 1.0)
        if mode == 1:           # only the reciprocal directions
            mask[:PacketRow.ix] = False
            mask[PacketRow.tmin:] = False
        if mode == 2:           # only the directions
            mask[:PacketRow.dx] = False
            mask[PacketRow.ix:] = False
        junk = rng.choice(JUNK, size=packets.rows.shape)

        def edit(rows, mask=mask, junk=junk, mode=mode):
            rows[mask] = junk[mask]
            if mode == 3:
                rows[PacketRow.tmin] = np.where(rng.random(rows.shape[1]) < 0.5, -np.inf,
                                                rows[PacketRow.tmin])
        yield f"junk {trial} (mode {mode})", packets, edit


def main(name, trials=24):
    bvh = raysort.load_scene("cornell").bvh()
    traversal = raysort.create("traversals", name)
    for case, packets, edit in cases(bvh, np.random.default_rng(7), trials):
        edit(packets.rows)
        packets.prim[:] = -1
        print(json.dumps({"start": case}), flush=True)
        for any_hit in (False, True):
            traversal.intersect(bvh, packets, any_hit)
        print(json.dumps({"case": case}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
