#!/usr/bin/env bash
# Fuzzes every target for SECONDS each (default 600), JOBS at a time (default 2), with
# libFuzzer's limits at 1 GiB of memory (and as the largest single allocation) and 10 s per
# input. Seeds come from make-seeds.sh; findings land in artifacts/<target>/; each run's
# statistics in logs/<target>.log (`stat::number_of_executed_units` is the execution count).
set -euo pipefail
cd "$(dirname "$0")"
seconds=${1:-600}
jobs=${2:-2}
[ -d corpus ] || { echo "run ./make-seeds.sh first" >&2; exit 1; }
cargo +nightly fuzz build -O
mkdir -p logs
cargo +nightly fuzz list | xargs -P "$jobs" -I{} sh -c "
  cargo +nightly fuzz run -O {} corpus/{} -- -max_total_time=$seconds -rss_limit_mb=1024 \
    -malloc_limit_mb=1024 -timeout=10 -print_final_stats=1 > logs/{}.log 2>&1
  echo \"{}: exit \$?, \$(grep -h 'number_of_executed_units' logs/{}.log | tail -1)\"
" || true
