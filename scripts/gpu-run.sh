#!/usr/bin/env bash
# One GPU session's work in one command: profiles of mvpcc (CUDA, wgpu) and PyTorch side by side,
# fresh training data made on the machine's CPU cores, then one leg of the default model's
# training relay for the remaining minutes. Everything it leaves is in OUT, in at most 8 files
# of at most 15 MiB (what the device tool brings back). docs/training.md says how to run a leg
# and how to judge it; `--tiny` runs the whole script on the CPU in a few minutes, so a typo
# never costs GPU time.
#
#   scripts/gpu-run.sh [options] OUT
#
#   --bin FILE        mvpcc built with --features cuda,wgpu, plain or .xz (scripts/build-cuda.sh)
#                     [target/cuda-dist/mvpcc.xz]
#   --minutes M       wall-clock budget of the whole script, minutes [9]
#   --profile-seconds S  the profiles' share of it, in seconds from the start [150]
#   --objects N       procedural vehicles to train on (prepare --synth) [6000]
#   --seed N          their seed; each leg should draw new ones [the date, YYYYMMDD]
#   --category LIST   what they are drawn from, NAME or NAME=WEIGHT each (prepare --category;
#                     e.g. car,bus,truck,train,motorcycle=3 for more motorcycles) [prepare's]
#   --init PATH|none  weights the leg starts from (train --init) [assets]
#   --config NAME     model of a fresh run (--init none): builtin (the built-in model's shape,
#                     as train's default), a preset or a config file [builtin]
#   --size S          view side of the data and the model [128]
#   --batch B         objects per step [16]
#   --lr R            first-stage learning rate [5e-4]
#   --losses gan|l1   the training losses: gan, train's defaults; l1, without the adversarial,
#                     perceptual and style terms (CPU legs 8-9, lab/2026-12-01-training-legs, found
#                     they cost CD; leg 12, the built-in model, trained so) [l1]
#   --loss-depth W    weight of train's depth term (train --loss-depth; leg 12 trained with
#                     100) [100]
#   --input-copy      the generator keeps its input's pixels (train --input-copy): for a fresh
#                     model (--init none), as the built-in one does; a leg from weights keeps
#                     theirs
#   --widen W         widen the --init weights to width W (train --widen): the leg starts from
#                     their output with room to learn more (docs/training.md)
#   --warmup-steps N  steps over which the rate rises to --lr (train --warmup-steps) [0]
#   --scaling S       on a machine with several GPUs, before the leg: S seconds of training on
#                     1, 2, … N of them (train --devices, --batch B per GPU), their steps/s and
#                     objects/s in profiles.txt [0: not measured]
#   --tiny            CPU smoke test: tiny model, 16 objects, 32² views, 3 minutes (its scaling
#                     runs on 1 and 2 CPU replicas)
#
# OUT gets: run.log (every command and its output, with times), profiles.txt (the
# `*_ms_median=` lines of every profile, mvpcc and PyTorch), train.json (the run's summary),
# complete.json (the `complete --json` reports of test partials, keyed built-in, leg and paper),
# run.tar.xz.part-* (the run directory without checkpoints: weights, config, log.jsonl,
# losses.png, samples/, and best/ with the best validation's weights but not its optimizers;
# best/ is left out when the two generators would not fit in the parts' 58 MiB, and the
# discriminator under --losses l1, which never trains it). Join the parts with
# `cat OUT/run.tar.xz.part-* | tar -xJ`.
set -uo pipefail

bin=target/cuda-dist/mvpcc.xz
minutes=9
profile_seconds=150
objects=6000
seed=$(date +%Y%m%d)
init=assets
config=builtin
size=128
batch=16
lr=5e-4
losses=l1
loss_depth=100
tiny=false
copy_args=()
category_args=()
widen_args=()
warmup=0
scaling=0
while [ $# -gt 1 ]; do
    case $1 in
    --bin) bin=$2 ;;
    --minutes) minutes=$2 ;;
    --profile-seconds) profile_seconds=$2 ;;
    --objects) objects=$2 ;;
    --seed) seed=$2 ;;
    --category) category_args=(--category "$2") ;;
    --init) init=$2 ;;
    --config) config=$2 ;;
    --size) size=$2 ;;
    --batch) batch=$2 ;;
    --lr) lr=$2 ;;
    --losses) losses=$2 ;;
    --loss-depth) loss_depth=$2 ;;
    --widen) widen_args=(--widen "$2") ;;
    --warmup-steps) warmup=$2 ;;
    --scaling) scaling=$2 ;;
    --tiny) tiny=true; shift; continue ;;
    --input-copy) copy_args=(--input-copy); shift; continue ;;
    *) echo "error: unknown option $1" >&2; exit 2 ;;
    esac
    shift 2
