#!/usr/bin/env bash
# The paper's Tables 5 (number of views) and 6 (early vs late fusion × XYZ vs XYZRGB) as trends
# at a scale two CPU cores allow: every row the same recipe, data, seed and steps, trained from
# scratch. Resumable: a row with a line in results.csv is skipped, a row with checkpoints goes on
# from its latest (`train --resume`), so the script can be stopped and run again at any time.
# Usage: run.sh MVPCC OUT [STEPS]   (RAYON_NUM_THREADS and nice are the caller's; ROWS="views-5
# views-6" runs only the rows named, so that two runs on disjoint rows can share the data)
set -euo pipefail
m=${1:?MVPCC} out=${2:?OUT} steps=${3:-1000}
mkdir -p "$out"
data=$out/data
if [ ! -f "$data/prepare.json" ]; then
  rm -rf "$data"
  "$m" -q prepare --synth 400 --seed 2026120756 --split 0.9 --samples 4 --size 64 --gt-size 256 \
    --views 5,6,7,8,10,12,17,19 --out "$data"
fi
results=$out/results.csv
[ -f "$results" ] || echo "row,views,fusion,channels,steps,cd_l1,cd_l2_half,f1,geometry_psnr,geometry_ssim,geometry_mae,color_psnr,color_ssim,color_mae,steps_per_second" > "$results"
if [ ! -f "$out/input.txt" ]; then
  "$m" eval --data "$data" --pred-dir "$data/clouds/test" --tau 0.01 > "$out/input.txt"
fi

row() { # name, cameras, fusion, channels
  local name=$1 cameras=$2 fusion=$3 channels=$4 run=$out/$1
  [ -n "${ROWS:-}" ] && [[ " $ROWS " != *" $name "* ]] && return
  grep -q "^$name," "$results" && return
  local views; views=$(tr ',' '\n' <<< "$cameras" | wc -l)
  if [ -d "$run/checkpoints" ] && [ -n "$(ls "$run/checkpoints")" ]; then
    "$m" -q train --data "$data" --out "$run" --resume --steps "$steps"
  else
    rm -rf "$run"
    mkdir -p "$out/configs"
    printf '{"width":16,"res_blocks":2,"size":64,"views":%s,"channels":"%s","padding":"zero","disc_width":16,"input_copy":true}\n' \
      "$views" "$channels" > "$out/configs/$name.json"
    "$m" -q train --data "$data" --config "$out/configs/$name.json" --views "$cameras" \
      --fusion "$fusion" --channels "$channels" --steps "$steps" --batch 4 --lr 5e-4 --seed 56 \
      --val-every 250 --val-samples 64 --seen-samples 0 --checkpoint-every 100 --keep 2 --out "$run"
  fi
  rm -rf "$run/complete"
  "$m" -q complete --paper --model "$run/generator.safetensors" --views "$cameras" \
    --input-dir "$data/clouds/test" --include 'partial_*.ply' --output-dir "$run/complete" --jobs 2
  "$m" eval --data "$data" --pred-dir "$run/complete" --tau 0.01 > "$run/eval.txt"
  local cd; cd=$(awk '$1 == "all" { print $6 "," $5 "," $8 }' "$run/eval.txt")
  # The last validation's view scores (the dataset's own frame, as the paper's Table 5) and
  # the last logged training rate.
  local logged; logged=$(python3 -c '
import json, sys
lines = [json.loads(l) for l in open(sys.argv[1])]
s = [l for l in lines if l["kind"] == "validation"][-1]["scores"]
g, c = s["geometry"], s.get("color") or {}
rates = [l["steps_per_second"] for l in lines if l["kind"] == "train"]
print(",".join(f"{x:.4f}" if isinstance(x, float) else "" for x in
      [g["psnr"], g["ssim"], g["mae"], c.get("psnr"), c.get("ssim"), c.get("mae"),
       rates[-1] if rates else None]))' "$run/log.jsonl")
  echo "$name,$views,$fusion,$channels,$steps,$cd,$logged" >> "$results"
}

# Table 6's rows first (the 4-view late XYZRGB row is Table 5's too), then Table 5's view counts:
# the four diagonal cameras above the object (5–8), then the ones above its front and back
# (10, 12), then its sides (17, 19).
row late-xyzrgb 5,6,7,8 late xyzrgb
row early-xyzrgb 5,6,7,8 early xyzrgb
row late-xyz 5,6,7,8 late xyz
row early-xyz 5,6,7,8 early xyz
row views-3 5,6,7 late xyzrgb
row views-5 5,6,7,8,10 late xyzrgb
row views-6 5,6,7,8,10,12 late xyzrgb
row views-8 5,6,7,8,10,12,17,19 late xyzrgb
