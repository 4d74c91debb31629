"""The ``lambert`` shader's bounce directions, held against the cosine law they must follow.

A Lambertian path tracer that samples the BRDF must send its bounce rays in directions
whose density is cos(theta) / pi over the hemisphere of the facing normal: then
cos^2(theta) is uniform on (0, 1] and the azimuth is uniform on a whole turn, jointly.
The directions come from a real render (the ``diffuse`` workload of the Cornell box, many
normals); the normals from the scene's faces and brute-force hits, independently of the
shader.  The furnace and the analytic images (tests/test_pipeline.py) check the weights.
"""
import numpy as np
import pytest

import raysort
from raysort.camera import Camera
from raysort.errors import PluginContractError
from raysort.procedural import PLANE_CAMERA, plane_under_sky
from raysort.rays import MAX_PACKET, RayRow
from raysort.scene import PointLight, Scene
from raysort.reference import brute_force
from raysort.shaders import lambert
from raysort.workloads import workload

SIZE = dict(width=64, height=64, spp=8, seed=11, tile=32)
COS2_BINS, PHI_BINS = 10, 12


@pytest.fixture(scope="module")
def bounce():
    """(directions, facing normals), float64 (3, n), of the first bounce of a render."""
    cornell = raysort.load_scene("cornell")
    primary = workload(cornell, "primary", **SIZE)
    rays = workload(cornell, "diffuse", **SIZE).rays
    prim = np.concatenate([     # brute force, a large packet at a time
        brute_force(cornell.vertices, cornell.faces,
                    primary.rays.take(np.arange(a, min(a + MAX_PACKET, len(primary))))).prim
        for a in range(0, len(primary), MAX_PACKET)])
    hit = np.flatnonzero(prim >= 0)
    assert len(rays) == len(hit) > 20_000
    nrm = cornell.face_normals()[prim[hit]].T.astype(np.float64)
    nrm *= np.where((nrm * primary.rays.directions[:, hit]).sum(axis=0) > 0, -1.0, 1.0)
    return rays.directions.astype(np.float64), nrm


def cos2_and_azimuth(directions, nrm):
    """cos^2 of the angle to the normal, and the azimuth in a tangent frame of our own."""
    helper = np.where(np.abs(nrm[0]) < 0.9, [[1.0], [0.0], [0.0]], [[0.0], [1.0], [0.0]])
    t1 = np.cross(helper.T, nrm.T).T
    t1 /= np.linalg.norm(t1, axis=0)
    t2 = np.cross(nrm.T, t1.T).T
    cos = (directions * nrm).sum(axis=0)
    phi = np.arctan2((directions * t2).sum(axis=0), (directions * t1).sum(axis=0))
    return cos, cos * cos, phi


def chi_square(a, b):
    """Pearson's statistic of the joint histogram of a in [0, 1] and b in [-pi, pi]
    against the uniform one, and its degrees of freedom."""
    i = np.minimum((a * COS2_BINS).astype(int), COS2_BINS - 1)
    j = np.minimum(((b + np.pi) / (2 * np.pi) * PHI_BINS).astype(int), PHI_BINS - 1)
    counts = np.bincount(i * PHI_BINS + j, minlength=COS2_BINS * PHI_BINS)
    expected = len(a) / (COS2_BINS * PHI_BINS)
    return ((counts - expected) ** 2 / expected).sum(), COS2_BINS * PHI_BINS - 1


def test_bounce_directions_are_unit_length(bounce):
    directions, _ = bounce
    np.testing.assert_allclose(np.linalg.norm(directions, axis=0), 1.0, rtol=0, atol=1e-6)


def test_bounce_directions_are_cosine_distributed(bounce):
    """cos^2(theta) and the azimuth are jointly uniform: a chi-square over 10 x 12 bins
    stays within six standard deviations of its mean (a generous bound for a fixed seed),
    while cos(theta), which is not uniform under the cosine law, fails the same test."""
    cos, cos2, phi = cos2_and_azimuth(*bounce)
    assert (cos > 0).all()
    stat, dof = chi_square(cos2, phi)
    bound = dof + 6 * np.sqrt(2 * dof)
    assert stat < bound
    wrong, _ = chi_square(cos, phi)       # what a uniform-hemisphere sampler would pass
    assert wrong > 10 * bound


