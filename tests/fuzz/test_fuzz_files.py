"""Property-based fuzzing of scene files (TOML) and mesh files.

Random bytes, real files truncated anywhere and real files with random edits:
loading them gives either a :class:`raysort.RaysortError` or a scene, and a
scene then renders (a tiny image, all finite).
"""
import importlib.resources
import os
import tempfile

import numpy as np
import pytest
import trimesh
from hypothesis import event, given
from hypothesis import strategies as st

import raysort

SCENE_FILES = {name: (importlib.resources.files("raysort.scenes") / f"{name}.toml").read_text()
               for name in ("cornell", "plane", "furnace")}
MESH_SUFFIXES = (".ply", ".obj", ".stl", ".off", ".glb")


def _as_bytes(data):
    return data.encode() if isinstance(data, str) else data


def _exported(file_type):
    cornell = raysort.load_scene("cornell")
    mesh = trimesh.Trimesh(cornell.vertices, cornell.faces, process=False)
    if file_type == "ply-ascii":
        return mesh.export(file_type="ply", encoding="ascii")
    return mesh.export(file_type=file_type)


MESH_FILES = {kind: _as_bytes(_exported(kind))
              for kind in ("ply", "ply-ascii", "obj", "stl", "off", "glb")}
SUFFIX = {"ply-ascii": ".ply"}


def edited(data):
    """``data`` truncated, or with a few bytes replaced (often by digits, which keeps a
    text file readable), inserted or deleted."""
    data = _as_bytes(data)
    cut = st.integers(0, len(data)).map(lambda k: data[:k])
    chunk = st.one_of(st.binary(min_size=1, max_size=4),
                      st.text("0123456789-.e", min_size=1, max_size=2).map(str.encode))
    edit = st.lists(st.tuples(st.integers(0, len(data)), st.sampled_from("rrrid"), chunk),
                    min_size=1, max_size=4)
    return st.one_of(cut, edit.map(lambda edits: _apply(data, edits)))


def _apply(data, edits):
    out = bytearray(data)
    for pos, op, chunk in edits:
        pos = min(pos, len(out))
        if op == "r":
            out[pos:pos + len(chunk)] = chunk
        elif op == "i":
            out[pos:pos] = chunk
        else:
            del out[pos:pos + len(chunk)]
    return bytes(out)


def load_and_render(name, data, extra=()):
    """Write ``data`` as ``name`` (and ``extra`` files) in a fresh directory and load it;
    a scene must render."""
    with tempfile.TemporaryDirectory() as tmp:
        for other, content in extra:
            with open(os.path.join(tmp, other), "wb") as f:
                f.write(content)
        path = os.path.join(tmp, name)
        with open(path, "wb") as f:
            f.write(data)
        try:
            scene = raysort.load_scene(path)
        except raysort.RaysortError as exc:
            event(f"error: {type(exc).__name__}")
            assert name in str(exc) or "scene file" in str(exc) or "mesh" in str(exc), str(exc)
            return
    event("loaded")
    if len(scene.faces) > 200_000:      # an edit that asks for a huge procedural mesh
        return
    image = raysort.Pipeline(scene).render(8, 6, 1).image
    assert np.isfinite(image).all()


@given(kind=st.sampled_from(sorted(MESH_FILES)), data=st.data())
def test_damaged_mesh_files(kind, data):
    load_and_render("m" + SUFFIX.get(kind, "." + kind),
                    data.draw(edited(MESH_FILES[kind]), label="file"))


@given(suffix=st.sampled_from(MESH_SUFFIXES), data=st.binary(max_size=600))
def test_random_bytes_as_mesh_files(suffix, data):
    load_and_render("junk" + suffix, data)


@given(name=st.sampled_from(sorted(SCENE_FILES)), data=st.data())
def test_damaged_scene_files(name, data):
    load_and_render("s.toml", data.draw(edited(SCENE_FILES[name]), label="file"))


@given(data=st.data())
def test_damaged_scene_file_with_its_mesh(data):
    """A scene file naming a mesh file, either of them damaged."""
    text = ('name = "t"\n[mesh]\nfile = "m.obj"\n[camera]\neye = [0.5, 0.5, 3]\n'
            'look_at = [0.5, 0.5, 0.5]\n[material]\nalbedo = [0.5, 0.5, 0.5]\n'
            '[[light]]\nposition = [0.5, 0.9, 0.5]\nintensity = [1, 1, 1]\n')
    scene = data.draw(st.one_of(st.just(_as_bytes(text)), edited(text)), label="scene")
    mesh = data.draw(st.one_of(st.just(MESH_FILES["obj"]), edited(MESH_FILES["obj"])),
                     label="mesh")
    load_and_render("s.toml", scene, extra=[("m.obj", mesh)])


@pytest.mark.parametrize("kind", sorted(MESH_FILES))
def test_the_undamaged_files_load(kind):
    """The fuzzed files start from meshes that load and render (else the test is empty)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "m" + SUFFIX.get(kind, "." + kind))
        with open(path, "wb") as f:
            f.write(MESH_FILES[kind])
        scene = raysort.load_scene(path)
        assert len(scene.faces) == 36
