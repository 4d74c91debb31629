"""``raysort bench`` end to end on tiny scenes: image check, exit status, --only, JSON."""
import json

import pytest

import raysort
from raysort.bvh import PRESETS
from raysort.bench.report import SCHEMA
from raysort.cli import main
from raysort.sdk import Counters, Traversal

TINY = ["--size", "16x16", "--spp", "1", "--depth", "1", "--repeat", "2", "-q"]


class Blind(Traversal):
    """Claims to be exact but never finds a hit: a deliberately different image."""

    def intersect(self, bvh, packets, any_hit=False):
        return Counters()


class BlindInexact(Blind):
    exact = False


@pytest.fixture
def blind():
    raysort.register("traversals", "bench_blind", Blind)
    raysort.register("traversals", "bench_blind_inexact", BlindInexact)
    yield
    raysort.unregister("traversals", "bench_blind")
    raysort.unregister("traversals", "bench_blind_inexact")


def bench(tmp_path, monkeypatch, *args):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out.json"
    status = main(["bench", *args, *TINY, "--json", str(out)])
    return status, (json.loads(out.read_text()) if out.exists() else None)


def test_json_keeps_every_round_and_the_orders(tmp_path, monkeypatch, capsys):
    status, rep = bench(tmp_path, monkeypatch, "plane", "cornell",
                        "--only", "ranged (8x8),ranged + nah,single")
    assert status == 0
    assert rep["schema"] == SCHEMA and rep["kind"] == "frame"
    assert set(rep["machine"]) >= {"cpu", "cores", "isa", "isas_compiled"}
    assert len(rep["load"]["before"]) == 3 and len(rep["load"]["after"]) == 3
    s = rep["settings"]
    assert (s["width"], s["height"], s["spp"], s["repeat"], s["warmup"]) == (16, 16, 1, 2, True)
    assert list(rep["groups"]) == ["plane", "cornell"]
    for g in rep["groups"].values():
        assert len(g["orders"]) == 2
        assert all(sorted(o) == sorted(r["label"] for r in g["configs"]) for o in g["orders"])
        assert [r["label"] for r in g["configs"]] == ["ranged (8x8)", "ranged + nah", "single"]
        for r in g["configs"]:
            assert len(r["rounds"]) == 2 and len(r["speedup_rounds"]) == 2
            assert r["seconds"]["median"] == pytest.approx(sum(r["rounds"]) / 2)
            assert r["seconds"]["min"] == min(r["rounds"])
            assert r["speedup_rounds"] == pytest.approx(
                [b / t for b, t in zip(g["configs"][0]["rounds"], r["rounds"])])
            assert r["baseline"] == "ranged (8x8)" and r["identical_image"] is True
            assert r["rays"] > 0 and r["counters_available"]
            assert set(r["counters_per_ray"]) == {"ia", "box1", "box4", "tri1", "tri4"}
            assert r["sort_share"] >= 0
        assert g["configs"][0]["speedup_rounds"] == [1.0, 1.0]
    text = capsys.readouterr().out
    assert "median [min-max]" in text and "order shuffled per round (seed 0)" in text


def test_an_exact_configuration_with_another_image_fails_the_bench(tmp_path, monkeypatch,
                                                                   capsys, blind):
    status, rep = bench(tmp_path, monkeypatch, "plane", "--add", "blind", "bench_blind", "none",
                        "--only", "ranged (8x8),blind")
    assert status == 1
    rows = {r["label"]: r for r in rep["groups"]["plane"]["configs"]}
    assert rows["blind"]["identical_image"] is False
    assert rows["blind"]["max_image_difference"] > 0
    assert rows["ranged (8x8)"]["identical_image"] is True
    out = capsys.readouterr().out
    assert "DIFFERS" in out and "ERROR" in out and "blind" in out


def test_an_inexact_configuration_may_differ(tmp_path, monkeypatch, capsys, blind):
    status, rep = bench(tmp_path, monkeypatch, "plane", "--add", "blind", "bench_blind_inexact",
                        "none", "--only", "ranged (8x8),blind")
    assert status == 0
    row = rep["groups"]["plane"]["configs"][1]
    assert row["exact_traversal"] is False and row["identical_image"] is False
    assert "inexact, max diff" in capsys.readouterr().out


