#!/usr/bin/env bash
# Judges a CPU leg's generator (MODEL) against the built-in one on the procedural validation
# split (val8) and the third-party validation set (tp30): the network alone and the whole
# pipeline. LEG is the leg's directory, holding the binary as ./mvpcc (legs 22-24); with
# `protocols`, each partial protocol's row (cameras, scanner) too (leg 24).
#   judge.sh LEG MODEL [protocols]
set -euo pipefail
cd "${1:?LEG}"
m=./mvpcc
model=${2:?MODEL}
rows='$1 == "all" { print w, "F1", $8, "cd_l1", $6, "cd_l2_half", $5 }'
[ "${3:-}" = protocols ] && rows='$1 == "all" || $1 == "protocol" {
  row = ($1 == "all") ? "all" : $2; print w, row, "F1", $(NF-2), "cd_l1", $(NF-4), "cd_l2_half", $(NF-5) }'
for data in /work/data/val8 /work/data/tp30; do
  name=$(basename $data)
  for mode in alone pipeline; do
    opts=()
    [ $mode = alone ] && opts=(--no-keep-input --no-symmetry)
    for who in builtin leg; do
      out=judge/$name-$mode-$who
      rm -rf $out
      extra=()
      [ $who = leg ] && extra=(--model "$model")
      $m -q complete --input-dir $data/clouds/test --include 'partial_*.ply' --output-dir $out --jobs 2 "${opts[@]}" "${extra[@]}"
      $m eval --data $data --pred-dir $out --tau 0.01 > $out.txt
      awk -v w="$name $mode $who" "$rows" $out.txt
    done
  done
done
