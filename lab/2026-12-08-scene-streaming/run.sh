#!/usr/bin/env bash
# Streamed `complete --scene` on a 50M-point generated LAZ tile: peak memory and wall time,
# streamed (with the networks, and --method mirror) and read whole (--method mirror), one run
# each, nothing else running. Appends one CSV row per run to results.csv.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --example big_tile
cargo build --release
work=${WORK:-/tmp/scene-streaming}
mkdir -p "$work"
[ -f "$work/tile50.laz" ] || target/release/examples/big_tile "$work/tile50.laz" --points 50000000
run() {
  local name=$1; shift
  /usr/bin/time -f "%e %M" -o "$work/$name.time" target/release/mvpcc complete --scene \
    "$work/tile50.laz" "$work/$name.laz" --json "$@" > "$work/$name.json" 2> "$work/$name.err"
  python3 - "$work" "$name" <<'PY' >> lab/2026-12-08-scene-streaming/results.csv
import json, sys
work, name = sys.argv[1:]
wall, kb = open(f"{work}/{name}.time").read().split()[-2:]
r = json.load(open(f"{work}/{name}.json")); s = r["scene"]; t = r["seconds"]
print(",".join(str(v) for v in [name, r["input_points"], r["output_points"], s.get("chunks", ""),
      s.get("largest_chunk", ""), len(s["vehicles"]), s["objects"], int(kb) // 1024, wall,
      round(r["input_points"] / float(wall)), round(t["read"], 1), round(t["vehicles"], 1),
      round(t["write"], 1)]))
PY
}
run streamed-network
run streamed-mirror --method mirror
run whole-mirror --method mirror --stream-from 100000000
