"""Run hostile-plugin cases in this process; one JSON line per case on stdout.

    python run_cases.py CASE [CASE ...]

Before a case it prints ``{"start": CASE}`` and after it ``{"case": CASE, ...}``
(flushed), so the parent can name the case during which this process died.
Each case registers its plugin in process and renders a small plane with a
point light (generator, sorter, traversal, shader and shadow rays all run);
sorters and traversals also trace a batch of random rays, closest and any hit,
on one and on two threads.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import raysort                                                   # noqa: E402
from raysort.camera import Camera                                # noqa: E402
from raysort.procedural import PLANE_CAMERA, plane_under_sky    # noqa: E402
from raysort.scene import PointLight, Scene                      # noqa: E402

from hostile_plugins import CASES                                # noqa: E402


def make_scene():
    mesh = plane_under_sky(size=40.0)
    return Scene.from_mesh(mesh.vertices, mesh.faces, camera=Camera(**PLANE_CAMERA),
                           albedo=0.5, lights=[PointLight((0, 3, 0), (5, 5, 5))],
                           name="hostile plane")


def make_rays(n=5000):
    rng = np.random.default_rng(3)
    origins = rng.uniform(-5, 5, (n, 3)) + [0, 6, 0]
    directions = rng.normal(size=(n, 3)) - [0, 1.5, 0]
    return raysort.RayBatch.from_arrays(origins, directions)


def exercise(kind, name, scene, rays):
    # nah's sub-packets of every size leave padding lanes for a broken traversal to
    # write into (the default sorter's full 64-ray packets may leave none)
    plugins = {"sorter": "nah", kind[:-1]: name}
    pipe = raysort.Pipeline(scene, **plugins, check_plugins=False)
    pipe.render(40, 24, 2, seed=1)
    if kind in ("sorters", "traversals"):
        for any_hit in (False, True):
            for threads in (1, 2):
                pipe.trace(rays, [0, 4500, 5000], any_hit=any_hit, threads=threads)


def main(names):
    scene, rays = make_scene(), make_rays()
    for name in names:
        kind, cls, _ = CASES[name]
        print(json.dumps({"start": name}), flush=True)
        raysort.register(kind, name, cls)
        try:
            exercise(kind, name, scene, rays)
            result = {"case": name, "outcome": "ok"}
        except BaseException as exc:          # report everything, signals aside
            result = {"case": name, "outcome": type(exc).__name__, "message": str(exc),
                      "raysort_error": isinstance(exc, raysort.RaysortError),
                      "plugin": getattr(exc, "name", None), "kind": getattr(exc, "kind", None)}
        finally:
            raysort.unregister(kind, name)
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
