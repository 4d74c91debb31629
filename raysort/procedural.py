"""Procedural triangle meshes that need no files.

These scenes are built into raysort: they serve as benchmark stand-ins when no
scene file is at hand and as test scenes whose correct image is known
analytically.  Everything is pure NumPy, deterministic (a fixed seed gives
identical arrays on every run) and vectorised over triangles.

Scenes
------
forest
    An outdoor scene standing in for the "Fairy Forest" benchmark: about
    170,000 triangles of undulating ground, tapered tree trunks with branches,
    many small randomly oriented leaf quads and grass tufts, open sky above.
    Incoherent secondary rays (leaves scatter in every direction) make it the
    stress test for ray sorting.  Seen from :data:`FOREST_CAMERA`.
furnace
    A closed icosphere that both emits and reflects uniformly (a "white
    furnace").  From :data:`FURNACE_CAMERA`, at the centre, every pixel must
    converge to ``emission * sum(albedo**k) = emission / (1 - albedo)``; any
    deviation is an energy loss or gain in the integrator.
cornell
    The classic Cornell box (unit size, open front) with a short and a tall
    block and a small area light below the ceiling.  A familiar, closed scene
    for visual regression.  Seen from :data:`CORNELL_CAMERA`.
plane
    One large square at ``y = 0``.  Under a uniform sky of radiance ``L`` every
    point of a diffuse plane reflects ``albedo * L`` (nothing above the plane
    occludes the sky), so every pixel seen from :data:`PLANE_CAMERA` has a
    known value.

Conventions
-----------
+y is up and units are about metres.  Every generator returns a
:class:`MeshData`.  Faces are wound counter-clockwise seen from the side their
normal ``cross(v1 - v0, v2 - v0)`` points to; closed solids (icospheres,
blocks, trunks) have outward normals, the Cornell walls face into the room,
the ground and the plane face up and the Cornell light faces down.  Camera
dictionaries have the keys ``eye``, ``look_at``, ``up`` and ``vfov`` (the
vertical field of view in degrees).

Every generator takes keyword-only parameters and raises
:class:`raysort.errors.ConfigError` (a :class:`ValueError`) naming the
parameter and its allowed range when one has a wrong type or value.
"""
from collections import namedtuple
from dataclasses import dataclass
import math

import numpy as np

from raysort.mesh import check_mesh, per_face
from raysort.params import integer, number

__all__ = [
    "MeshData",
    "forest",
    "furnace_sphere",
    "cornell_box",
    "plane_under_sky",
    "icosphere",
    "FOREST_CAMERA",
    "FURNACE_CAMERA",
    "CORNELL_CAMERA",
    "PLANE_CAMERA",
    "GENERATORS",
    "CAMERAS",
]


# ---------------------------------------------------------------------------
# Result type
# ---------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class MeshData:
    """A triangle mesh with optional per-face materials.

    Parameters
    ----------
    vertices : ndarray of float32, shape (V, 3)
        Vertex positions, C-contiguous and finite.
    faces : ndarray of int32, shape (F, 3)
        Vertex indices of each triangle, C-contiguous, in ``[0, V)``.
    albedo : ndarray of float32, shape (F, 3), or None
        Per-face diffuse reflectance in ``[0, 1]``; None means the scene
        default.
    emission : ndarray of float32, shape (F, 3), or None
        Per-face emitted radiance (``>= 0``); None means no emission.

    Arrays are converted to the dtypes above on construction and checked by
    :mod:`raysort.mesh` (a bad mesh is a :class:`raysort.errors.SceneError`).
    """

    vertices: np.ndarray
    faces: np.ndarray
    albedo: np.ndarray = None
    emission: np.ndarray = None

    def __post_init__(self):
        vertices, faces = check_mesh(self.vertices, self.faces, "MeshData")
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "faces", faces)
        for name, hi in (("albedo", 1.0), ("emission", math.inf)):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, per_face(name, getattr(self, name), len(faces),
                                                        0.0, hi, "MeshData"))

    @property
    def n_vertices(self):
        """Number of vertices."""
        return len(self.vertices)

    @property
    def n_faces(self):
        """Number of triangles."""
        return len(self.faces)


