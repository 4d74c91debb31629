"""raysort.bench.report: the JSON rows and the text tables, from injected timings."""
import io

import pytest

from raysort.bench.configs import Config
from raysort.bench.report import (
    failures,
    format_report,
    group_report,
    numpy_simd,
    pivot,
    write_chart,
)
from raysort.stats import Counters

SECONDS = [[2.0, 1.0, 4.0], [3.0, 1.0, 5.0], [2.0, 2.0, 2.0]]   # rounds x configurations
CONFIGS = [Config("base", "single", "none", baseline="base"),
           Config("fast", "single", "nah", baseline="base", paper="Ranged w/ sorting (ours)"),
           Config("odd", "lying", "none", baseline="base")]


def rows(identical=(True, True, False), exact=(True, True, True)):
    stage = {"sort": 0.1, "gather": 0.1, "traverse": 1.0}
    return [{"rays": 1000, "counters": Counters(rays=1000, ia=5, box1=10, box4=20, tri1=3,
                                                tri4=4),
             "stage_seconds": [stage] * 3, "exact_traversal": e, "identical_image": i,
             "max_image_difference": 0.0 if i else 0.5}
            for i, e in zip(identical, exact)]


def report(group):
    return {"kind": "frame", "machine": {"cpu": "CPU X", "cores": 2, "isa": "avx2",
                                         "isas_compiled": ["sse2", "avx2"], "python": "3"},
            "load": {"before": [1.0, 1.0, 1.0], "after": [2.0, 2.0, 2.0]},
            "settings": {"width": 16, "height": 8, "spp": 1, "depth": 2, "seed": 0,
                         "threads": 1, "repeat": 3, "order_seed": 4, "warmup": True,
                         "bvh": {}},
            "groups": {"sibenik": {**group, "scene": "sibenik", "triangles": 10,
                                   "bvh": {"leaves": 4, "mean_leaf_size": 2.5}}}}


def test_rows_hold_every_round_medians_and_per_round_speedups():
    g = group_report(CONFIGS, SECONDS, [[0, 1, 2], [2, 1, 0], [1, 0, 2]], rows(),
                     compare=[("odd", "fast"), ("missing", "base")])
    _, fast, odd = g["configs"]
    assert g["orders"] == [["base", "fast", "odd"], ["odd", "fast", "base"],
                           ["fast", "base", "odd"]]
    assert fast["rounds"] == [1.0, 1.0, 2.0]
    assert fast["seconds"] == {"median": 1.0, "min": 1.0, "max": 2.0, "iqr": 0.5}
    assert fast["speedup_rounds"] == [2.0, 3.0, 1.0]
    assert fast["speedup"]["median"] == 2.0       # not base median / fast median (2.0 / 1.0)
    assert odd["speedup_rounds"] == [0.5, 0.6, 1.0] and odd["speedup"]["median"] == 0.6
    assert fast["mrays_per_second"] == pytest.approx(1000 / 1.0 / 1e6)
    assert fast["sort_share"] == pytest.approx(0.2)
    assert fast["counters_per_ray"] == {"ia": 0.005, "box1": 0.01, "box4": 0.02,
                                        "tri1": 0.003, "tri4": 0.004}
    (c,) = g["comparisons"]
    assert (c["label"], c["over"], c["speedup_rounds"]) == ("odd", "fast", [0.25, 0.2, 1.0])


def test_an_unknown_baseline_falls_back_to_the_first_configuration():
    configs = [Config("a", "single", "none", baseline="gone"),
               Config("b", "single", "nah", baseline="gone")]
    g = group_report(configs, [[2.0, 1.0]], [[0, 1]], rows()[:2])
    assert [r["baseline"] for r in g["configs"]] == ["a", "a"]
    assert g["configs"][1]["speedup_rounds"] == [2.0]


def test_failures_are_exact_configurations_with_another_image():
    g = group_report(CONFIGS, SECONDS, [[0, 1, 2]] * 3, rows())
    assert failures(report(g)) == [("sibenik", "odd")]
    g = group_report(CONFIGS, SECONDS, [[0, 1, 2]] * 3, rows(exact=(True, True, False)))
    assert failures(report(g)) == []


def test_text_layout():
    g = group_report(CONFIGS, SECONDS, [[0, 1, 2]] * 3, rows(), compare=[("odd", "fast")])
    out = io.StringIO()
    format_report(report(g), out)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("raysort bench: 16x8, 1 spp, depth 2, seed 0, 1 thread(s)")
    assert "3 timed rounds after a warm-up round" in lines[0]
    assert "order shuffled per round (seed 4); median [min-max]" in lines[0]
    assert lines[1].startswith("machine: CPU X (2 cores), ISA avx2 (compiled sse2, avx2)")
    assert "load average [1.0, 1.0, 1.0] before, [2.0, 2.0, 2.0] after" in lines[1]
    text = out.getvalue()
    assert "sibenik (10 triangles; BVH 4 leaves, 2.5 triangles per leaf)" in text
    (fast,) = [line for line in lines if line.strip().startswith("fast ")]
    assert "1.000 [1.000-2.000]" in fast and "2.00 [1.00-3.00]" in fast and "same" in fast
    (odd,) = [line for line in lines if line.strip().startswith("odd ") and "over" not in line]
    assert "DIFFERS" in odd
    assert "odd over fast: 0.25 [0.20-1.00]x" in text
    assert "Table I (per ray)" in text and "N_IA" in text
    assert "Ranged w/ sorting (ours)" in text        # next to the paper's Table I
    assert lines[-1].startswith("ERROR: exact configurations differ") and "odd" in lines[-1]


