#![no_main]
//! The OBJ reader with its MTL: an input is `OBJ \n%%\n MTL`; the OBJ names `m.mtl` itself when
//! the fuzzer finds `mtllib m.mtl`.

use libfuzzer_sys::fuzz_target;
use mvpcc::datagen::mesh::{read_mesh, ReadOptions};

fuzz_target!(|data: &[u8]| {
    let (obj, mtl) = mvpcc_fuzz::halves(data);
    mvpcc_fuzz::file("m.mtl", mtl);
    let path = mvpcc_fuzz::file("mesh.obj", obj);
    for allow_missing_materials in [false, true] {
        let _ = read_mesh(
            &path,
            ReadOptions {
                allow_missing_materials,
            },
        );
    }
});