# ---------------------------------------------------------------------------
# Geometry helpers (float64 inside, MeshData converts at the end)
# ---------------------------------------------------------------------------

# One part of a scene: vertices (V, 3), faces (F, 3), albedo (F, 3) or None,
# emission (F, 3) or None.
_Part = namedtuple("_Part", "vertices faces albedo emission")

_QUAD_TRIS = np.array([[0, 1, 2], [0, 2, 3]])


def _per_face(color, n_items, faces_per_item):
    """Broadcast one colour or one colour per item to one colour per face."""
    color = np.broadcast_to(np.asarray(color, dtype=np.float64), (n_items, 3))
    return np.repeat(color, faces_per_item, axis=0)


def _triangles(corners, albedo=None, emission=None):
    """Independent triangles from ``corners`` (N, 3, 3), colours per triangle."""
    corners = np.asarray(corners, dtype=np.float64).reshape(-1, 3, 3)
    n = len(corners)
    faces = np.arange(3 * n).reshape(n, 3)
    return _Part(corners.reshape(-1, 3), faces,
                 None if albedo is None else _per_face(albedo, n, 1),
                 None if emission is None else _per_face(emission, n, 1))


def _quads(corners, albedo=None, emission=None):
    """Two triangles per quad from ``corners`` (N, 4, 3), counter-clockwise.

    The normal of both triangles is ``cross(c1 - c0, c2 - c0)``; colours are
    given per quad (or one for all).
    """
    corners = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 3)
    n = len(corners)
    faces = (4 * np.arange(n)[:, None, None] + _QUAD_TRIS).reshape(-1, 3)
    return _Part(corners.reshape(-1, 3), faces,
                 None if albedo is None else _per_face(albedo, n, 2),
                 None if emission is None else _per_face(emission, n, 2))


def _quad(corners, albedo=None, emission=None):
    """One quad (2 triangles) from its 4 corners, counter-clockwise."""
    return _quads(np.asarray(corners)[None], albedo, emission)


# Corner i of the unit cube has coordinates (i & 1, i >> 1 & 1, i >> 2 & 1);
# each face lists its corners counter-clockwise seen from outside.
_CUBE_CORNERS = np.array([[i & 1, i >> 1 & 1, i >> 2 & 1] for i in range(8)],
                         dtype=np.float64) - 0.5
_CUBE_FACES = np.array([
    [0, 4, 6, 2],   # -x
    [1, 3, 7, 5],   # +x
    [0, 1, 5, 4],   # -y
    [2, 6, 7, 3],   # +y
    [0, 2, 3, 1],   # -z
    [4, 5, 7, 6],   # +z
])
_NEG_X, _POS_X, _NEG_Y, _POS_Y, _NEG_Z, _POS_Z = range(6)


