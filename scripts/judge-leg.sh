#!/usr/bin/env bash
# Judges a training relay leg on the validation split: the leg's generator against the built-in
# one, the network alone (`--no-keep-input --no-symmetry`) and the whole `complete` pipeline,
# each scored by `mvpcc eval --tau 0.01`. A leg replaces the built-in model only if it is better
# in both (docs/training.md). `--method mirror` is scored too: issue #20 asks the pipeline to beat
# it in every category × protocol cell (the `cell` rows). Never run on the test split: choices
# are made here.
#
#   scripts/judge-leg.sh MODEL [MVPCC]     MODEL: a generator file or a run directory
#
# The validation split (150 generated objects, seed 8, two partials each, clouds only) is made
# once into target/valset; results go to target/judge/<mode>-<model>/ and a summary to stdout.
set -euo pipefail
cd "$(dirname "$0")/.."
model=$1
mvpcc=${2:-target/release/mvpcc}
val=target/valset
[ -e "$val/manifest.json" ] ||
    "$mvpcc" -q prepare --synth 150 --seed 8 --split 0 --samples 2 --size 64 --gt-size 256 \
        --clouds test --out "$val"
# Completes the validation partials into target/judge/NAME with the given `complete` options and
# scores them.
judge() {
    local name=$1 out=target/judge/$1
    shift
    rm -rf "$out"
    "$mvpcc" -q complete --input-dir "$val/clouds/test" --include 'partial_*.ply' \
        --output-dir "$out" "$@"
    echo "== $name"
    "$mvpcc" eval --data "$val" --pred-dir "$out" --tau 0.01
}
judge mirror --method mirror
for who in built-in leg; do
    model_args=()
    [ $who = built-in ] || model_args=(--model "$model")
    judge "alone-$who" "${model_args[@]}" --no-keep-input --no-symmetry
    judge "pipeline-$who" "${model_args[@]}"
done
