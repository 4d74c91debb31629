"""Scenes: a triangle mesh with materials, a camera, a sky and lights.

A scene comes from one of three places (see :func:`load_scene`):

* a name of a scene shipped with raysort (``sibenik``, ``sponza``, ``forest``,
  ``cornell``, ``furnace``, ``plane``; :func:`scene_names` lists them);
* a scene file (TOML), whose keys are documented in ``scenes/README.md``;
* any mesh file trimesh reads (PLY, OBJ, STL, GLB, ...), framed by a default
  camera.

Meshes load with ``process=False``, so vertices and faces stay exactly as
stored.  Per-face colours (e.g. Sibenik's PLY) become the diffuse albedo.
Degenerate (zero-area) triangles are kept and never hit.
"""
from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from raysort import _normals, procedural
from raysort.bvh import BVH, degenerate_faces
from raysort.camera import Camera
from raysort.errors import ConfigError, SceneError
from raysort.mesh import check_mesh, per_face
from raysort.output import shown
from raysort.params import vector3

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

__all__ = ["Scene", "PointLight", "load_scene", "load_mesh", "scene_names", "check_scene"]

DEFAULT_SCENE = "sibenik"
DEFAULT_ALBEDO = (0.7, 0.7, 0.7)


@dataclass(frozen=True)
class PointLight:
    """A point light for shadow rays: ``intensity`` in radiant intensity units (3
    numbers >= 0); ConfigError otherwise."""

    position: tuple
    intensity: tuple

    def __post_init__(self):
        position = vector3("light.position", self.position)
        intensity = vector3("light.intensity", self.intensity)
        if (intensity < 0).any():
            raise ConfigError(f"light.intensity must not be negative, got {self.intensity!r}")
        object.__setattr__(self, "position", tuple(position.tolist()))
        object.__setattr__(self, "intensity", tuple(intensity.tolist()))


@dataclass
class Scene:
    """Everything a render needs besides the plugins.

    Attributes
    ----------
    vertices : float32 (n, 3);  faces : int32 (m, 3)
    albedo : float32 (m, 3), diffuse reflectance per face
    emission : float32 (m, 3), emitted radiance per face (zeros if none)
    camera : Camera;  sky : float32 (3,), radiance of escaped rays
    lights : list of PointLight;  name : str;  source : str (where it came from)
    """

    vertices: np.ndarray
    faces: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    camera: Camera
    sky: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    lights: list = field(default_factory=list)
    name: str = "scene"
    source: str = ""
    _bvh: BVH = field(default=None, repr=False)
    _bvh_params: dict = field(default=None, repr=False)

    def __post_init__(self):
        where = self.source or self.name
        self.vertices, self.faces = check_mesh(self.vertices, self.faces, where)
        m = len(self.faces)
        self.albedo = per_face("albedo", self.albedo, m, 0.0, 1.0, where)
        self.emission = per_face("emission", self.emission, m, 0.0, np.inf, where)
        self.sky = per_face("sky", self.sky, 1, 0.0, np.inf, where).reshape(3)
        if not isinstance(self.camera, Camera):
            raise SceneError(f"scene '{where}': camera must be a raysort.Camera, got "
                             f"{type(self.camera).__name__}")
        self.lights = list(self.lights)
        if not all(isinstance(light, PointLight) for light in self.lights):
            raise SceneError(f"scene '{where}': lights must be raysort.scene.PointLight")

    @classmethod
    def from_mesh(cls, vertices, faces, *, camera=None, albedo=DEFAULT_ALBEDO, emission=0.0,
                  sky=(1.0, 1.0, 1.0), lights=(), name="mesh"):
        """A scene from arrays; the camera defaults to one framing the mesh."""
        vertices, faces = check_mesh(vertices, faces, name)
        if camera is None:
            camera = _framing(vertices, name)
        return cls(vertices, faces, albedo, emission, camera, sky, list(lights), name, name)

    @property
    def n_triangles(self):
        return len(self.faces)

    @property
    def bounds(self):
        """float32 (2, 3): the box of all vertices used by faces."""
        used = self.vertices[self.faces.reshape(-1)]
        return np.stack([used.min(axis=0), used.max(axis=0)]).astype(np.float32)

    def face_normals(self):
        """float32 (m, 3): each face's unit geometric normal, ``(v1 - v0) x (v2 - v0)``
        normalised in double (zero for a face of zero area); as stored, not facing any ray."""
        out = np.empty((len(self.faces), 3), np.float32)
        _normals.face_normals(np.ascontiguousarray(self.vertices, dtype=np.float32),
                              np.ascontiguousarray(self.faces, dtype=np.int32), out)
        return out

    def degenerate_faces(self):
        """Indices of degenerate faces: kept, but never hit (see
        :func:`raysort.bvh.degenerate_faces` for the rule)."""
        return degenerate_faces(self.vertices, self.faces)

    def bvh(self, **params):
        """The scene's BVH (see :class:`raysort.bvh.BVH` for ``params``), built on first
        use and rebuilt when the parameters change."""
        if self._bvh is None or self._bvh_params != params:
            self._bvh = BVH(self.vertices, self.faces, **params)
            self._bvh_params = dict(params)
        return self._bvh


