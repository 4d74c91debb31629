"""The brute-force references (raysort.reference).

``brute_force`` (Cython) must equal ``brute_force_numpy`` (an independent
NumPy float32 transcription) bit for bit on awkward small scenes and rays;
both are then checked against analytic answers and a float64 computation that
shares no code with either.
"""
import numpy as np
import pytest

from raysort.rays import RayBatch
from raysort.reference import brute_force, brute_force_numpy

from _helpers import batch, concat, random_rays

F32 = np.float32


# ---------------------------------------------------------------------------
# scenes and rays
# ---------------------------------------------------------------------------

def grid(n, plane_axis, level, lo=0.0):
    """An n x n grid of unit quads (2 triangles each, shared edges) in the plane axis = level."""
    a, b = [k for k in range(3) if k != plane_axis]
    ii, jj = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    V = np.zeros(((n + 1) ** 2, 3), np.float32)
    V[:, a], V[:, b], V[:, plane_axis] = ii.ravel() + lo, jj.ravel() + lo, level
    k = lambda i, j: i * (n + 1) + j  # noqa: E731
    F = [f for i in range(n) for j in range(n)
         for f in ([k(i, j), k(i + 1, j), k(i + 1, j + 1)],
                   [k(i, j), k(i + 1, j + 1), k(i, j + 1)])]
    return V, np.array(F, np.int32)


def small_scene(rng):
    """A few hundred triangles: random ones, two axis-aligned grids with shared edges, a fan
    around one shared vertex, exact duplicates and zero-area triangles, in shuffled order."""
    parts = []
    m = 150
    c = rng.random((m, 1, 3)) * 8 + 1
    parts.append(((c + rng.normal(size=(m, 3, 3)) * 0.6).reshape(-1, 3),
                  np.arange(3 * m).reshape(m, 3)))
    parts.append(grid(6, 2, 2.0, lo=1.0))                 # z = 2, x, y in [1, 7]
    parts.append(grid(4, 0, 5.0, lo=2.0))                 # x = 5, y, z in [2, 6]
    angles = np.arange(8) * (np.pi / 4)
    ring = np.column_stack([4 + 2 * np.cos(angles), np.full(8, 7.0), 4 + 2 * np.sin(angles)])
    parts.append((np.vstack([[4.0, 7.0, 4.0], ring]),     # fan in y = 7 around (4, 7, 4)
                  np.array([[0, 1 + i, 1 + (i + 1) % 8] for i in range(8)])))
    p = rng.random((4, 3)) * 8 + 1
    parts.append((np.vstack([p, (p[0] + p[1]) / 2]),      # zero-area triangles
                  np.array([[0, 0, 0], [0, 1, 1], [0, 1, 4], [2, 3, 3], [1, 1, 2], [3, 2, 3]])))
    Vs, Fs, base = [], [], 0
    for V, F in parts:
        Vs.append(np.asarray(V, np.float32))
        Fs.append(np.asarray(F, np.int32) + base)
        base += len(V)
    V, F = np.vstack(Vs), np.vstack(Fs)
    F = np.vstack([F, F[m:m + 10]])                       # exact duplicates of grid triangles
    return V, F[rng.permutation(len(F))].astype(np.int32)


