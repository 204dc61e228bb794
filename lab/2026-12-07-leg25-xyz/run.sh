#!/usr/bin/env bash
# Leg 25: the built-in model narrowed to geometry only (`--init assets --channels xyz`: the
# colour planes' weights dropped), on leg 22's data (300 procedural objects and the 17
# third-party training meshes ×3), the reconstruction and depth terms, niced on one thread.
set -euo pipefail
cd /work/leg25
RAYON_NUM_THREADS=1 nice -n 19 ./mvpcc train --data data --out run --init assets --channels xyz \
  --batch 4 --lr 2e-5 --warmup-steps 20 --loss-adversarial 0 --loss-perceptual 0 --loss-style 0 \
  --loss-depth 100 --val-every 1000 --seen-samples 0 --seed 25 --checkpoint-every 20 --keep 10
