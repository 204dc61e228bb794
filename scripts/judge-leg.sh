#!/usr/bin/env bash
# Judges a training relay leg on the validation split: the leg's generator against the built-in
# one, the network alone (`--no-keep-input --no-symmetry`) and the whole `complete` pipeline,
# each scored by `mvpcc eval --tau 0.01`. A leg replaces the built-in model only if it is better
# in both (docs/training.md, *The relay*). `--method mirror` is scored too: issue #20 asks the
# pipeline to beat it in every category × protocol cell (the `cell` rows). Never run on the test split: choices
# are made here.
#
#   scripts/judge-leg.sh [--seeds 8,9,10,11] MODEL [COMPLETE_OPTION...]
#
# MODEL: a generator file or a run directory. COMPLETE_OPTIONs go to the leg's completions
# only, to judge it with another threshold or merge distance (`--occupancy 0.02`). --seeds:
# the validation splits, 8 by default; a gain under about 0.005 on seed 8 is checked on 9-11
# too (docs/quality.md). Each split (150 generated objects, two partials each, clouds only)
# is made once into target/valset (seed 8) or target/valsetN; results go to
# target/judge/seedN/<mode>-<who>/. MVPCC names the binary [target/release/mvpcc].
#
# Prints each scoring's table, then one line per split and mode with F1@0.01 / cd_l1 /
# cd_l2_half of the built-in model and the leg and whether the leg is better in all three, and
# the cells where the leg's pipeline has a lower F1 than the mirror.
set -euo pipefail
cd "$(dirname "$0")/.."
seeds=8
if [ "${1:-}" = --seeds ]; then
    seeds=$2
    shift 2
fi
[ $# -ge 1 ] || { echo "usage: scripts/judge-leg.sh [--seeds 8,9,...] MODEL [COMPLETE_OPTION...]" >&2; exit 2; }
model=$1
shift
leg_options=("$@")
mvpcc=${MVPCC:-target/release/mvpcc}

# The split of seed $1: made once, then reused.
split_dir() {
    local dir=target/valset
    [ "$1" = 8 ] || dir=target/valset$1
    [ -e "$dir/manifest.json" ] ||
        "$mvpcc" -q prepare --synth 150 --seed "$1" --split 0 --samples 2 --size 64 \
            --gt-size 256 --clouds test --out "$dir" >&2
    echo "$dir"
}

# Completes the split's partials into OUT with the given `complete` options and writes eval's
# table beside it (OUT.txt).
judge() {
    local val=$1 out=$2
    shift 2
    rm -rf "$out"
    "$mvpcc" -q complete --input-dir "$val/clouds/test" --include 'partial_*.ply' \
        --output-dir "$out" "$@"
    "$mvpcc" eval --data "$val" --pred-dir "$out" --tau 0.01 >"$out.txt"
    echo "== $out"
    cat "$out.txt"
}

# F1@0.01, cd_l1 and cd_l2_half of the `all` row of an eval table.
overall() { awk '$1 == "all" { print $8, $6, $5 }' "$1"; }

# Whether the second table's `all` row is better than the first's in all three figures.
better() {
    paste <(overall "$1") <(overall "$2") |
        awk '{ print ($4 > $1 && $5 < $2 && $6 < $3) ? "better in all three" : "not better" }'
}

# The `cell` rows whose F1 is lower in the second table than in the first, with the difference.
cells_below() {
    paste <(awk '$1 == "cell" { print $2 "/" $4, $11 }' "$1") \
        <(awk '$1 == "cell" { print $11 }' "$2") |
        awk '$3 < $2 { printf " %s %+.4f", $1, $3 - $2 }'
}

summary=()
for seed in ${seeds//,/ }; do
    val=$(split_dir "$seed")
    dir=target/judge/seed$seed
    mkdir -p "$dir"
    judge "$val" "$dir/mirror" --method mirror
    judge "$val" "$dir/alone-built-in" --no-keep-input --no-symmetry
    judge "$val" "$dir/pipeline-built-in"
    judge "$val" "$dir/alone-leg" --model "$model" --no-keep-input --no-symmetry \
        "${leg_options[@]}"
    judge "$val" "$dir/pipeline-leg" --model "$model" "${leg_options[@]}"
    for mode in alone pipeline; do
        summary+=("seed $seed $mode: built-in $(overall "$dir/$mode-built-in.txt"), leg \
$(overall "$dir/$mode-leg.txt"): $(better "$dir/$mode-built-in.txt" "$dir/$mode-leg.txt")")
    done
    below=$(cells_below "$dir/mirror.txt" "$dir/pipeline-leg.txt")
    summary+=("seed $seed cells where the leg's pipeline F1 is below the mirror's:${below:- none}")
done
echo "== summary (F1@0.01 cd_l1 cd_l2_half)"
printf '%s\n' "${summary[@]}"
