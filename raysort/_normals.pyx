"""The faces' unit geometric normals in one C pass (:meth:`raysort.scene.Scene.face_normals`)."""
from libc.math cimport sqrt
from libc.stdint cimport int32_t


def face_normals(const float[:, ::1] vertices, const int32_t[:, ::1] faces, float[:, ::1] out):
    """Fill ``out`` (m, 3) with each face's unit normal ``(v1 - v0) x (v2 - v0)``, in
    double: the differences, the cross product's terms in NumPy's order, the length
    summed x, y, z; a zero normal for a zero length; then rounded to float32.
    IndexError at a vertex index out of range."""
    cdef Py_ssize_t m = faces.shape[0], nv = vertices.shape[0], f, bad = -1
    cdef int a
    cdef int32_t i0, i1, i2
    cdef double e0[3]
    cdef double e1[3]
    cdef double c[3]
    cdef double length
    if faces.shape[1] != 3 or vertices.shape[1] != 3 or out.shape[0] != m or out.shape[1] != 3:
        raise ValueError("face_normals: vertices (n, 3), faces (m, 3) and out (m, 3) expected")
    with nogil:
        for f in range(m):
            i0 = faces[f, 0]
            i1 = faces[f, 1]
            i2 = faces[f, 2]
            if not (0 <= i0 < nv and 0 <= i1 < nv and 0 <= i2 < nv):
                bad = f
                break
            for a in range(3):
                e0[a] = <double>vertices[i1, a] - <double>vertices[i0, a]
                e1[a] = <double>vertices[i2, a] - <double>vertices[i0, a]
            c[0] = e0[1] * e1[2] - e0[2] * e1[1]
            c[1] = e0[2] * e1[0] - e0[0] * e1[2]
            c[2] = e0[0] * e1[1] - e0[1] * e1[0]
            length = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
            for a in range(3):
                out[f, a] = <float>(c[a] / length) if length > 0 else <float>0.0
    if bad >= 0:
        raise IndexError(f"face_normals: face {bad} names a vertex beyond the {nv} vertices")
