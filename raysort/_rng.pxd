"""Counter-based random numbers: a pure function of (seed, pixel, sample, dimension).

No state is kept anywhere, so a ray's random numbers never depend on which
thread, batch or order produced it.  ``mix32`` is the "lowbias32" integer
hash (Chris Wellons); ``uniform`` maps its top 24 bits to [0, 1).
"""
from libc.stdint cimport uint32_t


cdef inline uint32_t mix32(uint32_t x) noexcept nogil:
    x ^= x >> 16
    x *= 0x7feb352du
    x ^= x >> 15
    x *= 0x846ca68bu
    x ^= x >> 16
    return x


cdef inline uint32_t hash4(uint32_t a, uint32_t b, uint32_t c, uint32_t d) noexcept nogil:
    return mix32(mix32(mix32(mix32(a ^ 0x9e3779b9u) ^ b) ^ c) ^ d)


cdef inline float uniform(uint32_t seed, uint32_t pixel, uint32_t sample,
                          uint32_t dim) noexcept nogil:
    """A float in [0, 1) for one (seed, pixel, sample, dimension)."""
    return (hash4(seed, pixel, sample, dim) >> 8) * (1.0 / 16777216.0)
