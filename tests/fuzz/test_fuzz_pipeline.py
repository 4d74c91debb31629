"""Property-based fuzzing of ``Pipeline(...)`` and ``render(...)`` arguments.

Any scene, plugin choice (names, specs, dicts, junk), tile, threads, batch size,
BVH parameters, image size, spp and seed: either a :class:`raysort.RaysortError`
or an image, and then exactly the image of the unsorted scalar pipeline
(``sorter="none"``, ``traversal="single"``) with the same generator, shader,
tile and seed, as the exactness rules promise.  Each example draws most
arguments from their valid ranges and up to two from anywhere, so that both
outcomes are common.
"""
import numpy as np
from hypothesis import event, given
from hypothesis import strategies as st

import raysort

from strategies import FLOATS, JUNK

WORDS = st.sampled_from(["nah", "none", "nah_numpy", "single", "wide", "ranged", "pinhole",
                         "lambert", "threshold", "max_cells", "packet_size", "jitter",
                         "max_depth", "shadow_rays", "russian_roulette", "true", "none", "1",
                         "0.5", "4097", "-1", "", ":", ",", "=", "nan", "1e999", "[1]"])
VALUES = st.one_of(st.integers(-2, 5000), FLOATS, st.booleans(), st.none(), JUNK)


def plugin(kind):
    """(valid, wild) choices of a plugin of ``kind``."""
    names = st.sampled_from(raysort.available(kind))
    specs = st.lists(WORDS, max_size=7).map("".join)
    configs = st.builds(lambda n, p: {"type": n, **p}, names,
                        st.dictionaries(WORDS, VALUES, max_size=3))
    return names, st.one_of(specs, configs, JUNK)


def number(lo, hi):
    """(valid, wild) integers."""
    return st.integers(lo, hi), st.one_of(st.integers(lo - 3, hi * 2), FLOATS, JUNK)


ARGUMENTS = {
    "scene": (st.sampled_from(["plane", "cornell"]),
              st.sampled_from([42, 3.5, b"plane", "nosuchscene", "x.toml", ["plane"]])),
    "generator": plugin("generators"), "sorter": plugin("sorters"),
    "traversal": plugin("traversals"), "shader": plugin("shaders"),
    "tile": number(1, 64), "threads": number(1, 3), "batch_rays": number(1, 3000),
    "check_plugins": (st.booleans(), JUNK),
    "bvh": (st.one_of(st.none(), st.fixed_dictionaries(
                {"max_leaf": st.integers(1, 16)},
                optional={"spatial_splits": st.floats(0, 4), "split_alpha": st.floats(0, 1)})),
            st.one_of(st.dictionaries(st.sampled_from(["max_leaf", "bins", "traversal_cost",
                                                       "spatial_splits", "split_alpha",
                                                       "leaf"]), VALUES, max_size=2), JUNK)),
    "width": number(1, 40), "height": number(1, 40), "spp": number(1, 3),
    "seed": number(0, 2**32 - 1),
}
RENDER = ("width", "height", "spp", "seed")


@given(data=st.data(), wild=st.sets(st.sampled_from(sorted(ARGUMENTS)), max_size=2))
def test_pipeline_and_render(data, wild):
    args = {name: data.draw(pair[name in wild], label=name) for name, pair in ARGUMENTS.items()}
    render = [args.pop(name) for name in RENDER]
    try:
        pipe = raysort.Pipeline(**args)
        result = pipe.render(*render)
    except raysort.RaysortError as exc:
        event(f"error: {type(exc).__name__}")
        return
    event("rendered")
    width, height = render[:2]
    assert result.image.shape == (height, width, 3) and np.isfinite(result.image).all()
    if pipe.traversal.exact:
        ref = raysort.Pipeline(pipe.scene, generator=pipe.generator, shader=pipe.shader,
                               sorter="none", traversal="single", tile=pipe.tile)
        assert result.image.tobytes() == ref.render(*render).image.tobytes()