def awkward_rays(rng, V, F):
    """Random rays plus every awkward case the hit rule has to settle."""
    n = 200
    lo, hi = V.min(axis=0), V.max(axis=0)
    out = [random_rays(rng, 600, (lo, hi))]
    # exactly through grid vertices and edge midpoints of the z = 2 grid (ties between
    # triangles sharing an edge or a vertex; exact dyadic arithmetic)
    target = rng.integers(2, 15, size=(n, 2)) / 2.0
    d = np.column_stack([rng.choice([-2, -1, -0.5, 0.5, 1, 2], size=(n, 2)), np.full(n, -4.0)])
    o = np.column_stack([target - d[:, :2] * 1.25, np.full(n, 7.0)])
    out.append(batch(o, d))
    # through the fan's centre vertex
    o = np.array([4.0, 7.0, 4.0]) + rng.normal(size=(40, 3))
    out.append(batch(o, np.array([4.0, 7.0, 4.0]) - o))
    # starting exactly on a surface (the z = 2 and x = 5 grids), tmin = 0 and tmin > 0
    o = np.column_stack([rng.random((n, 2)) * 6 + 1, np.full(n, 2.0)])
    d = rng.normal(size=(n, 3))
    out.append(batch(o, d, tmin=0.0))
    out.append(batch(o, d, tmin=1e-3))
    o = np.column_stack([np.full(n, 5.0), rng.random((n, 2)) * 4 + 2])
    out.append(batch(o, d, tmin=rng.choice([0.0, 1e-6, 0.5], size=n)))
    # starting on grid vertices
    o = np.column_stack([rng.integers(1, 8, size=(n, 2)), np.full(n, 2.0)])
    out.append(batch(o, d, tmin=0.0))
    # parallel to faces: a direction component exactly 0 (+0 or -0), some lying in a grid plane
    d = rng.normal(size=(n, 3))
    axis = rng.integers(0, 3, size=n)
    d[np.arange(n), axis] = rng.choice([0.0, -0.0], size=n)
    o = lo + rng.random((n, 3)) * (hi - lo)
    in_plane = rng.random(n) < 0.5
    o[in_plane & (axis == 2), 2] = 2.0
    o[in_plane & (axis == 0), 0] = 5.0
    o[in_plane & (axis == 1), 1] = 7.0
    out.append(batch(o, d))
    d2 = np.zeros((n, 3))
    d2[np.arange(n), axis] = rng.choice([-1.0, 1.0], size=n)   # axis-aligned directions
    out.append(batch(o, d2))
    # degenerate directions and magnitudes: zero, subnormal, huge
    o = lo + rng.random((6, 3)) * (hi - lo)
    out.append(batch(o, [[0, 0, 0], [1e-45, 0, -1], [3e-39, 1, 0], [1e30, 1, 1],
                         [1e-30, 1e-30, 1e-30], [-3e38, 1, 1]]))
    return concat(*out)


def invalid_rays(rng, V):
    """Rays that must never hit: non-finite origin/direction, tmin >= tmax, bad tmin/tmax.
    Each would hit the scene if it were valid (it aims at the middle of it)."""
    rows = []
    centre = (V.min(axis=0) + V.max(axis=0)) / 2
    base_o = centre + np.array([0.3, 0.2, 20.0])
    base_d = np.array([0.01, 0.02, -1.0])
    for comp in range(6):
        for bad in (np.nan, np.inf, -np.inf):
            o, d = base_o.copy(), base_d.copy()
            (o if comp < 3 else d)[comp % 3] = bad
            rows.append((o, d, 0.0, np.inf))
    for tmin, tmax in [(5.0, 5.0), (30.0, 1.0), (0.0, 0.0), (-1.0, np.inf), (-1e-30, 50.0),
                       (np.nan, np.inf), (0.0, np.nan), (np.inf, np.inf), (-np.inf, np.inf),
                       (0.0, -1.0), (0.0, -np.inf)]:
        rows.append((base_o, base_d, tmin, tmax))
    o, d, tmin, tmax = (np.array(x) for x in zip(*rows))
    return batch(o, d, tmin.astype(F32), tmax.astype(F32))


def assert_bitwise_equal(a, b, label=""):
    """Same t, prim, u, v bit for bit on every ray (hits and misses)."""
    for field in ("prim", "t", "u", "v"):
        x, y = getattr(a, field), getattr(b, field)
        bad = np.flatnonzero(x.view(np.uint32) != y.view(np.uint32))
        assert len(bad) == 0, (f"{label}: {field} differs on {len(bad)} rays, e.g. ray {bad[0]}: "
                               f"{x[bad[0]]!r} vs {y[bad[0]]!r}")


@pytest.fixture(scope="module")
def scene():
    return small_scene(np.random.default_rng(2024))


# ---------------------------------------------------------------------------
# Cython == NumPy, bit for bit
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1])
def test_cython_equals_numpy(scene, seed):
    """brute_force and brute_force_numpy agree bit for bit on random and awkward rays."""
    V, F = scene
    rng = np.random.default_rng(seed)
    rays = awkward_rays(rng, V, F)
    hits = brute_force(V, F, rays)
    assert_bitwise_equal(hits, brute_force_numpy(V, F, rays), f"seed {seed}")
    hit = hits.prim >= 0
    assert 0.2 < hit.mean() < 0.95, "the rays must exercise both hits and misses"
    assert (hits.t[~hit] == np.inf).all()
    assert (hits.u[~hit] == 0).all() and (hits.v[~hit] == 0).all()


def test_cython_equals_numpy_random_soup():
    """Bit-for-bit agreement on a soup of tiny and huge random triangles."""
    rng = np.random.default_rng(7)
    m = 300
    size = rng.choice([1e-4, 1e-2, 1.0, 50.0], size=(m, 1, 1))
    V = (rng.random((m, 1, 3)) * 10 + rng.normal(size=(m, 3, 3)) * size).reshape(-1, 3)
    F = np.arange(3 * m, dtype=np.int32).reshape(m, 3)
    rays = random_rays(rng, 1000, (V.min(axis=0), V.max(axis=0)))
    assert_bitwise_equal(brute_force(V, F, rays), brute_force_numpy(V, F, rays))


