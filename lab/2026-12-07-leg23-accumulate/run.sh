#!/usr/bin/env bash
# Leg 23: leg 22's data (300 procedural + 17 third-party meshes ×3) with 16 objects per
# optimizer step (4 × 4 accumulated) at 1e-5: tests whether the CPU legs' losses came from
# batch-4 gradient noise.
set -euo pipefail
cd /work/leg23
nice -n 19 ./mvpcc train --data data --out run --init assets --batch 4 --accumulate 4 --lr 1e-5 \
  --loss-adversarial 0 --loss-perceptual 0 --loss-style 0 --loss-depth 100 \
  --val-every 1000 --seen-samples 0 --seed 23 --checkpoint-every 20 --keep 10
