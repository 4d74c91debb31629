"""raysort.sweep: configurations timed against the baseline, saved as they arrive, resumable."""
import csv
import json
import statistics

import pytest
from distributed import Client, LocalCluster

import raysort
from raysort import sweep
from raysort.cli import main
from raysort.errors import ConfigError
from raysort.sorters.none import NoneSorter

TINY = dict(width=32, height=32, spp=1, rounds=2)


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
