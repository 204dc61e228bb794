#!/usr/bin/env bash
# Table 3 (the paper's real-MLS protocol) on generated objects with the four fixed cameras:
# 150 test objects (seed 7, as Tables 1-2) x 4 partials (front, behind, left, right), the input
# alone, `complete --paper` and the default `complete` with the built-in model, scored on the
# fine ground truth at tau 0.01 and 0.005.
#   run.sh MVPCC OUT
set -euo pipefail
m=$(realpath "${1:?MVPCC}")
out=${2:?OUT}
mkdir -p "$out"
cd "$out"
[ -f evalset-four/manifest.json ] || $m -q prepare --synth 150 --seed 7 --split 0 --samples 4 \
  --size 64 --gt-size 256 --partial single-camera --clouds test --out evalset-four
for mode in paper default; do
  opts=()
  [ $mode = paper ] && opts=(--paper)
  [ -d out-$mode ] || $m -q complete --input-dir evalset-four/clouds/test --include 'partial_*.ply' \
    --output-dir out-$mode "${opts[@]}"
done
echo "completion,cd_l1,f1_0.01,f1_0.005" > results.csv
for who in input paper default; do
  pred=out-$who
  [ $who = input ] && pred=evalset-four/clouds/test
  $m eval --data evalset-four --pred-dir $pred --tau 0.01,0.005 > eval-$who.txt
  awk -v w=$who '$1 == "all" { print w "," $6 "," $8 "," $11 }' eval-$who.txt >> results.csv
done
cat results.csv
