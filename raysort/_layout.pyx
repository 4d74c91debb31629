"""The Python face of ``include/raysort/types.h``, derived from it, never written again.

* :data:`NODE_DTYPE`, :data:`NODE4_DTYPE`, :data:`NODE8_DTYPE`, :data:`NODE16_DTYPE`,
  :data:`TRI_DTYPE`, :data:`TRI8_DTYPE`: NumPy structured dtypes of ``rs_node``,
  ``rs_node4``, ``rs_node8``, ``rs_node16``, ``rs_tri`` and ``rs_tri8``, taken from a
  one-element Cython view of each struct (the scikit-learn idiom), so field names, types
  and offsets are the C compiler's;
* :class:`RayRow`, :class:`PacketRow`: the row indices of ray batches and gathered
  packets (``rs_ray_row``, ``rs_packet_row``) with the names types.h gives them;
* :data:`MAX_PACKET`, :data:`DEGENERATE_SIN2` and the random-number dimension budget.

:func:`c_layout` reads every field offset and struct size back from C, for
``tests/test_layout.py`` to compare with the dtypes.
"""
import enum

import numpy as np

from raysort._types cimport (rs_node, rs_node4, rs_node8, rs_node16, rs_tri, rs_tri8,
                             RS_MAX_PACKET,
                             RS_RAY_ROWS, RS_PACKET_ROWS, rs_ray_row_names, rs_packet_row_names,
                             RS_DEGENERATE_SIN2, RS_DIM_JITTER_X, RS_DIM_JITTER_Y,
                             RS_DIM_BOUNCE, RS_DIMS_PER_BOUNCE, RS_MAX_DEPTH, RS_DIM_AO)

__all__ = ["NODE_DTYPE", "NODE4_DTYPE", "NODE8_DTYPE", "NODE16_DTYPE", "TRI_DTYPE",
           "TRI8_DTYPE", "RayRow", "PacketRow", "MAX_PACKET", "DEGENERATE_SIN2", "RNG_DIMS",
           "c_layout"]

cdef rs_node _node
cdef rs_node4 _node4
cdef rs_tri _tri
cdef rs_node8 _node8
cdef rs_node16 _node16
cdef rs_tri8 _tri8

#: ``rs_node``: one node of the flat depth-first binary BVH
NODE_DTYPE = np.asarray(<rs_node[:1]> &_node).dtype
#: ``rs_node4``: one node of the 4-wide BVH
NODE4_DTYPE = np.asarray(<rs_node4[:1]> &_node4).dtype
#: ``rs_tri``: a triangle prepared for Moller-Trumbore
TRI_DTYPE = np.asarray(<rs_tri[:1]> &_tri).dtype
#: ``rs_node8``: one node of the 8-wide BVH
NODE8_DTYPE = np.asarray(<rs_node8[:1]> &_node8).dtype
#: ``rs_node16``: one node of the 16-wide BVH
NODE16_DTYPE = np.asarray(<rs_node16[:1]> &_node16).dtype
#: ``rs_tri8``: a structure-of-arrays group of up to eight triangles
TRI8_DTYPE = np.asarray(<rs_tri8[:1]> &_tri8).dtype


cdef list _rows(const char *const *names, int n):
    return [(names[i].decode(), i) for i in range(n)]


#: the rows of :attr:`raysort.rays.RayBatch.data` (``rs_ray_row``)
RayRow = enum.IntEnum("RayRow", _rows(rs_ray_row_names, RS_RAY_ROWS), module="raysort.rays")
#: the rows of :attr:`raysort.rays.Packets.rows` (``rs_packet_row``)
PacketRow = enum.IntEnum("PacketRow", _rows(rs_packet_row_names, RS_PACKET_ROWS),
                         module="raysort.rays")

#: widest sub-packet a traversal accepts (rays)
MAX_PACKET = RS_MAX_PACKET
#: a triangle whose squared angle sine is at most this is degenerate (never hit)
DEGENERATE_SIN2 = RS_DEGENERATE_SIN2
#: the random-number dimensions a path draws (see types.h)
RNG_DIMS = {"jitter_x": RS_DIM_JITTER_X, "jitter_y": RS_DIM_JITTER_Y,
            "bounce": RS_DIM_BOUNCE, "per_bounce": RS_DIMS_PER_BOUNCE,
            "max_depth": RS_MAX_DEPTH, "ao": RS_DIM_AO}


cdef Py_ssize_t _at(const void *field, const void *base):
    return <const char *> field - <const char *> base


def c_layout():
    """``{struct: (sizeof, {field: offsetof})}`` as the C compiler lays the structs out."""
    return {
        "rs_node": (sizeof(rs_node), {
            "lo": _at(&_node.lo, &_node), "hi": _at(&_node.hi, &_node),
            "offset": _at(&_node.offset, &_node), "count": _at(&_node.count, &_node),
            "axis": _at(&_node.axis, &_node), "flags": _at(&_node.flags, &_node)}),
        "rs_node4": (sizeof(rs_node4), {
            "lo": _at(&_node4.lo, &_node4), "hi": _at(&_node4.hi, &_node4),
            "child": _at(&_node4.child, &_node4), "count": _at(&_node4.count, &_node4),
            "pad": _at(&_node4.pad, &_node4)}),
        "rs_tri": (sizeof(rs_tri), {
            "v0": _at(&_tri.v0, &_tri), "e1": _at(&_tri.e1, &_tri), "e2": _at(&_tri.e2, &_tri),
            "id": _at(&_tri.id, &_tri), "pad": _at(&_tri.pad, &_tri)}),
        "rs_node8": (sizeof(rs_node8), {
            "lo": _at(&_node8.lo, &_node8), "hi": _at(&_node8.hi, &_node8),
            "child": _at(&_node8.child, &_node8), "count": _at(&_node8.count, &_node8),
            "pad": _at(&_node8.pad, &_node8)}),
        "rs_node16": (sizeof(rs_node16), {
            "lo": _at(&_node16.lo, &_node16), "hi": _at(&_node16.hi, &_node16),
            "child": _at(&_node16.child, &_node16), "count": _at(&_node16.count, &_node16),
            "pad": _at(&_node16.pad, &_node16)}),
        "rs_tri8": (sizeof(rs_tri8), {
            "v0": _at(&_tri8.v0, &_tri8), "e1": _at(&_tri8.e1, &_tri8),
            "e2": _at(&_tri8.e2, &_tri8), "id": _at(&_tri8.id, &_tri8)}),
    }
