"""The machinery of the sort-key sorters: per-ray keys, a radix sort, sub-packet cuts.

Shared by ``origin_direction``, ``two_point``, ``termination`` and ``garanzha``
(see those modules for the keys and their papers); built per ISA and called
through :func:`raysort.isa.module` like every kernel.  A key is built in one pass
over the rays:

1. every ray gives up to six coordinates in [0, 1] (``coordinates`` below):
   the origin normalised to the scene box, then either the unit direction's
   components mapped from [-1, 1], its octahedral map (two coordinates), or an
   end point ``o + L * d / |d|`` normalised like the origin;
2. each coordinate is quantised to :data:`COORD_BITS` bits;
3. the key is the OR of per-coordinate lookup tables (two bytes of each
   quantised coordinate index a table of the key bits they set).  Any bit
   split (Morton interleave, a block of one coordinate's bits first, a plain
   concatenation as in a hash) is just a table, built by :func:`key_table`.

Keys are left aligned in a uint64: the sort looks at the top ``8 * digits``
bits.  Within every large packet, ``(key, ray)`` pairs are sorted by a stable
LSD radix sort on bytes (a pass whose byte is the same for every key is
skipped), optionally after Garanzha and Loop's compression: runs of equal keys
in input order become one chunk, only chunks are sorted, and the runs are
copied back in chunk order (the result is the same order; the work is on
fewer items when the input has long runs).  The sorted run is then cut into
sub-packets of at most ``packet_size`` rays, and also wherever the top
``split_bits`` bits of the key change.

Coordinates that are NaN map to 0 and everything is clamped to [0, 1], so no
ray (NaN, infinite, zero direction) can make the kernel misbehave; the gather
marks such rays inactive anyway.
"""
from libc.math cimport INFINITY, copysignf, fabsf, sqrtf
from libc.stdint cimport int32_t, int64_t, uint32_t, uint64_t
from libc.string cimport memset
from raysort._types cimport rs_maxf, rs_minf

import numpy as np

from raysort import isa
from raysort.sdk import MAX_PACKET, ConfigError, Sorter, boolean, check_packets, integer

#: bits each coordinate is quantised to (a key table has two byte-tables per coordinate)
COORD_BITS = 16
#: most coordinates a key draws from
MAX_COORDS = 6

# how the coordinates after the origin's three are made
cdef enum:
    DIR_COMPONENTS = 0      # (d/|d| + 1) / 2 per component: coordinates 3, 4, 5
    DIR_OCTAHEDRAL = 1      # octahedral map of d/|d| to [0,1]^2: coordinates 3, 4
    END_POINT = 2           # o + L d/|d|, normalised like the origin: coordinates 3, 4, 5

COORDINATES = {"components": DIR_COMPONENTS, "octahedral": DIR_OCTAHEDRAL,
               "end_point": END_POINT}

# the end point is pulled this much inside the box it would leave (Meister's hippie does
# the same), so that a ray ending on the far wall keeps its wall's cell
cdef float EXIT_SHRINK = 1.0 - 1.0e-3
cdef float QMAX = 65535.0   # 2**COORD_BITS - 1
cdef float ONE = 1.0        # float constants: a bare 0.5 or 1.0 would make the C double
cdef float HALF = 0.5
#: bits of the octant prefix (the signs of dx, dy, dz)
OCTANT_BITS = 3


cdef inline float unit(float x) noexcept nogil:
    """x clamped to [0, 1]; NaN -> 0 (MAXSS/MINSS semantics: no branch)."""
    return rs_minf(rs_maxf(x, 0), 1)


cdef inline uint32_t quantise(float x) noexcept nogil:
    return <uint32_t> (unit(x) * QMAX)