def test_invalid_rays_miss(scene):
    """NaN / inf components, tmin >= tmax, negative or NaN tmin and NaN tmax: a miss in both."""
    V, F = scene
    rays = invalid_rays(np.random.default_rng(3), V)
    for hits in (brute_force(V, F, rays), brute_force_numpy(V, F, rays)):
        assert (hits.prim == -1).all(), np.flatnonzero(hits.prim != -1)
        assert (hits.t == np.inf).all()
        assert (hits.u == 0).all() and (hits.v == 0).all()
    assert not brute_force(V, F, rays, any_hit=True).any()
    # the same rays made valid do hit: the misses above come from the validity rule
    assert (brute_force(V, F, valid_twin(rays)).prim >= 0).all()


def valid_twin(rays):
    """The base ray of :func:`invalid_rays` repeated, valid (finite, 0 <= tmin < tmax)."""
    n = len(rays)
    return batch(np.repeat(rays.origins[:, -1:].T, n, 0),
                 np.repeat(rays.directions[:, -1:].T, n, 0))


def test_mixed_valid_and_invalid(scene):
    """Invalid rays interleaved with valid ones change nothing for the valid ones."""
    V, F = scene
    rng = np.random.default_rng(11)
    good = awkward_rays(rng, V, F)
    bad = invalid_rays(rng, V)
    rays = concat(good, bad)
    perm = rng.permutation(len(rays))
    rays = rays.take(perm)
    hits = brute_force(V, F, rays)
    assert_bitwise_equal(hits, brute_force_numpy(V, F, rays))
    ref = brute_force(V, F, good)
    inv = np.argsort(perm)
    for field in ("prim", "t", "u", "v"):
        assert np.array_equal(getattr(hits, field)[inv[:len(good)]].view(np.uint32),
                              getattr(ref, field).view(np.uint32))
    assert (hits.prim[inv[len(good):]] == -1).all()


# ---------------------------------------------------------------------------
# any hit
# ---------------------------------------------------------------------------

def test_any_hit_matches_closest(scene):
    """any_hit is True exactly where the closest-hit query finds a primitive."""
    V, F = scene
    rng = np.random.default_rng(5)
    rays = concat(awkward_rays(rng, V, F), invalid_rays(rng, V))
    closest = brute_force(V, F, rays)
    occluded = brute_force(V, F, rays, any_hit=True)
    assert occluded.dtype == bool and occluded.shape == (len(rays),)
    assert np.array_equal(occluded, closest.prim >= 0)


def test_any_hit_with_shadow_tmax(scene):
    """With tmax limited (shadow rays), a ray is occluded iff its closest hit lies below tmax."""
    V, F = scene
    rng = np.random.default_rng(6)
    rays = awkward_rays(rng, V, F)
    t = brute_force(V, F, rays).t
    finite = np.isfinite(t)
    choice = rng.integers(0, 4, size=len(rays))
    tmax = np.where(choice == 0, t,                                      # exactly at the hit
           np.where(choice == 1, np.nextafter(t, F32(np.inf)),           # just beyond it
           np.where(choice == 2, t * F32(0.5), rng.random(len(rays)) * 20))).astype(F32)
    tmax[~finite & (choice < 3)] = 10.0
    rays.tmax[:] = tmax
    # the closest hit in (tmin, inf) is t, so one in (tmin, tmax) exists iff t < tmax
    # (tmax <= tmin makes the ray invalid, and then t > tmin >= tmax too)
    expected = t < tmax
    assert expected.sum() > 100 and (~expected & finite).sum() > 100
    assert np.array_equal(brute_force(V, F, rays, any_hit=True), expected)
    closest = brute_force(V, F, rays)
    assert np.array_equal(closest.prim >= 0, expected)
    assert_bitwise_equal(closest, brute_force_numpy(V, F, rays))


# ---------------------------------------------------------------------------
# analytic checks, independent of both implementations
# ---------------------------------------------------------------------------

H = 2.5
SQUARE_V = np.array([[0, H, 0], [1, H, 0], [1, H, 1], [0, H, 1]], np.float32)
# triangle 0 covers z <= x, triangle 1 covers z >= x; they share the diagonal x == z
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]], np.int32)


def both(V, F, rays):
    a, b = brute_force(V, F, rays), brute_force_numpy(V, F, rays)
    assert_bitwise_equal(a, b)
    return a


