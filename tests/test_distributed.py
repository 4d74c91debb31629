"""raysort.distributed: tiles as Dask tasks give the local render's image, bit for bit.

Logic runs on an in-process (threads) LocalCluster; pickling, the per-worker BVH
cache, missing plugins and worker deaths on LocalClusters of worker processes.
"""
import os
import signal
import subprocess
import sys
import time

import dask
import numpy as np
import pytest
from distributed import Client, LocalCluster

import raysort
from raysort import distributed as rd
from raysort import registry
from raysort.cli import main
from raysort.errors import ClusterError, ConfigError, PluginError
from raysort.sorters.none import NoneSorter

SIZE = (96, 64, 4)                    # width, height, spp: 24 tiles of 16x16


def cluster(**kw):
    return LocalCluster(dashboard_address=":0", **kw)      # any free port: no clashes


def assert_same_image(image, ref):
    assert image.max() > 0, "a black image proves nothing"
    differ = np.flatnonzero(image.view(np.uint32) != ref.view(np.uint32))
    assert len(differ) == 0, f"{len(differ)} channels differ from the local render"


@pytest.fixture(scope="module")
def pipe():
    # two tiles share each batch (1024 rays a tile): tasks hold whole runs of two tiles
    return raysort.Pipeline("cornell", tile=16, batch_rays=2048)


@pytest.fixture(scope="module")
def local(pipe):
    return pipe.render(*SIZE)


@pytest.fixture(scope="module")
def threads_client():
    with cluster(n_workers=2, threads_per_worker=2, processes=False) as c, Client(c) as client:
        yield client


@pytest.fixture(scope="module")
def process_client():
    """Two single-threaded worker processes.  They see only raysort's own plugins
    (RAYSORT_DISABLE_PLUGIN_AUTOLOAD), as if nothing else were installed on them."""
    with cluster(n_workers=2, threads_per_worker=1, processes=True,
                 env={"RAYSORT_DISABLE_PLUGIN_AUTOLOAD": "1"}) as c, Client(c) as client:
        yield client


# --------------------------------------------------------------------------
# the image
# --------------------------------------------------------------------------

@pytest.mark.parametrize("per_task", [None, 1, 5, 24])
def test_threads_cluster_gives_the_local_image(pipe, local, threads_client, per_task):
    """Any grouping of tiles into tasks, two workers of two threads: the same image and
    the same work counted; progress counts every tile once."""
    seen = []
    with dask.config.set({"raysort.tiles-per-task": per_task}):
        result = pipe.render(*SIZE, client=threads_client,
                             progress=lambda done, total: seen.append((done, total)))
    assert_same_image(result.image, local.image)
    assert seen == [(k, 24) for k in range(1, 25)]
    assert result.stats.rays == local.stats.rays
    assert result.stats.counters == local.stats.counters
    assert result.stats.shadow_rays == local.stats.shadow_rays
    assert result.stats.threads == 4
    assert result.settings == local.settings


@pytest.mark.parametrize("sorter, traversal", [("none:packet_size=16", "ranged"),
                                               ("nah:max_cells=2", "partition")])
def test_plugins_travel_with_their_parameters(threads_client, sorter, traversal):
    pipe = raysort.Pipeline("cornell", sorter=sorter, traversal=traversal, tile=16,
                            shader="lambert:max_depth=1")
    assert_same_image(pipe.render(*SIZE, client=threads_client).image, pipe.render(*SIZE).image)


def test_process_workers_give_the_local_image_and_build_one_bvh_each(pipe, local,
                                                                     process_client):
    """Over pickling and two renders, each worker process builds the scene's BVH once."""
    with dask.config.set({"raysort.tiles-per-task": 1}):
        for _ in range(2):
            assert_same_image(pipe.render(*SIZE, client=process_client).image, local.image)
    key = rd.scene_key(pipe.scene)
    builds = [info["bvh_builds"].get(key) for info in process_client.run(rd.cache_info).values()]
    assert builds and all(n == 1 for n in builds if n is not None), builds
    assert any(n == 1 for n in builds), builds


def test_every_installed_plugin_is_rebuilt_from_its_recipe():
    """What a worker gets (name and parameters) recreates each plugin exactly."""
    for kind, group in rd._KINDS.items():
        for name in registry.available(group):
            try:
                plugin = registry.create(group, name)
            except raysort.PluginError:
                continue                     # broken plugins are reported elsewhere
            again = registry.create(group, rd._plugin_config(kind, plugin))
            assert type(again) is type(plugin) and again.params() == plugin.params(), name


