"""``raysort sweep``: time a matrix of configurations against a baseline, here or on Dask.

A timing is only comparable on one machine at one time.  So one task of a
sweep is one configuration (scene, sorter, traversal, depth, image settings)
and it renders that configuration *and the baseline* in turn on the same worker
for N rounds, swapping which goes first each round; it reports the per-round
ratio ``baseline seconds / configuration seconds`` (above 1: faster than the
baseline), its median, and the worker's host, CPU and SIMD path.  The table
groups results by machine; ratios from different machines are never mixed.

Results are written as they arrive: a JSON file (``{"results": [row, ...]}``,
one flat row per task) and optionally a CSV file of the same rows for a data
frame.  An interrupted sweep keeps every finished row; ``--resume`` runs only
the tasks missing from the file (and those that failed).  Without
``--scheduler`` the tasks run one after another in this process.
"""
from __future__ import annotations

import csv
import itertools
import json
import math
import os
import reprlib
import statistics
import sys
import time
import uuid
from dataclasses import asdict, dataclass

import numpy as np

from raysort import registry
from raysort.errors import ConfigError
from raysort.output import shown
from raysort.pipeline import Pipeline
from raysort.scene import load_scene

__all__ = ["Job", "add_parser", "format_table", "matrix", "run_sweep", "time_against_baseline"]

#: the paper's baseline (Manta's ranged traversal over 8x8 packets in generation order)
PAPER_BASELINE = {"sorter": "none:packet_size=64", "traversal": "ranged"}
#: the "format" of a results file
FORMAT = "raysort-sweep-1"


@dataclass(frozen=True)
class Job:
    """One task of a sweep: a configuration to time against the baseline."""

    scene: str
    sorter: str
    traversal: str
    depth: int = 2
    width: int = 256
    height: int = 256
    spp: int = 4
    seed: int = 0
    rounds: int = 3
    baseline_sorter: str = PAPER_BASELINE["sorter"]
    baseline_traversal: str = PAPER_BASELINE["traversal"]

    @property
    def key(self):
        """Identifies the task in a results file (for ``--resume``)."""
        return json.dumps(asdict(self), sort_keys=True)

    @property
    def label(self):
        return f"{self.traversal} + {self.sorter}"

    def pipelines(self, scene):
        """(configuration, baseline) pipelines; Lambertian, no shadow rays, as the paper."""
        shader = {"type": "lambert", "max_depth": self.depth, "shadow_rays": False}
        return tuple(Pipeline(scene, sorter=s, traversal=t, shader=shader)
                     for s, t in ((self.sorter, self.traversal),
                                  (self.baseline_sorter, self.baseline_traversal)))


def matrix(scenes, sorters=None, traversals=None, depths=(2,), **settings):
    """Every (scene, depth, traversal, sorter) combination as a :class:`Job`.

    ``sorters`` and ``traversals`` default to every installed plugin of the kind;
    ``settings`` are the other :class:`Job` fields (size, spp, rounds, baseline).
    """
    sorters = list(sorters or registry.available("sorters"))
    traversals = list(traversals or registry.available("traversals"))
    return [Job(scene, sorter, traversal, depth, **settings) for scene, depth, traversal, sorter
            in itertools.product(scenes, depths, traversals, sorters)]


def time_against_baseline(pipe, baseline, rounds, width, height, spp, seed):
    """Render ``pipe`` and ``baseline`` in turn for ``rounds`` rounds, swapping which goes
    first each round, after one small untimed render each (lazy set-up such as a wide
    BVH); returns the seconds, the per-round ratios and whether the images agree.

    (It stands in for ``raysort.bench``'s function that does the same job.)
    """
    for p in (pipe, baseline):
        p.render(16, 16, 1, seed)
    seconds, base_seconds, identical, difference = [], [], True, 0.0
    for r in range(rounds):
        timed = {}
        for which in ((0, 1) if r % 2 == 0 else (1, 0)):
            timed[which] = (pipe, baseline)[which].render(width, height, spp, seed)
        out, base = timed[0], timed[1]
        seconds.append(out.stats.wall_seconds)
        base_seconds.append(base.stats.wall_seconds)
        identical &= np.array_equal(out.image.view(np.uint32), base.image.view(np.uint32))
        difference = max(difference, float(np.abs(out.image - base.image).max()))
    ratios = [b / s for b, s in zip(base_seconds, seconds)]
    return {
        "seconds": seconds, "baseline_seconds": base_seconds, "ratios": ratios,
        "median_seconds": statistics.median(seconds),
        "median_baseline_seconds": statistics.median(base_seconds),
        "median_ratio": statistics.median(ratios), "min_ratio": min(ratios),
        "max_ratio": max(ratios), "identical_image": bool(identical),
        "max_image_difference": difference,
        "exact_traversal": bool(type(pipe.traversal).exact and type(baseline.traversal).exact),
        "rays": out.stats.total_rays,
        "counters_per_ray": out.stats.closest_hit_counters().per_ray(),
    }


