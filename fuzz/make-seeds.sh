#!/usr/bin/env bash
# Writes small valid seed files for every fuzz target into fuzz/corpus/<target>/, made by the
# mvpcc binary given as $1 (default: target/release/mvpcc) and by hand here; nothing is copied
# from ../shared/reference.
set -euo pipefail
cd "$(dirname "$0")"
MVPCC=$(realpath "${1:-../target/release/mvpcc}")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
c=corpus
mkdir -p $c/{cloud_ply,cloud_pcd,cloud_las,cloud_laz,cloud_xyz,mesh_obj,mesh_gltf,mesh_ply,views,weights,run_files}

# A 60-point cloud with colour: two rows of a box's side.
python3 - "$work/box.ply" <<'PY'
import sys
with open(sys.argv[1], "w") as f:
    f.write("ply\nformat ascii 1.0\nelement vertex 60\nproperty float x\nproperty float y\n"
            "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
            "property float intensity\nend_header\n")
    for i in range(60):
        f.write(f"{i % 30 * 0.1:.2f} {i // 30 * 0.5:.2f} {0.02 * (i % 7):.2f} {i * 4} 100 200 {i}\n")
PY
cp "$work/box.ply" $c/cloud_ply/ascii.ply
for enc in binary ascii compressed; do
  "$MVPCC" filter -q --sor-k 0 --encoding $enc "$work/box.ply" "$work/box_$enc.pcd"
  cp "$work/box_$enc.pcd" $c/cloud_pcd/$enc.pcd
done
"$MVPCC" filter -q --sor-k 0 "$work/box.ply" $c/cloud_ply/binary.ply
"$MVPCC" filter -q --sor-k 0 "$work/box.ply" $c/cloud_las/box.las
"$MVPCC" filter -q --sor-k 0 "$work/box.ply" $c/cloud_laz/box.laz
"$MVPCC" filter -q --sor-k 0 "$work/box.ply" $c/cloud_xyz/box.xyz
printf 'x,y,z\n1,2,3\n4,5,6\n7,8,9.5\n' > $c/cloud_xyz/header.xyz
# Attributes LAS has no field for become extra bytes, described by their VLR.
awk '/^end_header/ { print "property short reflectance"; print; body = 1; next }
     body { print $0, NR % 50 - 25; next } { print }' "$work/box.ply" > "$work/extra.ply"
"$MVPCC" filter -q --sor-k 0 "$work/extra.ply" $c/cloud_las/extra.las
"$MVPCC" filter -q --sor-k 0 "$work/extra.ply" $c/cloud_laz/extra.laz

# Meshes: a textured-less cube as OBJ + MTL (split by \n%%\n), PLY, glTF and GLB.
python3 - $c <<'PY'
import base64, json, struct, sys
c = sys.argv[1]
v = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
         (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
obj = "mtllib m.mtl\n" + "".join(f"v {a} {b} {d}\n" for a, b, d in v) + "usemtl red\n"
obj += "".join(f"f {a+1} {b+1} {d+1}\n" for a, b, d in faces)
mtl = "newmtl red\nKd 0.8 0.1 0.1\n"
open(f"{c}/mesh_obj/cube.obj", "w").write(obj + "\n%%\n" + mtl)
ply = (f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
       f"property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
       f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
ply += "".join(f"{a} {b} {d} 200 30 30\n" for a, b, d in v)
ply += "".join(f"3 {a} {b} {d}\n" for a, b, d in faces)
open(f"{c}/mesh_ply/cube.ply", "w").write(ply)
positions = b"".join(struct.pack("<3f", *p) for p in v)
indices = b"".join(struct.pack("<3H", *f) for f in faces)
buffer = positions + indices
def gltf(uri):
    g = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "scene": 0,
         "nodes": [{"mesh": 0}],
         "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
         "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.8, 1]}}],
         "buffers": [{"byteLength": len(buffer)}],
         "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
                         {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)}],
         "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3",
                        "min": [0, 0, 0], "max": [1, 1, 1]},
                       {"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"}]}
    if uri:
        g["buffers"][0]["uri"] = uri
    return json.dumps(g).encode()
embedded = "data:application/octet-stream;base64," + base64.b64encode(buffer).decode()
open(f"{c}/mesh_gltf/embedded.gltf", "wb").write(gltf(embedded))
open(f"{c}/mesh_gltf/external.gltf", "wb").write(gltf("b.bin") + b"\n%%\n" + buffer)
j = gltf(None)
j += b" " * (-len(j) % 4)
b = buffer + b"\0" * (-len(buffer) % 4)
glb = struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(j) + 8 + len(b))
glb += struct.pack("<I4s", len(j), b"JSON") + j + struct.pack("<I4s", len(b), b"BIN\0") + b
open(f"{c}/mesh_gltf/cube.glb", "wb").write(glb)
PY

# Views (16 px, one camera) and frame.json.
"$MVPCC" project -q --size 16 --views 5 "$work/box.ply" "$work/views"
{ cat "$work/views/locations_005.png"; printf '\n%%%%\n'; cat "$work/views/color_005.png"; } \
  > $c/views/pair.png
cp "$work/views/locations_005.png" $c/views/locations.png
cp "$work/views/frame.json" $c/run_files/frame.json

# Weights and a run's files: one step of the tiny model on two generated objects.
"$MVPCC" prepare -q --synth 2 --split 0.5 --samples 1 --size 32 --gt-size 64 \
  --min-points 300 --max-points 1000 --out "$work/data"
"$MVPCC" train -q --data "$work/data" --out "$work/run" --config tiny --steps 1 --batch 1 \
  --val-samples 1
cp "$work/run/generator.safetensors" $c/weights/generator.safetensors
cp "$work/run/discriminator.safetensors" $c/weights/discriminator.safetensors
cp ../assets/orienter.safetensors $c/weights/orienter.safetensors
for f in train.json config.json log.jsonl; do cp "$work/run/$f" $c/run_files/$f; done
cp "$work/run"/checkpoints/step-*/state.json $c/run_files/state.json
du -sh $c/*