cdef void ray_keys(const float *ox, const float *oy, const float *oz, const float *dx,
                   const float *dy, const float *dz, const float *tmax, const float *prev_t,
                   int n, int mode, const float *lo, const float *hi, const float *scale,
                   float length, float prev_scale, const uint64_t *table, bint low_bytes,
                   bint octant, uint64_t *keys) noexcept nogil:
    """The key of rays [0, n).  The float work is branch free (min/max and selects by
    multiplication): diffuse directions would mispredict a branch on a sign half the
    time, which costs more than all the arithmetic."""
    cdef int i, k, n_coords = 5 if mode == DIR_OCTAHEDRAL else 6
    cdef float o[3]
    cdef float d[3]
    cdef float c[6]
    cdef float inv, s, L, p, ex, u, v, fu, fv, below, r
    cdef uint32_t q
    cdef uint64_t key
    for i in range(n):
        o[0] = ox[i]
        o[1] = oy[i]
        o[2] = oz[i]
        # d / |d| (inf or NaN for a zero or non-finite direction: its key is then arbitrary);
        # the octahedral map divides by |d|_1 itself and needs no unit vector
        inv = ONE if mode == DIR_OCTAHEDRAL else ONE / sqrtf(dx[i] * dx[i] + dy[i] * dy[i]
                                                              + dz[i] * dz[i])
        d[0] = dx[i] * inv
        d[1] = dy[i] * inv
        d[2] = dz[i] * inv
        for k in range(3):
            c[k] = (o[k] - lo[k]) * scale[k]
        if mode == DIR_COMPONENTS:
            for k in range(3):
                c[3 + k] = HALF * d[k] + HALF
        elif mode == DIR_OCTAHEDRAL:
            s = ONE / (fabsf(d[0]) + fabsf(d[1]) + fabsf(d[2]))
            u = d[0] * s
            v = d[1] * s
            # the lower hemisphere (below = 1) folds over the diagonals
            fu = copysignf(ONE - fabsf(v), u)
            fv = copysignf(ONE - fabsf(u), v)
            below = <float> (d[2] < 0)
            c[3] = HALF * (u + below * (fu - u)) + HALF
            c[4] = HALF * (v + below * (fv - v)) + HALF
        else:
            L = length
            if prev_t != NULL:
                p = prev_t[i]
                if p > 0 and p < INFINITY:
                    L = p * prev_scale
            if not tmax[i] >= L:    # also when tmax is NaN or negative
                L = tmax[i] if tmax[i] > 0 else 0
            # where the ray leaves the scene box (for an origin inside it), pulled in a little
            ex = INFINITY
            for k in range(3):
                r = ONE / d[k]
                ex = rs_minf(ex, rs_maxf((lo[k] - o[k]) * r, (hi[k] - o[k]) * r))
            L = rs_minf(rs_maxf(ex * EXIT_SHRINK, 0), L)
            for k in range(3):
                c[3 + k] = (o[k] + L * d[k] - lo[k]) * scale[k]
        key = 0
        if low_bytes:
            for k in range(n_coords):
                q = quantise(c[k])
                key |= table[(2 * k) * 256 + (q & 255)] | table[(2 * k + 1) * 256 + (q >> 8)]
        else:                       # a short key uses only the top byte of every coordinate
            for k in range(n_coords):
                key |= table[(2 * k + 1) * 256 + (quantise(c[k]) >> 8)]
        if octant:                  # the direction's octant first (bit k: d[k] < 0)
            key = (key >> 3 | <uint64_t> (dx[i] < 0) << 63 | <uint64_t> (dy[i] < 0) << 62
                   | <uint64_t> (dz[i] < 0) << 61)
        keys[i] = key


