#!/usr/bin/env bash
# The paper's Tables 7 (erosion) and 8 (statistical outlier filter) with the built-in model
# (XYZRGB; the paper's rows are its XYZ-only model) in `complete --paper` on the procedural
# validation split (seed 8, 300 partials), scored against the fine ground truth at τ = 0.01.
# Usage: run.sh MVPCC DATA OUT [COMPLETE OPTIONS...]  (e.g. --model XYZ.safetensors: the
# options go to every row's `complete`)
set -euo pipefail
m=${1:?MVPCC} data=${2:?DATA} out=${3:?OUT}
shift 3
model=("$@")
mkdir -p "$out"
row() { # name, then complete's options
  local name=$1; shift
  rm -rf "$out/$name"
  "$m" -q complete --paper --input-dir "$data/clouds/test" --include 'partial_*.ply' \
    --output-dir "$out/$name" --jobs 2 "${model[@]}" "$@"
  "$m" eval --data "$data" --pred-dir "$out/$name" --tau 0.01 > "$out/$name.txt"
  awk -v w="$name" '$1 == "all" { print w "," $6 "," $5 "," $8 }' "$out/$name.txt"
}
echo "row,cd_l1,cd_l2_half,f1"
"$m" eval --data "$data" --pred-dir "$data/clouds/test" --tau 0.01 > "$out/input.txt"
awk '$1 == "all" { print "input," $6 "," $5 "," $8 }' "$out/input.txt"
row erode-0 --erode 0
row erode-1 --erode 1
row erode-3 --erode 3
row erode-5 --erode 5
row sor-none --sor-k 0
row sor-8 --sor-std 8
row sor-2 --sor-std 2
