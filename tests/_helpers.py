"""Helpers shared by test modules (importable because tests/ is on sys.path)."""
import numpy as np

import raysort
from raysort.rays import RayBatch


def exact_traversals():
    """Installed traversals that promise brute force's hits bit for bit (``exact``);
    outside libraries such as Embree declare ``exact = False`` and are held to a
    tolerance in tests/traversals/test_inexact_traversals.py instead."""
    return [name for name in raysort.available("traversals")
            if raysort.load("traversals", name).exact]


def random_rays(rng, n, bounds, *, spread=1.5):
    """Rays from random points in (a box ``spread`` times) ``bounds`` toward random directions."""
    lo, hi = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * spread
    origins = centre + (rng.random((n, 3)) * 2 - 1) * half
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return RayBatch.from_arrays(origins, directions)


def batch(origins, directions, tmin=0.0, tmax=np.inf):
    """A RayBatch from lists of origins and directions (float32)."""
    return RayBatch.from_arrays(np.asarray(origins, np.float32),
                                np.asarray(directions, np.float32), tmin, tmax)


def concat(*batches):
    """One RayBatch holding the rays of several, in order."""
    out = RayBatch(sum(len(b) for b in batches))
    out.data[:, :len(out)] = np.concatenate([b.data[:, :len(b)] for b in batches], axis=1)
    return out


def assert_same_hits(hits, ref, label=""):
    """Same prim everywhere; same t bit for bit; same u, v where hit."""
    bad = np.flatnonzero(hits.prim != ref.prim)
    assert len(bad) == 0, (f"{label}: {len(bad)} rays hit another primitive, e.g. ray {bad[0]}: "
                           f"{hits.prim[bad[0]]} (t={hits.t[bad[0]]!r}) vs brute force "
                           f"{ref.prim[bad[0]]} (t={ref.t[bad[0]]!r})")
    assert np.array_equal(hits.t.view(np.uint32), ref.t.view(np.uint32)), f"{label}: t differs"
    hit = ref.prim >= 0
    assert np.array_equal(hits.u[hit].view(np.uint32), ref.u[hit].view(np.uint32)), label
    assert np.array_equal(hits.v[hit].view(np.uint32), ref.v[hit].view(np.uint32)), label


def grid_scene(rng, g=8, zero_area=0):
    """A g x g grid of unit quads in z = 0 (shared edges and vertices), plus exact
    duplicates of 24 faces and ``zero_area`` degenerate triangles on its vertices, faces
    shuffled: rays through edges and vertices tie at equal t."""
    ii, jj = np.meshgrid(np.arange(g + 1), np.arange(g + 1), indexing="ij")
    V = np.column_stack([ii.ravel(), jj.ravel(), np.zeros(ii.size)]).astype(np.float32)
    k = lambda i, j: i * (g + 1) + j  # noqa: E731
    F = np.array([f for i in range(g) for j in range(g)
                  for f in ([k(i, j), k(i + 1, j), k(i + 1, j + 1)],
                            [k(i, j), k(i + 1, j + 1), k(i, j + 1)])], np.int32)
    flat = np.arange(zero_area, dtype=np.int32)
    F = np.vstack([F, F[rng.choice(len(F), 24, replace=False)],
                   np.column_stack([flat, flat, flat + 1])])
    return V, F[rng.permutation(len(F))]


def grid_tie_rays(rng, n):
    """``n`` rays down onto :func:`grid_scene`'s grid, each hitting a vertex, an edge
    midpoint or a quad centre exactly (dyadic coordinates)."""
    target = rng.integers(0, 17, size=(n, 2)) / 2.0       # vertices, edge midpoints, centres
    d = np.column_stack([rng.choice([-2, -1, -0.5, 0.5, 1, 2], size=(n, 2)), np.full(n, -4.0)])
    o = np.column_stack([target - d[:, :2] * 1.25, np.full(n, 5.0)])   # exact dyadic hits
    return batch(o, d)


def tie_case(rng, coherent=False):
    """:func:`grid_scene` with 20 zero-area triangles, 3000 :func:`grid_tie_rays` (in
    chunks of one direction with ``coherent``) and brute force's hits, every ray a hit:
    (V, F, rays, hits)."""
    from raysort.reference import brute_force

    V, F = grid_scene(rng, zero_area=20)
    rays = grid_tie_rays(rng, 3000)
    if coherent:
        rays = rays.take(np.lexsort(rays.directions[:2]))
    ref = brute_force(V, F, rays)
    assert (ref.prim >= 0).all()
    return V, F, rays, ref


def trace_one_call(name, bvh, rays, any_hit=False, size=None):
    """Trace ``rays`` in input order with traversal ``name`` in one call, in sub-packets
    of ``size`` rays (one sub-packet if None); returns (hits or occluded flags, counters)."""
    from raysort.rays import gather, scatter, scatter_occluded

    n = len(rays)
    offsets = np.array([0, n], np.int32) if size is None else \
        np.append(np.arange(0, n, size), n).astype(np.int32)
    packets = gather(rays, np.arange(n, dtype=np.int32), offsets)
    counters = raysort.create("traversals", name).intersect(bvh, packets, any_hit=any_hit)
    hits = scatter_occluded(packets, n) if any_hit else scatter(packets, n)
    return hits, counters


def triangle_soup(rng, m=600):
    """Random triangles of mixed sizes, a fifth of them on one floor (boxes of zero
    height)."""
    centres = rng.random((m, 1, 3)) * 10
    V = (centres + rng.normal(size=(m, 3, 3)) * rng.choice([0.05, 0.5, 2.0], (m, 1, 1)))
    V[: m // 5, :, 1] = 3.0
    return V.reshape(-1, 3).astype(np.float32), np.arange(3 * m, dtype=np.int32).reshape(m, 3)


def run(capsys, *argv):
    """``raysort.cli.main(argv)`` in process -> (exit code, stdout, stderr)."""
    from raysort.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(err, *fragments):
    """stderr is exactly one 'raysort: error: ...' line (no traceback) containing fragments."""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("raysort: error: "), err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def child_records(proc, name):
    """The JSON lines a child process running cases printed (``{"start": case}`` before
    each, its outcome after); the test fails, naming the case, if the child died."""
    import json
    import signal

    import pytest

    records = [json.loads(line) for line in proc.stdout.splitlines()]
    if proc.returncode:
        last = records[-1].get("start") if records else None
        code = proc.returncode
        pytest.fail(f"{name} died ({signal.Signals(-code).name if code < 0 else code}) "
                    f"on the case {last!r}:\n{proc.stderr[-2000:]}")
    return records
