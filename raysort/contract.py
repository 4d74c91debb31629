"""The contracts at every boundary of a frame, checked before anything reaches a kernel.

Two kinds of input cross into raysort's C code:

* **caller arguments** (``Pipeline.trace``'s ``rays`` and ``packets``); a
  mistake raises :class:`~raysort.errors.ConfigError` naming the argument;
* **plugin results** (a generator's rays, a sorter's order, a traversal's hits,
  a shader's next bounce); a broken one raises
  :class:`~raysort.errors.PluginContractError` naming the plugin, its
  distribution and what was wrong.  So does a plugin method that raises.

Each check reads its arrays once, in Cython (:mod:`raysort._contract`, built for
every ISA like the kernels).  The
pipeline runs the plugin checks on every plugin from outside raysort; raysort's
own plugins that declare ``trusted = True`` skip them when
``Pipeline(check_plugins=False)``.  Plugin authors can run the same checks in
their tests (they are in :mod:`raysort.sdk`).
"""
from __future__ import annotations

import numbers
import operator

import numpy as np

from raysort import _contract, isa
from raysort.errors import ConfigError, PluginContractError, PluginError
from raysort.orders import is_identity_order
from raysort.paths import Bounce, ShadowRays
from raysort.rays import (MAX_PACKET, MAX_RAYS, PACKET_ROWS, RAY_ROWS, PacketRow, RayBatch,
                          RayRow)
from raysort.stats import WHOLE_NUMBERS, Counters

__all__ = ["check_packets", "check_ray_batch", "sort_arrays", "check_sort", "check_hits",
           "check_packet_arrays", "packet_arrays", "check_rays", "check_counters",
           "check_generated",
           "check_bounce", "call_plugin", "before_traversal", "plugin_error"]

_BAD = _contract.Bad
_INT32, _FLOAT32 = np.dtype(np.int32), np.dtype(np.float32)


def _kernels():
    """The check kernels built for the active ISA (:mod:`raysort._contract`)."""
    return isa.module("_contract")
_TMIN, _ORIGIN, _DIRECTION = RayRow.tmin, RayRow.ox, RayRow.dx     # three rows each
_LANE_TMIN, _LANE_T = PacketRow.tmin, PacketRow.t
_PACKET_ARRAYS = ("rows", "prim", "u", "v", "index", "starts", "counts")
_COUNTER_FIELDS = WHOLE_NUMBERS
_KIND_WORD = {"generators": "generator", "sorters": "sorter", "traversals": "traversal",
              "shaders": "shader"}


# --------------------------------------------------------------------------
# naming the culprit
# --------------------------------------------------------------------------

def _provenance(kind, name, cls):
    """``(distribution, text)`` saying where a plugin comes from."""
    from raysort import registry

    for info in registry.list_plugins(kind):
        if info.name == name:
            if info.distribution == "<in-process>":
                return info.distribution, "registered in process"
            return info.distribution, f"from distribution '{info.distribution}' {info.version}"
    if cls is None:
        return None, "not a registered plugin"
    from importlib import metadata

    module = cls.__module__
    dists = metadata.packages_distributions().get(module.partition(".")[0])
    if dists:
        return dists[0], f"from distribution '{dists[0]}'"
    return None, f"defined in module '{module}', not an installed distribution"


def plugin_error(kind, plugin, what, *, broke=True):
    """A PluginContractError naming the plugin (an instance or a registered name)."""
    if isinstance(plugin, str):
        name, cls = plugin, None
    else:
        name, cls = getattr(plugin, "name", "") or type(plugin).__name__, type(plugin)
    distribution, where = _provenance(kind, name, cls)
    verb = "broke its contract" if broke else "failed"
    return PluginContractError(f"{_KIND_WORD[kind]} {name!r} ({where}) {verb}: {what}",
                               kind=kind, name=name, distribution=distribution)


def call_plugin(kind, plugin, method, *args):
    """``plugin.method(*args)``; an exception it raises becomes a PluginContractError
    naming the plugin (the original is its ``__cause__``)."""
    try:
        return getattr(plugin, method)(*args)
    except PluginError:
        raise
    except Exception as exc:
        raise plugin_error(kind, plugin, f"{method}() raised {type(exc).__name__}: {exc}",
                            broke=False) from exc


