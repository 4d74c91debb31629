"""A script that calls raysort's private kernel entry points (the ``def`` functions of the
Cython modules) with arrays whose lengths, layout or values do not fit together gets a
ValueError naming the function, never a crash or a write past an array.

Each case is a call that, before the kernels checked it, read or wrote outside its arrays
(most crashed the interpreter: the misaligned packets, the 0-sized stream, the cyclic
8-wide tree, nah's 0 packet size, pinhole's 65536 strata, ...).  The cases run in a child
process (a crash fails its case, not the test run), once for the ISA-independent modules
and once per ISA this CPU runs for the kernels built per ISA.  Each run first makes
valid calls of the same functions (``VALID``), which must pass.
"""
import subprocess
import sys
import textwrap

import pytest

from raysort import isa

from _helpers import child_records

PRELUDE = """
import json, sys
import numpy as np
import raysort
from raysort import isa, _bvh, _widen, _reference
from raysort.bvh import NODE_DTYPE, NODE8_DTYPE, NODE16_DTYPE, TRI_DTYPE, TRI8_DTYPE
from raysort.rays import gather, aligned_empty
isa.use(sys.argv[1])
K = isa.module
scene = raysort.load_scene("cornell")
V, F = scene.vertices, scene.faces
bvh = raysort.BVH(V, F, spatial_splits=0)     # the tree _bvh.build(..., n, ...) makes
def u8(a):
    return np.ascontiguousarray(a).view(np.uint8).reshape(-1)
def rays(n):
    rng = np.random.default_rng(1)
    return raysort.RayBatch.from_arrays(rng.uniform(-0.5, 0.5, (n, 3)) + [0, 0.5, 0],
                                        rng.normal(size=(n, 3)))
def packets(n):
    return gather(rays(n), np.arange(n, dtype=np.int32), np.array([0, n], np.int32))
def misaligned(a):
    raw = np.zeros(a.size + 1, a.dtype)
    out = raw[1:].reshape(a.shape)
    out[...] = a
    return out
def gather_args(n=64, **edit):
    r = rays(n)
    p = packets(n)
    args = dict(src=r.data, order=np.arange(n, dtype=np.int32),
                offsets=np.array([0, n], np.int32), starts=p.starts.copy(), dst=p.rows,
                prim=p.prim, u=p.u, v=p.v, index=p.index,
                packets=np.array([0, n], np.int32))
    args.update(edit)
    return args
def shade_args(n=16, **edit):
    i32 = lambda k: np.zeros(k, np.int32)
    args = dict(rays=rays(n).data, t=np.ones(n, np.float32), prim=np.full(n, -1, np.int32),
                faces=np.zeros((len(F), 8), np.float32), emitters=np.zeros((0, 4), np.float32),
                sky=np.ones(3, np.float32), pixel=i32(n), sample=i32(n), slot=i32(n),
                thr=np.ones((3, n), np.float32), depth=0, max_depth=2, seed=1,
                russian_roulette=False, rr_depth=1, light_pos=np.zeros((0, 3), np.float32),
                light_int=np.zeros((0, 3), np.float32), radiance=np.zeros((1, 3)),
                next_rays=raysort.RayBatch(n).data, next_parent=i32(n),
                next_thr=np.zeros((3, n), np.float32), sh_rays=raysort.RayBatch(0).data,
                sh_parent=i32(0), sh_slot=i32(0), sh_contrib=np.zeros((3, 0), np.float32))
    args.update(edit)
    return args
def ao_args(n=16, **edit):
    i32 = lambda k: np.zeros(k, np.int32)
    args = dict(rays=rays(n).data, t=np.ones(n, np.float32), prim=np.full(n, -1, np.int32),
                normals=scene.face_normals(), pixel=i32(n), sample=i32(n), slot=i32(n),
                thr=np.ones((3, n), np.float32), samples=4, distance=1.0, background=1.0,
                seed=1, radiance=np.zeros((1, 3)), ao_rays=raysort.RayBatch(4 * n).data,
                ao_parent=i32(4 * n), ao_slot=i32(4 * n),
                ao_weight=np.zeros((3, 4 * n), np.float32))
    args.update(edit)
    return args
def nah_args(n=64, **edit):
    args = dict(rays=rays(n).data, packets=np.array([0, n], np.int32),
                root_extent=np.ones(3, np.float32), threshold=0.25, max_axes=3,
                packet_size=64, order=np.zeros(n + 16, np.int32),
                offsets=np.zeros(n + 1, np.int32))
    args.update(edit)
    return args
def cyclic8():
    nodes = np.array(bvh.wide8.nodes)
    nodes[0]["child"][0] = 0 if len(nodes) == 1 else 1
    nodes[-1]["child"][0] = 1       # a later node pointing back: a cycle
    return nodes
"""