def test_only_runs_the_named_configurations_in_that_order(tmp_path, monkeypatch):
    status, rep = bench(tmp_path, monkeypatch, "plane", "--only", "single,ranged + nah")
    assert status == 0
    rows = rep["groups"]["plane"]["configs"]
    assert [r["label"] for r in rows] == ["single", "ranged + nah"]
    # the table's baseline is not among them: the first one is
    assert {r["baseline"] for r in rows} == {"single"}


def test_unknown_label_or_plugin_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "plane", *TINY, "--only", "nope"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown configuration 'nope'" in err[0]
    assert main(["bench", "plane", *TINY, "--traversals", "no_such"]) == 2
    assert "no_such" in capsys.readouterr().err
    assert main(["bench", "plane", *TINY, "--bvh", "nonsense"]) == 2
    assert "unknown preset 'nonsense'" in capsys.readouterr().err


def test_list_prints_the_configurations_without_running(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--list", "--sorters", "all", "--traversals", "single"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(raysort.available("sorters"))
    assert all(line.startswith("single + ") for line in lines)


def test_manta_bvh_preset_gives_the_same_images(tmp_path, monkeypatch, capsys):
    status, rep = bench(tmp_path, monkeypatch, "cornell", "--bvh", "preset=manta,max_leaf=64",
                        "--only", "ranged (8x8),ranged + nah,partition (32x32)")
    assert status == 0
    g = rep["groups"]["cornell"]
    assert rep["settings"]["bvh"] == {"preset": "manta", "max_leaf": 64}
    # the parameters the tree was built with: the preset's, the one given on top
    assert rep["settings"]["bvh_params"] == {**PRESETS["manta"], "max_leaf": 64}
    assert "max_leaf 64, bins 16, traversal_cost 64, spatial_splits 0" in capsys.readouterr().out
    assert all(r["identical_image"] for r in g["configs"])


def test_kernels_table_every_traversal_and_layout(tmp_path, monkeypatch, capsys, blind):
    status, rep = bench(tmp_path, monkeypatch, "cornell", "--kernels",
                        "--workloads", "primary,diffuse", "--traversals",
                        "single,ranged,bench_blind_inexact")
    assert status == 0
    assert rep["kind"] == "kernels"
    assert list(rep["groups"]) == ["cornell primary", "cornell diffuse:depth=1"]
    for g in rep["groups"].values():
        rows = {r["label"]: r for r in g["configs"]}
        assert len(rows) == 9
        assert all(rows[f"{t} / {p}"]["identical_hits"] for t in ("single", "ranged")
                   for p in ("8x8", "32x32", "nah"))
        assert rows["bench_blind_inexact / nah"]["identical_hits"] is False
        assert all(len(r["rounds"]) == 2 and r["sort_seconds"]["median"] >= 0
                   for r in g["configs"])
    out = capsys.readouterr().out
    assert "Mrays/s (median)" in out and "bench_blind_inexa" in out


def test_kernels_an_exact_traversal_with_other_hits_fails(tmp_path, monkeypatch, blind):
    status, _ = bench(tmp_path, monkeypatch, "plane", "--kernels", "--workloads", "primary",
                      "--traversals", "single,bench_blind")
    assert status == 1


def test_chart_bars_and_heat_map(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "plane", *TINY, "--only", "ranged (8x8),single",
                 "--chart", "bars.png"]) == 0
    assert main(["bench", "plane", *TINY, "--sorters", "none,nah", "--traversals",
                 "single,ranged", "--chart", "heat.png"]) == 0
    for name in ("bars.png", "heat.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_baseline_names_the_configuration_speedups_are_taken_over(tmp_path, monkeypatch):
    status, rep = bench(tmp_path, monkeypatch, "plane", "--only",
                        "ranged (8x8),partition (32x32),ranged + nah",
                        "--baseline", "partition (32x32)")
    assert status == 0
    rows = {r["label"]: r for r in rep["groups"]["plane"]["configs"]}
    assert {r["baseline"] for r in rows.values()} == {"partition (32x32)"}
    assert rows["ranged + nah"]["speedup_rounds"] == pytest.approx(
        [p / t for p, t in zip(rows["partition (32x32)"]["rounds"],
                               rows["ranged + nah"]["rounds"])])


def test_kernels_matrix_of_sorters_and_traversals_per_workload(tmp_path, monkeypatch, capsys):
    status, rep = bench(tmp_path, monkeypatch, "cornell", "--kernels", "--sorters", "none,nah",
                        "--traversals", "single,ranged",
                        "--workloads", "diffuse,diffuse:depth=2,shadow")
    assert status == 0
    assert list(rep["groups"]) == ["cornell diffuse:depth=1", "cornell diffuse:depth=2",
                                   "cornell shadow:depth=0"]
    for g in rep["groups"].values():
        rows = {r["label"]: r for r in g["configs"]}
        assert set(rows) == {"single + none", "single + nah", "ranged + none", "ranged + nah"}
        assert rows["ranged + nah"]["baseline"] == "ranged + none"
        assert all(r["identical_hits"] for r in rows.values())
    assert rep["groups"]["cornell shadow:depth=0"]["any_hit"] is True


def test_compared_pairs_are_per_round_ratios_too(tmp_path, monkeypatch, capsys):
    status, rep = bench(tmp_path, monkeypatch, "plane", "--only",
                        "ranged (8x8),partition (32x32),ranged + nah")
    assert status == 0
    g = rep["groups"]["plane"]
    rows = {r["label"]: r for r in g["configs"]}
    (pair,) = [c for c in g["comparisons"] if c["label"] == "ranged + nah"]
    assert pair["over"] == "partition (32x32)"
    assert pair["speedup_rounds"] == pytest.approx(
        [p / t for p, t in zip(rows["partition (32x32)"]["rounds"],
                               rows["ranged + nah"]["rounds"])])
    assert "ranged + nah over partition (32x32):" in capsys.readouterr().out


FAST = ["--size", "8x8", "--spp", "1", "--repeat", "1", "--no-warmup", "-q"]


@pytest.fixture
def nothing_runs(monkeypatch):
    """Fail the test if a scene is loaded (a render or a timing would follow)."""
    def load_scene(spec):
        raise AssertionError(f"scene {spec!r} loaded")

    monkeypatch.setattr("raysort.bench.frame.load_scene", load_scene)
    monkeypatch.setattr("raysort.bench.kernels.load_scene", load_scene)


def one_line_error(capsys, argv, *fragments):
    """``raysort bench ARGV`` exits 2 with one stderr line holding ``fragments``."""
    assert main(["bench", *argv]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("raysort: error: "), err
    for fragment in fragments:
        assert fragment in err[0], (fragment, err[0])


@pytest.mark.parametrize("text, args, problem", [
    ("config = [1]\n", ["--list"], "'config' must be an array of tables"),
    ("[matrix]\nlabel = '{foo}'\n", ["--sorters", "none", "--traversals", "ranged"],
     "[matrix]: label '{foo}' is not a valid template"),
    ("[matrix]\nlabel = '{0}'\n", ["--sorters", "none", "--traversals", "ranged"],
     "[matrix]: label '{0}' is not a valid template"),
    ("[kernels]\nlabel = '{x}'\n", ["--kernels", "--traversals", "ranged"],
     "[kernels]: label '{x}' is not a valid template"),
    ("[kernels]\npackets = 3\n", ["--kernels", "--traversals", "ranged"],
     "'packets' must be a table"),
    ("[kernels]\npackets = {}\n", ["--kernels", "--traversals", "ranged"],
     "[kernels.packets] names no packet layout"),
    ("[render]\nshader = 3\n", ["--only", "ranged (8x8)"], "'shader' must be a name"),
    ("[render]\nshader = 'ao'\n", ["--only", "ranged (8x8)"],
     "configs.toml [render]: depth_parameter 'max_depth': shader 'ao' does not read"),
    ("[render]\nshader = {type = 'nope'}\n", ["--only", "ranged (8x8)"],
     "[render]: unknown shader 'nope'"),
    ("[render]\ndepth_parameter = 'nope'\n", ["--only", "ranged (8x8)"],
     "[render]: depth_parameter 'nope': shader 'lambert' does not read parameter 'nope'"),
    ("[render]\ncompare = 'xy'\n", ["--only", "ranged (8x8)"], "'compare' must be an array"),
    ("[render]\ncompare = [['ranged (8x8)', 'ranged + nah', 'x']]\n", ["--only", "ranged (8x8)"],
     "'compare' must be an array"),
])
def test_a_bad_configs_file_is_one_line_before_anything_runs(tmp_path, monkeypatch, capsys,
                                                             nothing_runs, text, args, problem):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.toml").write_text(text)
    one_line_error(capsys, ["cornell", *FAST, "--configs", "mine.toml", *args, "--json", "b.json"],
                   "--configs 'mine.toml'", problem)
    assert [p.name for p in tmp_path.iterdir()] == ["mine.toml"]


@pytest.mark.parametrize("args, problem", [
    (["--json", "b.json", "--chart", "b.json"], "--chart 'b.json' is the --json file 'b.json'"),
    (["--json", "b.json", "--chart", "./b.json"], "--chart './b.json' is the --json file"),
    (["--json", "mine.toml", "--configs", "mine.toml"], "is the --configs file 'mine.toml'"),
    (["--json", ""], "--json: cannot write '': the path is empty"),
    (["--chart", ""], "--chart: cannot write '': the path is empty"),
    (["--chart", "c"], "--chart 'c': the extension names the format"),
    (["--chart", "c.pgf"], "--chart 'c.pgf': the extension names the format"),
    (["--baseline", ""], "unknown configuration ''"),
])
def test_bad_output_paths_are_one_line_before_anything_runs(tmp_path, monkeypatch, capsys,
                                                            nothing_runs, args, problem):
    pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.toml").write_text("")
    one_line_error(capsys, ["cornell", *FAST, "--only", "ranged (8x8)", *args], problem)
    assert [p.name for p in tmp_path.iterdir()] == ["mine.toml"]


@pytest.mark.parametrize("args, problem", [
    (["cornell", "missing.ply", "--only", "ranged (8x8)"], "mesh 'missing.ply' does not exist"),
    (["cornell", "nosuchscene", "--only", "ranged (8x8)"], "unknown scene 'nosuchscene'"),
    (["cornell", "--kernels", "--traversals", "ranged", "--workloads", "primary,nope"],
     "unknown workload kind 'nope'"),
    (["cornell", "--bvh", "", "--only", "ranged (8x8)"], "--bvh is empty"),
])
def test_every_scene_and_workload_is_checked_before_any_is_timed(tmp_path, monkeypatch, capsys,
                                                                 nothing_runs, args, problem):
    """A bad second scene or workload kind fails before the first is loaded or timed."""
    monkeypatch.chdir(tmp_path)
    one_line_error(capsys, [*args, *FAST, "--json", "b.json"], problem)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("mode", [
    ["--only", "ranged (8x8)"],
    ["--kernels", "--traversals", "ranged", "--only", "ranged / 8x8"]])
def test_a_corrupt_second_mesh_fails_before_anything_is_timed(tmp_path, monkeypatch, capsys,
                                                              mode):
    """Every mesh is read before the first scene is timed: a corrupt second one is the
    command's one error line, and nothing was timed or written."""
    def no_timing(*args, **kwargs):
        raise AssertionError("a scene was timed")

    monkeypatch.setattr("raysort.bench.frame.run_checked", no_timing)
    monkeypatch.setattr("raysort.bench.kernels.run_checked", no_timing)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\n")
    one_line_error(capsys, ["cornell", "bad.ply", *mode, *FAST, "--json", "b.json"], "bad.ply")
    assert [p.name for p in tmp_path.iterdir()] == ["bad.ply"]


def test_chart_takes_the_format_its_extension_names(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "cornell", *FAST, "--only", "ranged (8x8)", "--chart", "c.pdf"]) == 0
    assert (tmp_path / "c.pdf").read_bytes()[:5] == b"%PDF-"


def test_undecodable_names_are_charted(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)
    label = "\udcff $\\frac$"                 # a label from a command line that is not UTF-8
    assert main(["bench", "cornell", *FAST, "--add", label, "ranged", "none", "--only", label,
                 "--json", "b.json", "--chart", "c.png"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.json", "c.png"]


def test_a_failing_chart_leaves_no_file(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)

    def broken(*args):
        raise RuntimeError("broken chart")

    monkeypatch.setattr("raysort.bench.report._bars", broken)
    with pytest.raises(RuntimeError, match="broken chart"):
        main(["bench", "cornell", *FAST, "--only", "ranged (8x8)", "--json", "b.json",
              "--chart", "c.png"])
    assert list(tmp_path.iterdir()) == []