# --------------------------------------------------------------------------
# mesh files
# --------------------------------------------------------------------------

def _not_a_file(path):
    """Why ``path`` is not a readable regular file ("does not exist", "is not a file",
    or what the operating system says), or None."""
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return "does not exist"
    except OSError as exc:          # a name too long, a loop of links, ...
        return f"cannot be read: {exc.strerror or exc}"
    return None if stat.S_ISREG(mode) else "is not a file"


def load_mesh(path):
    """``(vertices, faces, face_colors)`` of a mesh file; colours are uint8 (m, 3) or None."""
    import trimesh

    path = Path(path)
    problem = _not_a_file(path)
    if problem:
        raise SceneError(f"mesh '{path}' {problem}")
    try:
        with np.errstate(all="ignore"):       # garbage numbers are caught by check_mesh
            mesh = trimesh.load(str(path), process=False)
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise SceneError(f"mesh '{path}' is not a readable mesh file ({type(exc).__name__}: "
                         f"{exc})") from None
    if isinstance(mesh, trimesh.Scene):
        geoms = [g for g in mesh.dump() if isinstance(g, trimesh.Trimesh)]
        if not geoms:
            raise SceneError(f"mesh '{path}' has no triangle faces")
        mesh = trimesh.util.concatenate(geoms) if len(geoms) > 1 else geoms[0]
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise SceneError(f"mesh '{path}' has no triangle faces")
    colors = None
    visual = getattr(mesh, "visual", None)
    if getattr(visual, "kind", None) == "face":
        colors = np.asarray(visual.face_colors)[:, :3].astype(np.uint8)
    elif getattr(visual, "kind", None) == "vertex":
        vc = np.asarray(visual.vertex_colors)[:, :3].astype(np.float64)
        colors = np.rint(vc[np.asarray(mesh.faces)].mean(axis=1)).astype(np.uint8)
    vertices, faces = check_mesh(mesh.vertices, mesh.faces, path)
    return vertices, faces, colors


# --------------------------------------------------------------------------
# scene files
# --------------------------------------------------------------------------

_SCHEMA = {
    "": {"name", "description", "credits", "mesh", "camera", "material", "emitter", "sky",
         "light"},
    "mesh": {"file", "procedural", "params", "face_colors"},
    "camera": {"eye", "look_at", "up", "vfov"},
    "material": {"albedo"},
    "emitter": {"face_color", "radiance"},
    "sky": {"radiance"},
    "light": {"position", "intensity"},
}


def _packaged_dir():
    return resources.files("raysort.scenes")


def scene_names():
    """Names of the scenes shipped with raysort."""
    return sorted(p.name[:-5] for p in _packaged_dir().iterdir() if p.name.endswith(".toml"))


def check_scene(spec):
    """What ``spec`` names, before anything is read: ``"packaged"`` (a scene shipped with
    raysort), ``"file"`` (a ``.toml`` scene file) or ``"mesh"`` (a mesh file); SceneError
    for an unknown name or a file that does not exist or is not one."""
    spec = os.fspath(spec)
    if not os.path.exists(spec) and spec in scene_names():
        return "packaged"
    path = Path(spec)
    toml = path.suffix.lower() == ".toml"
    if not toml and not os.path.lexists(path) and not path.suffix:
        raise SceneError(f"unknown scene {spec!r}; packaged scenes: {', '.join(scene_names())}"
                         f" (or give a .toml scene file or a mesh file)")
    problem = _not_a_file(path)
    if problem:
        raise SceneError(f"{'scene file' if toml else 'mesh'} '{path}' {problem}")
    return "file" if toml else "mesh"


def load_scene(spec=None):
    """A :class:`Scene` from a packaged name, a ``.toml`` scene file or a mesh file."""
    spec = DEFAULT_SCENE if spec is None else os.fspath(spec)
    kind = check_scene(spec)
    if kind == "packaged":
        with resources.as_file(_packaged_dir() / f"{spec}.toml") as path:
            return _load_scene_file(Path(path))
    path = Path(spec)
    if kind == "file":
        return _load_scene_file(path)
    vertices, faces, colors = load_mesh(path)
    albedo = colors / 255.0 if colors is not None else DEFAULT_ALBEDO
    return Scene.from_mesh(vertices, faces, albedo=albedo, name=shown(path.stem))


def _framing(vertices, where):
    """The default camera: it sees the whole mesh."""
    try:
        return Camera.framing(vertices.min(axis=0), vertices.max(axis=0))
    except ConfigError as exc:
        raise SceneError(f"mesh '{where}' cannot be framed by a camera: {exc}") from None


