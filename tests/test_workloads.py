"""The workload kinds (primary, ao, diffuse, shadow): each checked against what it must be,
computed independently (camera geometry, brute-force hits, the light positions)."""
import numpy as np
import pytest

import raysort
from raysort.reference import brute_force
from raysort.workloads import KINDS, Workload, bounce_rays, camera_rays, workload

SIZE = dict(width=40, height=24, spp=2, seed=4, tile=16)


def hits_of(scene, work):
    return brute_force(scene.vertices, scene.faces, work.rays)


def facing_normals(scene, prim, directions):
    """Unit face normals (float64, (3, n)) turned against the incoming directions."""
    nrm = scene.face_normals()[prim].T.astype(np.float64)
    return nrm * np.where((nrm * directions).sum(axis=0) > 0, -1.0, 1.0)


def packet_of(packets, n):
    return np.searchsorted(packets, np.arange(n), side="right") - 1


@pytest.fixture(scope="module")
def cornell():
    return raysort.load_scene("cornell")


def test_the_four_kinds():
    assert list(KINDS) == ["primary", "ao", "diffuse", "shadow"]
    assert [KINDS[k].any_hit for k in KINDS] == [False, True, False, True]


def test_primary_rays_go_through_their_pixel_centres(cornell):
    """Without jitter each ray points at its pixel's centre (computed here from the camera
    frame); each large packet is one sample pass over one tile, Morton ordered."""
    work, paths = camera_rays(cornell, generator="pinhole:jitter=False", **SIZE)
    assert isinstance(work, Workload) and not work.any_hit
    assert len(work) == 40 * 24 * 2
    eye, fwd, right, up = (v.astype(np.float64) for v in cornell.camera.frame(40, 24))
    x, y = paths.pixel % 40, paths.pixel // 40
    d = (fwd[:, None] + (2 * (x + 0.5) / 40 - 1) * right[:, None]
         + (1 - 2 * (y + 0.5) / 24) * up[:, None])
    d /= np.linalg.norm(d, axis=0)
    np.testing.assert_allclose(work.rays.directions, d, atol=2e-6)
    np.testing.assert_array_equal(work.rays.origins, np.repeat(eye[:, None], len(work), 1))
    sizes = np.diff(work.packets)
    # tiles of 16: 3 x 2 tiles (the last column 8 wide, the last row 8 high), 2 passes each
    np.testing.assert_array_equal(sizes, np.repeat([256, 256, 128, 128, 128, 64], 2))
    for k in range(len(sizes)):
        a, b = work.packets[k], work.packets[k + 1]
        assert len(set(paths.sample[a:b].tolist())) == 1, "one sample pass per large packet"
        px, py = x[a:a + 4], y[a:a + 4]         # Morton order: a 2x2 square first
        assert sorted(zip(px - px.min(), py - py.min())) == [(0, 0), (0, 1), (1, 0), (1, 1)]
        assert len(set(paths.pixel[a:b].tolist())) == b - a


@pytest.mark.parametrize("depth", [1, 2])
def test_diffuse_rays_leave_every_hit_of_the_previous_depth(cornell, depth):
    """Depth k rays: one per hit of the depth k-1 rays (brute force), starting at the hit
    point, into the hemisphere the ray came from, in their parents' large packets."""
    prev = workload(cornell, "primary", **SIZE) if depth == 1 else \
        workload(cornell, f"diffuse:depth={depth - 1}", **SIZE)
    work = workload(cornell, f"diffuse:depth={depth}", **SIZE)
    assert work.label == f"cornell diffuse:depth={depth}" and not work.any_hit
    hits = hits_of(cornell, prev)
    hit = np.flatnonzero(hits.prim >= 0)
    assert len(work) == len(hit) > 0
    point = prev.rays.origins[:, hit] + hits.t[hit] * prev.rays.directions[:, hit]
    np.testing.assert_allclose(work.rays.origins, point, atol=1e-3)
    nrm = facing_normals(cornell, hits.prim[hit], prev.rays.directions[:, hit])
    assert ((work.rays.directions * nrm).sum(axis=0) > 0).all()
    per_packet = np.bincount(packet_of(prev.packets, len(prev))[hit],
                             minlength=len(prev.packets) - 1)
    # a tile's batch (its 2 passes) whose rays all missed traces nothing and adds no packets
    per_tile = per_packet.reshape(-1, 2)
    np.testing.assert_array_equal(np.diff(work.packets), per_tile[per_tile.sum(1) > 0].ravel())
    assert np.isinf(work.rays.tmax).all()


