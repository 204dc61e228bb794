#!/usr/bin/env bash
# Leg 22: the built-in model on procedural vehicles plus the third-party training meshes
# (scripts/thirdparty/train-sources.tsv, each mesh three times under other names).
set -euo pipefail
cd /work/leg22
m=./mvpcc
[ -d meshes ] || {
  nice -n 19 $m synth --count 300 --seed 2026120722 --out meshes
  for k in 1 2 3; do for f in /tmp/trainmeshes/*/*.glb; do
    c=$(basename "$(dirname "$f")"); cp "$f" "meshes/$c/tp${k}_$(basename "$f")"; done; done
}
[ -f data/manifest.json ] || nice -n 19 $m prepare --meshes meshes --out data --forward auto \
  --size 128 --gt-size 256 --samples 4 --seed 2026120722
nice -n 19 $m train --data data --out run --init assets --batch 4 --lr 2e-5 \
  --loss-adversarial 0 --loss-perceptual 0 --loss-style 0 --loss-depth 100 \
  --val-every 250 --val-samples 32 --patience 8 --seed 22 --checkpoint-every 100