done
[ $# -eq 1 ] || { echo "usage: scripts/gpu-run.sh [options] OUT" >&2; exit 2; }
case $losses in
gan) loss_args=() ;;
l1) loss_args=(--loss-adversarial 0 --loss-perceptual 0 --loss-style 0) ;;
*) echo "error: --losses $losses: gan or l1" >&2; exit 2 ;;
esac
loss_args+=(--loss-depth "$loss_depth")
rate_args=(--lr "$lr")
[ "$warmup" = 0 ] || rate_args+=(--warmup-steps "$warmup")
out=$1
mkdir -p "$out"
out=$(cd "$out" && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/mvpcc-gpu-run.XXXXXX")
# The unpacked binary, the data and the run are 100+ MB a leg: left behind, the smoke test's
# copies filled a shared disk. Whatever comes back is in OUT by then; a data job still running
# when a step fails is stopped first, so that it writes nothing after the removal.
cleanup() {
    kill $(jobs -p) 2>/dev/null
    wait 2>/dev/null
    rm -rf "$work"
}
trap cleanup EXIT
start=$(date +%s)
deadline=$((start + minutes * 60))
log=$out/run.log
profiles=$out/profiles.txt
: >"$log"
: >"$profiles"

device=cuda
split=0.93
gt_size=256
workers=6
val_every=200
runs=5
warmup=3
# Seconds kept back after training for the completion timings and the packing.
margin=90
# Validations without a better CD before a stage ends: train's own default on a GPU leg, where
# the clock ends the run. The smoke test's tiny model often re-projects nothing at first, so
# no validation is ever better and its stages would run out within seconds, ending the run
# before the interrupt it is there to test.
patience_args=()
if $tiny; then
    device=cpu objects=16 split=0.67 size=32 gt_size=64 batch=2 workers=1 val_every=5 runs=1
    warmup=0
    config=tiny init=none margin=20 patience_args=(--patience 1000) profile_seconds=100000
    scaling=8
    [ "$minutes" -gt 3 ] && minutes=3 && deadline=$(($(date +%s) + 180))
fi

if [ ${#widen_args[@]} -gt 0 ] && [ "$init" = none ] && ! $tiny; then
    echo "error: --widen widens the --init weights; --init none has none" >&2
    exit 2
fi

say() { echo "[$(date -u +%H:%M:%S)] $*" | tee -a "$log" >&2; }
# Runs a command with a time limit, logging it and its output; its status is returned.
step() {
    local limit=$1
    shift
    say "\$ $*"
    timeout -k 10 "$limit" "$@" >>"$log" 2>&1
    local status=$?
    [ $status -eq 0 ] || say "exit status $status"
    return $status
}
# A profile's last line, `<what>_ms_median=<ms>`, with what was profiled. The profiles run in
# the order of what is quickest to measure, each within what is left of their share of the time
# (150 s at most), so that the leg gets the rest whatever a slow kernel compilation costs.
profile() {
    local label=$1 left=$((start + profile_seconds - $(date +%s)))
    shift
    if [ $left -lt 10 ]; then
        echo "$label skipped (the profiles' $profile_seconds s were spent)" >>"$profiles"
        return
    fi
    if step $((left < 150 ? left : 150)) "$@"; then
        echo "$label $(grep '_ms_median=' "$log" | tail -1)" >>"$profiles"
    else
        echo "$label failed (see run.log)" >>"$profiles"
    fi
}

# xz where the machine has it, else Python's lzma module (same format).
unxz_to() { if command -v xz >/dev/null; then xz -dc "$1" >"$2"; else
    python3 -c 'import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.argv[1]), open(sys.argv[2], "wb"))' "$1" "$2"; fi; }
xz_stream() { if command -v xz >/dev/null; then xz -T0 -3; else
    python3 -c 'import lzma, shutil, sys; shutil.copyfileobj(sys.stdin.buffer, lzma.open(sys.stdout.buffer, "wb", preset=3))'; fi; }

case $bin in
*.xz) unxz_to "$bin" "$work/mvpcc" || { say "cannot unpack $bin"; exit 1; } ;;
*) cp "$bin" "$work/mvpcc" || { say "cannot copy $bin"; exit 1; } ;;
esac
chmod +x "$work/mvpcc"
mvpcc=$work/mvpcc
say "mvpcc $($mvpcc --version), device $device, out $out"
# A binary older than an option the leg passes would fail after the data is made, minutes into
# the lease: checked here instead (a stale target/cuda-dist is the usual cause).
init_args=(--config "$config" "${copy_args[@]}")
[ "$init" = none ] || init_args=(--init "$init" "${copy_args[@]}" "${widen_args[@]}")
train_help=$("$mvpcc" train --help 2>&1)
for option in "${init_args[@]}" "${loss_args[@]}" "${rate_args[@]}"; do
    case $option in
    --*) grep -qw -- "$option" <<<"$train_help" ||
        { say "$bin: its train has no $option; rebuild it (scripts/build-cuda.sh)"; exit 1; } ;;
    esac
