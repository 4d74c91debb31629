"""Hand-built packets a script might give a traversal, one broken array each; run in a
child process by test_hand_built_packets.py:

    python packets_cases.py TRAVERSAL

prints one JSON line per case: ``{"start": CASE}`` before it and its outcome after."""
import json
import sys

import numpy as np

import raysort
from raysort.rays import gather


def _set(attr, index, value):
    def broken(p):
        getattr(p, attr)[index] = value
    return broken


def _replace(attr, make):
    def broken(p):
        setattr(p, attr, make(getattr(p, attr)))
    return broken


CASES = {
    "start far past the lanes": _set("starts", 0, 10**8),
    "negative start": _set("starts", 1, -400),
    "start not a multiple of 4": _set("starts", 1, 65),
    "count past the lanes": _set("counts", 4, 10**4),
    "count above the widest packet": _set("counts", 0, 10**8),
    "negative count": _set("counts", 0, -5),
    "rows too short": _replace("rows", lambda r: np.zeros((r.shape[0], 8), np.float32)),
    "rows missing": _replace("rows", lambda r: r[:5].copy()),
    "prim too short": _replace("prim", lambda a: a[:3].copy()),
    "u too short": _replace("u", lambda a: a[:3].copy()),
    "index too short": _replace("index", lambda a: a[:3].copy()),
    "counts shorter than starts": _replace("counts", lambda a: a[:2].copy()),
}


def main(name):
    scene = raysort.load_scene("cornell")
    pipe = raysort.Pipeline(scene, traversal=name)
    rng = np.random.default_rng(1)
    n = 300
    rays = raysort.RayBatch.from_arrays(rng.uniform(-0.5, 0.5, (n, 3)) + [0, 0.5, 0],
                                        rng.normal(size=(n, 3)))
    for case, broken in [("unbroken", None), *CASES.items()]:
        packets = gather(rays, np.arange(n, dtype=np.int32),
                         np.array([0, 64, 128, 192, 256, 300], np.int32))
        if broken is not None:
            broken(packets)
        print(json.dumps({"start": case}), flush=True)
        try:
            pipe.traversal.intersect(pipe.bvh, packets, False)
            result = {"case": case, "outcome": "ok"}
        except Exception as exc:
            result = {"case": case, "outcome": type(exc).__name__, "message": str(exc)}
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