def make_keys(rays, str coordinates, bounds, const uint64_t[:, :, ::1] table, *,
              float length=0, prev_t=None, float prev_scale=1, bint octant=False):
    """uint64 keys of a :class:`~raysort.rays.RayBatch` (see the module docstring).

    ``coordinates``: a key of :data:`COORDINATES`; ``bounds``: the (2, 3) scene box;
    ``table``: from :func:`key_table`; ``length``: the end-point distance (world
    units) where ``prev_t`` (float32 per ray, or None) is not a positive finite
    number, which otherwise gives ``prev_t * prev_scale``; ``octant``: the top
    :data:`OCTANT_BITS` bits are the signs of the direction, the table's key follows.
    """
    cdef int n = len(rays), mode = COORDINATES[coordinates]
    box = np.asarray(bounds, dtype=np.float32)
    extent = box[1] - box[0]
    cdef float[::1] lo = np.ascontiguousarray(box[0])
    cdef float[::1] hi = np.ascontiguousarray(box[1])
    # 1 / extent, 0 on a flat (or inverted, or non-finite) axis: it carries no order
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(extent > 0, np.float32(1) / extent, 0).astype(np.float32)
    inv[~np.isfinite(inv)] = 0
    cdef float[::1] scale = inv
    out = np.empty(n, dtype=np.uint64)
    if n == 0:
        return out
    o, d = rays.origins, rays.directions
    cdef const float[::1] ox = o[0], oy = o[1], oz = o[2]
    cdef const float[::1] dx = d[0], dy = d[1], dz = d[2]
    cdef const float[::1] tmax = rays.tmax
    cdef const float[::1] prev = None
    if prev_t is not None:
        prev = np.ascontiguousarray(prev_t, dtype=np.float32)
        if prev.shape[0] != n:
            raise ConfigError(f"rays.prev_t has {prev.shape[0]} values for {n} rays")
    cdef uint64_t[::1] keys = out
    cdef const float *prev_ptr = &prev[0] if prev is not None else NULL
    if table.shape[0] != MAX_COORDS or table.shape[1] != 2 or table.shape[2] != 256:
        raise ValueError(f"a key table has shape ({MAX_COORDS}, 2, 256), got "
                         f"{(table.shape[0], table.shape[1], table.shape[2])}")
    cdef bint low_bytes = bool(np.asarray(table)[:, 0].any())
    with nogil:
        ray_keys(&ox[0], &oy[0], &oz[0], &dx[0], &dy[0], &dz[0], &tmax[0], prev_ptr, n, mode,
                 &lo[0], &hi[0], &scale[0], length, prev_scale, &table[0, 0, 0], low_bytes, octant,
                 &keys[0])
    return out


def key_table(levels):
    """The lookup table of a bit split: ``levels`` lists, most significant first, the
    coordinates that give their next most significant bit at each level.

    ``[(0, 1, 2)] * 3 + [(0, 1, 2, 3, 4, 5)] * 8`` is three levels of origin bits
    followed by eight levels of 6-D interleave (Meister's AILA layout).  Key bits
    run from bit 63 down; at most 64 bits and :data:`COORD_BITS` levels of a
    coordinate.  Returns ``(table, bits)``.
    """
    table = np.zeros((MAX_COORDS, 2, 256), dtype=np.uint64)
    used = [0] * MAX_COORDS
    pos = 63
    byte = np.arange(256, dtype=np.uint64)
    for level in levels:
        for coord in level:
            if not 0 <= coord < MAX_COORDS:
                raise ValueError(f"a key draws from coordinates 0..{MAX_COORDS - 1}, got {coord}")
            if used[coord] == COORD_BITS:
                raise ValueError(f"coordinate {coord} has only {COORD_BITS} bits")
            if pos < 0:
                raise ValueError("a key holds at most 64 bits")
            bit = COORD_BITS - 1 - used[coord]            # next most significant bit
            half, b = divmod(bit, 8)
            table[coord, half] |= ((byte >> np.uint64(b)) & np.uint64(1)) << np.uint64(pos)
            used[coord] += 1
            pos -= 1
    return table, 63 - pos


# ---------------------------------------------------------------------------------------
# sorting

