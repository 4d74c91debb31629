"""A sorter plugin distributed as its own package, used by name as the README promises.

``plugins/raysort-morton`` is installed with pip into a temporary directory
(never into the environment) and found through its entry point; the short
example sorter of the README's "Write your own sorter" section is registered
in process.  Both must keep the sorter contract and leave the image bit for
bit unchanged.
"""
import importlib
import importlib.util
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import raysort
from raysort.contract import check_sort
from raysort.output import read_exr
from raysort.rays import RayBatch

PLUGIN_DIR = Path(__file__).resolve().parents[1] / "plugins" / "raysort-morton"


@pytest.fixture(scope="module")
def morton_site(tmp_path_factory):
    """``pip install --target`` the plugin, put the target on sys.path, yield the target."""
    if not PLUGIN_DIR.is_dir():
        pytest.skip(f"{PLUGIN_DIR} not found: the plugin sources ship with the repository only")
    if importlib.util.find_spec("setuptools") is None:
        pytest.skip("building the plugin with --no-build-isolation needs setuptools")
    # build from a copy: setuptools writes build/ and *.egg-info next to the sources
    src = tmp_path_factory.mktemp("src") / "raysort-morton"
    shutil.copytree(PLUGIN_DIR, src, ignore=shutil.ignore_patterns(
        "build", "dist", "*.egg-info", "__pycache__"))
    target = tmp_path_factory.mktemp("site")
    env = dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_NO_INPUT="1")
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps",
                           "--no-build-isolation", "--no-index", "--target", str(target),
                           str(src)], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, f"pip install failed:\n{proc.stdout}\n{proc.stderr}"
    sys.path.insert(0, str(target))
    importlib.invalidate_caches()
    raysort.refresh()
    yield target
    sys.path.remove(str(target))
    sys.modules.pop("raysort_morton", None)
    importlib.invalidate_caches()
    raysort.refresh()


# -- the README example, read from the README itself -----------------------------
README = Path(__file__).resolve().parents[1] / "README.md"