# --------------------------------------------------------------------------
# arrays
# --------------------------------------------------------------------------

def _index_array(value, label, fail, *, length=None):
    """``value`` as a contiguous 1-d int32 or int64 array (no value changes)."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        fail(f"{label} must be a 1-d integer array ({exc})")
    if arr.ndim == 1 and arr.size == 0:
        arr = arr.astype(np.int32)                  # [] is an empty float array
    if arr.ndim != 1 or arr.dtype.kind not in "iu":
        fail(f"{label} must be a 1-d integer array, got {arr.dtype} with shape {arr.shape}")
    if length is not None and len(arr) != length:
        fail(f"{label} has {len(arr)} entries, expected {length}")
    if arr.dtype == np.int32:
        return np.ascontiguousarray(arr)
    # int64 holds every other integer dtype but uint64, whose huge values turn negative
    # here and so are still out of range
    return np.ascontiguousarray(arr, dtype=np.int64)


def _finite(arr, label, fail):
    code, where = _kernels().finite(arr.reshape(-1))
    if code:
        index = ", ".join(str(int(i)) for i in np.unravel_index(where, arr.shape))
        fail(f"{label}[{index}] is {arr.reshape(-1)[where]} (values must be finite)")


def _batch_layout(rays, label, fail):
    """A RayBatch whose ``data`` is still the float32 (8, capacity) layout the kernels read."""
    if not isinstance(rays, RayBatch):
        fail(f"{label} must be a raysort.RayBatch, got {type(rays).__name__}")
    data, n = getattr(rays, "data", None), getattr(rays, "n", None)
    if not (isinstance(data, np.ndarray) and data.dtype == np.float32 and data.ndim == 2
            and data.shape[0] == len(RAY_ROWS) and data.flags.c_contiguous):
        fail(f"{label}.data must be a C-contiguous float32 array of {len(RAY_ROWS)} rows, got "
             f"{getattr(data, 'dtype', type(data).__name__)} with shape "
             f"{getattr(data, 'shape', None)}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) \
            or not 0 <= n <= min(data.shape[1], MAX_RAYS):
        fail(f"{label} holds n={n!r} rays in a capacity of {data.shape[1]}")


def _rays(rays, label, fail):
    """Every ray finite or marked invalid (``not tmin < tmax``)."""
    code, i = _kernels().rays(rays.data, len(rays))
    if code == _BAD.BAD_TMIN:
        fail(f"{label} ray {i} has tmin = {rays.data[_TMIN, i]} < 0 (mark an unused ray "
             f"invalid with tmin >= tmax)")
    if code == _BAD.BAD_RAY:
        origin = rays.data[_ORIGIN:_ORIGIN + 3, i].tolist()
        direction = rays.data[_DIRECTION:_DIRECTION + 3, i].tolist()
        fail(f"{label} ray {i} has origin {origin} and direction {direction}: not finite, yet "
             f"not marked invalid (tmin >= tmax)")


# --------------------------------------------------------------------------
# caller arguments
# --------------------------------------------------------------------------

def _config_fail(msg):
    raise ConfigError(msg)


def check_ray_batch(rays, label="rays"):
    """A caller's ray batch: a :class:`RayBatch` with its own layout (ConfigError)."""
    if not isinstance(rays, RayBatch):
        raise ConfigError(f"{label} must be a raysort.RayBatch (make one with "
                          f"RayBatch.from_arrays(origins, directions)), got "
                          f"{type(rays).__name__}")
    _batch_layout(rays, label, _config_fail)
    return rays


def check_packets(packets, n):
    """A caller's large-packet boundaries for ``n`` rays, as int32.

    They must be integers that start at 0, never decrease and end at ``n``
    (a repeated boundary is an empty large packet); ``n`` must fit int32 indices.
    """
    if n > MAX_RAYS:
        raise ConfigError(f"a batch holds at most {MAX_RAYS} rays (int32 indices), got {n}")

    arr = _index_array(packets, "packets", _config_fail)
    if len(arr) == 0 or arr[0] != 0 or arr[-1] != n:
        raise ConfigError(f"packets (large-packet boundaries) must start at 0 and end at {n}, "
                          f"the number of rays; got {arr.tolist() if len(arr) < 8 else arr}")
    code, i = _kernels().index_array(arr, 0, n + 1, True)
    if code:
        raise ConfigError(f"packets must not decrease, got {arr[i - 1]} then {arr[i]} at "
                          f"position {i}")
    return arr.astype(np.int32, copy=False)