def _measure(job, pipe, baseline):
    """A result row: the job, its timings (or its error) and where it ran."""
    from raysort.bench import machine_info
    from raysort.distributed import scene_key, worker_info

    row = dict(asdict(job), key=job.key, label=job.label, scene_name=pipe.scene.name,
               scene_hash=scene_key(pipe.scene), error=None)
    try:
        row.update(time_against_baseline(pipe, baseline, job.rounds, job.width, job.height,
                                          job.spp, job.seed))
    except Exception as exc:  # noqa: BLE001 (one broken configuration must not end a sweep)
        row["error"] = f"{type(exc).__name__}: {exc}"
    machine = machine_info()
    row.update(worker_info(), cpu=machine["cpu"], cores=machine["cores"],
               raysort=machine["raysort"], finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    return row


def _remote(scene, key, recipes, job):
    """A sweep task on a Dask worker: the pipelines come from the worker's cache."""
    from raysort.distributed import worker_pipeline

    return _measure(job, *(worker_pipeline(scene, key, r) for r in recipes))


# --------------------------------------------------------------------------
# running and saving
# --------------------------------------------------------------------------

def run_sweep(jobs, path, *, client=None, csv_path=None, resume=False, progress=None):
    """Run ``jobs``, saving every row to ``path`` (JSON) and ``csv_path`` as it arrives.

    ``resume`` keeps the finished rows of an existing ``path`` and runs only the
    other jobs; without it an existing ``path`` is an error (nothing is lost).
    Returns every row, in the order of ``jobs`` (then rows of the file that are
    not in ``jobs``).
    """
    if not resume and os.path.exists(path):
        raise ConfigError(f"{path} exists: pass --resume to continue that sweep, or choose "
                          f"another file")
    store = _Store(path, csv_path, [job.key for job in jobs], _read(path) if resume else {})
    todo = [job for job in jobs if not store.finished(job.key)]
    scenes = {spec: load_scene(spec) for spec in dict.fromkeys(job.scene for job in todo)}
    pipes = [job.pipelines(scenes[job.scene]) for job in todo]   # checks every name here
    if client is None:
        measured = (_measure(job, *pair) for job, pair in zip(todo, pipes))
    else:
        measured = _run_on(client, todo, scenes, pipes)
    done = len(jobs) - len(todo)
    for row in measured:
        store.add(row)
        done += 1
        if progress:
            progress(done, len(jobs))
    return store.rows()


def _run_on(client, todo, scenes, pipes):
    """Rows of ``todo`` as they finish on the workers of ``client``."""
    from raysort.distributed import (
        finished,
        pipeline_recipe,
        send_scene,
        worker_threads,
    )

    if not todo:
        return
    recipes = [[pipeline_recipe(p) for p in pair] for pair in pipes]   # refuses local plugins
    worker_threads(client)                         # wait for a worker, like a render
    sent = {spec: send_scene(client, scene) for spec, scene in scenes.items()}
    token = uuid.uuid4().hex[:8]
    futures = []
    for i, (job, recipe) in enumerate(zip(todo, recipes)):
        scene_hash, scene = sent[job.scene]
        futures.append(client.submit(_remote, scene, scene_hash, recipe, job,
                                     key=f"raysort-sweep-{token}-{i}"))
    try:
        yield from finished(client, futures)
    finally:
        client.cancel([f for f in futures if not f.done()]
                      + [f for _, f in sent.values()])


class _Store:
    """The rows of a sweep by key, written whole to JSON (and CSV) after every new row."""

    def __init__(self, path, csv_path, order, rows):
        self.path, self.csv_path, self.order, self.by_key = path, csv_path, order, rows

    def finished(self, key):
        return key in self.by_key and self.by_key[key]["error"] is None

    def add(self, row):
        self.by_key[row["key"]] = row
        _write(self.path, self.csv_path, self.rows())

    def rows(self):
        """In the sweep's order, then rows of the file from other sweeps."""
        ours = set(self.order)
        return ([self.by_key[k] for k in self.order if k in self.by_key]
                + [r for k, r in self.by_key.items() if k not in ours])


def _read(path):
    """The rows of the results file ``path`` by key ({} if there is none).

    The whole file is checked here, before any job runs: every row must hold what
    resuming, writing and the table read later (:func:`_row_problem`).
    """
    if not os.path.exists(path):
        return {}
    try:
        with open(path, encoding="utf-8") as fh:
            doc = json.load(fh)
    except RecursionError:
        raise ConfigError(f"cannot resume from {path}: nested too deeply") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"cannot resume from {path}: {exc}") from None
    problem = _file_problem(doc)
    if problem is not None:
        raise ConfigError(f"cannot resume from {path}: {problem}")
    return {row["key"]: row for row in doc["results"]}