cdef int radix_sort(uint64_t *key, int32_t *item, uint64_t *key_tmp, int32_t *item_tmp,
                    int n, int digits) noexcept nogil:
    """Stable LSD radix sort of (key, item) by the top ``digits`` bytes of key.

    Returns 1 when the result is in the tmp arrays, 0 when in key/item."""
    cdef int32_t count[8][256]
    cdef int i, j, shift, flip = 0
    cdef int32_t pos, c
    cdef uint64_t *ks = key
    cdef uint64_t *kd = key_tmp
    cdef int32_t *is_ = item
    cdef int32_t *id_ = item_tmp
    cdef uint64_t *kt
    cdef int32_t *it
    memset(count, 0, digits * sizeof(count[0]))
    for i in range(n):
        for j in range(digits):
            count[j][(key[i] >> (56 - 8 * j)) & 255] += 1
    for j in range(digits - 1, -1, -1):
        shift = 56 - 8 * j
        if count[j][(key[0] >> shift) & 255] == n:
            continue                # every key has this byte: the pass would not move anything
        pos = 0
        for i in range(256):
            c = count[j][i]
            count[j][i] = pos
            pos += c
        for i in range(n):
            c = count[j][(ks[i] >> shift) & 255]
            count[j][(ks[i] >> shift) & 255] = c + 1
            kd[c] = ks[i]
            id_[c] = is_[i]
        kt = ks
        ks = kd
        kd = kt
        it = is_
        is_ = id_
        id_ = it
        flip ^= 1
    return flip


cdef int sort_packet(const uint64_t *keys, int start, int end, int digits, bint compress,
                     int packet_size, int split_bits, int32_t *order, int32_t *offsets,
                     uint64_t *ckey, int32_t *citem, uint64_t *ckey_tmp, int32_t *citem_tmp,
                     int32_t *cstart, uint64_t *skey) noexcept nogil:
    """Sort rays [start, end) by key into order[start:end]; write sub-packet starts to
    offsets and return their number.  Work buffers hold end - start (+1) items."""
    cdef int i, j, c, nc = 0, pos, last, flip, first
    cdef uint64_t mask
    cdef uint64_t *sk
    cdef int32_t *si
    # chunks: every ray, or (compress) every run of equal keys in input order
    for i in range(start, end):
        if not compress or i == start or keys[i] != keys[i - 1]:
            ckey[nc] = keys[i]
            citem[nc] = nc
            cstart[nc] = i
            nc += 1
    cstart[nc] = end
    flip = radix_sort(ckey, citem, ckey_tmp, citem_tmp, nc, digits)
    sk = ckey_tmp if flip else ckey
    si = citem_tmp if flip else citem
    # decompress: each chunk's rays, in input order, at the chunk's sorted place
    pos = start
    for j in range(nc):
        c = si[j]
        for i in range(cstart[c], cstart[c + 1]):
            order[pos] = i
            skey[pos - start] = sk[j]
            pos += 1
    # sub-packets: at most packet_size rays, and a new one where the key's top bits change
    mask = 0 if split_bits == 0 else ~(<uint64_t> 0) << (64 - split_bits)
    c = 0
    last = start
    for pos in range(start, end):
        if (pos == start or pos - last == packet_size
                or (skey[pos - start] ^ skey[pos - start - 1]) & mask):
            offsets[c] = pos
            c += 1
            last = pos
    return c


