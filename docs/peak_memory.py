"""Peak memory (resident set) of a command, e.g. a render: the figure BENCHMARKS.md quotes.

    python docs/peak_memory.py raysort render sibenik --size 1024x1024 --spp 4 --threads 2

runs the command in a child process and prints its peak resident set size
(``ru_maxrss`` of the finished child, Linux: KiB) and its wall time.
"""
import resource
import subprocess
import sys
import tempfile
import time


def main(argv):
    if not argv:
        print(__doc__.strip().splitlines()[0], file=sys.stderr)
        return 2
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:      # the render's files land here
        status = subprocess.run(argv, cwd=tmp).returncode
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"peak resident set: {peak:.0f} MB, {seconds:.1f} s wall, exit status {status}: "
          f"{' '.join(argv)}")
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