def test_axis_aligned_square_exact_t():
    """Straight down (and up) onto the unit square at y = 2.5: t, prim, u, v are exact."""
    rays = batch([[0.25, 10, 0.625], [0.75, 10, 0.125], [0.25, 10, 0.625], [0.25, -1.5, 0.625]],
                 [[0, -1, 0], [0, -1, 0], [0, -2, 0], [0, 1, 0]])
    hits = both(SQUARE_V, SQUARE_F, rays)
    assert hits.prim.tolist() == [1, 0, 1, 1]
    assert hits.t.tolist() == [7.5, 7.5, 3.75, 4.0]
    # triangle 1: P = v0 + u (1, 0, 1) + v (0, 0, 1) -> u = x, v = z - x
    # triangle 0: P = v0 + u (1, 0, 0) + v (1, 0, 1) -> v = z, u = x - z
    assert hits.u.tolist() == [0.25, 0.625, 0.25, 0.25]
    assert hits.v.tolist() == [0.375, 0.125, 0.375, 0.375]


def test_open_interval_at_tmin_and_tmax():
    """A hit at exactly tmin or exactly tmax is rejected; one ulp inside is accepted."""
    t = F32(7.5)
    below, above = np.nextafter(t, F32(0)), np.nextafter(t, F32(np.inf))
    o, d = [[0.25, 10, 0.625]] * 4, [[0, -1, 0]] * 4
    rays = batch(o, d, tmin=np.array([0, below, t, 0], F32),
                 tmax=np.array([t, np.inf, np.inf, above], F32))
    hits = both(SQUARE_V, SQUARE_F, rays)
    assert hits.prim.tolist() == [-1, 1, -1, 1]


def test_shared_edge_reports_lower_index():
    """A ray through the shared diagonal hits both triangles at equal t: the lower index wins."""
    rays = batch([[0.5, 10, 0.5], [0.25, 10, 0.25], [0, 10, 0], [1, 10, 1]], [[0, -1, 0]] * 4)
    hits = both(SQUARE_V, SQUARE_F, rays)
    assert hits.prim.tolist() == [0, 0, 0, 0] and (hits.t == 7.5).all()
    swapped = both(SQUARE_V, SQUARE_F[::-1].copy(), rays)    # the same triangles, reversed
    assert swapped.prim.tolist() == [0, 0, 0, 0] and (swapped.t == 7.5).all()
    # each triangle alone is hit by the same rays (so the tie is real)
    for k in range(2):
        assert (both(SQUARE_V, SQUARE_F[k:k + 1], rays).prim == 0).all()


def test_shared_vertex_fan_reports_lowest_index():
    """A ray through the centre vertex of a fan hits all 8 triangles: the lowest index wins."""
    rng = np.random.default_rng(1)
    ring = [[1, 0, 0], [1, 1, 0], [0, 1, 0], [-1, 1, 0], [-1, 0, 0], [-1, -1, 0], [0, -1, 0],
            [1, -1, 0]]
    V = np.array([[0, 0, 0]] + ring, np.float32)
    F = np.array([[0, 1 + i, 1 + (i + 1) % 8] for i in range(8)])
    for perm in (np.arange(8), rng.permutation(8), rng.permutation(8)):
        rays = batch([[0, 0, 3], [0, 0, -2]], [[0, 0, -1], [0, 0, 1]])
        hits = both(V, F[perm], rays)
        assert hits.prim.tolist() == [0, 0] and hits.t.tolist() == [3.0, 2.0]


def test_ray_just_outside_misses():
    """One ulp across an edge or a corner of a triangle misses; one ulp inside hits."""
    tri = SQUARE_F[:1]                                   # z <= x, 0 <= x <= 1
    half, one = F32(0.5), F32(1.0)
    up, down = np.nextafter(half, F32(1)), np.nextafter(half, F32(0))
    points = [(half, up),                                # above the diagonal: outside
              (half, down),                              # below it: inside
              (np.nextafter(one, F32(2)), half),         # beyond x = 1: outside
              (np.nextafter(one, F32(0)), half),         # inside
              (half, np.nextafter(F32(0), F32(-1))),     # below z = 0: outside
              (half, F32(0))]                            # on the edge z = 0: inside
    o = [[x, 10, z] for x, z in points]
    hits = both(SQUARE_V, tri, batch(o, [[0, -1, 0]] * len(o)))
    assert hits.prim.tolist() == [-1, 0, -1, 0, -1, 0]