def _readme_example():
    """The first Python block of the README's "Write your own sorter" section, executed."""
    if not README.is_file():
        pytest.skip("README.md ships with the repository only")
    section = README.read_text(encoding="utf-8").split("### Write your own sorter", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    namespace = {}
    exec(compile(code, str(README), "exec"), namespace)
    return namespace["OctantSorter"]


@pytest.fixture
def octant_registered():
    raysort.register("sorters", "octant_example", _readme_example())
    yield "octant_example"
    raysort.unregister("sorters", "octant_example")


def _render(scene, sorter, *size):
    return raysort.Pipeline(scene, sorter=sorter, traversal="ranged").render(*size)


@pytest.fixture(scope="module")
def none_image(sibenik):
    """The reference: Sibenik 48x32, 2 spp, seed 0 with no sorting."""
    image = _render(sibenik, "none", 48, 32, 2).image
    assert image.max() > 0, "the reference render is black; comparing with it proves nothing"
    return image


def _assert_bitwise_equal(image, ref, label):
    assert image.shape == ref.shape
    differ = np.flatnonzero(image.view(np.uint32) != ref.view(np.uint32))
    assert len(differ) == 0, f"{label}: {len(differ)} channels differ from the 'none' render"


def _reference_keys(rays, bounds, bits):
    """MortonSorter's documented key, one ray at a time in plain Python."""
    lo, hi = bounds[0].tolist(), bounds[1].tolist()
    cells = 1 << bits
    keys = []
    for o, d in zip(rays.origins.T.tolist(), rays.directions.T.tolist()):
        coords = [(o[k] - lo[k]) / (hi[k] - lo[k]) if hi[k] > lo[k] else 0.0 for k in range(3)]
        coords += [(c + 1.0) / 2.0 for c in d]
        key = 0
        for k, u in enumerate(coords):
            u = 0.0 if math.isnan(u) else min(max(u, 0.0), 1.0)
            q = min(int(u * cells), cells - 1)
            for b in range(bits):
                key |= ((q >> b) & 1) << (6 * b + k)
        keys.append(key)
    return np.array(keys, dtype=np.uint64)


def _reference_offsets(packets, size):
    """Each large packet cut every ``size`` rays from its start."""
    cuts = [s for a, b in zip(packets[:-1], packets[1:]) for s in range(a, b, size)]
    return np.array(cuts + [packets[-1]])


# -- the installed package -------------------------------------------------------

def test_installed_plugin_is_found_by_name(morton_site):
    """The entry point makes 'morton' a sorter name, attributed to its distribution."""
    assert (morton_site / "raysort_morton.py").is_file()
    assert "morton" in raysort.available("sorters")
    info = {p.name: p for p in raysort.list_plugins("sorters", load=True)}["morton"]
    assert (info.distribution, info.version, info.status) == ("raysort-morton", "0.1.0", "ok")
    assert info.target == "raysort_morton:MortonSorter"
    assert "Morton code" in info.description
    cls = raysort.load("sorters", "morton")
    assert issubclass(cls, raysort.Sorter) and cls.__module__ == "raysort_morton"
    assert Path(sys.modules["raysort_morton"].__file__).parent == morton_site


def test_morton_sort_keeps_contract_and_orders_by_key(morton_site, sibenik, workloads):
    """On Sibenik diffuse rays the order is a real reordering: by (large packet, key),
    ties in input order, with fixed-size cuts inside each large packet."""
    work = workloads(sibenik, "diffuse")
    n = len(work.rays)
    sorter = raysort.create("sorters", {"type": "morton", "bits": 5, "packet_size": 32})
    assert sorter.params() == {"bits": 5, "packet_size": 32}
    order, offsets = check_sort("morton", sorter.sort(work.rays, work.packets, sibenik.bounds),
                                n, work.packets)
    assert not np.array_equal(order, np.arange(n)), "morton left the rays in input order"
    packet = np.searchsorted(work.packets, np.arange(n), side="right") - 1
    expected = np.lexsort((np.arange(n), _reference_keys(work.rays, sibenik.bounds, 5), packet))
    np.testing.assert_array_equal(order, expected)
    np.testing.assert_array_equal(offsets, _reference_offsets(work.packets.tolist(), 32))


def test_morton_sort_survives_degenerate_input(morton_site):
    """NaN/inf rays, a flat scene box, empty large packets and an empty batch give a
    valid result without numerical warnings (they are errors under pytest)."""
    sorter = raysort.create("sorters", "morton:packet_size=2")
    origins = [[0, 0, 0], [np.nan, 1, 1], [np.inf, -np.inf, 0], [2, 2, 2], [1, 1, 1],
               [1, 5, 1], [1, -5, 1]]            # the last two differ only on the flat axis
    directions = [[1, 0, 0], [0, 1, 0], [0, 0, np.nan], [-1, 0, 0], [0, -1, 0],
                  [0, 0, 1], [0, 0, 1]]
    rays = RayBatch.from_arrays(origins, directions)
    packets = np.array([0, 0, 3, 3, 7], np.int32)
    flat = np.array([[0, 0, 0], [2, 0, 2]], np.float32)
    order, offsets = check_sort("morton", sorter.sort(rays, packets, flat), 7, packets)
    expected = np.lexsort((np.arange(7), _reference_keys(rays, flat, 4), [0, 0, 0, 1, 1, 1, 1]))
    np.testing.assert_array_equal(order, expected)
    assert list(order[-2:]) == [5, 6], "rays equal but for the flat axis must keep input order"
    np.testing.assert_array_equal(offsets, [0, 2, 3, 5, 7])
    empty = np.array([0], np.int32)
    assert [list(a) for a in check_sort("morton", sorter.sort(RayBatch(0), empty, flat),
                                        0, empty)] == [[], [0]]


def test_render_with_installed_plugin_is_bit_identical(morton_site, sibenik, none_image):
    """Pipeline(sorter="morton") renders exactly the 'none' image; the traversal did
    different work, so the reordering really reached it."""
    result = raysort.Pipeline("sibenik", sorter="morton", traversal="ranged").render(48, 32, 2)
    assert result.settings["sorter"].startswith("morton")
    _assert_bitwise_equal(result.image, none_image, "morton")
    ref = _render(sibenik, "none", 48, 32, 2).stats.closest_hit_counters()
    assert result.stats.closest_hit_counters().box4 != ref.box4


def test_bad_morton_config_is_a_config_error(morton_site):
    """Unknown parameters and out-of-range values name the plugin and the problem."""
    with pytest.raises(raysort.ConfigError, match=r"'nope'.*takes: bits, packet_size"):
        raysort.create("sorters", {"type": "morton", "nope": 1})
    for bad in ({"bits": 0}, {"bits": 11}, {"bits": 2.5}, {"bits": True}):
        with pytest.raises(raysort.ConfigError, match=r"'morton'.*bits must be an integer in 1"):
            raysort.create("sorters", {"type": "morton", **bad})
    with pytest.raises(raysort.ConfigError, match=r"packet_size must be an integer in 1\.\.4096"):
        raysort.create("sorters", "morton:packet_size=4097")


def test_cli_renders_with_installed_plugin(morton_site, sibenik, tmp_path):
    """`raysort render --sorter morton` in a fresh process (plugin on PYTHONPATH only)
    exits 0 and writes the same pixels as an in-process 'none' render."""
    out = tmp_path / "morton.exr"
    env = {k: v for k, v in os.environ.items() if k != "RAYSORT_DISABLE_PLUGIN_AUTOLOAD"}
    env["PYTHONPATH"] = str(morton_site)
    proc = subprocess.run([sys.executable, "-m", "raysort", "render", "sibenik", "--sorter",
                           "morton", "--traversal", "ranged", "--size", "16x12", "--spp", "1",
                           "-o", str(out), "-q"], capture_output=True, text=True, env=env,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert out.is_file() and out.with_suffix(".png").is_file()
    ref = _render(sibenik, "none", 16, 12, 1).image
    _assert_bitwise_equal(read_exr(out), ref, "CLI morton")


def test_plugin_is_gone_after_cleanup(morton_site):
    """Without the target dir on sys.path, a refresh forgets 'morton' (what the
    fixture's finalizer relies on to keep other tests clean)."""
    sys.path.remove(str(morton_site))
    importlib.invalidate_caches()
    raysort.refresh()
    try:
        assert "morton" not in raysort.available("sorters")
        with pytest.raises(raysort.UnknownPluginError, match="available sorters"):
            raysort.load("sorters", "morton")
    finally:
        sys.path.insert(0, str(morton_site))
        importlib.invalidate_caches()
        raysort.refresh()


# -- the README example, in process ----------------------------------------------

def test_readme_example_sorter_works(octant_registered, sibenik, workloads, none_image):
    """The README's OctantSorter keeps the contract, groups each large packet by
    octant, and renders the 'none' image bit for bit."""
    work = workloads(sibenik, "diffuse")
    n = len(work.rays)
    sorter = raysort.create("sorters", {"type": octant_registered, "packet_size": 16})
    order, offsets = check_sort(octant_registered, sorter.sort(work.rays, work.packets,
                                                               sibenik.bounds), n, work.packets)
    d = work.rays.directions.T.tolist()
    octant = np.array([sum(1 << k for k in range(3) if ray[k] < 0) for ray in d])
    packet = np.searchsorted(work.packets, np.arange(n), side="right") - 1
    np.testing.assert_array_equal(order, np.lexsort((np.arange(n), octant, packet)))
    np.testing.assert_array_equal(offsets, _reference_offsets(work.packets.tolist(), 16))
    assert not np.array_equal(order, np.arange(n))
    image = _render(sibenik, octant_registered, 48, 32, 2).image
    _assert_bitwise_equal(image, none_image, "octant_example")


def test_contract_judges_unsigned_offsets():
    """What a third-party sorter gets back for unsigned offsets (e.g. a cumsum of
    uint64 counts): valid ones are accepted like unsigned ``order`` is, and
    decreasing ones are reported as such, never a raw TypeError or a wrapped size.

    Fails at present: raysort/contract.py line 44 (``reduceat`` with uint64
    starts) raises TypeError, and line 36 (``np.diff`` of unsigned offsets)
    wraps, so the message blames a 4294967295-ray sub-packet.
    """
    order = np.arange(5, dtype=np.uint64)
    valid = check_sort("unsigned", (order, np.array([0, 2, 5], np.uint64)), 5, [0, 5])
    np.testing.assert_array_equal(valid[1], [0, 2, 5])
    with pytest.raises(raysort.PluginContractError, match="increase strictly"):
        check_sort("unsigned", (order, np.array([0, 3, 2, 5], np.uint32)), 5, [0, 5])