# ISA-independent modules: (body, fragment of the ValueError's message)
SHARED = {
    "brute_force with prim shorter than the lanes": ("""
        p = packets(64)
        _reference.brute_force(u8(bvh.triangles), p.rows, p.prim[:3].copy(), p.u, p.v, False)
        """, "brute_force: "),
    "brute_force with rows missing": ("""
        p = packets(64)
        _reference.brute_force(u8(bvh.triangles), p.rows[:4].copy(), p.prim, p.u, p.v, False)
        """, "brute_force: "),
    "build with a face beyond the vertices": ("""
        f = F.copy(); f[3, 1] = 10**6
        n = len(f)
        _bvh.build(V, f, 4, 16, 1.0, n, 0.0, u8(np.zeros(2 * n, NODE_DTYPE)),
                   np.zeros(n, np.int32), u8(np.zeros(n, TRI_DTYPE)))
        """, "build: faces[3]"),
    "build with max_leaf above a leaf's count": ("""
        n = len(F)
        _bvh.build(V, F, 70000, 16, 1.0, n, 0.0, u8(np.zeros(2 * n, NODE_DTYPE)),
                   np.zeros(n, np.int32), u8(np.zeros(n, TRI_DTYPE)))
        """, "build: max_leaf"),
    "build of no faces into empty buffers": ("""
        _bvh.build(V, F[:0].copy(), 4, 16, 1.0, 0, 0.0, np.zeros(0, np.uint8),
                   np.zeros(0, np.int32), np.zeros(0, np.uint8))
        """, "build: "),
    "triangles into too small a buffer": ("""
        _bvh.triangles(V, F, u8(np.zeros(2, TRI_DTYPE)))
        """, "triangles: "),
    "refit with an order entry beyond the faces": ("""
        order = np.array(bvh.order); order[0] = 10**7
        _bvh.refit(V, F, order, u8(np.array(bvh.nodes)), u8(np.array(bvh.triangles)))
        """, "refit: order[0]"),
    "refit with a right child beyond the nodes": ("""
        nodes = np.array(bvh.nodes); nodes[0]["offset"] = 10**7
        _bvh.refit(V, F, bvh.order, u8(nodes), u8(np.array(bvh.triangles)))
        """, "refit: node 0"),
    "refit with a leaf past the order": ("""
        nodes = np.array(bvh.nodes)
        leaf = np.flatnonzero(nodes["count"] > 0)[-1]
        nodes[leaf]["count"] = 60000
        _bvh.refit(V, F, bvh.order, u8(nodes), u8(np.array(bvh.triangles)))
        """, "refit: node"),
    "collapse of no nodes": ("""
        _bvh.collapse(np.zeros(0, np.uint8), np.zeros(64, np.uint8))
        """, "collapse: "),
    "collapse of a tree whose children point back": ("""
        nodes = np.array(bvh.nodes); nodes[1]["count"] = 0; nodes[1]["offset"] = 0
        _bvh.collapse(u8(nodes), u8(np.zeros(len(nodes), raysort.bvh.NODE4_DTYPE)))
        """, "collapse: node"),
    "collapse into too small an output": ("""
        _bvh.collapse(u8(bvh.nodes), np.zeros(16, np.uint8))
        """, "collapse: out_bytes"),
    "collapse8 with a leaf beyond the triangles": ("""
        nodes = np.array(bvh.nodes)
        leaf = np.flatnonzero(nodes["count"] > 0)[-1]
        nodes[leaf]["count"] = 60000
        _bvh.collapse8(u8(nodes), u8(bvh.triangles), u8(np.zeros(len(nodes), NODE8_DTYPE)),
                       u8(np.zeros(len(nodes), TRI8_DTYPE)), 1.0, 0.4, 32)
        """, "collapse8: node"),
    "collapse8 into too few groups": ("""
        nodes = bvh.nodes
        _bvh.collapse8(u8(nodes), u8(bvh.triangles), u8(np.zeros(len(nodes), NODE8_DTYPE)),
                       u8(np.zeros(1, TRI8_DTYPE)), 1.0, 0.4, 32)
        """, "collapse8: "),
    "widen16 of an 8-wide tree with a cycle": ("""
        nodes = cyclic8()
        _widen.widen16(u8(nodes), u8(np.zeros(len(nodes), NODE16_DTYPE)))
        """, "widen16: node"),
}

