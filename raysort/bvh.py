"""The bounding volume hierarchy every traversal walks.

A binary BVH built with binned SAH (Cython, nogil), optionally with spatial
splits (SBVH), and stored as a flat depth-first array of 32-byte nodes,
exposed as the NumPy structured dtype :data:`NODE_DTYPE` (the C struct
``rs_node`` of ``raysort/types.h``).  Triangles are stored in BVH order as
:data:`TRI_DTYPE` records (``v0``, edges ``e1``/``e2`` and the input index
``id``), ready for Moller-Trumbore; with spatial splits a triangle may be
stored in several leaves.

Every kernel trusts these arrays (child indices, triangle offsets, the depth that
sizes its stack), so a BVH's arrays are read-only, in memory NumPy will not make
writeable again (:func:`frozen`), and its tree attributes cannot be assigned: a
script reads them, and a changed tree is a new BVH (or :meth:`BVH.refit`).
"""
from __future__ import annotations

import threading
import time
from typing import NamedTuple

import numpy as np

from raysort import _bvh, _widen
from raysort._layout import (NODE4_DTYPE, NODE8_DTYPE, NODE16_DTYPE, NODE_DTYPE, TRI8_DTYPE,
                             TRI_DTYPE)
from raysort.errors import ConfigError
from raysort.mesh import check_mesh
from raysort.params import integer, number
from raysort.rays import aligned_empty

__all__ = ["BVH", "Wide8", "Wide16", "PRESETS", "NODE_DTYPE", "NODE4_DTYPE", "NODE8_DTYPE",
           "NODE16_DTYPE", "TRI_DTYPE", "TRI8_DTYPE", "prepare_triangles", "degenerate_faces",
           "frozen", "check_tree"]

#: named sets of build parameters (``BVH(..., preset="manta")``, ``bvh={"preset": "manta"}``,
#: ``raysort bench --bvh manta``); parameters given next to a preset override it.
PRESETS = {
    # binned SAH with DynBVH's costs (C_trav = C_isec = 1): leaves of ~2 triangles, and
    # spatial splits up to 10 % more references (whole frames 1.01-1.07x faster with
    # `stream`, 1.03-1.19x with `wide8`; BENCHMARKS.md §12)
    "default": {"max_leaf": 8, "bins": 16, "traversal_cost": 1.0, "spatial_splits": 0.1,
                "split_alpha": 1e-3},
    # leaves of tens of triangles, as the paper's Manta counts imply: its Table I has
    # about ten triangle tests per box test (Sibenik: 16 ranged, 5.5 partition, 7 ranged
    # + sorting).  A node visit costing 64 triangle tests, leaves of up to 256, gives
    # ~80 triangles per leaf on Sibenik and 10, 8.5 and 14 on its diffuse rays.
    "manta": {"max_leaf": 256, "bins": 16, "traversal_cost": 64.0, "spatial_splits": 0.0,
              "split_alpha": 1e-3},
}

#: largest ``spatial_splits`` reference budget (references <= 5x the triangles)
MAX_SPATIAL_SPLITS = 4.0


class Wide8(NamedTuple):
    """The BVH collapsed to 8-wide nodes (``BVH.wide8``, for the ``wide8`` traversal)."""

    nodes: np.ndarray       #: NODE8_DTYPE, root first, 64-byte aligned
    groups: np.ndarray      #: TRI8_DTYPE leaf triangle groups, 64-byte aligned
    depth: int              #: levels of 8-wide nodes
    sah_cost: float         #: SAH cost (node test 1, one 8-triangle group test GROUP_COST)
    build_seconds: float    #: time the collapse took


class Wide16(NamedTuple):
    """The 8-wide BVH widened to 16-wide nodes (``BVH.wide16``, for the ``wide16``
    traversal); its leaves are the 8-wide tree's triangle groups."""

    nodes: np.ndarray       #: NODE16_DTYPE, root first, 64-byte aligned
    groups: np.ndarray      #: the 8-wide tree's TRI8_DTYPE groups (the same array)
    depth: int              #: levels of 16-wide nodes
    build_seconds: float    #: time the widening took (after the 8-wide collapse)


def frozen(array, align=64):
    """A read-only copy of ``array``, C-contiguous with its data ``align``-aligned,
    whose flag NumPy refuses to set writeable again (its base is a read-only
    memoryview): what the kernels read cannot be edited in place."""
    array = np.asarray(array)
    out = aligned_empty(array.shape, array.dtype, align)
    out[...] = array
    view = memoryview(out.reshape(-1).view(np.uint8)).toreadonly()
    return np.frombuffer(view, dtype=array.dtype).reshape(array.shape)