def _check_keys(where, section, table):
    if not isinstance(table, dict):
        raise SceneError(f"scene file '{where}': [{section}] must be a table")
    unknown = sorted(set(table) - _SCHEMA[section])
    if unknown:
        prefix = f"{section}." if section else ""
        raise SceneError(f"scene file '{where}': unknown key '{prefix}{unknown[0]}' (known: "
                         f"{', '.join(sorted(_SCHEMA[section]))})")


def _tables(where, doc, key):
    value = doc.get(key, [])
    tables = value if isinstance(value, list) else [value]
    for t in tables:
        _check_keys(where, key, t)
    return tables


def _typed(where, key, value, kind, what):
    if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
        raise SceneError(f"scene file '{where}': {key} must be {what}, got {value!r}")
    return value


def _number3(where, key, value):
    try:
        return vector3(key, value)
    except ConfigError as exc:
        raise SceneError(f"scene file '{where}': {exc}") from None


def _non_negative3(where, key, value):
    arr = _number3(where, key, value)
    if (arr < 0).any():
        raise SceneError(f"scene file '{where}': {key} must not be negative, got {value!r}")
    return arr


def _load_scene_file(path):
    where = path
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"cannot read scene file '{path}': {exc}") from None
    except RecursionError:
        raise SceneError(f"cannot read scene file '{path}': nested too deeply") from None
    _check_keys(where, "", doc)
    for section in ("mesh", "camera", "material", "sky"):
        if section in doc:
            _check_keys(where, section, doc[section])
    mesh_cfg = doc.get("mesh")
    if not mesh_cfg or ("file" in mesh_cfg) == ("procedural" in mesh_cfg):
        raise SceneError(f"scene file '{where}': [mesh] needs exactly one of 'file' or "
                         f"'procedural'")
    for key, kind, what in (("file", str, "a path"), ("procedural", str, "a name"),
                            ("params", dict, "a table"), ("face_colors", bool, "true or false")):
        if key in mesh_cfg:
            _typed(where, f"mesh.{key}", mesh_cfg[key], kind, what)
    for key in ("name", "description", "credits"):
        if key in doc:
            _typed(where, key, doc[key], str, "a string")
    colors = base_albedo = base_emission = default_camera = None
    if "file" in mesh_cfg:
        if "params" in mesh_cfg:
            raise SceneError(f"scene file '{where}': mesh.params goes with mesh.procedural")
        vertices, faces, colors = load_mesh(path.parent / mesh_cfg["file"])
    else:
        kind = mesh_cfg["procedural"]
        if kind not in procedural.GENERATORS:
            raise SceneError(f"scene file '{where}': unknown procedural mesh {kind!r}; known: "
                             f"{', '.join(sorted(procedural.GENERATORS))}")
        try:
            data = procedural.GENERATORS[kind](**mesh_cfg.get("params", {}))
        except (ConfigError, TypeError) as exc:
            raise SceneError(f"scene file '{where}': mesh.params: {exc}") from None
        vertices, faces = data.vertices, data.faces
        base_albedo, base_emission = data.albedo, data.emission
        default_camera = procedural.CAMERAS.get(kind)

    material = doc.get("material", {})
    albedo = _number3(where, "material.albedo", material.get("albedo", DEFAULT_ALBEDO))
    if base_albedo is not None:
        albedo = base_albedo
    elif colors is not None and mesh_cfg.get("face_colors", True):
        albedo = colors / 255.0
    emission = np.zeros((len(faces), 3), np.float32)
    if base_emission is not None:
        emission[:] = base_emission
    for em in _tables(where, doc, "emitter"):
        if colors is None:
            raise SceneError(f"scene file '{where}': [[emitter]] selects faces by colour but "
                             f"the mesh has no face colours")
        color = _number3(where, "emitter.face_color", em.get("face_color"))
        if not ((color >= 0) & (color <= 255) & (color == np.round(color))).all():
            raise SceneError(f"scene file '{where}': emitter.face_color must be 3 integers "
                             f"in 0..255, got {em.get('face_color')!r}")
        match = (colors == color.astype(np.uint8)).all(axis=1)
        emission[match] = _non_negative3(where, "emitter.radiance", em.get("radiance"))

    cam_cfg = doc.get("camera") or default_camera
    if cam_cfg is None:
        camera = _framing(vertices, where)
    else:
        try:
            camera = Camera(**cam_cfg)
        except (ConfigError, TypeError) as exc:
            raise SceneError(f"scene file '{where}': camera: {exc}") from None
    try:
        lights = [PointLight(lt.get("position"), lt.get("intensity"))
                  for lt in _tables(where, doc, "light")]
    except ConfigError as exc:
        raise SceneError(f"scene file '{where}': {exc}") from None
    sky = _non_negative3(where, "sky.radiance", doc.get("sky", {}).get("radiance", (0, 0, 0)))
    try:
        return Scene(vertices, faces, albedo, emission, camera, sky, lights,
                     doc.get("name", shown(path.stem)), str(path))
    except SceneError as exc:
        raise SceneError(f"scene file '{where}': {exc}") from None
