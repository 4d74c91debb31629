"""Rendering on a Dask cluster: tiles as tasks, one BVH per worker, the same image.

``Pipeline.render(..., client=client)`` hands its tiles to :func:`render_tiles`,
which runs them as tasks on the workers of a ``dask.distributed.Client``:

* **The scene** is sent once per render, inside the task graph: one task holds
  the scene's arrays (not its BVH) and every tile task depends on it, so each
  worker fetches it once, from the scheduler's graph or a peer.  Workers need
  raysort and the plugins installed but not the scene's files: a packaged name,
  a ``.toml``, a mesh or an in-memory :class:`~raysort.scene.Scene` all travel
  the same way (a few MB).  Unlike scattered data, a scene lost with every
  worker that held it is made again from the graph.  Tasks carry the scene's
  content hash (:func:`scene_key`).
* **The BVH** is built once per worker process and scene: a worker keeps its
  pipelines in a small cache keyed by the content hash and the configuration
  (:func:`worker_pipeline`), and every pipeline of one scene shares that scene's
  BVH.  It lives as long as the worker process.
* **Plugins** travel by name and parameters and are created on the worker from
  its own entry points, so they must be installed on every worker.  A worker
  that lacks one fails with a :class:`~raysort.errors.PluginError` naming the
  plugin and the worker.  A plugin registered in process
  (:func:`raysort.register`) or passed as an instance of an unregistered class
  exists only in the client's process and is refused before anything is sent.
* **Tasks** are groups of tiles (:func:`tiles_per_task`, or the Dask config
  ``raysort.tiles-per-task``), large enough that
  Dask's cost per task stays small against the work, and small enough that
  every worker thread gets several.  A task renders its tiles as the local
  threads do (``Pipeline._render_tiles``, several tiles per batch at low spp);
  the client assembles
  finished tiles in place, so the image is bit-identical to a local render
  whatever the number of workers, threads or tiles per task.
* **Failures**: when a worker dies its tasks run again elsewhere (the image
  does not change).  A task that kills several workers in turn ends the render
  with a :class:`~raysort.errors.ClusterError`; so does a cluster left without
  workers for ``raysort.no-workers-timeout`` (Dask config, default 60 s; e.g.
  ``DASK_RAYSORT__NO_WORKERS_TIMEOUT=10s``), or a lost scheduler.

Dask is an optional dependency (``pip install "raysort[distributed]"``); this
module imports it only inside its functions.
"""
from __future__ import annotations

import contextlib
import hashlib
import logging
import math
import os
import socket
import threading
import time
import uuid
from collections import OrderedDict
from dataclasses import replace

from raysort import registry
from raysort.errors import ClusterError, ConfigError, PluginError

__all__ = ["connect", "dask_client", "render_tiles", "finished", "worker_threads", "tiles_per_task",
           "scene_key",
           "send_scene", "pipeline_recipe", "worker_pipeline", "worker_info", "cache_info"]

INSTALL = "pip install 'raysort[distributed]'"

#: pixel samples a task should hold at least (tiles x pixels x spp).  Dask spends
#: a few milliseconds per task (scheduling, pickling, moving the tiles back);
#: 2^18 samples of a depth-2 path tracer are well over 0.1 s of work on one core.
TASK_SAMPLES = 1 << 18
#: tasks per worker thread at least: balances the load and bounds the work a
#: dying worker takes with it.
TASKS_PER_THREAD = 8
#: how often the client looks for finished tiles while none are ready (seconds)
POLL_SECONDS = 0.02
#: how often it asks the scheduler whether any worker is left (seconds)
WATCH_SECONDS = 1.0

#: plugin kinds as Pipeline's keyword arguments
_KINDS = {"generator": "generators", "sorter": "sorters", "traversal": "traversals",
          "shader": "shaders"}


def _dask():
    try:
        import distributed
    except ImportError:
        raise ConfigError(f"rendering on a Dask cluster needs dask.distributed: {INSTALL}") \
            from None
    return distributed


# --------------------------------------------------------------------------
# client side
# --------------------------------------------------------------------------