def test_default_grouping_keeps_tasks_large_and_numerous():
    # the paper's 1024x1024, 64 spp on 2 workers: 4 tiles of 65536 samples per task
    assert rd.tiles_per_task(1024, 1024, 64, 2) == 4
    for tiles, spp, threads in [(1024, 4, 2), (1024, 1, 64), (24, 4, 4), (1, 1, 1)]:
        n = rd.tiles_per_task(tiles, 1024, spp, threads)
        enough_tasks = tiles // n >= rd.TASKS_PER_THREAD * threads
        assert n == 1 or enough_tasks
        assert n * 1024 * spp >= rd.TASK_SAMPLES or not (tiles // (n + 1)
                                                          >= rd.TASKS_PER_THREAD * threads)


# --------------------------------------------------------------------------
# plugins the workers cannot have
# --------------------------------------------------------------------------

class _Script(NoneSorter):
    """A sorter class defined in a script."""


def test_in_process_plugin_is_refused_before_anything_is_sent(threads_client):
    raysort.register("sorters", "scripted", _Script)
    try:
        with pytest.raises(ConfigError, match="'scripted'.*registered in process"):
            raysort.Pipeline("cornell", sorter="scripted").render(8, 8, 1, client=threads_client)
    finally:
        raysort.unregister("sorters", "scripted")
    with pytest.raises(ConfigError, match="instance of .*_Script"):
        raysort.Pipeline("cornell", sorter=_Script()).render(8, 8, 1, client=threads_client)


def install(site, distribution, sorter, target, monkeypatch):
    """A distribution that registers ``sorter = target``, on this process's sys.path
    (which worker processes spawned afterwards inherit)."""
    info = site / f"{distribution.replace('-', '_')}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {distribution}\n"
                                   f"Version: 1.0\n")
    (info / "entry_points.txt").write_text(f"[raysort.sorters]\n{sorter} = {target}\n")
    monkeypatch.syspath_prepend(str(site))
    registry.refresh()


@pytest.fixture
def client_only_plugin(tmp_path, monkeypatch):
    """A sorter 'faraway' from a distribution 'raysort-faraway', installed here only (the
    process_client workers ignore every distribution but raysort)."""
    install(tmp_path, "raysort-faraway", "faraway", "raysort.sorters.none:NoneSorter",
            monkeypatch)
    yield "faraway"
    monkeypatch.undo()
    registry.refresh()


def test_worker_without_the_plugin_names_plugin_and_worker(client_only_plugin, process_client):
    pipe = raysort.Pipeline("cornell", sorter=client_only_plugin)
    with pytest.raises(PluginError) as info:
        pipe.render(8, 8, 1, client=process_client)
    message = str(info.value)
    assert "unknown sorter 'faraway'" in message
    assert any(address in message for address in process_client.nthreads()), message
    assert "install the plugin's package on every worker" in message


# --------------------------------------------------------------------------
# faults
# --------------------------------------------------------------------------

def test_killed_worker_tasks_run_elsewhere_and_the_image_is_unchanged(pipe):
    # four times the frame of the other tests: 48 tasks, so that the busiest worker still
    # holds some when the first tile comes back (with 12 the workers can finish them all)
    size = (2 * SIZE[0], 2 * SIZE[1], SIZE[2])
    local = pipe.render(*size)
    with cluster(n_workers=2, threads_per_worker=1, processes=True) as c, Client(c) as client:
        pids = client.run(os.getpid)
        killed = []

        def kill_the_busiest(done, total):
            if not killed:
                processing = client.processing()
                victim = max(processing, key=lambda w: len(processing[w]))
                killed.append(len(processing[victim]))
                os.kill(pids[victim], signal.SIGKILL)

        with dask.config.set({"raysort.tiles-per-task": 1}):
            result = pipe.render(*size, client=client, progress=kill_the_busiest)
        assert killed and killed[0] >= 1, "the killed worker had no task: nothing was tested"
        assert_same_image(result.image, local.image)


