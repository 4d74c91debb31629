"""Hostile plugins: each breaks its kind's contract in one way (or tries to).

Every class wraps a well-behaved built-in (``pinhole``, ``none``, ``single``,
``lambert``) and corrupts its result, so that everything but the one fault is
valid.  :data:`CASES` maps a case name to ``(kind, class, expected)``:
``"contract"`` means the pipeline must raise :class:`raysort.PluginContractError`
naming the plugin; ``"ok"`` means the input is odd but legal and the render must
simply work.  ``run_cases.py`` registers them one at a time and runs each.
"""
import numpy as np

import raysort
from raysort.paths import Bounce
from raysort.rays import RayBatch

CASES = {}


def case(kind, expected="contract"):
    def register(cls):
        CASES[cls.__name__] = (kind, cls, expected)
        return cls
    return register


# ---------------------------------------------------------------------------
# generators: wrap pinhole
# ---------------------------------------------------------------------------

class _Generator(raysort.Generator):
    def generate(self, camera, pixels, samples, width, height, spp, seed):
        rays = raysort.create("generators", "pinhole").generate(
            camera, pixels, samples, width, height, spp, seed)
        return self.corrupt(rays)


@case("generators")
class GenReturnsNone(_Generator):
    def corrupt(self, rays):
        return None


@case("generators")
class GenReturnsArray(_Generator):
    def corrupt(self, rays):
        return rays.data


@case("generators")
class GenOneRayShort(_Generator):
    def corrupt(self, rays):
        return rays.take(np.arange(len(rays) - 1))


@case("generators")
class GenOneRayExtra(_Generator):
    def corrupt(self, rays):
        return rays.take(np.append(np.arange(len(rays)), 0))


@case("generators")
class GenNaNOrigin(_Generator):
    def corrupt(self, rays):
        rays.origins[0, 5] = np.nan
        return rays


@case("generators")
class GenInfDirection(_Generator):
    def corrupt(self, rays):
        rays.directions[2, -1] = -np.inf
        return rays


@case("generators")
class GenNegativeTmin(_Generator):
    def corrupt(self, rays):
        rays.tmin[3] = -1.0
        return rays


@case("generators", "ok")
class GenNaNMarkedInvalid(_Generator):
    """NaN rays marked invalid (tmin >= tmax) are legal: they just never hit."""

    def corrupt(self, rays):
        rays.origins[:, ::2] = np.nan
        rays.tmin[::2], rays.tmax[::2] = np.inf, -np.inf
        return rays


@case("generators", "ok")
class GenHugeValues(_Generator):
    """Huge but finite float32 origins and directions are legal rays."""

    def corrupt(self, rays):
        rays.origins[:] = 3e38
        rays.directions[:] = -3e38
        return rays


@case("generators")
class GenFloat64Data(_Generator):
    def corrupt(self, rays):
        rays.data = rays.data.astype(np.float64)
        return rays


@case("generators")
class GenSevenRows(_Generator):
    def corrupt(self, rays):
        rays.data = np.ascontiguousarray(rays.data[:7])
        return rays


@case("generators")
class GenCountBeyondCapacity(_Generator):
    def corrupt(self, rays):
        rays.n = 10**6
        return rays


@case("generators")
class GenRaises(_Generator):
    def corrupt(self, rays):
        raise RuntimeError("generator exploded")


# ---------------------------------------------------------------------------
# sorters: wrap none
# ---------------------------------------------------------------------------

class _Sorter(raysort.Sorter):
    def sort(self, rays, packets, bounds):
        order, offsets = raysort.create("sorters", "none").sort(rays, packets, bounds)
        return self.corrupt(order.astype(np.int64), offsets.astype(np.int64), packets)


@case("sorters")
class SortReturnsNone(_Sorter):
    def corrupt(self, order, offsets, packets):
        return None


@case("sorters")
class SortReturnsList(_Sorter):
    def corrupt(self, order, offsets, packets):
        return [order, offsets]


@case("sorters")
class SortReturnsTriple(_Sorter):
    def corrupt(self, order, offsets, packets):
        return order, offsets, offsets


@case("sorters")
class SortFloatOrder(_Sorter):
    def corrupt(self, order, offsets, packets):
        return order.astype(np.float64), offsets


@case("sorters")
class SortStringOrder(_Sorter):
    def corrupt(self, order, offsets, packets):
        return order.astype(str), offsets


@case("sorters")
class SortShortOrder(_Sorter):
    def corrupt(self, order, offsets, packets):
        return order[:-1], offsets


@case("sorters")
class SortIndexTooLarge(_Sorter):
    def corrupt(self, order, offsets, packets):
        order[7] = len(order)
        return order, offsets


