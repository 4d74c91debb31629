"""Counter-based random numbers: a pure function of (seed, pixel, sample, dimension).

No state is kept anywhere, so a ray's random numbers never depend on which
thread, batch or order produced it.  ``mix32`` is the "lowbias32" integer
hash (Chris Wellons); ``uniform`` maps its top 24 bits to [0, 1).

The hash is a chain, ``mix32(mix32(mix32(mix32(seed') ^ pixel) ^ sample) ^ dim)``,
so the numbers of one path share a prefix: ``path_key(seed, pixel, sample)`` hashes
it once and ``uniform_at(key, dim)`` draws each dimension with one more ``mix32``;
``uniform(seed, pixel, sample, dim)`` is the same number in one call.  The samples
of one pixel share the shorter prefix ``pixel_key(seed_key(seed), pixel)``.
"""
from libc.stdint cimport int32_t, uint32_t


cdef inline uint32_t mix32(uint32_t x) noexcept nogil:
    x ^= x >> 16
    x *= 0x7feb352du
    x ^= x >> 15
    x *= 0x846ca68bu
    x ^= x >> 16
    return x


cdef inline uint32_t seed_key(uint32_t seed) noexcept nogil:
    """The part of the hash that depends on the seed alone."""
    return mix32(seed ^ 0x9e3779b9u)


cdef inline uint32_t pixel_key(uint32_t seed_k, uint32_t pixel) noexcept nogil:
    """The hash prefix of one pixel, from ``seed_key(seed)`` (shared by its samples)."""
    return mix32(seed_k ^ pixel)


cdef inline uint32_t sample_key(uint32_t seed_k, uint32_t pixel, uint32_t sample) noexcept nogil:
    """The hash prefix of one (pixel, sample), from ``seed_key(seed)``."""
    return mix32(pixel_key(seed_k, pixel) ^ sample)


cdef inline uint32_t path_key(uint32_t seed, uint32_t pixel, uint32_t sample) noexcept nogil:
    """The hash prefix every random number of one (seed, pixel, sample) shares."""
    return sample_key(seed_key(seed), pixel, sample)


cdef inline float uniform_at(uint32_t key, uint32_t dim) noexcept nogil:
    """A float in [0, 1) for dimension ``dim`` of the path with this ``path_key``.

    24 bits times 2^-24 in float arithmetic is exact, so the value does not depend
    on how the compiler evaluates it (the bits go through a signed int, which SIMD
    converts directly)."""
    return <float><int32_t>(mix32(key ^ dim) >> 8) * <float>(1.0 / 16777216.0)


cdef inline float uniform(uint32_t seed, uint32_t pixel, uint32_t sample,
                          uint32_t dim) noexcept nogil:
    """A float in [0, 1) for one (seed, pixel, sample, dimension)."""
    return uniform_at(path_key(seed, pixel, sample), dim)