def prepare_triangles(vertices, faces):
    """Triangles in input order as :data:`TRI_DTYPE` (what brute force tests)."""
    vertices, faces = check_mesh(vertices, faces)
    tris = np.zeros(len(faces), dtype=TRI_DTYPE)
    _bvh.triangles(vertices, faces, tris.view(np.uint8).reshape(-1))
    return tris


def degenerate_faces(vertices, faces):
    """Indices of the degenerate faces, which are kept but never hit.

    The rule is the triangle set-up's in ``raysort/_bvh.pyx`` (the sine of the
    angle at the first vertex at most 2^-20, zero area included), which gives
    such a triangle zero edges; this reads it back from there.
    """
    tris = prepare_triangles(vertices, faces)
    flat = (tris["e1"] == 0).all(axis=1) & (tris["e2"] == 0).all(axis=1)
    return np.flatnonzero(flat)


class BVH:
    """A binned-SAH BVH over a triangle mesh.

    Parameters
    ----------
    vertices : float32 (n, 3)
    faces : int32 (m, 3)
    preset : str, default "default"
        a named set of the parameters below (:data:`PRESETS`: ``"default"``, or
        ``"manta"`` for leaves of tens of triangles as in the paper's Manta); the
        parameters given override it.
    max_leaf : int, default 8
        a node with more triangles is always split.
    bins : int, default 16
        SAH bins per axis (1..64).
    traversal_cost : float, default 1.0
        SAH cost of visiting a node relative to one triangle test (DynBVH: 1);
        larger values make shallower trees with bigger leaves.
    spatial_splits : float, default 0.1
        the reference budget of spatial splits (SBVH, Stich et al. 2009): a
        node may be split by a plane that cuts triangles, each cut triangle
        then sits in both children, so that long or diagonal triangles stop
        bloating the boxes; the leaves hold at most ``(1 + spatial_splits)``
        times as many triangle references as the mesh has triangles (0: no
        spatial splits, the plain binned-SAH tree, which the ``manta`` preset
        keeps; 0..4).
    split_alpha : float, default 1e-3
        spatial splits are tried only in nodes whose best object split's
        children overlap by more than ``split_alpha`` times the root's surface
        area (Stich et al.'s alpha, 1e-5 in their paper; 0 tries them everywhere,
        1 nowhere; 0..1).  1e-3 builds Sibenik and Sponza in half the time of
        1e-5 with the same 8-wide SAH cost (BENCHMARKS.md §12).

    Attributes
    ----------
    (The tree's arrays are read-only and these attributes cannot be assigned; see
    the module docstring.)
    nodes : NODE_DTYPE array, depth first (root first)
    triangles : TRI_DTYPE array in BVH order
    order : int32 array, ``triangles[p]`` is input triangle ``order[p]`` (each
        triangle once, or with spatial splits once or more)
    references : int, ``len(order)``
    build_seconds : float, the time the build took
    depth : int, number of levels
    bounds : float32 (2, 3), the root box
    vertices, faces : the mesh it was built over (vertices move with refit)
    wide : NODE4_DTYPE array, the same tree collapsed to 4-wide nodes (built on
        first use; child >= 0 is an inner node, child < 0 a leaf whose
        triangles start at -child - 1)
    wide8 : :class:`Wide8`, the same tree collapsed to 8-wide nodes by a
        SAH-optimal dynamic program, leaves as SoA groups of 8 triangles
        (built on first use, see :meth:`collapse8`)
    """

    #: SAH cost of one 8-triangle group test, relative to one 8-box node test
    #: (measured on Sibenik and Sponza, see the README's wide8 section)
    WIDE8_GROUP_COST = 0.4
    #: most triangles a wide8 leaf made of several binary leaves may hold
    WIDE8_MAX_LEAF = 32

    def __init__(self, vertices, faces, *, preset="default", max_leaf=None, bins=None,
                 traversal_cost=None, spatial_splits=None, split_alpha=None):
        params = self.check_parameters(preset=preset, max_leaf=max_leaf, bins=bins,
                                       traversal_cost=traversal_cost,
                                       spatial_splits=spatial_splits, split_alpha=split_alpha)
        self.preset = preset
        self.max_leaf, self.bins = params["max_leaf"], params["bins"]
        self.traversal_cost = params["traversal_cost"]
        self.spatial_splits, self.split_alpha = params["spatial_splits"], params["split_alpha"]
        vertices, faces = check_mesh(vertices, faces)
        n = len(faces)
        capacity = n + int(self.spatial_splits * n)
        if 2 * capacity + 1 > np.iinfo(np.int32).max:
            raise ConfigError(f"bvh: {n} triangles with spatial_splits={self.spatial_splits} "
                              f"need more references than a BVH can index")
        start = time.perf_counter()
        nodes = np.zeros(max(2 * capacity, 1), dtype=NODE_DTYPE)
        order = np.zeros(max(capacity, 1), dtype=np.int32)
        triangles = np.zeros(max(capacity, 1), dtype=TRI_DTYPE)
        n_nodes, n_refs, self._depth = _bvh.build(
            vertices, faces, self.max_leaf, self.bins, self.traversal_cost, capacity,
            self.split_alpha, nodes.view(np.uint8).reshape(-1), order,
            triangles.view(np.uint8).reshape(-1))
        self._nodes = frozen(nodes[:n_nodes])
        self._order, self._triangles = frozen(order[:n_refs]), frozen(triangles[:n_refs])
        self.references = n_refs
        self.build_seconds = time.perf_counter() - start
        self._vertices, self._faces = frozen(vertices), frozen(faces)
        self._update_bounds()
        self._wide = None
        self._wide8 = None
        self._wide16 = None
        self._wide_lock = threading.Lock()

    @staticmethod
    def check_parameters(preset="default", **given):
        """The build parameters of ``preset`` with those ``given`` (not None) on top,
        checked; ConfigError naming the preset or parameter otherwise."""
        if not isinstance(preset, str) or preset not in PRESETS:
            raise ConfigError(f"bvh: unknown preset {preset!r} (presets: "
                              f"{', '.join(PRESETS)})")
        unknown = sorted(set(given) - set(PRESETS[preset]))
        if unknown:
            raise ConfigError(f"bvh: unknown parameter {unknown[0]!r} (BVH takes: preset, "
                              f"{', '.join(PRESETS[preset])})")
        p = {**PRESETS[preset], **{k: v for k, v in given.items() if v is not None}}
        return {"max_leaf": integer("max_leaf", p["max_leaf"], 1, 65535),
                "bins": integer("bins", p["bins"], 1, 64),
                "traversal_cost": number("traversal_cost", p["traversal_cost"], 0, 1000,
                                         lo_open=True),
                "spatial_splits": number("spatial_splits", p["spatial_splits"], 0,
                                         MAX_SPATIAL_SPLITS),
                "split_alpha": number("split_alpha", p["split_alpha"], 0, 1)}

    # the tree, read only (see the module docstring)
    nodes = property(lambda self: self._nodes, doc="NODE_DTYPE array, depth first (root first)")
    triangles = property(lambda self: self._triangles, doc="TRI_DTYPE array in BVH order")
    order = property(lambda self: self._order,
                     doc="int32 array: ``triangles[p]`` is input triangle ``order[p]``")
    depth = property(lambda self: self._depth, doc="number of levels")
    bounds = property(lambda self: self._bounds, doc="float32 (2, 3), the root box")
    vertices = property(lambda self: self._vertices,
                        doc="the mesh's vertices (they move with :meth:`refit`)")
    faces = property(lambda self: self._faces, doc="the mesh's faces")

    @property
    def wide(self):
        with self._wide_lock:
            if self._wide is None:
                out = aligned_empty((len(self._nodes),), NODE4_DTYPE)
                n, self._wide_depth = _bvh.collapse(self._nodes.view(np.uint8).reshape(-1),
                                                    out.view(np.uint8).reshape(-1))
                self._wide = frozen(out[:n])
            return self._wide

    @property
    def wide_depth(self):
        """Levels of the 4-wide tree (:attr:`wide`)."""
        BVH.wide.fget(self)     # collapsed on first use
        return self._wide_depth

    @property
    def wide8(self):
        with self._wide_lock:
            if self._wide8 is None:
                self._wide8 = BVH.collapse8(self)     # this class's: from its own tree
            return self._wide8

    @property
    def wide16(self):
        """The 8-wide tree widened to 16-wide nodes (:class:`Wide16`), built on first use."""
        wide8 = BVH.wide8.fget(self)
        with self._wide_lock:
            if self._wide16 is None or self._wide16.groups is not wide8.groups:
                start = time.perf_counter()
                nodes = aligned_empty((len(wide8.nodes),), NODE16_DTYPE, 64)
                n, depth = _widen.widen16(wide8.nodes.view(np.uint8).reshape(-1),
                                          nodes.view(np.uint8).reshape(-1))
                self._wide16 = Wide16(frozen(nodes[:n]), wide8.groups, depth,
                                      time.perf_counter() - start)
            return self._wide16

    def collapse8(self, group_cost=None, max_leaf=None):
        """The tree collapsed to 8-wide nodes (:class:`Wide8`) with the given SAH cost of a
        triangle-group test (relative to a node test) and largest merged leaf."""
        group_cost = number("group_cost", self.WIDE8_GROUP_COST if group_cost is None
                            else group_cost, 0, 1000, lo_open=True)
        max_leaf = integer("max_leaf", self.WIDE8_MAX_LEAF if max_leaf is None else max_leaf,
                           1, 65535 * 8)
        start = time.perf_counter()
        n_leaves = int((self._nodes["count"] > 0).sum())
        nodes = aligned_empty((len(self._nodes),), NODE8_DTYPE, 64)
        groups = aligned_empty((len(self._triangles) // 8 + n_leaves + 1,), TRI8_DTYPE, 64)
        n, n_groups, depth, sah = _bvh.collapse8(
            self._nodes.view(np.uint8).reshape(-1), self._triangles.view(np.uint8).reshape(-1),
            nodes.view(np.uint8).reshape(-1), groups.view(np.uint8).reshape(-1),
            1.0, group_cost, max_leaf)
        return Wide8(frozen(nodes[:n]), frozen(groups[:n_groups]), depth, sah,
                     time.perf_counter() - start)

    def _update_bounds(self):
        self._bounds = frozen(np.stack([self._nodes[0]["lo"], self._nodes[0]["hi"]])
                              .astype(np.float32))

    def refit(self, vertices):
        """Move the triangles to new positions of the same vertices and refit the boxes.

        The tree keeps its shape.  With spatial splits a leaf's box becomes the box
        of its triangles' whole boxes (the cuts are not redone): conservative, so
        every hit stays exact, but the tree loses what the cuts gained; build a new
        BVH after large motions."""
        vertices, faces = check_mesh(vertices, self._faces)
        nodes, triangles = self._nodes.copy(), self._triangles.copy()
        _bvh.refit(vertices, faces, self._order, nodes.view(np.uint8).reshape(-1),
                   triangles.view(np.uint8).reshape(-1))
        self._vertices, self._nodes, self._triangles = (frozen(vertices), frozen(nodes),
                                                        frozen(triangles))
        self._update_bounds()
        with self._wide_lock:
            self._wide = None       # collapsed again from the refitted boxes on use
            self._wide8 = None

    def stats(self):
        """Node, leaf and depth figures and the SAH cost (with this tree's C_trav)."""
        nodes = self.nodes
        leaf = nodes["count"] > 0
        ext = nodes["hi"] - nodes["lo"]
        area = ext[:, 0] * ext[:, 1] + ext[:, 1] * ext[:, 2] + ext[:, 2] * ext[:, 0]
        root = max(float(area[0]), 1e-30)
        sah = (self.traversal_cost * area[~leaf].sum()
               + (area[leaf] * nodes["count"][leaf]).sum()) / root
        return {
            "nodes": int(len(nodes)),
            "leaves": int(leaf.sum()),
            "depth": int(self.depth),
            "mean_leaf_size": float(nodes["count"][leaf].mean()),
            "max_leaf_size": int(nodes["count"][leaf].max()),
            "references": int(self.references),
            "triangles": int(len(self.faces)),
            "sah_cost": float(sah),
            "build_seconds": float(self.build_seconds),
        }

    def __repr__(self):
        return (f"BVH(triangles={len(self.faces)}, references={self.references}, "
                f"nodes={len(self.nodes)}, depth={self.depth})")


#: what the traversals read of a BVH: a subclass may add to a BVH, not redefine these
_TREE = ("nodes", "triangles", "order", "depth", "bounds", "vertices", "faces", "wide",
         "wide_depth", "wide8", "wide16", "collapse8", "__getattribute__")


def check_tree(bvh):
    """``bvh`` if a traversal may read it: a :class:`BVH` whose tree is the one it
    built.  A subclass may add to a BVH but not redefine what traversals read (the tree
    is checked when built, not at every call); ConfigError otherwise."""
    if not isinstance(bvh, BVH):
        raise ConfigError(f"bvh must be a raysort.BVH, got {type(bvh).__name__}")
    cls = type(bvh)
    if cls is not BVH:
        for name in _TREE:
            if getattr(cls, name) is not getattr(BVH, name):
                raise ConfigError(f"{cls.__name__} redefines BVH.{name}: a traversal reads "
                                  f"the tree BVH built, which a subclass may not replace")
    return bvh