def numpy_face_records(scene):
    """The face records and the emitters' table as NumPy statements (lambert.pyx): normal,
    the emitter row (int32 bits, -1 for none) and albedo; the emitting faces' emission."""
    at = lambert.FACE_LAYOUT
    records = np.zeros((len(scene.faces), at["floats"]), np.float32)
    records[:, at["normal"]:at["normal"] + 3] = scene.face_normals()
    records[:, at["albedo"]:at["albedo"] + 3] = scene.albedo
    emits = (scene.emission != 0).any(axis=1)
    row = np.where(emits, np.cumsum(emits) - 1, -1).astype(np.int32)
    records.view(np.int32)[:, at["emitter"]] = row
    emitters = np.zeros((emits.sum(), 4), np.float32)
    emitters[:, :3] = scene.emission[emits]
    return records, emitters


def degenerate_mesh_scene():
    """Random triangles with zero-area faces (repeated and collinear vertices) and emitters."""
    rng = np.random.default_rng(5)
    vertices = rng.normal(0, 1e3, (300, 3)).astype(np.float32)
    vertices[10:20] = vertices[0]                       # repeated vertices
    vertices[20:30] = vertices[1] + np.float32(2) * (vertices[1] - vertices[0])
    faces = rng.integers(0, 300, (2000, 3)).astype(np.int32)
    faces[:50, 1] = faces[:50, 0]                       # zero area
    emission = np.where(rng.random((2000, 1)) < 0.1, rng.random((2000, 3)), 0.0)
    emission[::7, :2] = 0.0                             # one channel only
    return raysort.Scene.from_mesh(vertices, faces, albedo=rng.random((2000, 3)),
                                   emission=emission)


@pytest.mark.parametrize("name", ["sibenik", "cornell", "forest", "furnace", "degenerate"])
def test_face_records_match_the_scene_bit_for_bit(name):
    """The one-pass face records equal ``Scene.face_normals`` and the scene's materials."""
    scene = degenerate_mesh_scene() if name == "degenerate" else raysort.load_scene(name)
    shader = lambert.LambertShader()
    shader.prepare(scene)
    _, records, emitters, *_ = shader._prepared
    want_records, want_emitters = numpy_face_records(scene)
    assert np.array_equal(records.view(np.uint32), want_records.view(np.uint32))
    assert np.array_equal(emitters.view(np.uint32), want_emitters.view(np.uint32))
    assert records.ctypes.data % (4 * lambert.FACE_LAYOUT["floats"]) == 0
    assert len(emitters) > 0 or name in ("sibenik", "forest")


def test_face_records_reject_an_emitters_table_of_the_wrong_size():
    scene = degenerate_mesh_scene()
    out = np.empty((len(scene.faces), lambert.FACE_LAYOUT["floats"]), np.float32)
    emitters = np.empty((np.count_nonzero(scene.emission.any(axis=1)), 4), np.float32)
    for rows in (emitters[1:], np.empty((len(emitters) + 1, 4), np.float32)):
        with pytest.raises(ValueError, match="one per emitting face"):
            lambert._face_records(scene.face_normals(), scene.albedo, scene.emission, out,
                                  rows)


@pytest.mark.parametrize("rows, capacity, n", [(3, 10, 7), (3, 10, 10), (3, 10, 0), (3, 0, 0),
                                               (1, 5, 3), (3, 1000, 999)])
def test_pack_rows_moves_each_rows_head_together(rows, capacity, n):
    """The (rows, n) heads of rows ``capacity`` apart, packed in place into a C-contiguous
    array (overlapping moves included): ``flat.reshape(rows, capacity)[:, :n]``."""
    flat = np.arange(rows * capacity, dtype=np.float32)
    want = flat.reshape(rows, capacity)[:, :n].copy()
    got = lambert._pack_rows(flat, rows, n)
    assert got.flags.c_contiguous and np.shares_memory(got, flat) or got.size == 0
    assert got.shape == (rows, n) and np.array_equal(got, want)
    with pytest.raises(ValueError):
        lambert._pack_rows(flat, rows, capacity + 1)