def _finite(value):
    """A number the table can format: not a bool, NaN, an infinity or an int past float."""
    try:
        return (isinstance(value, (int, float)) and not isinstance(value, bool)
                and math.isfinite(value))
    except OverflowError:
        return False


_TEXT = (lambda v: isinstance(v, str), "a string")
_ERROR = (lambda v: v is None or isinstance(v, str), "null or a string")
_WHOLE = (lambda v: isinstance(v, int) and not isinstance(v, bool), "a whole number")
_FLAG = (lambda v: isinstance(v, bool), "true or false")
_FINITE = (_finite, "a finite number")
#: the fields of every row that resuming and the table read, with what each must be
_ROW_FIELDS = {"key": _TEXT, "error": _ERROR, "scene": _TEXT, "label": _TEXT,
               "depth": _WHOLE, "host": _TEXT}
#: the fields the table reads of a finished row (``error`` null) besides
_FINISHED_FIELDS = {
    "scene_name": _TEXT, "baseline_sorter": _TEXT, "baseline_traversal": _TEXT,
    "worker": _TEXT, "cpu": _TEXT, "isa": _TEXT, "identical_image": _FLAG,
    "exact_traversal": _FLAG, "median_seconds": _FINITE, "median_baseline_seconds": _FINITE,
    "median_ratio": _FINITE, "min_ratio": _FINITE, "max_ratio": _FINITE}
#: how deep values may nest in a row (the rows written here nest 2 levels)
_MAX_NESTING = 32