# --------------------------------------------------------------------------
# plugin results
# --------------------------------------------------------------------------

def _failer(kind, plugin):
    def fail(msg):
        raise plugin_error(kind, plugin, msg)
    return fail


def sort_arrays(plugin, result, n):
    """A sorter's ``(order, offsets)`` for ``n`` rays as contiguous int32 arrays, checking
    what is not a matter of their values (the tuple, integer types, ``len(order) == n``,
    an offset at all, every value within int32); :func:`check_sort` checks the rest."""
    if type(result) is tuple and len(result) == 2:
        order, offsets = result
        if (type(order) is np.ndarray and type(offsets) is np.ndarray
                and order.dtype is _INT32 and offsets.dtype is _INT32
                and order.shape == (n,) and offsets.ndim == 1 and len(offsets)
                and order.flags.c_contiguous and offsets.flags.c_contiguous):
            return order, offsets                   # what the built-in sorters return
    fail = _failer("sorters", plugin)
    if not (isinstance(result, tuple) and len(result) == 2):
        fail(f"sort() must return (order, offsets), got {type(result).__name__}")
    order = _index_array(result[0], "order", fail)
    offsets = _index_array(result[1], "offsets", fail)
    if len(order) != n:
        fail(f"order has {len(order)} entries for {n} rays")
    if len(offsets) < 1:
        fail(f"offsets must run from 0 to {n}, got an empty array")
    if order.dtype != np.int32:
        code, where = _kernels().index_array(order, 0, n, False)
        if code:
            fail(f"order is not a permutation of the batch: order[{where}] = {order[where]} "
                 f"is out of range 0..{n - 1}")
        order = order.astype(np.int32)
    if offsets.dtype != np.int32:
        code, where = _kernels().index_array(offsets, 0, n + 1, False)
        if code:
            fail(f"offsets must run from 0 to {n}, got {offsets[0]}..{offsets[-1]} with "
                 f"{offsets[where]} at position {where}")
        offsets = offsets.astype(np.int32)
    return order, offsets


def check_sort(plugin, result, n, packets):
    """Validate a sorter's ``(order, offsets)`` for ``n`` rays; returns them as int32 arrays.

    ``plugin`` is the sorter or its name.  ``order`` must be a permutation of
    ``range(n)``; ``offsets`` must start at 0, increase strictly and end at
    ``n``; each sub-packet holds at most 4096 rays, all from one large packet
    (``packets``: valid boundaries, see :func:`check_packets`).  (The pipeline
    runs these checks inside its gather, :func:`raysort.rays.gather_checked`,
    and this function only to say what is wrong.)
    """
    fail = _failer("sorters", plugin)
    order, offsets = sort_arrays(plugin, result, n)
    packets = check_packets(packets, n)
    code, where = _kernels().sort_result(order, offsets, packets, n, MAX_PACKET,
                                         is_identity_order(order))
    if code in (_BAD.BAD_OFFSETS_START, _BAD.BAD_OFFSETS_END, _BAD.BAD_OFFSETS_RANGE):
        fail(f"offsets must run from 0 to {n}, got {offsets[0]}..{offsets[-1]}"
             + (f" with {offsets[where + 1]} at position {where + 1}"
                if code == _BAD.BAD_OFFSETS_RANGE else ""))
    if code == _BAD.BAD_OFFSETS_ORDER:
        fail(f"offsets must increase strictly (no empty sub-packets), got "
             f"{offsets[where]} then {offsets[where + 1]} at position {where + 1}")
    if code == _BAD.BAD_PACKET_SIZE:
        fail(f"sub-packet {where} holds {offsets[where + 1] - offsets[where]} rays; the most "
             f"a traversal takes is {MAX_PACKET}")
    if code == _BAD.BAD_INDEX_RANGE:
        fail(f"order is not a permutation of the batch: order[{where}] = {order[where]} is "
             f"out of range 0..{n - 1}")
    if code == _BAD.BAD_INDEX_REPEAT:
        fail(f"order is not a permutation of the batch: ray {order[where]} appears twice "
             f"(again at order[{where}])")
    if code == _BAD.BAD_MIXED:
        fail(f"sub-packet {where} mixes rays of different large packets")
    return order, offsets