def test_pivot_grid_of_rows_and_columns():
    configs = [Config("t1 + a", "t1", "a", row="t1", column="a"),
               Config("t1 + b", "t1", "b", row="t1", column="b"),
               Config("t2 + b", "t2", "b", row="t2", column="b")]
    g = group_report(configs, [[1.0, 2.0, 4.0]], [[0, 1, 2]], rows())
    names, cols, grid = pivot(g["configs"], lambda r: r["speedup"]["median"])
    assert (names, cols) == (["t1", "t2"], ["a", "b"])
    assert grid[0].tolist() == [1.0, 0.5] and grid[1, 1] == 0.25
    assert grid[1, 0] != grid[1, 0]                    # no t2 + a: NaN


def chart_report(name, labels):
    """A one-group frame report, ``name`` its scene and ``labels`` its configurations."""
    configs = [Config(label, "single", "none", baseline=labels[0]) for label in labels]
    g = group_report(configs, [[1.0 + k for k in range(len(labels))]], [list(range(len(labels)))],
                     rows()[:len(labels)])
    rep = report(g)
    rep["groups"] = {name: rep["groups"]["sibenik"]}
    return rep


@pytest.mark.parametrize("name, magic", [("c.png", b"\x89PNG\r\n\x1a\n"), ("c.pdf", b"%PDF"),
                                         ("c.svg", b"<?xml")])
def test_chart_is_written_in_the_format_its_extension_names(tmp_path, name, magic):
    pytest.importorskip("matplotlib")
    write_chart(chart_report("plane", ["a", "b"]), tmp_path / name)
    assert (tmp_path / name).read_bytes().startswith(magic)
    assert [p.name for p in tmp_path.iterdir()] == [name]


def test_chart_draws_undecodable_names_and_dollars_as_they_are(tmp_path):
    pytest.importorskip("matplotlib")
    rep = chart_report("\udcff.ply", ["a \udcff", "$\\frac$"])      # a file name not UTF-8
    write_chart(rep, tmp_path / "c.svg")
    svg = (tmp_path / "c.svg").read_text()
    assert "\\xff.ply" in svg and "$\\frac$" in svg


def test_text_shows_undecodable_names_as_escapes():
    out = io.StringIO()
    format_report(chart_report("\udcff.ply", ["a \udcff", "b"]), out)
    text = out.getvalue()
    assert "\\xff.ply (10 triangles" in text and "a \\xff" in text
    assert "\udcff" not in text


@pytest.mark.parametrize("features,level", [
    ({"X86_V2": True, "X86_V3": True, "X86_V4": True}, "avx512"),
    ({"X86_V2": True, "X86_V3": True, "X86_V4": False, "AVX512F": True}, "avx2"),
    ({"X86_V2": True, "X86_V3": False, "X86_V4": False, "AVX2": True}, "baseline"),
    ({"AVX2": True, "AVX512F": True, "AVX512_SKX": True}, "avx512"),
    ({"AVX2": True, "AVX512F": True, "AVX512_SKX": False}, "avx2"),
    ({"AVX2": False, "AVX512_SKX": False, "SSE42": True}, "baseline"),
    ({"ASIMD": True, "NEON": True}, None),
])
def test_numpy_simd_names_the_level_numpy_runs(features, level):
    """NumPy 2.4's grouped levels (X86_V4 held off by NPY_DISABLE_CPU_FEATURES while
    AVX512F stays set), the older feature names, and a NumPy that is not x86."""
    assert numpy_simd(features) == level


def test_machine_info_says_numpy_simd_and_the_header_shows_it(monkeypatch):
    import raysort.bench.report as report_module
    assert report_module.machine_info()["numpy_simd"] in ("avx512", "avx2", "baseline", None)
    monkeypatch.setattr(report_module, "numpy_simd", lambda: "avx2")
    machine = report_module.machine_info()
    assert machine["numpy_simd"] == "avx2"
    group = group_report(CONFIGS[:2], [row[:2] for row in SECONDS], [[0, 1]] * 3, rows()[:2])
    out = io.StringIO()
    format_report({**report(group), "machine": {**report(group)["machine"], **machine}}, out)
    assert "NumPy's SIMD avx2" in out.getvalue()