@case("sorters")
class SortIndexNegative(_Sorter):
    def corrupt(self, order, offsets, packets):
        order[0] = -1
        return order, offsets


@case("sorters")
class SortIndexHuge(_Sorter):
    def corrupt(self, order, offsets, packets):
        order[3] = 2**40 + 3          # 3 again after an int32 wrap
        return order, offsets


@case("sorters")
class SortRepeatedIndex(_Sorter):
    def corrupt(self, order, offsets, packets):
        order[1] = order[0]
        return order, offsets


@case("sorters")
class SortOffsetsDescend(_Sorter):
    def corrupt(self, order, offsets, packets):
        offsets[1], offsets[2] = offsets[2], offsets[1]
        return order, offsets


@case("sorters")
class SortOffsetsEmptyPacket(_Sorter):
    def corrupt(self, order, offsets, packets):
        return order, np.insert(offsets, 1, offsets[1])


@case("sorters")
class SortOffsetsPastEnd(_Sorter):
    def corrupt(self, order, offsets, packets):
        offsets[1] = 10**9
        return order, offsets


@case("sorters")
class SortOffsetsHuge(_Sorter):
    def corrupt(self, order, offsets, packets):
        offsets[1] = 2**32 + offsets[1]     # the same value after an int32 wrap
        return order, offsets


@case("sorters")
class SortOffsetsNotFromZero(_Sorter):
    def corrupt(self, order, offsets, packets):
        return order, offsets[1:]


@case("sorters")
class SortSubPacketTooBig(_Sorter):
    def corrupt(self, order, offsets, packets):
        n = len(order)
        return order, np.array([0, n])       # render: 256 rays in one packet, but across
                                             # large packets; trace: one 5000-ray packet


@case("sorters")
class SortMixesLargePackets(_Sorter):
    def corrupt(self, order, offsets, packets):
        order[[0, -1]] = order[[-1, 0]]
        return order, offsets


@case("sorters", "ok")
class SortMutatesPackets(_Sorter):
    """Scribbling over its ``packets`` argument must not hurt the pipeline."""

    def corrupt(self, order, offsets, packets):
        packets[:] = 7
        return order, offsets


@case("sorters")
class SortRaises(_Sorter):
    def corrupt(self, order, offsets, packets):
        raise ZeroDivisionError("sorter exploded")


# ---------------------------------------------------------------------------
# traversals: wrap single
# ---------------------------------------------------------------------------

class _Traversal(raysort.Traversal):
    def intersect(self, bvh, packets, any_hit=False):
        counters = raysort.create("traversals", "single").intersect(bvh, packets, any_hit)
        return self.corrupt(packets, counters, any_hit)

    @staticmethod
    def hit_lanes(packets):
        return np.flatnonzero(packets.prim >= 0)


