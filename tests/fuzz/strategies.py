"""Hypothesis strategies shared by the fuzz tests: awkward numbers and arrays."""
import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

#: every kind of float a user can pass: NaN, +-inf, zero, subnormal, huge (beyond float32)
FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-45, -1e-45, 1e-40, 3.4e38, -3.4e38, 1e39, 1e300, 1.0, -1.0]),
    st.floats(-10, 10),
)

#: values that are not numbers at all
JUNK = st.sampled_from([None, "1", "abc", b"x", object(), [1, [2]], {"a": 1}, 1 + 2j, True])


def float_arrays(shape):
    """Float64 arrays of ``shape`` with any float in them."""
    return hnp.arrays(np.float64, shape, elements=FLOATS)


def ray_arrays(max_n=40):
    """(origins, directions): usually two (n, 3) arrays, sometimes mismatched or junk."""
    n = st.integers(0, max_n)
    good = n.flatmap(lambda k: st.tuples(float_arrays((k, 3)), float_arrays((k, 3))))
    shapes = hnp.array_shapes(min_dims=0, max_dims=3, max_side=5)
    odd = st.tuples(shapes.flatmap(float_arrays), shapes.flatmap(float_arrays))
    return st.one_of(good, good, good, odd, st.tuples(JUNK, JUNK))


def interval(n):
    """A tmin or tmax: a scalar, an array of n (or of another length), or junk."""
    return st.one_of(FLOATS, float_arrays((n,)), float_arrays((n + 1,)), JUNK)