def before_traversal(packets):
    """What :func:`check_hits` compares with: take it after the gather, before the
    traversal runs (the arrays, and a copy of the row ``t``, which holds each ray's tmax)."""
    return packet_arrays(packets), packets.rows[_LANE_T].copy()


def packet_arrays(packets):
    """The arrays of ``packets`` that :func:`check_packet_arrays` compares with."""
    p = packets
    return p.rows, p.prim, p.u, p.v, p.index, p.starts, p.counts      # _PACKET_ARRAYS


def check_hits(plugin, packets, before, order, offsets, n_prim, any_hit):
    """Validate what a traversal wrote into ``packets``, gathered by ``order`` and
    ``offsets`` (``before`` from :func:`before_traversal`).

    Its arrays must be the ones it was given, unchanged in shape and type; each
    lane must still hold its ray (padding lanes untouched); ``prim`` is -1 or a
    triangle index below ``n_prim``; a closest hit has ``tmin < t < tmax`` and
    finite ``u``, ``v`` (an invalid ray's interval is empty).
    """
    fail = _failer("traversals", plugin)
    arrays, t0 = before
    order = _index_array(order, "check_hits: order", _config_fail)
    offsets = _index_array(offsets, "check_hits: offsets", _config_fail)
    if (len(offsets) == 0 or offsets[0] != 0 or offsets[-1] != len(order)
            or (np.diff(offsets) < 0).any()):
        raise ConfigError("check_hits: offsets must run from 0 to len(order) without "
                          "decreasing: the sorter's result the packets were gathered by")
    order, offsets = order.astype(np.int32, copy=False), offsets.astype(np.int32, copy=False)
    check_packet_arrays(plugin, packets, arrays)
    rows, prim, u, v, index, starts, counts = arrays
    code, lane = _kernels().hits(rows, t0, prim, u, v, index, starts, counts, order, offsets,
                                n_prim, any_hit)
    if code == _BAD.BAD_SHAPE:
        fail("intersect() reshaped or retyped an array of the packets")
    if code == _BAD.BAD_LAYOUT:
        fail(f"intersect() changed packets.starts or packets.counts (sub-packet {lane}); "
             f"they say where the gather put each sub-packet")
    if code == _BAD.BAD_PADDING:
        fail(f"it wrote into padding lane {lane}, which holds no ray")
    if code == _BAD.BAD_LANE_INDEX:
        fail(f"packets.index[{lane}] was changed to {index[lane]}")
    if code == _BAD.BAD_PRIM:
        fail(f"lane {lane}: prim = {prim[lane]} is neither -1 (a miss) nor a triangle index "
             f"0..{n_prim - 1}")
    if code == _BAD.BAD_T:
        fail(f"lane {lane} (ray {index[lane]}): a hit at t = {rows[_LANE_T, lane]} outside "
             f"the ray's interval ({rows[_LANE_TMIN, lane]}, {t0[lane]})")
    if code == _BAD.BAD_UV:
        fail(f"lane {lane}: a hit with u = {u[lane]}, v = {v[lane]} (must be finite)")


def batch_hit_fault(plugin, rays, hits, n_prim, ray):
    """Report the hit of ``ray`` that a traversal reading the batch itself found to
    break the hit contract (:func:`check_hits`'s rules) when it wrote ``hits``."""
    fail = _failer("traversals", plugin)
    if not -1 <= hits.prim[ray] < n_prim:
        fail(f"ray {ray}: prim = {hits.prim[ray]} is neither -1 (a miss) nor a triangle "
             f"index 0..{n_prim - 1}")
    if not rays.tmin[ray] < hits.t[ray] < rays.tmax[ray]:
        fail(f"ray {ray}: a hit at t = {hits.t[ray]} outside the ray's interval "
             f"({rays.tmin[ray]}, {rays.tmax[ray]})")
    fail(f"ray {ray}: a hit with u = {hits.u[ray]}, v = {hits.v[ray]} (must be finite), or "
         f"a hit of an invalid ray")


