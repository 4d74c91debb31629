"""Run-time ISA dispatch: every ISA this CPU runs gives brute force's hits and one image.

All ISAs are checked in this one installation through ``raysort.isa.use``;
an ISA that is compiled but not supported here is reported as a skip.
"""
import os
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import raysort
from raysort import isa
from raysort.rays import gather, scatter, scatter_occluded
from raysort.reference import brute_force

from _helpers import assert_same_hits, random_rays

AVAILABLE = isa.available()


def _builtin(kind):
    return [i.name for i in raysort.list_plugins(kind) if i.distribution == "raysort"]


def test_the_best_available_isa_is_active_by_default():
    if os.environ.get("RAYSORT_ISA"):
        pytest.skip("RAYSORT_ISA forces the ISA")
    assert isa.active() == [i for i in AVAILABLE if i not in isa.ON_REQUEST][-1]


def test_an_emulated_isa_runs_only_when_asked_for():
    """``avx512emu`` (tests only) is known, needs AVX2, is never the default and, where
    it is built and runs, reports itself from its kernels."""
    assert "avx512emu" in isa.ISAS and "avx512emu" in isa.ON_REQUEST
    assert isa.active() not in isa.ON_REQUEST or os.environ.get("RAYSORT_ISA")
    if "avx512emu" not in AVAILABLE:
        pytest.skip("avx512emu is not built (RAYSORT_BUILD_ISAS=avx512emu) or needs AVX2")
    previous = isa.use("avx512emu")
    try:
        assert isa.module("_gather").compiled_isa() == "avx512emu"
    finally:
        isa.use(previous)


def test_baseline_is_always_available():
    assert isa.baseline() in AVAILABLE and "scalar" in isa.supported()
    assert isa.available() == [i for i in isa.compiled() if i in isa.supported()]


def test_info_names_compiled_and_active():
    info = isa.info()
    assert info["active"] in info["available"]
    assert set(info["available"]) <= set(info["compiled"]) & set(info["supported"])


def test_use_switches_the_kernel_modules(each_isa):
    assert isa.active() == each_isa
    assert isa.module("_gather").compiled_isa() == each_isa
    for name in ("traversals.single", "traversals.wide", "sorters.nah", "generators.pinhole"):
        mod = isa.module(name)
        expected = f"raysort.{name}" if each_isa == isa.baseline() else \
            f"raysort._isa.{each_isa}.{name}"
        assert mod.__name__ == expected


def test_use_rejects_unknown_isa():
    with pytest.raises(raysort.ConfigError, match="unknown ISA"):
        isa.use("avx9000")


def test_every_traversal_matches_brute_force(each_isa, sibenik, rng):
    rays = random_rays(rng, 3000, sibenik.bvh().bounds)
    ref = brute_force(sibenik.vertices, sibenik.faces, rays)
    order, offsets = raysort.create("sorters", "nah").sort(rays, np.array([0, len(rays)],
                                                                          np.int32),
                                                          sibenik.bvh().bounds)
    for name in _builtin("traversals"):
        packets = gather(rays, order, offsets)
        raysort.create("traversals", name).intersect(sibenik.bvh(), packets)
        assert_same_hits(scatter(packets, len(rays)), ref, f"{each_isa}/{name}")
        packets = gather(rays, order, offsets)
        raysort.create("traversals", name).intersect(sibenik.bvh(), packets, any_hit=True)
        assert np.array_equal(scatter_occluded(packets, len(rays)), ref.prim >= 0), name


def _render():
    pipe = raysort.Pipeline("sibenik", sorter="nah", traversal="ranged")
    return pipe.render(48, 32, spp=2, seed=5).image


@pytest.fixture(scope="module")
def baseline_image():
    previous = isa.use(isa.baseline())
    try:
        return _render()
    finally:
        isa.use(previous)


def test_images_are_bit_identical_across_isas(each_isa, baseline_image):
    image = _render()
    assert np.array_equal(image.view(np.uint32), baseline_image.view(np.uint32))


@pytest.mark.parametrize("value, message", [
    ("avx9000", "unknown ISA"),
    ("scalar", None),
])
def test_raysort_isa_environment(tmp_path, value, message):
    code = "import raysort.isa as i; print(i.active())"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path, env=dict(os.environ, RAYSORT_ISA=value), timeout=120)
    if message is None:
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.strip() == value
    else:
        assert proc.returncode != 0 and message in proc.stderr


def test_cli_reports_a_bad_raysort_isa_in_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "raysort", "plugins"], capture_output=True,
                          text=True, cwd=tmp_path, env=dict(os.environ, RAYSORT_ISA="avx9000"),
                          timeout=120)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "unknown ISA" in proc.stderr


def test_the_isa_table_is_what_setup_py_reads():
    """setup.py reads ``raysort/_isa_table.py`` by path, without the package: the file runs
    on its own (it imports nothing) and gives raysort.isa its names."""
    table = runpy.run_path(str(Path(isa.__file__).with_name("_isa_table.py")))
    assert table["ISAS"] == isa.ISAS
    assert table["ON_REQUEST"] == isa.ON_REQUEST
    assert set(table["ON_REQUEST"]) <= set(isa.ISAS) and set(table["NEEDS"]) == set(isa.ISAS)
    assert not [k for k, v in table.items() if type(v).__name__ == "module"]
