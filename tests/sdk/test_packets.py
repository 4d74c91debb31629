"""``raysort.sdk.packets``: which large-packet boundaries a kernel may take as they are."""
import numpy as np
import pytest

from raysort.sdk import plain_packets


def test_the_pipelines_packets_are_plain():
    """Contiguous int32 ending at n, as the pipeline passes them (the kernel then checks
    the start and the order: a plain array need not start at 0)."""
    assert plain_packets(np.array([0, 64, 100], np.int32), 100)
    assert plain_packets(np.array([5, 3, 100], np.int32), 100)
    assert plain_packets(np.array([0], np.int32), 0)


@pytest.mark.parametrize("packets", [
    [0, 64, 100],                                           # a list
    np.array([0, 64, 100], np.int64),                       # another dtype
    np.array([0, 64, 99], np.int32),                        # not ending at n
    np.array([0, 0, 64, 64, 100, 100], np.int32)[::2],      # not contiguous
    np.array([[0, 100]], np.int32),                         # not one-dimensional
    np.array([], np.int32),                                 # empty
])
def test_anything_else_is_not(packets):
    """What is not the pipeline's kind goes through check_packets first."""
    assert not plain_packets(packets, 100)