def test_the_next_throughput_is_contiguous():
    """A bounce's throughput comes back C-contiguous (so the paths need not copy it),
    one column per next ray."""
    pipe = raysort.Pipeline("cornell")
    records = []
    pipe.render(16, 16, spp=2, tap=lambda r: records.append(r) if not r.shadow else None)
    first = records[0]
    radiance = np.zeros((16 * 16, 3))
    bounce = pipe.shader.shade(pipe.scene, first.rays, first.hits, first.paths, 0, 0, radiance)
    assert 0 < len(bounce.rays) < len(first.rays)       # some rays escape the box
    assert bounce.throughput.shape == (3, len(bounce.rays))
    assert bounce.throughput.flags.c_contiguous


def assert_padded(batch):
    """Every lane of ``batch``'s rows past its rays is inactive padding, as a new batch's."""
    pad = batch.data[:, len(batch):]
    expected = np.zeros_like(pad)
    expected[int(RayRow.tmin)] = np.inf
    expected[int(RayRow.tmax)] = -np.inf
    np.testing.assert_array_equal(pad, expected)


@pytest.mark.parametrize("name, more_lights", [("cornell", 0), ("cornell", 2), ("forest", 0)])
def test_shade_continues_every_hit_as_numpy_computes_it(each_isa, name, more_lights):
    """One ``shade`` call on every ISA, held against NumPy statements of the same
    float32 operations (lambert.pyx, _shading.pxd), on brute-force hits of which a random
    third in the batch's second half are turned into misses, so that runs of hits
    (copied row by row) and runs with gaps (ray by ray) both occur.  Each hit continues
    in order, from its hit point pushed off the facing normal, with the throughput times
    the face's albedo; each miss adds the sky; each light adds a shadow ray from the same
    point for each hit it lights, with its weight: hit by hit, and for one hit light by
    light (``more_lights`` added to the cornell box's one), so the parents ascend."""
    scene = raysort.load_scene(name)
    scene.lights += [PointLight((0.2 * i - 0.3, 0.8, 0.1 * i), (0.5 * i, 1.0, 0.7))
                     for i in range(more_lights)]
    rays = workload(scene, "primary", width=48, height=48, seed=4).rays
    n = len(rays)
    hits = raysort.Hits(n)
    for a in range(0, n, MAX_PACKET):
        part = brute_force(scene.vertices, scene.faces,
                           rays.take(np.arange(a, min(a + MAX_PACKET, n))))
        hits.t[a:a + len(part.t)], hits.prim[a:a + len(part.t)] = part.t, part.prim
    rng = np.random.default_rng(9)
    gone = (rng.random(n) < 1 / 3) & (np.arange(n) >= n // 2)
    hits.t[gone], hits.prim[gone] = np.inf, -1
    hit = np.flatnonzero(hits.prim >= 0)
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, hits.prim >= 0, 0]))).max()
    assert len(hit) > n // 2 and gone.sum() > n // 8
    assert runs >= 2 * 64 if name == "cornell" else runs < 64    # the forest's sky: gaps
    thr = rng.uniform(0.1, 1.0, (3, n)).astype(np.float32)
    paths = raysort.Paths(np.arange(n), np.zeros(n), np.arange(n), thr)
    radiance = np.zeros((n, 3))
    shader = lambert.LambertShader()
    bounce = shader.shade(scene, rays, hits, paths, 0, 7, radiance)

    np.testing.assert_array_equal(bounce.parent, hit)
    o, d, t = rays.origins[:, hit], rays.directions[:, hit], hits.t[hit]
    p = o + t * d
    nrm = scene.face_normals()[hits.prim[hit]].T.astype(np.float32)
    facing = nrm[0] * d[0] + nrm[1] * d[1] + nrm[2] * d[2]
    nrm = np.where(facing > 0, -nrm, nrm)
    eps = (np.float32(1) + np.abs(p).max(axis=0)) * np.float32(1 / 8192)
    start = p + eps * nrm
    out = bounce.rays
    assert_padded(out)
    np.testing.assert_array_equal(out.origins, start)
    np.testing.assert_array_equal(out.tmin, 0)
    np.testing.assert_array_equal(out.tmax, np.inf)
    assert ((out.directions * nrm).sum(axis=0) > 0).all()
    albedo = np.asarray(scene.albedo, np.float32)[hits.prim[hit]].T
    np.testing.assert_array_equal(bounce.throughput, thr[:, hit] * albedo)
    emitted = np.zeros((3, n), np.float32)
    emitted[:, ~gone & (hits.prim >= 0)] = np.asarray(scene.emission, np.float32)[
        hits.prim[hit]].T
    sky = np.asarray(scene.sky, np.float32)[:, None]
    added = np.where(hits.prim >= 0, thr * emitted, thr * sky).astype(np.float64)
    np.testing.assert_array_equal(radiance, added.T)
    if scene.lights:                # per hit (rows), per light (columns)
        pos = np.asarray([light.position for light in scene.lights], np.float32).T
        w = pos[:, None, :] - start[:, :, None]
        dist2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2]
        cosl = w[0] * nrm[0][:, None] + w[1] * nrm[1][:, None] + w[2] * nrm[2][:, None]
        lit = (cosl > 0) & (dist2 > 0)
        assert 0 < lit.sum() < lit.size
        dist = np.sqrt(dist2)
        inv = np.float32(1) / dist
        weight = cosl * inv * np.float32(1 / np.pi) / dist2
        intensity = np.asarray([light.intensity for light in scene.lights], np.float32).T
        contribution = (thr[:, hit] * albedo)[:, :, None] * intensity[:, None, :] * weight
        shadow = bounce.shadow
        assert_padded(shadow.rays)      # the lanes past its rays: no scratch left in them
        each = np.broadcast_to(hit[:, None], lit.shape)
        np.testing.assert_array_equal(shadow.parent, each[lit])
        np.testing.assert_array_equal(shadow.slot, each[lit])      # slot i is path i's
        np.testing.assert_array_equal(shadow.rays.origins,
                                      np.broadcast_to(start[:, :, None], w.shape)[:, lit])
        np.testing.assert_array_equal(shadow.rays.directions, (w * inv)[:, lit])
        np.testing.assert_array_equal(shadow.rays.tmin, 0)
        np.testing.assert_array_equal(shadow.rays.tmax, dist[lit])
        np.testing.assert_array_equal(shadow.contribution, contribution[:, lit])
    else:
        assert bounce.shadow is None


