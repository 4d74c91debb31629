"""Built-in traversals: ``single``, ``masked``, ``ranged`` and ``partition``.

Each is a Cython module with one packet kernel over the shared scaffolding of
``_common.pxd``; all use the numeric kernels of ``include/raysort/simd.h``.
"""
