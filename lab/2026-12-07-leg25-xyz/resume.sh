#!/usr/bin/env bash
# Leg 25 resumed from its latest checkpoint, one thread, niced.
set -euo pipefail
cd /work/leg25
RAYON_NUM_THREADS=1 nice -n 19 ./mvpcc train --data data --out run --resume