def sort_keys(const uint64_t[::1] keys, const int32_t[::1] packets, int digits, *,
              bint compress=False, int packet_size=64, int split_bits=0):
    """``(order, offsets)``: rays sorted by key within each large packet (see the module
    docstring); ``digits`` = how many top bytes of the key are sorted (1..8)."""
    cdef int n = keys.shape[0], n_packets = packets.shape[0] - 1, p, n_sub = 0, widest = 1
    if not 1 <= digits <= 8 or not 1 <= packet_size or not 0 <= split_bits <= 64:
        raise ValueError(f"digits 1..8, packet_size >= 1, split_bits 0..64; got {digits}, "
                         f"{packet_size}, {split_bits}")
    for p in range(n_packets):
        widest = max(widest, packets[p + 1] - packets[p])
    order = np.empty(max(n, 1), dtype=np.int32)
    offsets = np.empty(n + 1, dtype=np.int32)
    cdef int32_t[::1] order_mv = order, offsets_mv = offsets
    cdef uint64_t[::1] ckey = np.empty(widest, np.uint64), ckey_tmp = np.empty(widest, np.uint64)
    cdef uint64_t[::1] skey = np.empty(widest, np.uint64)
    cdef int32_t[::1] citem = np.empty(widest, np.int32), citem_tmp = np.empty(widest, np.int32)
    cdef int32_t[::1] cstart = np.empty(widest + 1, np.int32)
    cdef const uint64_t *kp = &keys[0] if n else NULL
    with nogil:
        for p in range(n_packets):
            if packets[p + 1] > packets[p]:
                n_sub += sort_packet(kp, packets[p], packets[p + 1], digits, compress,
                                     packet_size, split_bits, &order_mv[0], &offsets_mv[n_sub],
                                     &ckey[0], &citem[0], &ckey_tmp[0], &citem_tmp[0],
                                     &cstart[0], &skey[0])
    offsets_mv[n_sub] = n
    return order[:n], offsets[:n_sub + 1].copy()


# ---------------------------------------------------------------------------------------
# the plugin base

class KeySorter(Sorter):
    """A sorter that orders each large packet by a uint64 key per ray.

    A subclass sets ``self.levels`` (the bit split, see :func:`key_table`),
    ``self.coordinates`` (a key of :data:`COORDINATES`), ``self.packet_size`` and
    ``self.split_bits``, and may override :meth:`end_length` (two-point keys) and
    :attr:`compress`.
    """

    trusted = True
    #: Garanzha and Loop's compress-sort-decompress (same order, fewer items to sort)
    compress = False

    def _setup(self, levels, bits, packet_size, split_bits, octant=False):
        """Validate the common parameters and build the key table.

        ``octant``: prefix the key with the direction's octant and never let a
        sub-packet mix octants (the key's ``bits`` then include the 3 octant bits)."""
        self.packet_size = integer("packet_size", packet_size, 1, MAX_PACKET)
        self.octant = boolean("octant", octant)
        prefix = OCTANT_BITS if self.octant else 0
        levels = _truncate(levels, 64 - prefix)
        self.bits = integer("bits", bits, 1 + prefix, prefix + sum(len(lv) for lv in levels))
        self._table, _ = key_table(_truncate(levels, self.bits - prefix))
        self.split_bits = integer("split_bits", split_bits, 0, self.bits)
        self._split = max(self.split_bits, prefix)
        self._digits = (self.bits + 7) // 8

    def end_length(self, rays, bounds):
        """``(length, prev_t, prev_scale)`` for end-point keys (world units)."""
        return 0.0, None, 1.0

    def keys(self, rays, bounds):
        """The uint64 key of every ray (left aligned, ``bits`` significant bits)."""
        length, prev_t, prev_scale = self.end_length(rays, bounds)
        return isa.module("sorters._keysort").make_keys(
            rays, self.coordinates, bounds, self._table, length=length, prev_t=prev_t,
            prev_scale=prev_scale, octant=self.octant)

    def sort(self, rays, packets, bounds):
        packets = check_packets(packets, len(rays))
        bounds = np.asarray(bounds, dtype=np.float32).reshape(2, 3)
        return isa.module("sorters._keysort").sort_keys(
            self.keys(rays, bounds), packets, self._digits, compress=self.compress,
            packet_size=self.packet_size, split_bits=self._split)


def _truncate(levels, bits):
    """The first ``bits`` key bits of a bit split (the last level may be cut short)."""
    out = []
    for level in levels:
        if bits <= 0:
            break
        level = tuple(level)[:bits]
        out.append(level)
        bits -= len(level)
    return out


def scene_diagonal(bounds):
    """Length of the scene box's diagonal (0 for an empty or non-finite box)."""
    box = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    diag = float(np.linalg.norm(box[1] - box[0]))
    return diag if np.isfinite(diag) else 0.0