# kernels built per ISA
PER_ISA = {
    "a traversal given misaligned packet rows": ("""
        p = packets(64); p.rows = misaligned(p.rows)
        K("traversals.masked").trace(bvh, p, False)
        """, "16-byte aligned"),
    "a traversal given misaligned u": ("""
        p = packets(64); p.u = misaligned(p.u)
        K("traversals.ranged").trace(bvh, p, False)
        """, "16-byte aligned"),
    "stream with a stream_size of 0": ("""
        K("traversals.stream").trace(bvh, packets(256), False, 0, 0, 8, 8, False)
        """, "trace: stream_size"),
    "stream's trace_batch with a stream_size of 0": ("""
        r = rays(64)
        out = np.zeros((4, 64), np.float32)
        K("traversals.stream").trace_batch(bvh, r.data, np.arange(64, dtype=np.int32),
                                           np.array([0, 64], np.int32), 0, 1, False, out,
                                           0, 0, 8, 8)
        """, "trace_batch: stream_size"),
    "gather with offsets that jump past n and descend": ("""
        a = gather_args(64, offsets=np.array([0, 10**6, 64], np.int32),
                        starts=np.array([0, 8], np.int32))
        K("_gather").gather(**a)
        """, "gather: offsets"),
    "gather with offsets that do not end at n": ("""
        a = gather_args(64, offsets=np.array([0, 32], np.int32))
        K("_gather").gather(**a)
        """, "gather: offsets"),
    "gather with one packet boundary": ("""
        K("_gather").gather(**gather_args(64, packets=np.array([64], np.int32)))
        """, "gather: "),
    "gather into misaligned rows": ("""
        a = gather_args(64)
        a["dst"] = misaligned(a["dst"])
        K("_gather").gather(**a)
        """, "gather: dst"),
    "sort_result with packets of one boundary": ("""
        K("_contract").sort_result(np.arange(8, dtype=np.int32), np.array([0, 8], np.int32),
                                   np.array([8], np.int32), 8, 4096)
        """, "sort_result: "),
    "sort_result with no offsets": ("""
        K("_contract").sort_result(np.arange(4, dtype=np.int32), np.zeros(0, np.int32),
                                   np.array([0, 4], np.int32), 4, 4096)
        """, "sort_result: "),
    "sort_result with an order shorter than n": ("""
        K("_contract").sort_result(np.arange(2, dtype=np.int32), np.array([0, 8], np.int32),
                                   np.array([0, 8], np.int32), 8, 4096)
        """, "sort_result: "),
    "contract rays with n beyond the batch": ("""
        K("_contract").rays(rays(8).data, 10**7)
        """, "rays: "),
    "contract paths with parent shorter than m": ("""
        K("_contract").paths(rays(64).data, 64, np.zeros(2, np.int32),
                             np.zeros((3, 64), np.float32), None, 64, 1)
        """, "paths: "),
    "contract paths with slot shorter than m": ("""
        K("_contract").paths(rays(64).data, 64, np.zeros(64, np.int32),
                             np.zeros((3, 64), np.float32), np.zeros(2, np.int32), 64, 1)
        """, "paths: slot"),
    "pinhole with 65536 strata": ("""
        eye, fwd, right, up = (np.zeros(3, np.float32) for _ in range(4))
        K("generators.pinhole")._generate(eye, fwd, right, up, np.arange(4, dtype=np.int32),
                                          np.array([5], np.int32), 2, 2, 65536, True, 1,
                                          raysort.RayBatch(4).data)
        """, "_generate: "),
    "nah with a packet size of 0": ("""
        K("sorters.nah")._sort(**nah_args(64, packet_size=0))
        """, "_sort: "),
    "nah with packets past the rays": ("""
        K("sorters.nah")._sort(**nah_args(64, packets=np.array([0, 10**6], np.int32)))
        """, "_sort: packets"),
    "nah with descending packets": ("""
        K("sorters.nah")._sort(**nah_args(64, packets=np.array([0, 50, 20, 64], np.int32)))
        """, "_sort: packets must not descend"),
    "nah with an order without room past n": ("""
        K("sorters.nah")._sort(**nah_args(64, order=np.zeros(64, np.int32)))
        """, "_sort: packets"),
    "lambert's _shade with t shorter than prim": ("""
        K("shaders.lambert")._shade(**shade_args(16, t=np.ones(2, np.float32)))
        """, "_shade: "),
    "lambert's _shade with faces of 3 floats": ("""
        K("shaders.lambert")._shade(**shade_args(16, faces=np.zeros((len(F), 3), np.float32)))
        """, "_shade: faces"),
    "lambert's _shade with next rays shorter than their parents": ("""
        K("shaders.lambert")._shade(**shade_args(16, next_rays=raysort.RayBatch(0).data))
        """, "_shade: next"),
    "ao's _ao with 0 samples": ("""
        K("shaders.ao")._ao(**ao_args(16, samples=0))
        """, "_ao: "),
    "ao's _ao with AO weights shorter than the parents": ("""
        K("shaders.ao")._ao(**ao_args(16, ao_weight=np.zeros((3, 2), np.float32)))
        """, "_ao: AO"),
}