@contextlib.contextmanager
def connect(scheduler):
    """A ``Client`` for ``--scheduler``, closed on exit.

    ``scheduler`` is the address of a running scheduler (``tcp://host:8786``)
    or ``local[:N]``: a ``LocalCluster`` of N single-threaded worker processes
    (default: one per core), started here and closed on exit.
    """
    dd = _dask()
    import dask.config

    name, _, count = scheduler.partition(":")
    if name == "local":
        try:
            n = int(count) if count else os.cpu_count() or 1
        except ValueError:
            n = 0
        if n < 1:
            raise ConfigError(f"--scheduler local:N needs a whole number N >= 1, got "
                              f"{scheduler!r}")
        # The scheduler serves HTTP even without a dashboard: any free port, no clash.
        # No dashboard to feed, so no worker profiler sampling every thread 100 times a
        # second.  And no MALLOC_TRIM_THRESHOLD_ (Dask's nanny default): it turns off
        # glibc's adaptive mmap threshold, so every large temporary array of a tile is
        # mapped and faulted in afresh (70x the page faults, 10-15 % more CPU per render).
        # The workers log nothing: a task's error reaches the caller as the exception
        # itself (one line from the command), not also as a worker's logged traceback.
        with dask.config.set({"distributed.worker.profile.enabled": False,
                              "distributed.nanny.pre-spawn-environ": {}}), \
                dd.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                dashboard_address=":0", silence_logs=logging.CRITICAL) \
                as cluster, dd.Client(cluster) as client:
            yield client
        return
    try:
        client = dd.Client(scheduler)
    except (OSError, ValueError, TypeError) as exc:  # unreachable, refused, malformed
        raise ClusterError(f"cannot connect to the Dask scheduler {scheduler!r}: {exc}") \
            from None
    with client:
        yield client


def _no_workers_timeout():
    import dask.config
    from dask.utils import parse_timedelta

    return parse_timedelta(dask.config.get("raysort.no-workers-timeout", "60s"))


def worker_threads(client):
    """Threads over all workers of ``client``, waiting for a first worker to join."""
    dd = _dask()
    timeout = _no_workers_timeout()
    try:
        client.wait_for_workers(1, timeout=timeout)
    except (dd.TimeoutError, TimeoutError):
        raise ClusterError(f"no Dask worker joined the scheduler {client.scheduler.address} "
                           f"within {timeout:g} s") from None
    return sum(client.nthreads().values())


def tiles_per_task(n_tiles, tile_pixels, spp, threads):
    """Default tiles per task: at least :data:`TASK_SAMPLES` pixel samples each, but
    no fewer than :data:`TASKS_PER_THREAD` tasks per worker thread when the frame
    is too small for both."""
    by_work = math.ceil(TASK_SAMPLES / (tile_pixels * spp))
    by_balance = n_tiles // (TASKS_PER_THREAD * max(1, threads))
    return max(1, min(by_work, by_balance))


def scene_key(scene):
    """Content hash of everything in a scene that can change an image (not its name)."""
    h = hashlib.blake2b(digest_size=16)
    for array in (scene.vertices, scene.faces, scene.albedo, scene.emission, scene.sky):
        h.update(str((array.dtype.str, array.shape)).encode())
        h.update(array.tobytes())
    h.update(repr((scene.camera, scene.lights)).encode())
    return h.hexdigest()


def send_scene(client, scene):
    """``(content hash, future)``: a task holding the scene (without its BVH).

    Its arguments live in the scheduler's graph, so the scene can be made again
    if every worker holding it dies; it is sent once however many tasks use it.
    """
    import dask.config

    key = scene_key(scene)
    with dask.config.set({"distributed.admin.large-graph-warning-threshold": "1GB"}):
        future = client.submit(_identity, _without_bvh(scene),
                               key=f"raysort-scene-{key}-{uuid.uuid4().hex[:8]}")
    return key, future


def _identity(value):
    return value


def _without_bvh(scene):
    """A shallow copy of ``scene`` (same arrays) that has not built a BVH: what is
    sent, and what a worker caches (the object Dask holds must stay picklable)."""
    return replace(scene, _bvh=None, _bvh_params=None)


