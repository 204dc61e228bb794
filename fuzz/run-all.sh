#!/usr/bin/env bash
# Fuzzes the named targets (default: all) until each has run 10^6 inputs or SECONDS seconds
# (default 600), JOBS at a time (default 2), with libFuzzer's limits at 1 GiB of memory (and as
# the largest single allocation) and 10 s per input. Seeds come from make-seeds.sh; findings
# land in artifacts/<target>/; each run's statistics in logs/<target>.log
# (`stat::number_of_executed_units` is the execution count).
#
#   fuzz/run-all.sh [SECONDS [JOBS [TARGET...]]]
set -euo pipefail
cd "$(dirname "$0")"
seconds=${1:-600}
jobs=${2:-2}
shift $(( $# < 2 ? $# : 2 ))
[ -d corpus ] || { echo "run ./make-seeds.sh first" >&2; exit 1; }
cargo +nightly fuzz build -O
mkdir -p logs
targets=("$@")
[ ${#targets[@]} -gt 0 ] || mapfile -t targets < <(cargo +nightly fuzz list)
printf '%s\n' "${targets[@]}" | xargs -P "$jobs" -I{} sh -c "
  cargo +nightly fuzz run -O {} corpus/{} -- -runs=1000000 -max_total_time=$seconds \
    -rss_limit_mb=1024 -malloc_limit_mb=1024 -timeout=10 -print_final_stats=1 \
    > logs/{}.log 2>&1
  echo \"{}: exit \$?, \$(grep -h 'number_of_executed_units' logs/{}.log | tail -1), \$(grep -h 'total_time\|Done' logs/{}.log | tail -1)\"
" || true