done
if [ ${#category_args[@]} -gt 0 ] && ! "$mvpcc" prepare --help 2>&1 | grep -q NAME=WEIGHT; then
    say "$bin: its prepare takes no category weights; rebuild it (scripts/build-cuda.sh)"
    exit 1
fi
if command -v nvidia-smi >/dev/null; then
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader | tee -a "$profiles" >>"$log"
fi
# A Vulkan loader for wgpu, when the caller carried one (docs/gpu.md), and the driver's own
# Vulkan and EGL manifests where the loader would not find them. Unpacked into / of the GPU
# machine, which starts bare each time; never by the smoke test, which runs on a developer's.
vulkan=false
if ! $tiny && ls .gl/*.deb >/dev/null 2>&1; then
    vulkan=true
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    egl=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    [ -e $icd ] && export VK_DRIVER_FILES=$icd
    [ -e $egl ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$egl
fi

# The data is made on the CPU cores while the GPU is profiled; niced, so the profiles' host
# threads keep their cores (PyTorch and mvpcc are profiled under the same load).
data=$work/data
say "\$ prepare --synth $objects --seed $seed ${category_args[*]} --size $size (in the background)"
nice -n 15 "$mvpcc" --quiet prepare --synth "$objects" --seed "$seed" "${category_args[@]}" --split "$split" \
    --size "$size" --gt-size "$gt_size" --samples 4 --out "$data" >>"$log" 2>&1 &
prepare=$!

# The same lines run in --tiny (on the CPU, tiny model) and on the GPU, so the test of --tiny
# checks every flag the GPU run passes.
if $tiny; then
    devices=(cpu) step_configs=(tiny) forward_configs=(tiny) torch_device=cpu profile_batch=2
else
    devices=(cuda) step_configs=(small cpu) forward_configs=(original) torch_device=cuda
    profile_batch=16
    $vulkan && devices+=(wgpu)
fi
timing=(--runs "$runs" --warmup "$warmup")
torch=benches/reference/generator_torch.py
have_torch=false
python3 -c 'import torch' 2>/dev/null && have_torch=true ||
    say "no PyTorch here: its profiles are skipped"
step_profile() {
    profile "mvpcc $1 $2 train step, batch $profile_batch$3:" "$mvpcc" profile "${timing[@]}" \
        --device "$1" --config "$2" --train --batch "$profile_batch" "${@:4}"
}
forward_profile() {
    profile "mvpcc $1 $2 forward, batch 1:" "$mvpcc" profile "${timing[@]}" --device "$1" \
        --config "$2"
}
torch_step_profile() {
    $have_torch && profile "torch $torch_device $1 train step, batch $profile_batch:" python3 \
        "$torch" "${timing[@]}" --device "$torch_device" --config "$1" --train \
        --batch "$profile_batch"
}
torch_forward_profile() {
    $have_torch && profile "torch $torch_device $1 forward, batch 1:" python3 "$torch" \
        "${timing[@]}" --device "$torch_device" --config "$1"
}
# The forward passes first (they compile in seconds), then PyTorch's steps, then mvpcc's: the
# first GAN step of a process compiles and tunes kernels for every shape of both networks'
# backward passes, which took over 150 s on an H200 (docs/gpu.md). The sliced layers and the
# other devices come last.
for f in "${forward_configs[@]}"; do
    forward_profile "${devices[0]}" "$f"
    torch_forward_profile "$f"
done
for c in "${step_configs[@]}"; do torch_step_profile "$c"; done
for c in "${step_configs[@]}"; do step_profile "${devices[0]}" "$c" ""; done
for c in "${step_configs[@]}"; do
    step_profile "${devices[0]}" "$c" ", sliced layers" --layers sliced
done
for d in "${devices[@]:1}"; do
    for f in "${forward_configs[@]}"; do forward_profile "$d" "$f"; done
    for c in "${step_configs[@]}"; do step_profile "$d" "$c" ""; done
done

# Should CUDA fail where wgpu ran (a driver the binary's CUDA bindings do not fit, say), the leg
# still trains, on wgpu.
ran() { grep -q "^mvpcc $1 ${forward_configs[0]} forward, batch 1: .*_ms_median=" "$profiles"; }
if ! $tiny && ! ran cuda && ran wgpu; then
    device=wgpu
    say "CUDA failed its profile where wgpu ran: the leg and the timings run on wgpu"
fi

say "waiting for the data"
wait $prepare || { say "prepare failed"; exit 1; }
du -sh "$data" >>"$log"

# Data-parallel throughput, 1 → N devices at the same batch per device: what `--devices` buys.
# The last log record's rate excludes the first steps' kernel compilation when S allows.
if [ "$scaling" -gt 0 ]; then
    if $tiny; then
        lists=(cpu cpu,cpu)
    else
        gpus=$(nvidia-smi -L 2>/dev/null | grep -c '^GPU')
        lists=()
        for ((k = 1; k <= gpus; k++)); do
            lists+=("$(seq -s, -f 'cuda:%g' 0 $((k - 1)))")
        done
        [ "$gpus" -gt 1 ] || { say "one GPU: no scaling to measure"; lists=(); }
    fi
    for list in "${lists[@]}"; do
        k=$(tr ',' '\n' <<<"$list" | wc -l)
        scale=$work/scale-$k
        say "\$ train --devices $list --batch $((batch * k)) ($scaling s)"
        timeout -k 30 $((scaling + 30)) timeout --foreground -s INT "$scaling" "$mvpcc" --quiet \
            train --data "$data" --out "$scale" "${init_args[@]}" --size "$size" \
            --devices "$list" --batch $((batch * k)) "${rate_args[@]}" "${loss_args[@]}" \
            --val-every 0 --seen-samples 0 --log-every 5 --workers "$workers" 2>>"$log"
        rate=$(grep -o '"steps_per_second":[0-9.e+-]*' "$scale/log.jsonl" 2>/dev/null | tail -1 |
            cut -d: -f2)
        if [ -n "$rate" ]; then
            echo "scaling devices=$k ($list) batch=$((batch * k)): steps_per_second=$rate" \
                "objects_per_second=$(awk -v r="$rate" -v b=$((batch * k)) 'BEGIN { print r * b }')" \
                >>"$profiles"
        else
            echo "scaling devices=$k ($list): no rate logged (see run.log)" >>"$profiles"
        fi
        rm -rf "$scale"
    done
fi

run=$work/run
left=$((deadline - $(date +%s) - margin))
# The smoke test trains for half a minute however slow the machine it runs on is.
$tiny && [ $left -lt 30 ] && left=30
[ $left -gt 10 ] || { say "no time left to train"; exit 1; }
# SIGINT is train's Ctrl-C: it checkpoints, then validates the last step and draws its samples.
# timeout answers 124 when it sent the signal, whatever train then did; train's own status is
# in its summary (train.json, "outcome": "interrupted"). --foreground: without it timeout
# sends the signal to train and then to its whole process group, train among them, and a
# second SIGINT makes train exit at once, writing nothing (a CI run on a loaded machine lost
# its train.json so).
say "\$ train --data $data --out $run ${init_args[*]} --size $size --device $device --batch $batch ${rate_args[*]} ${loss_args[*]} ($left s)"
timeout -k 60 $((left + 60)) timeout --foreground -s INT "$left" "$mvpcc" train --data "$data" --out "$run" \
    "${init_args[@]}" --size "$size" --device "$device" --batch "$batch" "${rate_args[@]}" \
    "${loss_args[@]}" \
    --val-every "$val_every" --val-samples 32 --checkpoint-every 500 --workers "$workers" \
    "${patience_args[@]}" --json >"$out/train.json" 2>>"$log"
status=$?
[ $status -eq 0 ] || [ $status -eq 124 ] || say "train: exit status $status"

# Packed before the timings below, so that a command stopped at its limit still brings the
# leg back.
# The device tool brings back 8 files of 16 MiB, 64 MiB in all: the four reports and four
# parts of 15 MiB at most. Floats barely compress, and the cpu preset's generator alone is
# 35 MB: with best/'s copy the run would not fit, and the last weights are what a leg continues.
say "packing"
packed=$work/run.tar.xz
leave=(--exclude checkpoints --exclude 'best/*.bpk')
[ "$losses" = l1 ] && leave+=(--exclude 'discriminator*')
pack() { tar -C "$run" "${leave[@]}" -cf - . | xz_stream >"$packed"; }
pack
if [ "$(stat -c %s "$packed")" -gt $((58 << 20)) ]; then
    leave+=(--exclude best)
    pack
    say "best/ left out: the run's last weights alone fit what comes back"
fi
split -b 15M "$packed" "$out/run.tar.xz.part-"

# The network's share of `complete` (encoder, fusion, decoder), median over the files after
# the first, whose kernels are compiled and tuned on the way.
cases=$work/cases
mkdir -p "$cases"
cp assets/example/car_partial.ply "$cases/"
find "$data/clouds/test" -name 'partial_*.ply' 2>/dev/null | head -8 |
    while read -r f; do cp "$f" "$cases/$(echo "${f#"$data"/clouds/test/}" | tr / _)"; done
# The built-in model, the leg's, and the built-in one in the paper's pipeline (`--paper`: the
# paper's Table 4 stages). The reports are kept whole, for their per-stage times, in one file of
# OUT (complete.json), since what comes back is counted in files.
for name in built-in leg paper; do
    case $name in
    built-in) args=() label="model built-in" ;;
    leg) args=(--model "$run") label="model $run" ;;
    paper) args=(--paper) label="model built-in, --paper" ;;
    esac
    report=$work/complete-$name.json
    say "\$ complete --input-dir $cases --device $device --jobs 1 --json ${args[*]}"
    # A file that fails is listed in the report with its error; the others still count.
    timeout 90 "$mvpcc" complete --input-dir "$cases" --output-dir "$work/completed-$name" \
        --device "$device" --jobs 1 --json "${args[@]}" >"$report" 2>>"$log"
    python3 - "$report" "$label" >>"$profiles" <<'PY'
import json, statistics, sys
try:
    reports = json.load(open(sys.argv[1]))["results"]
except (ValueError, KeyError):
    reports = []
seconds = [r["seconds"] for r in reports if r["status"] == "completed"]
failed = sum(r["status"] == "failed" for r in reports)
line = f"mvpcc complete, {sys.argv[2]}, {len(seconds)} files completed, {failed} failed"
seconds = seconds[1:] or seconds
if seconds:
    net = statistics.median(1e3 * (s["encoder"] + s["fusion"] + s["decoder"]) for s in seconds)
    total = statistics.median(1e3 * s["total"] for s in seconds)
    line += f": network_ms_median={net:.1f} total_ms_median={total:.1f}"
print(line + ("" if reports else " (no report: see run.log)"))
PY
done
python3 - "$work" >"$out/complete.json" <<'PY'
import json, sys
reports = {}
for name in ("built-in", "leg", "paper"):
    try:
        reports[name] = json.load(open(f"{sys.argv[1]}/complete-{name}.json"))
    except (OSError, ValueError):
        reports[name] = None
json.dump(reports, sys.stdout, indent=1)
PY
ls -l "$out" | tee -a "$log" >&2
