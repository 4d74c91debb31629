#!/usr/bin/env bash
# Every number in BENCHMARKS.md comes from one of these commands (run from the
# repository root, raysort installed with both yardsticks and the bench extra):
#
#   pip install ".[bench]" ./plugins/raysort-embree ./plugins/raysort-mitsuba
#   bash docs/benchmarks.sh            # under 20 minutes on a shared 2-core VM
#
# Results land in docs/bench/ (JSON with every round, charts, text tables).
set -euo pipefail
cd "$(dirname "$0")/.."
out=docs/bench
mkdir -p "$out"
scenes="sibenik sponza forest"
paper='ranged (8x8),partition (32x32),ranged + nah,partition + nah'
run() {     # run NAME ARGS...: the table to NAME.txt (and the terminal), JSON to NAME.json
    local name=$1; shift
    echo "== raysort bench $*" | tee "$out/$name.txt"
    raysort bench "$@" -q --json "$out/$name.json" | tee -a "$out/$name.txt"
}
uptime | tee "$out/load.txt"

# 1. the paper's experiment (Fig. 2, Table I): every configuration, default BVH;
#    besides the speedups over ranged (8x8), the per-round speedup of ranged + nah
#    over partition (32x32) (the paper: 15 % on average; [render] compare)
run frame $scenes --repeat 3 --chart "$out/frame.png"
# 2. the paper's configurations with Manta-like leaves (about ten triangle tests
#    per box test), more rounds
run manta $scenes --repeat 5 --bvh manta --only "$paper"
# 3. traversal alone: camera and first-bounce diffuse rays, 8x8 / 32x32 / nah
#    packets, every installed traversal (yardsticks included), one thread
run kernels sibenik --kernels --workloads primary,diffuse --repeat 5
# 4. the matrix of sorters x traversals, first and second bounce and shadow rays
run matrix sibenik --kernels --sorters all --traversals all \
    --workloads diffuse,diffuse:depth=2,shadow --repeat 3 --chart "$out/matrix.png"
run matrix-sponza sponza --kernels --sorters all --traversals all \
    --workloads diffuse,diffuse:depth=2,shadow --repeat 3 --chart "$out/matrix-sponza.png"
# the forest has no point light: no shadow rays
run matrix-forest forest --kernels --sorters all --traversals all \
    --workloads diffuse,diffuse:depth=2 --repeat 3 --chart "$out/matrix-forest.png"
# 5. peak memory of a 1024x1024 render on two threads, 4 and 1 samples per pixel
python docs/peak_memory.py raysort render sibenik --size 1024x1024 --spp 4 --threads 2 \
    --sorter nah --traversal partition -q | tee "$out/memory.txt"
python docs/peak_memory.py raysort render sibenik --size 1024x1024 --spp 1 --threads 2 \
    --sorter nah --traversal partition -q | tee -a "$out/memory.txt"
uptime | tee -a "$out/load.txt"
# the Markdown tables of BENCHMARKS.md, from the JSON above
python docs/bench_markdown.py "$out"/frame.json "$out"/manta.json "$out"/kernels.json \
    "$out"/matrix.json "$out"/matrix-sponza.json "$out"/matrix-forest.json > "$out/tables.md"
