#!/usr/bin/env bash
# Leg 24: leg 22's meshes (300 procedural + 17 third-party ×3) scanned as single-camera partials
# only: tests whether the network fills what one camera misses better once it trains on that.
set -euo pipefail
cd /work/leg24
m=./mvpcc
[ -f data/manifest.json ] || nice -n 19 $m prepare --meshes meshes --out data --forward auto \
  --size 128 --gt-size 256 --samples 4 --partial single-camera --seed 2026120724
nice -n 19 $m train --data data --out run --init assets --batch 4 --lr 1e-5 \
  --loss-adversarial 0 --loss-perceptual 0 --loss-style 0 --loss-depth 100 \
  --val-every 1000 --seen-samples 0 --seed 24 --checkpoint-every 20 --keep 10