VALID_SHARED = """
n = len(F)
nodes, order, tris = np.zeros(2 * n, NODE_DTYPE), np.zeros(n, np.int32), np.zeros(n, TRI_DTYPE)
n_nodes, n_refs, _ = _bvh.build(V, F, 4, 16, 1.0, n, 0.0, u8(nodes), order, u8(tris))
assert np.array_equal(nodes[:n_nodes], bvh.nodes) and np.array_equal(order, bvh.order)
_bvh.triangles(V, F, u8(np.zeros(n, TRI_DTYPE)))
_bvh.refit(V, F, bvh.order, u8(np.array(bvh.nodes)), u8(np.array(bvh.triangles)))
out4 = np.zeros(len(bvh.nodes), raysort.bvh.NODE4_DTYPE)
assert _bvh.collapse(u8(bvh.nodes), u8(out4))[0] == len(bvh.wide)
assert len(bvh.wide8.nodes) and len(bvh.wide16.nodes)
p = packets(64)
_reference.brute_force(u8(bvh.triangles), p.rows, p.prim, p.u, p.v, False)
"""

VALID_PER_ISA = """
for name in ("single", "masked", "ranged", "partition", "frustum", "wide", "wide8", "wide16"):
    K("traversals." + name).trace(bvh, packets(64), False)
K("traversals.stream").trace(bvh, packets(256), False, 64, 0, 8, 8, True)
out = np.zeros((4, 64), np.float32)
K("traversals.stream").trace_batch(bvh, rays(64).data, np.arange(64, dtype=np.int32),
                                   np.array([0, 64], np.int32), 0, 1, False, out, 64, 0, 8, 8)
assert K("_gather").gather(**gather_args(64))[0]
assert K("_contract").sort_result(np.arange(8, dtype=np.int32), np.array([0, 8], np.int32),
                                  np.array([0, 8], np.int32), 8, 4096)[0] == 0
assert K("_contract").rays(rays(8).data, 8)[0] == 0
assert K("_contract").paths(rays(64).data, 64, np.zeros(64, np.int32),
                            np.zeros((3, 64), np.float32), np.zeros(64, np.int32), 64, 1)[0] == 0
eye, fwd, right, up = (np.ones(3, np.float32) for _ in range(4))
K("generators.pinhole")._generate(eye, fwd, right, up, np.arange(4, dtype=np.int32),
                                  np.array([5], np.int32), 2, 2, 2, True, 1,
                                  raysort.RayBatch(4).data)
K("sorters.nah")._sort(**nah_args(64))
K("shaders.lambert")._shade(**shade_args(16))
K("shaders.ao")._ao(**ao_args(16))
"""

RUNNER = """
def report(case, fn):
    print(json.dumps({"start": case}), flush=True)
    try:
        fn()
        result = {"case": case, "type": None, "message": ""}
    except Exception as exc:
        result = {"case": case, "type": type(exc).__name__, "message": str(exc)}
    print(json.dumps(result), flush=True)
"""


def _script(cases, valid):
    parts = [PRELUDE, RUNNER, "def valid():\n" + textwrap.indent(valid, "    "),
             "report('valid', valid)\n"]
    for k, (name, (body, _)) in enumerate(cases.items()):
        parts.append(f"def case_{k}():\n" + textwrap.indent(textwrap.dedent(body), "    "))
        parts.append(f"report({name!r}, case_{k})\n")
    return "\n".join(parts)


def _run(cases, valid, isa_name, tmp_path):
    # from another directory: `python -c` in the checkout would import the source tree
    proc = subprocess.run([sys.executable, "-c", _script(cases, valid), isa_name],
                          capture_output=True, text=True, check=False, timeout=600,
                          cwd=tmp_path)
    records = child_records(proc, f"the private kernels ({isa_name})")
    outcomes = {r["case"]: r for r in records if "case" in r}
    assert outcomes.pop("valid")["type"] is None, records
    assert set(outcomes) == set(cases)
    for name, (_, fragment) in cases.items():
        result = outcomes[name]
        assert result["type"] == "ValueError" and fragment in result["message"], (name, result)


def test_isa_independent_kernels_refuse_what_does_not_fit(tmp_path):
    _run(SHARED, VALID_SHARED, isa.baseline(), tmp_path)


@pytest.mark.parametrize("isa_name", [name for name in isa.ISAS
                                      if name in isa.compiled() and name in isa.supported()])
def test_per_isa_kernels_refuse_what_does_not_fit(isa_name, tmp_path):
    _run(PER_ISA, VALID_PER_ISA, isa_name, tmp_path)