def _file_problem(doc):
    """Why ``doc`` (a parsed results file) cannot be resumed, or None: the first bad row."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else None
        return f"not a raysort sweep file (format {found!r})"
    if not isinstance(doc.get("results"), list):
        return "'results' is not a list of rows"
    seen = {}
    for number, row in enumerate(doc["results"], 1):
        problem = _row_problem(row)
        if problem is None and row["key"] in seen:
            problem = f"the same key as row {seen[row['key']]}"
        if problem is not None:
            return f"row {number}: {problem}"
        seen[row["key"]] = number
    return None


def _row_problem(row):
    """Why ``row`` is not a row of a results file, or None."""
    if not isinstance(row, dict):
        return f"not an object: {reprlib.repr(row)}"
    fields = dict(_ROW_FIELDS, **(_FINISHED_FIELDS if row.get("error") is None else {}))
    for name, (check, what) in fields.items():
        if name not in row:
            return f"no {name!r}"
        if not check(row[name]):
            return f"{name!r} must be {what}, got {reprlib.repr(row[name])}"
    if _nesting(row) > _MAX_NESTING:
        return f"values nested more than {_MAX_NESTING} levels deep"
    return None


def _nesting(value, limit=_MAX_NESTING):
    """How deep lists and objects nest in ``value`` (counting stops past ``limit``)."""
    if limit < 0 or not isinstance(value, (list, dict)):
        return 0
    items = value.values() if isinstance(value, dict) else value
    return 1 + max((_nesting(v, limit - 1) for v in items), default=0)


def _write(path, csv_path, rows):
    from raysort import output

    output.write_json(path, {"format": FORMAT, "results": rows})
    if csv_path:
        flat = [_flat(row) for row in rows]
        columns = list(dict.fromkeys(k for row in flat for k in row))
        with (output.atomic_target(csv_path) as tmp,
              open(tmp, "w", newline="", encoding="utf-8") as fh):
            writer = csv.DictWriter(fh, columns)
            writer.writeheader()
            writer.writerows(flat)


def _flat(row, prefix=""):
    """One CSV row: nested dicts become ``outer.inner`` columns, lists space-separated."""
    out = {}
    for k, v in row.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            v = " ".join(map(repr, v)) if isinstance(v, list) else v
            out[shown(prefix + k)] = shown(v) if isinstance(v, str) else v
    return out


# --------------------------------------------------------------------------
# reporting
# --------------------------------------------------------------------------

def format_table(rows, stream=None):
    """The rows grouped by machine (host, CPU, SIMD path): median seconds and ratios."""
    stream = sys.stdout if stream is None else stream
    rows = [{k: shown(v) if isinstance(v, str) else v for k, v in row.items()}
            for row in rows]                     # a stream may not take a name's odd bytes
    machines = {}
    for row in rows:
        if row["error"] is None:
            machines.setdefault((row["host"], row["cpu"], row["isa"]), []).append(row)
    for (host, cpu, isa), group in machines.items():
        workers = sorted({r["worker"] for r in group})
        print(f"\nmachine {host}: {cpu}, SIMD {isa} ({len(workers)} worker"
              f"{'s' if len(workers) > 1 else ''})", file=stream)
        print(f"  {'scene':14} {'depth':>5}  {'configuration':30} {'baseline':28} "
              f"{'s/frame':>9} {'base s':>9} {'ratio':>7} {'(min-max)':>13}  image",
              file=stream)
        for r in group:
            image = ("same" if r["identical_image"] else
                     "DIFFERS" if r["exact_traversal"] else "inexact traversal")
            base = f"{r['baseline_traversal']} + {r['baseline_sorter']}"
            print(f"  {r['scene_name'][:14]:14} {r['depth']:5}  {r['label'][:30]:30} "
                  f"{base[:28]:28} {r['median_seconds']:9.4f} "
                  f"{r['median_baseline_seconds']:9.4f} {r['median_ratio']:6.2f}x "
                  f"({r['min_ratio']:.2f}-{r['max_ratio']:.2f})  {image}", file=stream)
    failed = [r for r in rows if r["error"] is not None]
    for r in failed:
        print(f"\nFAILED {r['scene']} {r['label']} depth {r['depth']} on {r['host']}: "
              f"{r['error']}", file=stream)


# --------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------

def add_parser(sub):
    from raysort.argtypes import SCHEDULER_HELP
    from raysort.argtypes import non_negative as _non_negative
    from raysort.argtypes import positive as _positive
    from raysort.argtypes import seed as _seed
    from raysort.argtypes import size as _size

    s = sub.add_parser("sweep", help="time a matrix of configurations against a baseline, "
                                     "here or on a Dask cluster",
                       description=__doc__.split("\n\n")[1].replace("\n", " "))
    s.add_argument("scenes", nargs="+", help="scenes (names, .toml or mesh files)")
    s.add_argument("--sorter", action="append", dest="sorters", metavar="SPEC",
                   help="a sorter to sweep (repeat; default: every installed sorter)")
    s.add_argument("--traversal", action="append", dest="traversals", metavar="SPEC",
                   help="a traversal to sweep (repeat; default: every installed traversal)")
    s.add_argument("--depth", action="append", dest="depths", type=_non_negative, metavar="D",
                   help="diffuse bounces (repeat; default 2)")
    s.add_argument("--baseline-sorter", default=PAPER_BASELINE["sorter"], metavar="SPEC",
                   help=f"the baseline's sorter ({PAPER_BASELINE['sorter']})")
    s.add_argument("--baseline-traversal", default=PAPER_BASELINE["traversal"], metavar="SPEC",
                   help=f"the baseline's traversal ({PAPER_BASELINE['traversal']})")
    s.add_argument("--size", type=_size, default=(256, 256), help="WIDTHxHEIGHT (256x256)")
    s.add_argument("--spp", type=_positive, default=4, help="samples per pixel (4)")
    s.add_argument("--seed", type=_seed, default=0, help="random seed, 0..2**32-1 (0)")
    s.add_argument("--rounds", type=_positive, default=3,
                   help="interleaved rounds of configuration and baseline (3)")
    s.add_argument("--scheduler", default=None, metavar="ADDRESS", help=SCHEDULER_HELP)
    s.add_argument("-o", "--output", default="sweep.json", help="results as JSON (sweep.json)")
    s.add_argument("--csv", default=None, help="also write the results as CSV")
    s.add_argument("--resume", action="store_true",
                   help="continue the sweep in --output: run only what is missing or failed")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_sweep)


def cmd_sweep(args):
    from raysort import output
    from raysort.distributed import dask_client
    from raysort.progress import Progress

    for path in (args.output, args.csv):
        if path is not None:                     # "" too: it cannot be written
            output.check_writable(path)
    output.check_distinct([("-o", "the results file", args.output),
                           ("--csv", "the CSV file", args.csv)])
    width, height = args.size
    jobs = matrix(args.scenes, args.sorters, args.traversals, args.depths or (2,),
                  width=width, height=height, spp=args.spp, seed=args.seed,
                  rounds=args.rounds, baseline_sorter=args.baseline_sorter,
                  baseline_traversal=args.baseline_traversal)
    with dask_client(args.scheduler) as client:
        progress = Progress("sweep", unit="task", enabled=not args.quiet)
        try:
            rows = run_sweep(jobs, args.output, client=client, csv_path=args.csv,
                             resume=args.resume, progress=progress)
        finally:
            progress.close()
    format_table(rows)
    print(shown(f"\nwrote {args.output}" + (f" and {args.csv}" if args.csv else "")))
    bad = [r for r in rows if r["error"] is not None
           or (r["exact_traversal"] and not r["identical_image"])]
    return 1 if bad else 0