@pytest.mark.parametrize("check_plugins", [True, False])
def test_paths_breaking_the_bounce_contract_stop_the_render(each_isa, check_plugins):
    """``lambert`` checks the paths it makes as it writes them (the pipeline's
    ``check_bounce`` then reads only their types and shapes): a light so bright that
    its shadow rays' contributions overflow float32 stops the render with an error that
    names the shader and says it is the scene's light, from the kernel's check on every
    ISA, with or without the pipeline's checks; one a million times dimmer renders."""
    def scene(intensity):
        mesh = plane_under_sky(size=3.0)
        return Scene.from_mesh(mesh.vertices, mesh.faces, camera=Camera(**PLANE_CAMERA),
                               albedo=0.5, name="lit",
                               lights=[PointLight((0, 0.01, 0), (intensity,) * 3)])

    pipe = raysort.Pipeline(scene(3e38), check_plugins=check_plugins)
    with pytest.raises(PluginContractError, match="SceneError: a shadow ray's contribution "
                                                  "is not a float32 number.*too bright") as info:
        pipe.render(16, 16, spp=1)
    assert (info.value.kind, info.value.name) == ("shaders", "lambert")
    image = raysort.Pipeline(scene(3e32), check_plugins=check_plugins).render(16, 16, 1).image
    assert np.isfinite(image).all() and image.max() > 1e32
