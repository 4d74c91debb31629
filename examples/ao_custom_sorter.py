"""Compose a pipeline with your own sorter and compare it with ``nah`` on ambient-occlusion rays.

    python examples/ao_custom_sorter.py                       # Sibenik, 256x256, 8 AO rays per hit
    python examples/ao_custom_sorter.py sponza --size 128 --rounds 9

The sorter is a plain NumPy class defined below and registered in this process only (no
packaging).  The AO rays are the ones a render with the ``ao`` shader traces, in the same
large packets (``raysort.workloads``).  Each sorter is timed on sort + gather + traverse +
scatter with the ``ranged`` packet traversal, rounds interleaved so that a busy machine
slows every configuration alike; the table shows medians, the median of the per-round
speed-ups over ``none`` and the traversal's work per ray (the paper's Table I counters).
"""
import argparse
import statistics
import time

import numpy as np

import raysort
from raysort.sdk import MAX_PACKET, Sorter, fixed_packets, integer
from raysort.workloads import workload


class OriginGridSorter(Sorter):
    """Rays of each large packet grouped by a coarse grid cell of their origin, then by
    direction octant: a simple stand-in for ``nah``'s buckets (octant x major axis, with
    an adaptive origin grid per bucket)."""

    def __init__(self, *, cells=4, packet_size=64):
        self.cells = integer("cells", cells, 1, 64)
        self.packet_size = integer("packet_size", packet_size, 1, MAX_PACKET)

    def sort(self, rays, packets, bounds):
        lo, hi = bounds[0][:, None], bounds[1][:, None]
        extent = np.maximum(hi - lo, 1e-30)
        cell = ((rays.origins - lo) / extent * self.cells).astype(np.int64)
        cell = np.clip(cell, 0, self.cells - 1)
        grid = (cell[0] * self.cells + cell[1]) * self.cells + cell[2]
        d = rays.directions
        octant = (d[0] < 0) * 1 + (d[1] < 0) * 2 + (d[2] < 0) * 4
        packet = np.repeat(np.arange(len(packets) - 1), np.diff(packets))
        # sub-packets never cross a large packet: sort by packet first
        order = np.lexsort((octant, grid, packet)).astype(np.int32)
        return order, fixed_packets(packets, self.packet_size)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scene", nargs="?", default="sibenik")
    parser.add_argument("--size", type=int, default=256, help="image edge in pixels (256)")
    parser.add_argument("--samples", type=int, default=8, help="AO rays per primary hit (8)")
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds (5)")
    args = parser.parse_args(argv)

    raysort.register("sorters", "origin_grid", OriginGridSorter, replace=True)
    scene = raysort.load_scene(args.scene)
    work = workload(scene, f"ao:samples={args.samples}", width=args.size, height=args.size)
    print(f"{work.label}: {len(work):,} AO rays in {len(work.packets) - 1} large packets")

    sorters = {"none": "none", "nah": "nah", "origin grid": "origin_grid:cells=4"}
    pipes = {label: raysort.Pipeline(scene, sorter=spec, traversal="ranged")
             for label, spec in sorters.items()}
    seconds = {label: [] for label in pipes}
    answers, counters = {}, {}
    for _ in range(args.rounds):                  # interleaved rounds
        for label, pipe in pipes.items():
            start = time.perf_counter()
            occluded, counters[label] = pipe.trace(work.rays, work.packets,
                                                   any_hit=work.any_hit)
            seconds[label].append(time.perf_counter() - start)
            answers[label] = occluded

    # a sorter only reorders: every configuration must answer the same for every ray
    for label, occluded in answers.items():
        assert np.array_equal(occluded, answers["none"]), f"{label} changed the answers"
    print(f"unoccluded: {1 - answers['none'].mean():.3f} of the AO rays")
    print(f"{'sorter':<12} {'median s':>9} {'Mrays/s':>8} {'vs none':>8} "
          f"{'N_IA':>6} {'N_B':>6} {'N_T':>6}   (per ray, ranged traversal)")
    for label, times in seconds.items():
        med, per = statistics.median(times), counters[label].per_ray()
        speedup = statistics.median(b / t for b, t in zip(seconds["none"], times))
        print(f"{label:<12} {med:9.4f} {len(work) / med / 1e6:8.2f} {speedup:7.2f}x "
              f"{per['ia']:6.2f} {per['box1'] + per['box4']:6.2f} "
              f"{per['tri1'] + per['tri4']:6.2f}")


if __name__ == "__main__":
    main()
