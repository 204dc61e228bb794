#![no_main]
//! The glTF reader, as binary GLB and as JSON glTF (whose buffers may name `b.bin`, the second
//! half of an input `GLTF \n%%\n BIN`).

use libfuzzer_sys::fuzz_target;
use mvpcc::datagen::mesh::{read_mesh, ReadOptions};

fuzz_target!(|data: &[u8]| {
    let options = ReadOptions {
        allow_missing_materials: true,
    };
    let path = mvpcc_fuzz::file("mesh.glb", data);
    let _ = read_mesh(&path, options);
    let (gltf, bin) = mvpcc_fuzz::halves(data);
    mvpcc_fuzz::file("b.bin", bin);
    let path = mvpcc_fuzz::file("mesh.gltf", gltf);
    let _ = read_mesh(&path, options);
});