def pipeline_recipe(pipe):
    """What a worker needs to rebuild ``pipe`` (plugins by name and parameters).

    Raises :class:`ConfigError` for a plugin that workers cannot find by name.
    """
    import raysort

    recipe = {kind: _plugin_config(kind, getattr(pipe, kind)) for kind in _KINDS}
    recipe.update(tile=pipe.tile, batch_rays=pipe.batch_rays,
                  check_plugins=pipe.check_plugins, bvh=dict(pipe.bvh_params))
    # the class travels by reference (its module and name), so this module needs no
    # import of raysort.pipeline, which imports it
    return {"pipeline": recipe, "raysort": raysort.__version__, "factory": type(pipe)}


def _plugin_config(kind, plugin):
    group, name = _KINDS[kind], plugin.name
    registered = {i.name: i.distribution for i in registry.list_plugins(group)}
    if registered.get(name) == "<in-process>":
        why = "it is registered in process (raysort.register), which no worker sees"
    elif name not in registered or registry.load(group, name) is not type(plugin):
        why = (f"it was given as an instance of {type(plugin).__module__}."
               f"{type(plugin).__qualname__}, which is not a plugin registered by name")
    else:
        return {"type": name, **plugin.params()}
    raise ConfigError(f"the {kind} {name or type(plugin).__name__!r} cannot be sent to Dask "
                      f"workers: {why}; workers create plugins by name from their installed "
                      f"entry points, so package it and install it on every worker")


