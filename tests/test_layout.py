"""The layout facts of include/raysort/types.h, as Python sees them.

The dtypes and row indices are derived from the C header (raysort/_layout.pyx); this
pins the numbers every kernel, the BVH arrays and outside plugins rely on, and checks
that each dtype field sits where the C compiler put it.
"""
import numpy as np
import pytest

from raysort import _layout, bvh, rays, sdk

PINNED = {      # struct: (itemsize, {field: offset})
    "rs_node": (32, {"lo": 0, "hi": 12, "offset": 24, "count": 28, "axis": 30, "flags": 31}),
    "rs_node4": (128, {"lo": 0, "hi": 48, "child": 96, "count": 112, "pad": 120}),
    "rs_tri": (48, {"v0": 0, "e1": 12, "e2": 24, "id": 36, "pad": 40}),
    "rs_node8": (256, {"lo": 0, "hi": 96, "child": 192, "count": 224, "pad": 240}),
    "rs_tri8": (320, {"v0": 0, "e1": 96, "e2": 192, "id": 288}),
    "rs_node16": (512, {"lo": 0, "hi": 192, "child": 384, "count": 448, "pad": 480}),
}
DTYPES = {"rs_node": bvh.NODE_DTYPE, "rs_node4": bvh.NODE4_DTYPE, "rs_tri": bvh.TRI_DTYPE,
          "rs_node8": bvh.NODE8_DTYPE, "rs_tri8": bvh.TRI8_DTYPE, "rs_node16": bvh.NODE16_DTYPE}


@pytest.mark.parametrize("struct", sorted(PINNED))
def test_dtype_offsets_are_the_c_compilers_and_pinned(struct):
    dtype = DTYPES[struct]
    c_size, c_offsets = _layout.c_layout()[struct]
    size, offsets = PINNED[struct]
    assert dtype.itemsize == c_size == size
    assert {name: dtype.fields[name][1] for name in dtype.names} == c_offsets == offsets


def test_dtype_field_types():
    assert bvh.NODE_DTYPE == np.dtype([("lo", "<f4", (3,)), ("hi", "<f4", (3,)), ("offset", "<i4"),
                                       ("count", "<u2"), ("axis", "u1"), ("flags", "u1")])
    assert bvh.NODE4_DTYPE == np.dtype([("lo", "<f4", (3, 4)), ("hi", "<f4", (3, 4)),
                                        ("child", "<i4", (4,)), ("count", "<u2", (4,)),
                                        ("pad", "<i4", (2,))])
    assert bvh.TRI_DTYPE == np.dtype([("v0", "<f4", (3,)), ("e1", "<f4", (3,)),
                                      ("e2", "<f4", (3,)), ("id", "<i4"), ("pad", "<i4", (2,))])


def test_rows():
    assert rays.RAY_ROWS == ("ox", "oy", "oz", "dx", "dy", "dz", "tmin", "tmax")
    assert rays.PACKET_ROWS == ("ox", "oy", "oz", "dx", "dy", "dz", "ix", "iy", "iz", "tmin", "t")
    assert [int(r) for r in sdk.RayRow] == list(range(8))
    assert [int(r) for r in sdk.PacketRow] == list(range(11))


def test_named_views_are_the_rows():
    batch = rays.RayBatch.from_arrays(np.arange(15.0).reshape(5, 3),
                                      np.ones((5, 3)), tmin=0.5, tmax=9.0)
    assert np.shares_memory(batch.tmax, batch.data[sdk.RayRow.tmax])
    packets = rays.gather(batch, np.arange(5, dtype=np.int32), np.array([0, 5], np.int32))
    lanes = packets.index >= 0
    for view, row in ((packets.origins, sdk.PacketRow.ox), (packets.directions, sdk.PacketRow.dx),
                      (packets.inverse_directions, sdk.PacketRow.ix)):
        assert np.shares_memory(view, packets.rows[row]) and view.shape[0] == 3
    assert np.array_equal(packets.origins[:, lanes], batch.origins[:, packets.index[lanes]])
    assert (packets.tmin[lanes] == 0.5).all() and (packets.t[lanes] == 9.0).all()
    assert np.array_equal(packets.active(), lanes)


def test_limits_and_rng_budget():
    assert sdk.MAX_PACKET == 4096
    assert _layout.DEGENERATE_SIN2 == 2.0 ** -40
    dims = _layout.RNG_DIMS
    assert (dims["jitter_x"], dims["jitter_y"]) == (0, 1) and dims["bounce"] == 2
    # the bounces of the deepest path end before the AO block starts
    assert dims["bounce"] + dims["per_bounce"] * dims["max_depth"] <= dims["ao"]
