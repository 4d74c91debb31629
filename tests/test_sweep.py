"""raysort.sweep: configurations timed against the baseline, saved as they arrive, resumable."""
import csv
import json
import os
import statistics
from dataclasses import asdict

import pytest
from distributed import Client, LocalCluster

import raysort
from raysort import sweep
from raysort.cli import main
from raysort.errors import ConfigError
from raysort.sorters.none import NoneSorter

from _helpers import assert_one_line_error, run

TINY = {"width": 32, "height": 32, "spp": 1, "rounds": 2}


def jobs(sorters=("none", "nah"), **kw):
    return sweep.matrix(["cornell"], list(sorters), ["ranged"], **dict(TINY, **kw))


def check_row(row, job):
    """A finished row: the job, per-round timings whose ratios are baseline / config."""
    assert row["error"] is None, row["error"]
    assert row["key"] == job.key and row["sorter"] == job.sorter and row["depth"] == job.depth
    assert len(row["seconds"]) == len(row["baseline_seconds"]) == job.rounds
    assert row["ratios"] == [b / s for b, s in zip(row["baseline_seconds"], row["seconds"])]
    assert row["median_ratio"] == statistics.median(row["ratios"])
    assert row["identical_image"] and row["exact_traversal"]
    assert row["rays"] > 0 and row["host"] and row["cpu"] and row["isa"]


