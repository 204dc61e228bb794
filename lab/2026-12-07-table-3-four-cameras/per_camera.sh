#!/usr/bin/env bash
# Table 3 by camera: run.sh's completions scored per sample index (1 front, 2 behind, 3 left,
# 4 right) with `eval --gt-dir`, each partial against its object's fine ground truth.
#   per_camera.sh MVPCC OUT   (OUT as given to run.sh)
set -euo pipefail
m=$(realpath "${1:?MVPCC}")
cd "${2:?OUT}"
test=evalset-four/clouds/test
echo "camera,completion,cd_l1,f1_0.01,f1_0.005" > per_camera.csv
for k in 1 2 3 4; do
  camera=$(echo front behind left right | cut -d' ' -f$k)
  rm -rf by-camera/$k
  for who in input paper default; do
    pred=out-$who
    [ $who = input ] && pred=$test
    (cd $test && find . -name "partial_$k.ply") | while read -r f; do
      dir=$(dirname "$f")
      mkdir -p by-camera/$k/gt/$dir by-camera/$k/$who/$dir
      ln -sf "$(realpath $test/$dir/gt.ply)" by-camera/$k/gt/$dir/partial_$k.ply
      ln -sf "$(realpath $pred/$dir/partial_$k.ply)" by-camera/$k/$who/$dir/partial_$k.ply
    done
    $m eval --gt-dir by-camera/$k/gt --pred-dir by-camera/$k/$who --tau 0.01,0.005 > by-camera/$k/$who.txt
    awk -v c=$camera -v w=$who '$1 == "all" || $1 == "mean" { print c "," w "," $(NF-7) "," $(NF-5) "," $(NF-2) }' \
      by-camera/$k/$who.txt >> per_camera.csv
  done
done
cat per_camera.csv
