"""Built-in traversals: ``single``, ``masked``, ``ranged``, ``partition`` and ``wide``.

Each is a Cython module with one packet kernel run by the SDK's traversal driver
(``raysort/sdk/driver.pxd``), which any outside traversal can use the same way; all use
the numeric kernels of ``include/raysort/simd.h``.
"""
