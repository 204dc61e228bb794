#!/usr/bin/env bash
# Tables 1-2 (synthetic test set, fine and coarse ground truth, per category) with the built-in
# model: 150 generated test objects (seed 7) x 2 partials of the default protocols, the input
# alone, `complete --paper` and the default `complete`, scored at tau 0.01.
#   run.sh MVPCC OUT
set -euo pipefail
m=$(realpath "${1:?MVPCC}")
out=${2:?OUT}
mkdir -p "$out"
cd "$out"
[ -f evalset/manifest.json ] || $m -q prepare --synth 150 --seed 7 --split 0 --samples 2 \
  --size 64 --gt-size 256 --out evalset
for mode in paper default; do
  opts=()
  [ $mode = paper ] && opts=(--paper)
  [ -d out-$mode ] || $m -q complete --input-dir evalset/clouds/test --include 'partial_*.ply' \
    --output-dir out-$mode "${opts[@]}"
done
echo "ground_truth,completion,row,cd_l1,f1_0.01" > results.csv
for gt in fine coarse; do
  for who in input paper default; do
    pred=out-$who
    [ $who = input ] && pred=evalset/clouds/test
    $m eval --data evalset --pred-dir $pred --tau 0.01 --ground-truth $gt > eval-$gt-$who.txt
    awk -v g=$gt -v w=$who '$1 == "all" || $1 == "category" {
      row = ($1 == "all") ? "all" : $2; print g "," w "," row "," $(NF-4) "," $(NF-2) }' \
      eval-$gt-$who.txt >> results.csv
  done
done
cat results.csv
