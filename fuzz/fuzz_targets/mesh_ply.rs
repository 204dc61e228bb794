#![no_main]
//! The mesh PLY reader (faces and colours, as `prepare --meshes` reads it).

use libfuzzer_sys::fuzz_target;
use mvpcc::datagen::mesh::{read_mesh, ReadOptions};

fuzz_target!(|data: &[u8]| {
    let path = mvpcc_fuzz::file("mesh.ply", data);
    let _ = read_mesh(
        &path,
        ReadOptions {
            allow_missing_materials: true,
        },
    );
});