def render_tiles(pipe, client, runs, width, height, spp, seed):
    """Yield ``(tile, (radiance, stats))`` (see ``Pipeline._render_tiles``) as tasks on
    ``client`` finish; ``runs`` are the frame's tiles in runs that share batches
    (``Pipeline._tile_groups``), which tasks keep whole.

    The Dask config ``raysort.tiles-per-task`` sets how many tiles make one task
    (default: :func:`tiles_per_task`).  Closing the generator early cancels the
    tasks not yet done.
    """
    import dask.config

    recipe = pipeline_recipe(pipe)
    per_task = dask.config.get("raysort.tiles-per-task", None)
    n_tiles = sum(len(run) for run in runs)
    if per_task is None:
        per_task = tiles_per_task(n_tiles, pipe.tile * pipe.tile, spp,
                                  sum(client.nthreads().values()))
    elif not isinstance(per_task, int) or per_task < 1:
        raise ConfigError(f"the Dask config raysort.tiles-per-task must be a whole number "
                          f">= 1, got {per_task!r}")
    # whole runs per task (a run's tiles share batches, as in a local render)
    per_task = max(1, per_task // len(runs[0])) if runs else 1
    groups = [runs[i:i + per_task] for i in range(0, len(runs), per_task)]
    key, scene = send_scene(client, pipe.scene)
    token = uuid.uuid4().hex[:8]
    futures = [client.submit(_render_group, scene, key, recipe, group, width, height, spp,
                             seed, key=f"raysort-tiles-{token}-{i}")
               for i, group in enumerate(groups)]
    try:
        for result in finished(client, futures):
            yield from result
    finally:
        with contextlib.suppress(Exception):  # the client may be gone already
            client.cancel([f for f in futures if not f.done()] + [scene])


def finished(client, futures):
    """Results of ``futures`` as they finish.

    A task's own error is raised as it is; a task that killed its workers, a
    lost scheduler, or a cluster without workers for ``raysort.no-workers-timeout``
    raise :class:`ClusterError`.
    """
    dd = _dask()
    from distributed.utils import CancelledError

    timeout = _no_workers_timeout()
    pending = dd.as_completed(futures, with_results=True, raise_errors=False)
    done = 0
    watched = idle = time.monotonic()
    while not pending.is_empty():
        if not pending.has_ready():
            now = time.monotonic()
            if now - watched >= WATCH_SECONDS:
                watched = now
                if _workers(client):
                    idle = now
                elif now - idle > timeout:
                    raise ClusterError(
                        f"every Dask worker of the scheduler {client.scheduler.address} is "
                        f"gone and none joined within {timeout:g} s ({done} of "
                        f"{len(futures)} tasks were done); giving up")
            time.sleep(POLL_SECONDS)
            continue
        # (the future's status may have moved on since: judge by what came back)
        future, result = next(pending)
        if isinstance(result, CancelledError):
            if client.status != "running":
                raise ClusterError(f"lost the Dask scheduler {client.scheduler.address} "
                                   f"({done} of {len(futures)} tasks were done)")
            raise ClusterError(f"Dask cancelled a task: {result}")
        if _is_error(result):
            raise _task_error(future, *result[1:])
        done += 1
        yield result


def _is_error(result):
    """``(type, exception, traceback)``: how as_completed hands over a task's error
    (results of raysort's tasks are lists and dicts, never such a tuple)."""
    return (isinstance(result, tuple) and len(result) == 3
            and isinstance(result[1], BaseException))


def _workers(client):
    try:
        return client.nthreads()
    except Exception as exc:  # connection lost: OSError, CommClosedError, TimeoutError
        raise ClusterError(f"lost the Dask scheduler {client.scheduler.address}: {exc}") \
            from None


def _task_error(future, exc, tb):
    from distributed.scheduler import KilledWorker

    if isinstance(exc, KilledWorker):
        last = getattr(exc.last_worker, "address", exc.last_worker)
        return ClusterError(
            f"the Dask worker running task {future.key} died {exc.allowed_failures + 1} "
            f"time(s), the last on {last}; a crash in a kernel or a plugin, or too little "
            f"memory? The worker logs tell")
    return exc.with_traceback(tb)


# --------------------------------------------------------------------------
# worker side
# --------------------------------------------------------------------------

#: worker-process caches: scene content hash -> Scene; (hash, recipe) -> Pipeline
_SCENES = OrderedDict()
_PIPELINES = OrderedDict()
_BVHS = {}                    # scene hash -> ids of the BVH objects built (diagnostics)
_LOCK = threading.Lock()      # a worker may run tasks on several threads
MAX_SCENES, MAX_PIPELINES = 4, 32


def worker_info():
    """Where a task runs: Dask worker address, host name and the active ISA."""
    from raysort import isa

    try:
        from distributed import get_worker
        address = get_worker().address
    except (ImportError, ValueError):
        address = "(not on a Dask worker)"
    return {"worker": address, "host": socket.gethostname(), "isa": isa.active()}


def worker_pipeline(scene, key, recipe):
    """The cached pipeline for (scene content hash, recipe) in this process.

    Built on first use with the BVH (one per scene and BVH parameters in this
    process); later tasks reuse it.
    """
    import raysort

    ident = (key, repr(sorted(recipe["pipeline"].items())))
    with _LOCK:
        pipe = _PIPELINES.get(ident)
        if pipe is not None:
            _PIPELINES.move_to_end(ident)
            return pipe
        where = "Dask worker {worker} on host {host}".format(**worker_info())
        if recipe["raysort"] != raysort.__version__:
            raise ConfigError(f"{where} runs raysort {raysort.__version__}, the client "
                              f"{recipe['raysort']}; install the same version everywhere")
        scene = _remember(_SCENES, key, _SCENES.get(key) or _without_bvh(scene), MAX_SCENES)
        try:
            pipe = recipe["factory"](scene, **recipe["pipeline"])
        except PluginError as exc:
            raise type(exc)(f"{where}: {exc}; install the plugin's package on every worker",
                            kind=exc.kind, name=exc.name, distribution=exc.distribution) \
                from None
        _BVHS.setdefault(key, set()).add(id(pipe.bvh))
        pipe.shader.prepare(scene)
        return _remember(_PIPELINES, ident, pipe, MAX_PIPELINES)


def _remember(cache, key, value, size):
    cache[key] = value
    cache.move_to_end(key)
    while len(cache) > size:
        cache.popitem(last=False)
    return value


def cache_info():
    """This process's caches: BVHs built per scene hash, pipelines kept."""
    with _LOCK:
        return {"bvh_builds": {k: len(v) for k, v in _BVHS.items()},
                "pipelines": len(_PIPELINES), "scenes": len(_SCENES)}


def _render_group(scene, key, recipe, group, width, height, spp, seed):
    """A task: render a group of runs of tiles with the worker's cached pipeline."""
    pipe = worker_pipeline(scene, key, recipe)
    return [done for run in group for done in pipe._render_tiles(run, width, height, spp, seed)]


def dask_client(scheduler):
    """A context giving the Dask client of ``--scheduler`` (see :func:`connect`), or None
    without one."""
    if scheduler is None:
        return contextlib.nullcontext()
    return connect(scheduler)