@case("traversals")
class TravReturnsNone(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        return None


@case("traversals")
class TravNegativeCounter(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        counters.box1 = -5
        return counters


@case("traversals")
class TravFloatCounter(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        counters.tri1 = float("nan")
        return counters


@case("traversals", "ok")
class TravHugeCounter(_Traversal):
    """Counters are Python ints: a huge count is odd but harmless."""

    def corrupt(self, packets, counters, any_hit):
        counters.tri1 = 10**30
        return counters


@case("traversals")
class TravPrimTooLarge(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.prim[self.hit_lanes(packets)] = 50_000_000
        return counters


@case("traversals")
class TravPrimNegative(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.prim[self.hit_lanes(packets)] = -7
        return counters


@case("traversals")
class TravNaNDistance(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.rows[10, self.hit_lanes(packets)] = np.nan
        return counters


@case("traversals")
class TravDistanceBeyondTmax(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.rows[10, self.hit_lanes(packets)] = np.inf
        return counters


@case("traversals")
class TravDistanceBehindOrigin(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.rows[10, self.hit_lanes(packets)] = -1.0
        return counters


@case("traversals")
class TravNaNBarycentrics(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.u[self.hit_lanes(packets)] = np.nan
        return counters


@case("traversals")
class TravHitsEveryLane(_Traversal):
    """Claims hits in padding lanes and on inactive rays too."""

    def corrupt(self, packets, counters, any_hit):
        packets.prim[:] = 0
        packets.rows[10] = 1.0
        return counters


@case("traversals")
class TravChangesIndex(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.index[packets.index >= 0] = 10**6
        return counters


@case("traversals")
class TravReplacesPrim(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.prim = np.zeros(3, np.int32)
        return counters


@case("traversals")
class TravReshapesPrim(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.prim.shape = (2, -1)
        return counters


@case("traversals")
class TravRetypesU(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        packets.u.dtype = np.int32
        return counters


@case("traversals")
class TravRaises(_Traversal):
    def corrupt(self, packets, counters, any_hit):
        raise MemoryError("traversal exploded")


# ---------------------------------------------------------------------------
# shaders: wrap lambert
# ---------------------------------------------------------------------------

class _Shader(raysort.Shader):
    def prepare(self, scene):
        self.inner = raysort.create("shaders", "lambert")
        self.inner.prepare(scene)

    def shade(self, scene, rays, hits, paths, depth, seed, radiance):
        bounce = self.inner.shade(scene, rays, hits, paths, depth, seed, radiance)
        return self.corrupt(bounce, radiance)


class _ShadowShader(_Shader):
    """Corrupts the shadow rays, when a bounce has some."""

    def shade(self, scene, rays, hits, paths, depth, seed, radiance):
        bounce = self.inner.shade(scene, rays, hits, paths, depth, seed, radiance)
        return bounce if bounce.shadow is None else self.corrupt(bounce, radiance)


@case("shaders")
class ShadeReturnsNone(_Shader):
    def corrupt(self, bounce, radiance):
        return None


@case("shaders")
class ShadeRaysNotABatch(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.rays = bounce.rays.data
        return bounce


@case("shaders")
class ShadeParentsDescend(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.parent = bounce.parent[::-1].copy()
        return bounce


@case("shaders")
class ShadeParentTooLarge(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.parent[-1] = 10**9
        return bounce


@case("shaders")
class ShadeParentNegative(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.parent[0] = -1
        return bounce


@case("shaders")
class ShadeParentShort(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.parent = bounce.parent[:-1]
        return bounce


@case("shaders")
class ShadeParentFloat(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.parent = bounce.parent.astype(np.float32)
        return bounce


@case("shaders")
class ShadeThroughputShape(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.throughput = bounce.throughput[:, :-1]
        return bounce


@case("shaders")
class ShadeThroughputNaN(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.throughput[1, 0] = np.nan
        return bounce


@case("shaders")
class ShadeNaNRay(_Shader):
    def corrupt(self, bounce, radiance):
        bounce.rays.directions[0, 0] = np.nan
        return bounce


@case("shaders")
class ShadeRadianceNaN(_Shader):
    def corrupt(self, bounce, radiance):
        radiance[0, 1] = np.nan
        return bounce


@case("shaders")
class ShadeRadianceInf(_Shader):
    def corrupt(self, bounce, radiance):
        radiance[-1, 0] = np.inf
        return bounce


@case("shaders")
class ShadeShadowSlotTooLarge(_ShadowShader):
    def corrupt(self, bounce, radiance):
        bounce.shadow.slot[0] = 10**6
        return bounce


@case("shaders")
class ShadeShadowSlotNegative(_ShadowShader):
    def corrupt(self, bounce, radiance):
        bounce.shadow.slot[0] = -1
        return bounce


@case("shaders")
class ShadeShadowParentsDescend(_ShadowShader):
    def corrupt(self, bounce, radiance):
        bounce.shadow.parent = bounce.shadow.parent[::-1].copy()
        return bounce


@case("shaders")
class ShadeShadowContributionShape(_ShadowShader):
    def corrupt(self, bounce, radiance):
        bounce.shadow.contribution = bounce.shadow.contribution.T
        return bounce


@case("shaders")
class ShadeShadowNotShadowRays(_ShadowShader):
    def corrupt(self, bounce, radiance):
        bounce.shadow = (bounce.shadow.rays, bounce.shadow.parent)
        return bounce


@case("shaders")
class ShadeEndlessPaths(_Shader):
    """Never ends a path: every ray bounces again, forever."""

    def corrupt(self, bounce, radiance):
        rays = RayBatch.from_arrays([[0.0, 1.0, 0.0]], [[0.0, 1.0, 0.0]])
        return Bounce(rays, np.zeros(1, np.int32), np.ones((3, 1), np.float32))


@case("shaders")
class ShadeRaises(_Shader):
    def corrupt(self, bounce, radiance):
        raise KeyError("shader exploded")


@case("shaders")
class ShadePrepareRaises(_Shader):
    def prepare(self, scene):
        raise ValueError("prepare exploded")

    def corrupt(self, bounce, radiance):
        return bounce


@case("shaders", "ok")
class ShadeNoShadow(_Shader):
    """Dropping the shadow rays is legal (a different image, not a broken one)."""

    def corrupt(self, bounce, radiance):
        return Bounce(bounce.rays, bounce.parent, bounce.throughput, None)