def check_packet_arrays(plugin, packets, arrays):
    """A traversal left ``packets`` holding the ``arrays`` it was given
    (:func:`packet_arrays`), unchanged in shape and type."""
    fail = _failer("traversals", plugin)
    for name, array in zip(_PACKET_ARRAYS, arrays):
        if getattr(packets, name, None) is not array:
            fail(f"intersect() replaced packets.{name}; write into the arrays instead")
    if any(a.shape != s or a.dtype != d for a, (s, d) in zip(arrays, _packet_shapes(packets))):
        fail("intersect() reshaped or retyped an array of the packets")


def _packet_shapes(packets):
    """(shape, dtype) of each array of freshly gathered ``packets``."""
    capacity = packets.rows.shape[1]
    return (((len(PACKET_ROWS), capacity), np.float32), ((capacity,), np.int32),
            ((capacity,), np.float32), ((capacity,), np.float32), ((capacity,), np.int32),
            ((packets.n_packets,), np.int32), ((packets.n_packets,), np.int32))


_COUNTER_VALUES = operator.attrgetter(*_COUNTER_FIELDS)


def check_counters(plugin, counters):
    """A traversal's :class:`Counters`: whole numbers >= 0, a bool ``available`` and a
    tuple of whole numbers >= 0 as ``stream_level_rays``."""
    if type(counters) is Counters and type(counters.available) is bool:
        values = _COUNTER_VALUES(counters) + counters.stream_level_rays \
            if type(counters.stream_level_rays) is tuple else ("",)
        if set(map(type, values)) == {int} and min(values) >= 0:
            return counters                          # the common case, in a few C loops
    fail = _failer("traversals", plugin)
    if not isinstance(counters, Counters):
        fail(f"intersect() must return raysort.stats.Counters, got {type(counters).__name__}")
    for name in _COUNTER_FIELDS:
        _whole_number(getattr(counters, name), f"Counters.{name}", fail)
    if not isinstance(counters.available, bool):
        fail(f"Counters.available must be True or False, got {counters.available!r}")
    levels = counters.stream_level_rays
    if not isinstance(levels, tuple):
        fail(f"Counters.stream_level_rays must be a tuple, got {type(levels).__name__}")
    for level, value in enumerate(levels):
        _whole_number(value, f"Counters.stream_level_rays[{level}]", fail)
    return counters


def _whole_number(value, label, fail):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
        fail(f"{label} must be a whole number >= 0, got {value!r}")


def check_generated(plugin, rays, n, *, with_rays=True):
    """A generator's result: a :class:`RayBatch` of ``n`` rays, each finite or
    marked invalid (``with_rays=False`` leaves that to the caller, as for
    :func:`check_bounce`)."""
    fail = _failer("generators", plugin)
    _batch_layout(rays, "generate() result", fail)
    if len(rays) != n:
        fail(f"generate() must return {n} rays (pixels x samples), got {len(rays)}")
    if with_rays:
        _rays(rays, "generate() result", fail)
    return rays


def check_rays(kind, plugin, rays, label):
    """Rays a plugin of ``kind`` made (``label`` says which): each finite or marked invalid
    (``not tmin < tmax``), with ``tmin >= 0``.  :func:`check_generated` and
    :func:`check_bounce` include it; the pipeline runs it inside its gather and this
    function only to say what is wrong."""
    _rays(rays, label, _failer(kind, plugin))