def test_local_sweep_saves_json_and_csv(tmp_path):
    todo = jobs(depths=(1, 2))
    rows = sweep.run_sweep(todo, str(tmp_path / "s.json"), csv_path=str(tmp_path / "s.csv"))
    assert [r["key"] for r in rows] == [j.key for j in todo]
    for row, job in zip(rows, todo):
        check_row(row, job)
    saved = json.loads((tmp_path / "s.json").read_text())
    assert saved["format"] == sweep.FORMAT and saved["results"] == rows
    with open(tmp_path / "s.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [float(r["median_ratio"]) for r in table] == [r["median_ratio"] for r in rows]
    assert table[0]["ratios"] == " ".join(map(repr, rows[0]["ratios"]))
    assert "counters_per_ray.tri4" in table[0]


def test_interrupted_sweep_keeps_what_finished_and_resumes(tmp_path):
    path, todo = str(tmp_path / "s.json"), jobs()

    def interrupt(done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sweep.run_sweep(todo, path, progress=interrupt)
    with open(path) as fh:
        first = json.load(fh)["results"]
    assert [r["key"] for r in first] == [todo[0].key]

    with pytest.raises(ConfigError, match="--resume"):
        sweep.run_sweep(todo, path)
    calls = []
    rows = sweep.run_sweep(todo, path, resume=True, progress=lambda *a: calls.append(a))
    assert calls == [(2, 2)]                         # only the missing job ran
    assert rows[0] == first[0]                       # the finished one is kept as it was
    check_row(rows[1], todo[1])


class _Broken(NoneSorter):
    def sort(self, rays, packets, bounds):
        raise RuntimeError("broken on purpose")


def test_failed_job_is_recorded_and_run_again_on_resume(tmp_path):
    path = str(tmp_path / "s.json")
    raysort.register("sorters", "flaky", _Broken)
    try:
        rows = sweep.run_sweep(jobs(["flaky"]), path)
    finally:
        raysort.unregister("sorters", "flaky")
    # the contract names the plugin and keeps the plugin's own exception
    assert rows[0]["error"].startswith("PluginContractError: sorter 'flaky'")
    assert rows[0]["error"].endswith("RuntimeError: broken on purpose")
    raysort.register("sorters", "flaky", NoneSorter)
    try:
        rows = sweep.run_sweep(jobs(["flaky"]), path, resume=True)
    finally:
        raysort.unregister("sorters", "flaky")
    check_row(rows[0], jobs(["flaky"])[0])


def test_sweep_on_dask_reports_each_worker(tmp_path):
    todo = jobs()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                      dashboard_address=":0") as c, Client(c) as client:
        rows = sweep.run_sweep(todo, str(tmp_path / "s.json"), client=client)
        workers = set(client.nthreads())
    for row, job in zip(rows, todo):
        check_row(row, job)
        assert row["worker"] in workers


def test_cli_sweep_on_a_local_cluster_groups_by_machine(tmp_path, capsys):
    out = tmp_path / "s.json"
    argv = ["sweep", "cornell", "--sorter", "none", "--sorter", "nah:max_cells=2",
            "--traversal", "ranged", "--size", "32x32", "--spp", "1", "--rounds", "2",
            "--scheduler", "local:1", "-o", str(out), "--csv", str(tmp_path / "s.csv"), "-q"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    rows = json.loads(out.read_text())["results"]
    assert len(rows) == 2 and all(r["worker"].startswith("tcp://") for r in rows)
    assert f"machine {rows[0]['host']}: {rows[0]['cpu']}" in text
    assert "ranged + nah:max_cells=2" in text and "ranged + none:packet_size=64" in text
    assert main(argv) == 2                           # the file exists: --resume or elsewhere
    assert "pass --resume" in capsys.readouterr().err


def test_cli_sweep_unknown_plugin_is_one_line(tmp_path, capsys):
    code = main(["sweep", "cornell", "--sorter", "nosuch", "-o", str(tmp_path / "s.json")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("raysort: error: unknown sorter 'nosuch'")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------
# bad arguments and files: one line, exit status 2, nothing run or written
# --------------------------------------------------------------------------

#: a one-job sweep that takes milliseconds
QUICK = ["--sorter", "none", "--traversal", "ranged", "--depth", "0", "--size", "8x8",
         "--spp", "1", "--rounds", "1", "-q"]
QUICK_JOB = sweep.Job("cornell", "none", "ranged", depth=0, width=8, height=8, spp=1, rounds=1)
#: a finished row of QUICK_JOB with every field resuming and the table read
GOOD_ROW = dict(asdict(QUICK_JOB), key=QUICK_JOB.key, label=QUICK_JOB.label, error=None,
                scene_name="cornell", worker="(not on a Dask worker)", host="h", cpu="c",
                isa="sse", identical_image=True, exact_traversal=True, median_seconds=0.5,
                median_baseline_seconds=0.5, median_ratio=1.0, min_ratio=1.0, max_ratio=1.0,
                ratios=[1.0], counters_per_ray={"ia": 1.0})


@pytest.fixture
def no_jobs(monkeypatch):
    """Fail the test if a job of the sweep runs."""
    def measure(job, pipe, baseline):
        raise AssertionError(f"{job.label} ran")

    monkeypatch.setattr(sweep, "_measure", measure)


@pytest.mark.parametrize("seed", ["4294967296", "99999999999999999999"])
def test_cli_sweep_seed_out_of_range_is_one_line(seed, tmp_path, capsys, monkeypatch, no_jobs):
    """--seed takes render's range (the shared argtype), checked before anything runs."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(["sweep", "cornell", *QUICK, "--seed", seed])
    assert info.value.code == 2
    assert_one_line_error(capsys.readouterr().err, "--seed", seed, "--help")
    assert os.listdir(tmp_path) == []


def _with(**fields):
    return dict(GOOD_ROW, **fields)


def _file(*rows):
    return {"format": sweep.FORMAT, "results": list(rows)}


@pytest.mark.parametrize("content, fragment", [
    (_file({"key": "abc"}), "row 1: no 'error'"),
    (_file({"key": "abc", "error": None}), "row 1: no 'scene'"),          # another sweep's
    (_file({"key": "abc", "error": "x"}), "row 1: no 'scene'"),
    (_file({"key": QUICK_JOB.key, "error": None}), "row 1: no 'scene'"),  # this sweep's
    (_file(GOOD_ROW, _with(key="abc", median_ratio=float("nan"))), "row 2: 'median_ratio'"),
    (_file(_with(min_ratio=float("inf"))), "row 1: 'min_ratio' must be a finite number"),
    (_file(_with(median_seconds=10**400)), "row 1: 'median_seconds'"),
    (_file(_with(identical_image="yes")), "row 1: 'identical_image' must be true or false"),
    (_file(_with(depth="0")), "row 1: 'depth' must be a whole number"),
    (_file(_with(key=["abc"])), "row 1: 'key' must be a string"),
    (_file(_with(error=1)), "row 1: 'error' must be null or a string"),
    (_file(GOOD_ROW, 3), "row 2: not an object"),
    (_file(GOOD_ROW, GOOD_ROW), "row 2: the same key as row 1"),
    (_file(_with(counters_per_ray=json.loads("[" * 900 + "]" * 900))), "row 1: values nested"),
    ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ({"format": sweep.FORMAT, "results": 3}, "'results' is not a list"),
    ([1, 2], "not a raysort sweep file"),
])
def test_cli_sweep_resume_refuses_a_malformed_file(content, fragment, tmp_path, capsys,
                                                   no_jobs):
    """The results file is checked whole before any job runs: the first bad row is named in
    one line, and the file is left as it was (no CSV either)."""
    path = tmp_path / "s.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    before = path.read_bytes()
    code, out, err = run(capsys, "sweep", "cornell", *QUICK, "-o", path,
                         "--csv", tmp_path / "s.csv", "--resume")
    assert code == 2 and out == ""
    assert_one_line_error(err, f"cannot resume from {path}: ", fragment)
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["s.json"]


def test_cli_sweep_resume_keeps_a_well_formed_row(tmp_path, capsys, no_jobs):
    """A row with the fields the checks ask for resumes (nothing left to run) and is shown."""
    path = tmp_path / "s.json"
    other = _with(key="abc", error="RuntimeError: x")
    path.write_text(json.dumps(_file(GOOD_ROW, other)))
    code, out, err = run(capsys, "sweep", "cornell", *QUICK, "-o", path, "--resume")
    assert code == 1 and err == ""                   # the other sweep's row failed
    assert "machine h: c, SIMD sse" in out and "FAILED cornell ranged + none" in out


#: a valid mesh of one triangle
TRIANGLE_PLY = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                b"end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")


def test_cli_sweep_scene_file_name_not_utf8(tmp_path, capsys):
    """A mesh whose file name is not UTF-8: the JSON keeps the name (so --resume finds the
    row), the CSV and the table show its odd bytes as \\xNN."""
    name = os.fsdecode(b"\xff.ply")
    try:
        (tmp_path / name).write_bytes(TRIANGLE_PLY)
    except (OSError, UnicodeError):
        pytest.skip("the file system takes only UTF-8 names")
    scene, out_json, out_csv = str(tmp_path / name), tmp_path / "s.json", tmp_path / "s.csv"
    argv = ["sweep", scene, *QUICK, "-o", out_json, "--csv", out_csv]
    code, out, err = run(capsys, *argv)
    assert code == 0, err
    assert "\\xff" in out
    rows = json.loads(out_json.read_text())["results"]
    assert [r["scene"] for r in rows] == [scene]
    with open(out_csv, newline="", encoding="utf-8") as fh:          # valid UTF-8
        assert [r["scene"] for r in csv.DictReader(fh)] == [scene.replace(name, "\\xff.ply")]
    code, out, err = run(capsys, *argv, "--sorter", "nah", "--resume")
    assert code == 0, err
    again = json.loads(out_json.read_text())["results"]
    assert again[0] == rows[0] and [r["sorter"] for r in again] == ["none", "nah"]


@pytest.mark.parametrize("csv_name", ["s.json", "./sub/../s.json"])
def test_cli_sweep_csv_may_not_be_the_results_file(csv_name, tmp_path, capsys, monkeypatch,
                                                   no_jobs):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    code, out, err = run(capsys, "sweep", "cornell", *QUICK, "-o", "s.json", "--csv", csv_name)
    assert code == 2 and out == ""
    assert_one_line_error(err, f"--csv {csv_name!r}", "'s.json'")
    assert os.listdir(tmp_path) == ["sub"]


@pytest.mark.parametrize("option", ["-o", "--csv"])
def test_cli_sweep_empty_output_path_is_one_line(option, tmp_path, capsys, monkeypatch,
                                                 no_jobs):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, "sweep", "cornell", *QUICK, option, "")
    assert code == 2 and out == ""
    assert_one_line_error(err, "cannot write ''", "the path is empty")
    assert os.listdir(tmp_path) == []