def test_shadow_rays_end_at_the_lights(cornell):
    """One ray per primary hit whose facing side sees the light, ending at the light."""
    primary = workload(cornell, "primary", **SIZE)
    work = workload(cornell, "shadow", **SIZE)
    assert work.any_hit and work.label == "cornell shadow:depth=0"
    light = np.array(cornell.lights[0].position)
    hits = hits_of(cornell, primary)
    hit = np.flatnonzero(hits.prim >= 0)
    point = primary.rays.origins[:, hit] + hits.t[hit] * primary.rays.directions[:, hit]
    nrm = facing_normals(cornell, hits.prim[hit], primary.rays.directions[:, hit])
    sees = ((light[:, None] - point) * nrm).sum(axis=0) > 1e-4
    assert 0 < len(work) and abs(len(work) - sees.sum()) <= 2   # grazing cases may differ
    end = work.rays.origins + work.rays.tmax * work.rays.directions
    np.testing.assert_allclose(end, np.repeat(light[:, None], len(work), 1), atol=1e-4)
    deeper = workload(cornell, "shadow:depth=1", **SIZE)
    assert len(deeper) > 0 and deeper.label == "cornell shadow:depth=1"


def test_counts_match_the_render_they_come_from(cornell):
    """A render's own statistics count the same rays as the workloads of its settings."""
    pipe = raysort.Pipeline(cornell, shader={"type": "lambert", "max_depth": 2,
                                             "shadow_rays": True}, tile=16)
    stats = pipe.render(40, 24, spp=2, seed=4).stats
    assert len(workload(cornell, "primary", **SIZE)) == stats.rays[0]
    assert len(workload(cornell, "diffuse", **SIZE)) == stats.rays[1]
    assert len(workload(cornell, "diffuse:depth=2", **SIZE)) == stats.rays[2]
    shadows = sum(len(workload(cornell, f"shadow:depth={d}", **SIZE)) for d in range(3))
    assert shadows == stats.shadow_rays
    ao = raysort.Pipeline(cornell, shader="ao:samples=3", tile=16).render(40, 24, 2, 4).stats
    assert len(workload(cornell, "ao:samples=3", **SIZE)) == ao.shadow_rays


def test_same_workload_for_any_thread_count(cornell):
    one = workload(cornell, "diffuse", **SIZE)
    two = workload(cornell, "diffuse", threads=2, **SIZE)
    np.testing.assert_array_equal(one.packets, two.packets)
    assert np.array_equal(one.rays.data.view(np.uint32), two.rays.data.view(np.uint32))


def test_dict_specs_and_the_old_helpers(cornell):
    a = workload(cornell, {"type": "diffuse", "depth": 1}, **SIZE)
    size = {k: v for k, v in SIZE.items()}
    b = bounce_rays(cornell, depth=1, **size)
    np.testing.assert_array_equal(a.packets, b.packets)
    np.testing.assert_array_equal(a.rays.data, b.rays.data)


def test_scene_without_lights_says_so():
    scene = raysort.Scene.from_mesh([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)], name="tri")
    with pytest.raises(raysort.ConfigError, match="scene 'tri' has no point lights"):
        workload(scene, "shadow", width=4, height=4)


@pytest.mark.parametrize("spec, message", [
    ("secondary", "unknown workload kind 'secondary'; kinds: primary, ao, diffuse, shadow"),
    ("diffuse:depth=0", "depth must be an integer in 1..64"),
    ("shadow:depth=-1", "depth must be an integer in 0..64"),
    ("primary:depth=1", "'primary' does not take 'depth' \\(it takes: no parameters\\)"),
    ("ao:radius=2", "'ao' does not take 'radius' \\(it takes: samples, distance\\)"),
    ("ao:samples=0", "samples must be an integer in 1..256"),
])
def test_bad_kinds_are_config_errors(cornell, spec, message):
    with pytest.raises(raysort.ConfigError, match=message):
        workload(cornell, spec, width=4, height=4)