def test_zero_area_and_in_plane_rays_never_hit():
    """Zero-area triangles are never hit, and a ray lying in a triangle's plane misses it."""
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], np.float32)
    F = np.array([[0, 1, 2], [0, 0, 0], [1, 1, 3], [0, 2, 0]], np.int32)  # all degenerate
    rays = batch([[0.5, 0, 1], [1, 0, 1], [0, 0, 1], [0.5, 0.5, 1]], [[0, 0, -1]] * 4)
    assert (both(V, F, rays).prim == -1).all()
    flat = np.array([[0, 1, 3]], np.int32)               # a real triangle in z = 0
    in_plane = batch([[-1, 0.25, 0], [0.25, -1, 0]], [[1, 0, 0], [0, 1, 0]])
    assert (both(V, flat, in_plane).prim == -1).all()
    assert (both(V, flat, batch([[0.25, 0.25, 1]], [[0, 0, -1]])).prim == 0).all()


def test_zero_area_triangle_with_repeated_vertex_never_hit():
    """A triangle whose last two vertices coincide has zero area and must never be hit
    (``Scene.degenerate_faces``: "they are kept and never hit").

    Here det = e1 . (d x e2) with e1 == e2 is 0 in exact arithmetic but rounds to a tiny
    non-zero value, and the kernel reports a hit at t = 0.5 whose point (1.15, 3.625, 5.455)
    is not even on the segment v0-v1."""
    V = np.array([[0.2, 1.65, 3.11], [5.32, 3.63, 8.83], [5.32, 3.63, 8.83]], np.float32)
    F = np.array([[0, 1, 2]], np.int32)
    rays = batch([[2.1, 5.6, 7.8]], [[-1.9, -3.95, -4.69]])
    hits = both(V, F, rays)
    assert hits.prim.tolist() == [-1], f"zero-area triangle hit at t={hits.t[0]}"
    assert not brute_force(V, F, rays, any_hit=True)[0]


def test_closest_hit_against_float64(scene):
    """Where a float64 Moller-Trumbore has a clear winner, brute force reports it (t to 1e-4)."""
    V, F = scene
    rng = np.random.default_rng(9)
    rays = random_rays(rng, 2000, (V.min(axis=0), V.max(axis=0)))
    hits = brute_force(V, F, rays)
    o, d = rays.origins.T.astype(float)[:, None], rays.directions.T.astype(float)[:, None]
    tri = V.astype(float)[F]
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("tk,rtk->rt", e1, p)
    with np.errstate(all="ignore"):
        s = o - v0
        u = np.einsum("rtk,rtk->rt", s, p) / det
        q = np.cross(s, e1)
        v = np.einsum("rtk,rtk->rt", d, q) / det
        t = np.einsum("tk,rtk->rt", e2, q) / det
    eps = 1e-5
    with np.errstate(invalid="ignore"):
        inside = (np.abs(det) > 1e-9) & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > 1e-4)
        near = (np.abs(det) > 1e-9) & (u > -eps) & (v > -eps) & (u + v < 1 + eps) & (t > -1e-4)
    t_in = np.where(inside, t, np.inf)
    t_near = np.where(near, t, np.inf)
    best = np.argmin(t_in, axis=1)
    best_t = t_in[np.arange(len(best)), best]
    t_near[np.arange(len(best)), best] = np.inf
    clear = np.isfinite(best_t) & (t_near.min(axis=1) > best_t * (1 + 1e-3))
    nothing = ~np.isfinite(t_near).any(axis=1) & ~np.isfinite(best_t)
    assert clear.sum() > 200 and nothing.sum() > 500
    assert np.array_equal(hits.prim[clear], best[clear])
    np.testing.assert_allclose(hits.t[clear], best_t[clear], rtol=1e-4)
    assert (hits.prim[nothing] == -1).all()
    # the reported (t, u, v) describe the same point
    h = hits.prim >= 0
    P_ray = o[h, 0] + hits.t[h, None] * d[h, 0]
    k = hits.prim[h]
    P_tri = v0[k] + hits.u[h, None] * e1[k] + hits.v[h, None] * e2[k]
    np.testing.assert_allclose(P_ray, P_tri, atol=1e-3)


def test_empty_and_padding():
    """An empty batch gives empty hits; a batch of 5 (3 padding lanes) gives exactly 5 results."""
    empty = RayBatch(0)
    assert len(brute_force(SQUARE_V, SQUARE_F, empty)) == 0
    assert len(brute_force(SQUARE_V, SQUARE_F, empty, any_hit=True)) == 0
    rays = batch([[0.25, 10, 0.625]] * 5, [[0, -1, 0]] * 5)
    hits = both(SQUARE_V, SQUARE_F, rays)
    assert len(hits) == 5 and (hits.prim == 1).all()