def _rotation_y(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _box(center, size, angle_y=0.0):
    """Face corners (6, 4, 3) of a box, outward and counter-clockwise.

    The faces come in the order -x, +x, -y, +y, -z, +z (before the rotation by
    ``angle_y`` radians about the vertical axis through ``center``).  A size of
    0 along an axis gives a flat rectangle whose two faces point both ways.
    """
    corners = _CUBE_CORNERS * np.asarray(size, dtype=np.float64)
    corners = corners @ _rotation_y(angle_y).T + np.asarray(center, dtype=np.float64)
    return corners[_CUBE_FACES]


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _tubes(points, radii, sides, albedo=None):
    """Tapered tubes (open prisms) along polylines, outward-facing.

    Parameters
    ----------
    points : ndarray, shape (N, K + 1, 3)
        Axis nodes of N tubes of K segments each.
    radii : ndarray, shape (N, K + 1)
        Radius at every node (> 0).
    sides : int
        Number of sides of the prism cross-section.
    albedo : array_like, shape (3,) or (N, 3), optional
        Colour per tube.

    Consecutive segments share their ring of vertices; every node's ring lies
    in the plane normal to the local axis direction, with a frame built from
    one helper axis per tube so that rings do not twist.
    """
    n, nodes = points.shape[:2]
    tangent = _unit(np.gradient(points, axis=1))
    mean_dir = _unit(points[:, -1] - points[:, 0])
    helper = np.where((np.abs(mean_dir[:, 0]) < 0.9)[:, None],
                      [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])[:, None, :]
    e1 = _unit(helper - np.sum(helper * tangent, axis=-1, keepdims=True) * tangent)
    e2 = np.cross(tangent, e1)
    theta = 2.0 * np.pi * np.arange(sides) / sides
    offsets = (np.cos(theta)[:, None] * e1[:, :, None, :]
               + np.sin(theta)[:, None] * e2[:, :, None, :])
    verts = points[:, :, None, :] + radii[:, :, None, None] * offsets   # (N, K+1, S, 3)

    j, k = np.meshgrid(np.arange(nodes - 1), np.arange(sides), indexing="ij")
    a = j * sides + k
    b = j * sides + (k + 1) % sides
    c, d = b + sides, a + sides
    template = np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], -2)
    template = template.reshape(-1, 3)
    faces = (np.arange(n)[:, None, None] * (nodes * sides) + template).reshape(-1, 3)
    return _Part(verts.reshape(-1, 3), faces,
                 None if albedo is None else _per_face(albedo, n, len(template)),
                 None)


def _concat(parts, default_albedo=0.5):
    """Join parts into one :class:`MeshData`, offsetting face indices.

    Albedo is None only if no part has one (parts without one get
    ``default_albedo``); emission likewise (parts without one get 0).
    """
    parts = [p for p in parts if len(p.faces)]
    starts = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
    vertices = np.concatenate([p.vertices for p in parts]) if parts else np.zeros((0, 3))
    faces = (np.concatenate([p.faces + s for p, s in zip(parts, starts)])
             if parts else np.zeros((0, 3), dtype=np.int64))

    def channel(name, fill):
        if all(getattr(p, name) is None for p in parts):
            return None
        return np.concatenate([
            np.full((len(p.faces), 3), fill) if getattr(p, name) is None
            else getattr(p, name) for p in parts])

    return MeshData(vertices, faces, channel("albedo", default_albedo),
                    channel("emission", 0.0))


# ---------------------------------------------------------------------------
# Icosphere and furnace
# ---------------------------------------------------------------------------