def check_bounce(plugin, bounce, n, slots, radiance, *, with_rays=True, with_paths=True):
    """A shader's :class:`Bounce` for ``n`` shaded rays whose paths add to
    ``radiance`` rows ``0..slots-1``; returns it with arrays of the pipeline's types.

    ``parent`` must ascend, each in ``0..n-1``; rays are finite or marked
    invalid; throughput and contributions are finite float (3, m) arrays; shadow
    rays' ``slot`` lie in ``0..slots-1``; ``radiance`` is still finite.  Each part
    is checked in one pass.  (The pipeline leaves the rays to its gather,
    ``with_rays=False``, and, ``with_paths=False``, the values of the parents,
    weights and slots to a raysort shader that checks them by these rules as it
    writes them: ``lambert``; their types and shapes are checked here.)
    """
    if (type(radiance) is np.ndarray and radiance.ndim == 2 and radiance.dtype == np.float64
            and radiance.flags.c_contiguous
            and _kernels().bounce_ok(bounce, n, slots, radiance, with_rays, Bounce, ShadowRays,
                                     RayBatch, with_paths)):
        return bounce           # the pipeline's own types, valid: checked in one C call
    fail = _failer("shaders", plugin)
    _finite(radiance, "radiance", fail)
    if not isinstance(bounce, Bounce):
        fail(f"shade() must return raysort.paths.Bounce, got {type(bounce).__name__}")
    parent, _, throughput = _paths(bounce.rays, bounce.parent, None, bounce.throughput, n,
                                   slots, "Bounce", "throughput", fail, with_rays)
    shadow = bounce.shadow
    if shadow is not None:
        if not isinstance(shadow, ShadowRays):
            fail(f"Bounce.shadow must be raysort.paths.ShadowRays or None, got "
                 f"{type(shadow).__name__}")
        shadow = ShadowRays(shadow.rays, *_paths(shadow.rays, shadow.parent, shadow.slot,
                                                 shadow.contribution, n, slots, "ShadowRays",
                                                 "contribution", fail, with_rays))
    return Bounce(bounce.rays, parent, throughput, shadow)


def _paths(rays, parent, slot, weight, n, slots, label, weight_name, fail, with_rays):
    """Rays continuing paths, their parents (ascending in 0..n-1), slots (0..slots-1 or
    None) and (3, m) weights, in one pass; returns (parent, slot, weight) as int32 and
    float32 arrays."""
    _batch_layout(rays, f"{label}.rays", fail)
    m = len(rays)
    parent = _int32(parent, f"{label}.parent", m, fail)
    slot = None if slot is None else _int32(slot, f"{label}.slot", m, fail)
    weight = _weights(weight, f"{label}.{weight_name}", m, fail)
    code, i = _kernels().paths(rays.data, m, parent, weight, slot, n, slots, with_rays)
    if code in (_BAD.BAD_TMIN, _BAD.BAD_RAY):
        _rays(rays, f"{label}.rays", fail)
    if code == _BAD.BAD_PARENT_RANGE:
        fail(f"{label}.parent[{i}] = {parent[i]} is out of range 0..{n - 1}")
    if code == _BAD.BAD_PARENT_ORDER:
        fail(f"{label}.parent must ascend, got {parent[i - 1]} then {parent[i]} at position "
             f"{i}")
    if code == _BAD.BAD_WEIGHT:
        fail(f"{label}.{weight_name}[:, {i}] is {weight[:, i].tolist()} (values must be "
             f"finite)")
    if code == _BAD.BAD_SLOT:
        fail(f"{label}.slot[{i}] = {slot[i]} is out of range 0..{slots - 1}")
    return parent, slot, weight


def _int32(value, label, length, fail):
    """A 1-d integer array of ``length`` entries as contiguous int32 (a value that does
    not fit is out of every range the pipeline uses, and said so)."""
    if (type(value) is np.ndarray and value.dtype is _INT32 and value.shape == (length,)
            and value.flags.c_contiguous):
        return value                                # what built-in shaders return
    arr = _index_array(value, label, fail, length=length)
    if arr.dtype != np.int32:
        bad = np.flatnonzero((arr < np.iinfo(np.int32).min) | (arr > np.iinfo(np.int32).max))
        if len(bad):
            fail(f"{label}[{bad[0]}] = {arr[bad[0]]} is out of range")
        arr = arr.astype(np.int32)
    return arr


def _weights(value, label, m, fail):
    """A float (3, m) array as float32 with contiguous rows (lambert's slices need no copy);
    a value beyond float32 becomes inf and fails the finiteness check."""
    if (type(value) is np.ndarray and value.dtype is _FLOAT32 and value.shape == (3, m)
            and value.strides[1] == 4):
        return value                                # what built-in shaders return
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        fail(f"{label} must be a float array of shape (3, {m}) ({exc})")
    if arr.shape != (3, m) or arr.dtype.kind != "f":
        fail(f"{label} must be a float array of shape (3, {m}), got {arr.dtype} with shape "
             f"{arr.shape}")
    if arr.dtype != np.float32:
        with np.errstate(over="ignore"):
            arr = arr.astype(np.float32)
    if m and arr.strides[1] != arr.itemsize:
        arr = np.ascontiguousarray(arr)
    return arr
