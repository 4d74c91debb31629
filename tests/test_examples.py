"""Every script in ``examples/`` runs, at a tiny size, in a fresh process, as a user would
run it (the Cython plugin is built and installed into a temporary folder first)."""
import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from raysort.output import read_exr, read_png

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
pytestmark = pytest.mark.skipif(not EXAMPLES.is_dir(),
                                reason="the examples ship with the repository only")


def run(*argv, cwd, env=None, timeout=600):
    """Run a command; fail with its output unless it exits 0; return its stdout."""
    env = dict(os.environ, **(env or {}))
    env.pop("RAYSORT_DISABLE_PLUGIN_AUTOLOAD", None)
    proc = subprocess.run([str(a) for a in argv], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)
    assert proc.returncode == 0, f"{argv} failed:\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


def test_ao_custom_sorter(tmp_path):
    out = run(sys.executable, EXAMPLES / "ao_custom_sorter.py", "sibenik", "--size", "16",
              "--rounds", "1", cwd=tmp_path)
    assert "AO rays" in out
    for label in ("none", "nah", "origin grid"):
        assert f"\n{label} " in out


def test_trace_numpy_rays(tmp_path):
    out = run(sys.executable, EXAMPLES / "trace_numpy_rays.py", "--rays", "500", cwd=tmp_path)
    assert "rays hit the mesh" in out and "agree to" in out


def test_trace_numpy_rays_with_a_mesh_file(tmp_path):
    import trimesh

    trimesh.creation.icosphere(subdivisions=2).export(tmp_path / "ball.ply")
    out = run(sys.executable, EXAMPLES / "trace_numpy_rays.py", tmp_path / "ball.ply",
              "--rays", "300", cwd=tmp_path)
    assert "(320 triangles)" in out


def test_bench_sorters(tmp_path):
    """The pytest-benchmark file runs each benchmark once (--benchmark-disable), on the
    default torus and on a user's mesh file."""
    pytest.importorskip("pytest_benchmark")
    args = [sys.executable, "-m", "pytest", EXAMPLES / "bench_sorters.py", "-q",
            "-p", "no:cacheprovider", "--benchmark-disable"]
    out = run(*args, cwd=tmp_path, env={"RAYSORT_SIZE": "12"})
    assert "6 passed" in out
    out = run(*args, cwd=tmp_path, env={"RAYSORT_SIZE": "8", "RAYSORT_MESH": "cornell",
                                         "RAYSORT_SORTERS": "none:packet_size=16;nah;nah_numpy"})
    assert "9 passed" in out


def test_flythrough(tmp_path):
    out = run(sys.executable, EXAMPLES / "flythrough.py", "cornell", "--frames", "3",
              "--size", "12x8", "--spp", "1", "-o", tmp_path / "frames", cwd=tmp_path)
    frames = sorted((tmp_path / "frames").iterdir())
    assert [f.name for f in frames] == [f"frame_{i:04d}.{ext}" for i in range(3)
                                        for ext in ("exr", "png")]
    images = [read_exr(f) for f in frames if f.suffix == ".exr"]
    assert all(im.shape == (8, 12, 3) and im.max() > 0 for im in images)
    assert not (images[0] == images[2]).all(), "the camera did not move"
    assert read_png(frames[1]).shape == (8, 12, 3)
    assert out.count("Mrays/s") == 3


@pytest.fixture(scope="module")
def stack_site(tmp_path_factory):
    """The Cython example plugin, built against the installed raysort and installed with
    pip into a temporary folder (never into the environment)."""
    for module in ("setuptools", "Cython"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"building the Cython example needs {module}")
    src = tmp_path_factory.mktemp("src") / "cython_traversal"
    shutil.copytree(EXAMPLES / "cython_traversal", src, ignore=shutil.ignore_patterns(
        "build", "*.egg-info", "__pycache__", "*.c", "*.so"))
    target = tmp_path_factory.mktemp("site")
    run(sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation",
        "--no-index", "--target", target, src, cwd=src,
        env={"PIP_DISABLE_PIP_VERSION_CHECK": "1", "PIP_NO_INPUT": "1"})
    return target


def test_cython_traversal_plugin(stack_site, tmp_path):
    """Found by name through its entry point, it gives single's hits bit for bit on
    primary, diffuse and shadow rays, and a bit-identical render."""
    out = run(sys.executable, EXAMPLES / "cython_traversal" / "demo.py", "cornell",
              "--size", "16", cwd=tmp_path, env={"PYTHONPATH": str(stack_site)})
    assert out.count("same as single: True") == 3 and "bit-identical" in out
