"""Triangle-mesh checks, one rule per fact, for every way a mesh enters raysort.

Mesh files, scene files, procedural meshes, :meth:`Scene.from_mesh` and the
:class:`~raysort.bvh.BVH` all call these, so the same bad mesh raises the same
:class:`~raysort.errors.SceneError` (naming where it came from) whatever the
path.  The degenerate-triangle rule lives with the triangle set-up in
``raysort/_bvh.pyx`` (:func:`raysort.bvh.degenerate_faces`).
"""
from __future__ import annotations

import numpy as np

from raysort.errors import SceneError
from raysort.params import FLOAT32_MAX

__all__ = ["check_mesh", "per_face"]

#: most vertices or faces: indices are int32 (and the BVH has 2 nodes per face)
MAX_ELEMENTS = 2**30


def _prefix(where):
    return f"mesh '{where}'" if where else "mesh"


def _numbers(value, what, where):
    """``value`` as an array of real numbers (no conversion yet)."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{_prefix(where)}: {what} must be an array of numbers ({exc})") \
            from None
    if arr.dtype.kind not in "iuf":
        raise SceneError(f"{_prefix(where)}: {what} must be numbers, got {arr.dtype}")
    return arr


def check_mesh(vertices, faces, where=None):
    """``(vertices, faces)`` as C-contiguous float32 (n, 3) and int32 (m, 3) arrays.

    There must be at least one face; face indices must be integers that index
    ``vertices``; every vertex must be finite in float32.  ``where`` (a file or
    scene name) goes into the message.
    """
    vertices = _numbers(vertices, "vertices", where)
    faces = _numbers(faces, "faces", where)
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise SceneError(f"{_prefix(where)} has no triangle faces (faces have shape "
                         f"{faces.shape}, not (m, 3) with m >= 1)")
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise SceneError(f"{_prefix(where)}: vertices have shape {vertices.shape}, not (n, 3)")
    if max(len(vertices), len(faces)) > MAX_ELEMENTS:
        raise SceneError(f"{_prefix(where)} has more than {MAX_ELEMENTS} vertices or faces")
    if faces.dtype.kind == "f":
        if not (np.isfinite(faces).all() and (faces == np.round(faces)).all()):
            raise SceneError(f"{_prefix(where)}: face indices must be whole numbers")
    lo, hi = faces.min(), faces.max()
    if lo < 0 or hi >= len(vertices):
        raise SceneError(f"{_prefix(where)}: face indices out of range 0..{len(vertices) - 1} "
                         f"(found {lo}..{hi})")
    bad = np.flatnonzero(~(np.abs(vertices) <= FLOAT32_MAX).all(axis=1))
    if len(bad):
        raise SceneError(f"{_prefix(where)}: {len(bad)} vertices are not finite in float32 "
                         f"(first: vertex {bad[0]} = {vertices[bad[0]].tolist()})")
    return (np.ascontiguousarray(vertices, dtype=np.float32),
            np.ascontiguousarray(faces, dtype=np.int32))


def per_face(what, value, m, lo, hi, where=None):
    """A per-face colour (``albedo``, ``emission``): one number or 3 for every face, or
    one row of 3 per face, each finite in float32 and in ``[lo, hi]``; float32 (m, 3)."""
    arr = _numbers(value, what, where)
    if arr.ndim <= 1 and arr.size in (1, 3):          # one grey value or one colour for all
        arr = np.broadcast_to(arr.reshape(-1), (m, 3))
    if arr.shape != (m, 3):
        raise SceneError(f"{_prefix(where)}: {what} must be 3 numbers or one row of 3 per "
                         f"face ({m}), got shape {arr.shape}")
    hi = min(hi, FLOAT32_MAX)
    if not ((arr >= lo) & (arr <= hi)).all():
        raise SceneError(f"{_prefix(where)}: {what} values must lie in [{lo}, {hi:.4g}]")
    return np.ascontiguousarray(arr, dtype=np.float32)