_PHI = (1.0 + math.sqrt(5.0)) / 2.0
_ICOSAHEDRON_VERTICES = np.array([
    [-1, _PHI, 0], [1, _PHI, 0], [-1, -_PHI, 0], [1, -_PHI, 0],
    [0, -1, _PHI], [0, 1, _PHI], [0, -1, -_PHI], [0, 1, -_PHI],
    [_PHI, 0, -1], [_PHI, 0, 1], [-_PHI, 0, -1], [-_PHI, 0, 1],
], dtype=np.float64)
_ICOSAHEDRON_FACES = np.array([
    [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
    [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
    [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
    [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
])
MAX_SUBDIVISIONS = 7


def _subdivide(vertices, faces):
    """Split every triangle into 4, sharing one new vertex per edge."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    mids = _unit(vertices[unique[:, 0]] + vertices[unique[:, 1]])
    m01, m12, m20 = (inverse.reshape(-1, 3) + len(vertices)).T
    a, b, c = faces.T
    new_faces = np.stack([
        np.stack([a, m01, m20], -1),
        np.stack([b, m12, m01], -1),
        np.stack([c, m20, m12], -1),
        np.stack([m01, m12, m20], -1),
    ], 1).reshape(-1, 3)
    return np.concatenate([vertices, mids]), new_faces


def _icosphere_part(radius, subdivisions):
    vertices = _unit(_ICOSAHEDRON_VERTICES)
    faces = _ICOSAHEDRON_FACES
    for _ in range(subdivisions):
        vertices, faces = _subdivide(vertices, faces)
    return _Part(vertices * radius, faces, None, None)


def icosphere(*, radius=1.0, subdivisions=2):
    """A closed icosphere centred on the origin, without materials.

    The mesh is a subdivided icosahedron with every vertex on the sphere,
    shared vertices, and outward counter-clockwise winding; it is watertight
    (every edge belongs to exactly two faces).  It has
    ``20 * 4**subdivisions`` faces and ``10 * 4**subdivisions + 2`` vertices.

    Parameters
    ----------
    radius : float, default 1.0
        Sphere radius, in (0, 1e6].
    subdivisions : int, default 2
        Number of 1-to-4 subdivisions of the icosahedron, in [0, 7].

    Returns
    -------
    MeshData
        With ``albedo=None`` and ``emission=None``.
    """
    radius = number("icosphere: radius", radius, 0.0, 1e6, lo_open=True)
    subdivisions = integer("icosphere: subdivisions", subdivisions, 0, MAX_SUBDIVISIONS)
    return _concat([_icosphere_part(radius, subdivisions)])


def furnace_sphere(*, radius=1.0, subdivisions=3, albedo=0.5, emission=1.0):
    """A closed, uniformly emitting and reflecting sphere (white furnace test).

    Seen from :data:`FURNACE_CAMERA` at the centre, every pixel must converge
    to ``emission * sum(albedo**k for k >= 0) = emission / (1 - albedo)``.
    The geometry is :func:`icosphere` (outward winding; the camera sees the
    back sides, so the renderer must shade both sides alike).

    Parameters
    ----------
    radius : float, default 1.0
        Sphere radius, in (0, 1e6].
    subdivisions : int, default 3
        Icosahedron subdivisions, in [0, 7] (default: 1280 faces).
    albedo : float, default 0.5
        Grey diffuse reflectance of every face (all channels), in [0, 1].
    emission : float, default 1.0
        Emitted radiance of every face (all channels), in [0, 1e6].

    Returns
    -------
    MeshData
    """
    radius = number("furnace_sphere: radius", radius, 0.0, 1e6, lo_open=True)
    subdivisions = integer("furnace_sphere: subdivisions", subdivisions, 0, MAX_SUBDIVISIONS)
    albedo = number("furnace_sphere: albedo", albedo, 0.0, 1.0)
    emission = number("furnace_sphere: emission", emission, 0.0, 1e6)
    sphere = _icosphere_part(radius, subdivisions)
    n = len(sphere.faces)
    return _concat([sphere._replace(albedo=np.full((n, 3), albedo),
                                    emission=np.full((n, 3), emission))])


# ---------------------------------------------------------------------------
# Cornell box
# ---------------------------------------------------------------------------

_WHITE = (0.73, 0.73, 0.73)
_RED = (0.65, 0.05, 0.05)
_GREEN = (0.12, 0.45, 0.15)
_CORNELL_LIGHT_SIZE = (0.235, 0.19)     # 130 x 105 of the classic 555-unit box
_CORNELL_LIGHT_Y = 1.0 - 1e-3


def cornell_box(*, light=15.0):
    """The classic Cornell box at unit size, open at the front.

    The room is the cube ``[0, 1]**3``: floor ``y = 0``, ceiling ``y = 1`` and
    back wall ``z = 0`` white (0.73), red wall (0.65, 0.05, 0.05) at ``x = 0``
    and green wall (0.12, 0.45, 0.15) at ``x = 1``; the front ``z = 1`` is
    open.  :data:`CORNELL_CAMERA` looks in through the opening along -z, so
    the red wall is on the left.  This is the classic 555-unit layout turned
    by 180 degrees about the vertical and scaled by 1/555: a short white cube
    (0.3 units) at the front right and a tall white block (0.3 x 0.6 x 0.3) at
    the back left, both rotated about +-17 degrees.  A 0.235 x 0.19 emissive
    quad (albedo 0.78) hangs 0.001 below the ceiling centre, facing down.
    Walls face into the room, blocks face out.  36 triangles.

    Parameters
    ----------
    light : float, default 15.0
        Emitted radiance of the light quad (all channels), in [0, 1e6].
        No other face emits.

    Returns
    -------
    MeshData
    """
    light = number("cornell_box: light", light, 0.0, 1e6)
    room = _box((0.5, 0.5, 0.5), (1.0, 1.0, 1.0))
    walls = [_NEG_X, _POS_X, _NEG_Y, _POS_Y, _NEG_Z]          # no front (+z)
    wall_colors = [_RED, _GREEN, _WHITE, _WHITE, _WHITE]
    lx, lz = _CORNELL_LIGHT_SIZE
    light_quad = _box((0.5, _CORNELL_LIGHT_Y, 0.5), (lx, 0.0, lz))[_NEG_Y]
    return _concat([
        _quads(room[walls][:, ::-1], wall_colors),            # reversed: inward
        _quads(_box((0.67, 0.15, 0.70), (0.3, 0.3, 0.3), math.radians(-17.0)), _WHITE),
        _quads(_box((0.34, 0.30, 0.38), (0.3, 0.6, 0.3), math.radians(17.0)), _WHITE),
        _quad(light_quad, (0.78, 0.78, 0.78), (light, light, light)),
    ])


# ---------------------------------------------------------------------------
# Plane under the sky
# ---------------------------------------------------------------------------

def plane_under_sky(*, size=100.0, albedo=0.5):
    """One square at ``y = 0`` centred on the origin, facing up (2 triangles).

    Under a uniform sky of radiance ``L`` every point of the plane reflects
    ``albedo * L``; every primary ray of :data:`PLANE_CAMERA` (vfov 60, any
    common aspect ratio) hits it when ``size`` is at least 30.

    Parameters
    ----------
    size : float, default 100.0
        Edge length, in (0, 1e6].
    albedo : float, default 0.5
        Grey diffuse reflectance (all channels), in [0, 1].

    Returns
    -------
    MeshData
    """
    size = number("plane_under_sky: size", size, 0.0, 1e6, lo_open=True)
    albedo = number("plane_under_sky: albedo", albedo, 0.0, 1.0)
    square = _box((0.0, 0.0, 0.0), (size, 0.0, size))[_POS_Y]
    return _concat([_quad(square, (albedo, albedo, albedo))])


# ---------------------------------------------------------------------------
# Forest
# ---------------------------------------------------------------------------

_GROUND_CELLS = 64
_GRASS_TUFTS = 2500
_BLADES_PER_TUFT = 3
_TRUNK_SIDES, _TRUNK_SEGMENTS = 8, 5
_BRANCH_SIDES, _BRANCH_SEGMENTS = 6, 2
_CLEARING = 3.5          # no trunk within this distance of the camera eye (> crown radius)


def _forest_camera(size):
    return dict(eye=(0.0, 1.7, -0.45 * size), look_at=(0.0, 2.5, 0.0),
                up=(0.0, 1.0, 0.0), vfov=60.0)


def _ground_height(rng):
    """A smooth height function (|h| <= 0.35 m, wavelengths 12-40 m)."""
    k = rng.uniform(2 * np.pi / 40.0, 2 * np.pi / 12.0, (3, 2))
    k *= rng.choice([-1.0, 1.0], (3, 2))
    phase = rng.uniform(0.0, 2 * np.pi, 3)
    amp = np.array([0.18, 0.10, 0.07])

    def height(x, z):
        x, z = np.asarray(x)[..., None], np.asarray(z)[..., None]
        return np.sum(amp * np.sin(k[:, 0] * x + k[:, 1] * z + phase), axis=-1)

    return height


def _ground(rng, size, height):
    n = _GROUND_CELLS
    t = np.linspace(-0.5 * size, 0.5 * size, n + 1)
    x, z = np.meshgrid(t, t, indexing="ij")
    grid = np.stack([x, height(x, z), z], axis=-1)
    # quad (i, j) -> corners (i, j), (i, j+1), (i+1, j+1), (i+1, j): normal +y
    corners = np.stack([grid[:-1, :-1], grid[:-1, 1:], grid[1:, 1:], grid[1:, :-1]],
                       axis=2).reshape(-1, 4, 3)
    color = np.array([0.32, 0.28, 0.14]) * rng.uniform(0.92, 1.08, (n * n, 1))
    color[:, 1] += rng.uniform(-0.015, 0.025, n * n)
    return _quads(corners, np.clip(color, 0.0, 1.0))


def _tree_positions(rng, trees, size):
    eye = np.array([0.0, -0.45 * size])
    xz = rng.uniform(-0.47 * size, 0.47 * size, (trees, 2))
    while True:
        near = np.linalg.norm(xz - eye, axis=1) < _CLEARING
        if not near.any():
            return xz
        xz[near] = rng.uniform(-0.47 * size, 0.47 * size, (near.sum(), 2))


def _trunks(rng, xz, height):
    """Trunk axis nodes (T, K+1, 3), radii (T, K+1), the tube part, heights."""
    t = len(xz)
    tree_h = rng.uniform(6.0, 11.0, t)
    r0 = rng.uniform(0.16, 0.32, t)
    s = np.linspace(0.0, 1.0, _TRUNK_SEGMENTS + 1)
    base_y = height(xz[:, 0], xz[:, 1]) - 0.3
    wiggle = np.cumsum(rng.normal(0.0, 0.07, (t, _TRUNK_SEGMENTS + 1, 2)), axis=1)
    wiggle -= wiggle[:, :1]
    nodes = np.empty((t, _TRUNK_SEGMENTS + 1, 3))
    nodes[..., 0] = xz[:, None, 0] + wiggle[..., 0]
    nodes[..., 2] = xz[:, None, 1] + wiggle[..., 1]
    nodes[..., 1] = base_y[:, None] + s * (0.8 * tree_h + 0.3)[:, None]
    radii = r0[:, None] * (1.0 - 0.65 * s + 0.3 * (1.0 - s) ** 6)
    bark = np.array([0.30, 0.20, 0.12]) * rng.uniform(0.75, 1.2, (t, 1))
    part = _tubes(nodes, radii, _TRUNK_SIDES, np.clip(bark, 0.0, 1.0))
    return nodes, radii, part, tree_h


def _branches(rng, nodes, radii, crown_r):
    """2-4 branches per tree, rising from the upper trunk into the crown."""
    t = len(nodes)
    count = rng.integers(2, 5, t)
    tree = np.repeat(np.arange(t), count)
    rank = np.arange(len(tree)) - np.repeat(np.cumsum(count) - count, count)
    b = len(tree)
    # attachment point on the trunk polyline
    pos = rng.uniform(0.45, 0.75, b) * _TRUNK_SEGMENTS
    seg = pos.astype(int)
    frac = (pos - seg)[:, None]
    start = nodes[tree, seg] * (1 - frac) + nodes[tree, seg + 1] * frac
    r_start = 0.5 * (radii[tree, seg] * (1 - frac[:, 0]) + radii[tree, seg + 1] * frac[:, 0])
    azimuth = (2 * np.pi * rank / count[tree] + rng.uniform(0, 2 * np.pi, t)[tree]
               + rng.uniform(-0.4, 0.4, b))
    elevation = rng.uniform(np.radians(25), np.radians(55), b)
    length = crown_r[tree] * rng.uniform(0.6, 0.95, b)

    def direction(elev):
        return np.stack([np.cos(elev) * np.cos(azimuth), np.sin(elev),
                         np.cos(elev) * np.sin(azimuth)], axis=-1)

    mid = start + 0.5 * length[:, None] * direction(elevation)
    tip = mid + 0.5 * length[:, None] * direction(elevation + np.radians(15))
    points = np.stack([start, mid, tip], axis=1)
    r = r_start[:, None] * np.array([1.0, 0.6, 0.2])
    bark = np.array([0.28, 0.19, 0.11]) * rng.uniform(0.8, 1.2, (b, 1))
    return _tubes(points, np.maximum(r, 0.01), _BRANCH_SIDES, np.clip(bark, 0.0, 1.0))


def _leaves(rng, centres, radii, per_tree):
    """Random diamond-shaped leaf quads in ellipsoidal crowns.

    ``centres`` (T, 3) and ``radii`` (T, 3) describe the crowns; leaves are
    denser towards the crown surface.
    """
    t = len(centres)
    shape = (t, per_tree)
    direction = _unit(rng.normal(size=shape + (3,)))
    r = rng.uniform(0.0, 1.0, shape + (1,)) ** 0.25
    centre = centres[:, None] + direction * r * radii[:, None]
    normal = _unit(rng.normal(size=shape + (3,)))
    helper = rng.normal(size=shape + (3,))
    tangent = helper - np.sum(helper * normal, axis=-1, keepdims=True) * normal
    tangent /= np.maximum(np.linalg.norm(tangent, axis=-1, keepdims=True), 1e-12)
    bitangent = np.cross(normal, tangent)
    half_len = rng.uniform(0.12, 0.22, shape + (1,))
    half_wid = half_len * rng.uniform(0.35, 0.55, shape + (1,))
    u, v = half_len * tangent, half_wid * bitangent
    corners = np.stack([centre - u, centre - v, centre + u, centre + v], axis=2)
    tint = np.array([0.10, 0.36, 0.07]) * rng.uniform(0.8, 1.2, (t, 1, 1))
    color = tint * rng.uniform(0.7, 1.3, shape + (1,))
    color[..., 0] += rng.uniform(0.0, 0.12, shape) ** 2 * 8.0   # some yellowing
    return _quads(corners, np.clip(color, 0.0, 1.0).reshape(-1, 3))


def _grass(rng, size, height, tufts):
    """Grass tufts: a few thin upright triangles each."""
    n = tufts * _BLADES_PER_TUFT
    root = np.repeat(rng.uniform(-0.5 * size, 0.5 * size, (tufts, 2)),
                     _BLADES_PER_TUFT, axis=0)
    root = np.clip(root + rng.normal(0.0, 0.05, (n, 2)), -0.5 * size + 0.2, 0.5 * size - 0.2)
    y = height(root[:, 0], root[:, 1]) - 0.02
    base = np.stack([root[:, 0], y, root[:, 1]], axis=-1)
    angle = rng.uniform(0.0, np.pi, n)
    across = np.stack([np.cos(angle), np.zeros(n), np.sin(angle)], -1)
    across *= rng.uniform(0.02, 0.04, (n, 1))
    lean = np.stack([rng.uniform(-0.12, 0.12, n), rng.uniform(0.25, 0.6, n),
                     rng.uniform(-0.12, 0.12, n)], -1)
    corners = np.stack([base - across, base + across, base + lean], axis=1)
    color = np.array([0.22, 0.42, 0.08]) * rng.uniform(0.7, 1.25, (n, 1))
    color[:, 0] += rng.uniform(0.0, 0.1, n)
    return _triangles(corners, np.clip(color, 0.0, 1.0))


def forest(*, seed=1, trees=90, leaves_per_tree=780, size=60.0):
    """An outdoor forest scene, a stand-in for the "Fairy Forest" benchmark.

    A square ``size`` x ``size`` patch of gently undulating ground (64 x 64
    quads, brownish green, |height| <= 0.35 m) with 2,500 grass tufts (3
    triangles each) and ``trees`` trees at seeded random positions (none
    within 3.5 m of the camera eye).  Each tree is 6-11 m tall: a tapered,
    slightly crooked 8-sided trunk of 5 segments, 2-4 six-sided branches of 2
    segments, and ``leaves_per_tree`` small, randomly oriented diamond leaf
    quads (2 triangles, green with per-tree and per-leaf variation) in an
    ellipsoidal crown starting about 1.8 m above the ground.  The sky is open.  The defaults
    give about 170,000 triangles; :data:`FOREST_CAMERA` looks into the forest
    from near its edge.

    Parameters
    ----------
    seed : int, default 1
        Seed of ``numpy.random.default_rng``, in [0, 2**63 - 1].  The same seed
        gives identical arrays.
    trees : int, default 90
        Number of trees, in [0, 1000].
    leaves_per_tree : int, default 780
        Leaf quads per tree, in [0, 10000].
    size : float, default 60.0
        Edge length of the ground square in metres, in [10, 10000].

    Returns
    -------
    MeshData
    """
    seed = integer("forest: seed", seed, 0, 2**63 - 1)
    trees = integer("forest: trees", trees, 0, 1000)
    leaves_per_tree = integer("forest: leaves_per_tree", leaves_per_tree, 0, 10000)
    size = number("forest: size", size, 10.0, 10000.0)

    rng = np.random.default_rng(seed)
    height = _ground_height(rng)
    parts = [_ground(rng, size, height), _grass(rng, size, height, _GRASS_TUFTS)]
    if trees:
        xz = _tree_positions(rng, trees, size)
        nodes, radii, trunks, tree_h = _trunks(rng, xz, height)
        crown_r = rng.uniform(1.8, 3.0, trees)
        crown_ry = 0.28 * tree_h + 0.6
        crown_c = nodes[:, -1].copy()
        crown_c[:, 1] = nodes[:, 0, 1] + 0.3 + 0.68 * tree_h
        parts += [trunks, _branches(rng, nodes, radii, crown_r),
                  _leaves(rng, crown_c, np.stack([crown_r, crown_ry, crown_r], -1),
                          leaves_per_tree)]
    return _concat(parts)


# ---------------------------------------------------------------------------
# Registries
# ---------------------------------------------------------------------------

FOREST_CAMERA = _forest_camera(60.0)
"""Camera inside the default :func:`forest`, at eye height looking in."""

FURNACE_CAMERA = dict(eye=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, 1.0),
                      up=(0.0, 1.0, 0.0), vfov=60.0)
"""Camera at the centre of :func:`furnace_sphere`."""

CORNELL_CAMERA = dict(eye=(0.5, 0.5, 1.0 + 800.0 / 555.0), look_at=(0.5, 0.5, 0.5),
                      up=(0.0, 1.0, 0.0), vfov=39.3)
"""The classic Cornell box camera (scaled), outside the open front."""

PLANE_CAMERA = dict(eye=(0.0, 2.0, -2.0), look_at=(0.0, 0.0, 0.0),
                    up=(0.0, 1.0, 0.0), vfov=60.0)
"""Camera above :func:`plane_under_sky`, looking 45 degrees down."""

GENERATORS = {
    "forest": forest,
    "furnace": furnace_sphere,
    "cornell": cornell_box,
    "plane": plane_under_sky,
}
"""Scene name -> generator function (keyword-only parameters)."""

CAMERAS = {
    "forest": FOREST_CAMERA,
    "furnace": FURNACE_CAMERA,
    "cornell": CORNELL_CAMERA,
    "plane": PLANE_CAMERA,
}
"""Scene name -> default camera dict (eye, look_at, up, vfov in degrees)."""