def test_task_that_kills_its_workers_is_a_clear_error(tmp_path, monkeypatch):
    """A sorter that crashes its process (as a segfaulting kernel would), installed on
    the client and the worker; Dask gives up after allowed-failures (0 here) deaths."""
    (tmp_path / "raysort_crasher.py").write_text(
        "import os, signal\n"
        "from raysort.sorters.none import NoneSorter\n\n"
        "class Crasher(NoneSorter):\n"
        "    def sort(self, rays, packets, bounds):\n"
        "        os.kill(os.getpid(), signal.SIGKILL)\n")
    install(tmp_path, "raysort-crasher", "crasher", "raysort_crasher:Crasher", monkeypatch)
    try:
        with dask.config.set({"distributed.scheduler.allowed-failures": 0}), \
                cluster(n_workers=1, threads_per_worker=1, processes=True) as c, \
                Client(c) as client:
            with pytest.raises(ClusterError, match=r"died 1 time\(s\), the last on tcp://"):
                raysort.Pipeline("cornell", sorter="crasher").render(16, 16, 1, client=client)
    finally:
        monkeypatch.undo()
        registry.refresh()


def test_every_worker_gone_is_a_clear_error_and_writes_nothing(tmp_path, capsys, monkeypatch):
    """`raysort render --scheduler ADDRESS`: the cluster loses all its workers after the
    first tile; the command fails with one line and leaves no file."""
    from raysort import progress

    with cluster(n_workers=2, threads_per_worker=1, processes=True) as c:
        class CloseEveryWorker(progress.Progress):
            def __call__(self, done, total, rays=None):
                if done == 1:
                    c.scale(0)
                    with Client(c.scheduler_address) as watcher:
                        while watcher.nthreads():
                            time.sleep(0.05)

        monkeypatch.setattr(progress, "Progress", CloseEveryWorker)
        out = tmp_path / "gone.exr"
        with dask.config.set({"raysort.tiles-per-task": 1, "raysort.no-workers-timeout": "1s"}):
            code = main(["render", "cornell", "--size", "128x128", "--spp", "4", "--tile", "16",
                         "--scheduler", c.scheduler_address, "-o", str(out), "-q"])
    # (the cluster's worker processes share stderr with this one: look for our line)
    ours = [line for line in capsys.readouterr().err.splitlines() if line.startswith("raysort")]
    assert code == 2
    assert len(ours) == 1 and ours[0].startswith("raysort: error: every Dask worker"), ours
    assert "is gone" in ours[0]
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------
# the command line and the optional dependency
# --------------------------------------------------------------------------

def test_cli_local_cluster_writes_the_local_image(tmp_path, capsys):
    from raysort import output

    argv = ["render", "cornell", "--size", "48x32", "--spp", "2", "--tile", "16", "-q"]
    assert main(argv + ["-o", str(tmp_path / "local.exr")]) == 0
    assert main(argv + ["--scheduler", "local:1", "-o", str(tmp_path / "dask.exr")]) == 0
    assert "(1 thread)" in capsys.readouterr().out
    assert_same_image(output.read_exr(tmp_path / "dask.exr"),
                      output.read_exr(tmp_path / "local.exr"))


@pytest.mark.parametrize("argv, fragment", [
    (["--scheduler", "local:0"], "local:N needs a whole number N >= 1"),
    (["--scheduler", "local:two"], "local:N needs a whole number N >= 1"),
    (["--scheduler", "tcp://127.0.0.1:9"], "cannot connect to the Dask scheduler"),
])
def test_bad_scheduler_is_one_line(tmp_path, capsys, argv, fragment):
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        code = main(["render", "cornell", "--size", "8x8", "-q", "-o", str(tmp_path / "x.exr")]
                    + argv)
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and fragment in err, err
    assert list(tmp_path.iterdir()) == []


def test_scheduler_without_dask_says_what_to_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)        # import fails
    code = main(["render", "cornell", "--scheduler", "local:1", "-q",
                 "-o", str(tmp_path / "x.exr")])
    assert code == 2
    assert "pip install 'raysort[distributed]'" in capsys.readouterr().err


def test_import_raysort_does_not_import_dask(tmp_path):
    code = ("import sys, raysort, raysort.cli, raysort.sweep; "
            "print(sorted(m for m in ('dask', 'distributed') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120, cwd=tmp_path).stdout
    assert out.strip() == "[]"


def test_cluster_error_is_a_raysort_error():
    assert issubclass(ClusterError, raysort.RaysortError)
