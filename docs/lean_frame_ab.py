"""The eleventh stop's lean-frame changes against the stop's first build, in one process
(BENCHMARKS.md section 8):

    python docs/lean_frame_ab.py OLD_LAMBERT.so OLD_GATHER.so SIZE SPP ROUNDS [SCENE]

OLD_LAMBERT.so is a copy of the first build's ``raysort/_isa/<isa>/shaders/lambert``
module (run with RAYSORT_ISA=<isa>), OLD_GATHER.so of its baseline ``raysort/_gather``.
'before' = that kernel (its paths checked by check_bounce's pass), that follow_paths,
truncate's padding through NumPy and the identity order read by the sort check;
'after' = this build.  Whole frames in alternated order; per-round ratios."""
import os
import statistics
import sys

import numpy as np
import raysort
from raysort import isa, pipeline
from raysort import rays as R
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests",
                                "benchmarks"))
from kernel_ab import load_copy     # noqa: E402

lambert_so, gather_so = sys.argv[1], sys.argv[2]
size, spp, rounds = int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
scene = sys.argv[6] if len(sys.argv) > 6 else "sibenik"
pipe = raysort.Pipeline(scene)
old_lambert = load_copy("shaders.lambert", lambert_so)    # after the Pipeline: it registers
old_gather = load_copy("_gather", gather_so)


class Shim:
    def __getattr__(self, name):
        if name == "_shade":
            return lambda *a: old_lambert._shade(*a) + (False,)
        return getattr(old_lambert, name)


def old_truncate(self, n):
    if not 0 <= n <= self.n:
        raise ValueError
    self.data[R._O:R._O + 3, n:self.n] = 0.0
    self.data[R._D:R._D + 3, n:self.n] = 0.0
    self.data[R._TMIN, n:] = np.inf
    self.data[R._TMAX, n:] = -np.inf
    self.n = int(n)
    if self.prev_t is not None:
        self.prev_t = self.prev_t[:n]
    return self


now = dict(lam=isa.module("shaders.lambert"), ident=pipeline.is_identity_order,
           checks=pipeline._checks_its_paths, trunc=R.RayBatch.truncate,
           follow=pipeline._follow_paths)


def configure(key):
    before = key == "before"
    isa._modules["shaders.lambert"] = Shim() if before else now["lam"]
    pipeline.is_identity_order = (lambda o: False) if before else now["ident"]
    pipeline._checks_its_paths = (lambda s: False) if before else now["checks"]
    R.RayBatch.truncate = old_truncate if before else now["trunc"]
    pipeline._follow_paths = old_gather.follow_paths if before else now["follow"]


print(pipe.describe(), isa.active(), flush=True)
pipe.render(64, 64, spp=1, seed=1)
runs = {"before": [], "after": []}
first, same = None, True
for r in range(rounds):
    for key in (("before", "after") if r % 2 == 0 else ("after", "before")):
        configure(key)
        res = pipe.render(size, size, spp=spp, seed=1)
        s = dict(res.stats.stage_seconds)
        s["frame"] = sum(s.values())
        s["framework"] = s["frame"] - s["traverse"]
        s["share %"] = 100 * s["framework"] / s["frame"]
        runs[key].append(s)
        img = np.asarray(res.image)
        if first is None:
            first = img
        same = same and np.array_equal(img, first)
        print(r, key, f"share {s['share %']:.2f}% framework {s['framework']:.3f} "
              f"traverse {s['traverse']:.3f}", flush=True)
print("every image bit-identical:", same)


def sp(v):
    return f"{statistics.median(v):8.4f} [{min(v):.4f}, {max(v):.4f}]"


print(f"  {'CPU s':<10}{'before':>28}{'after':>28}   after / before per round")
for st in runs["before"][0]:
    b = [x[st] for x in runs["before"]]
    a = [x[st] for x in runs["after"]]
    if min(b) == 0:
        continue
    print(f"  {st:<10}{sp(b):>28}{sp(a):>28}   {sp([y / x for x, y in zip(b, a)])}")
