#![no_main]
//! The laz point cloud reader: any bytes give a cloud or an error, never a panic, a hang or an
//! allocation the file cannot back.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = mvpcc_fuzz::file("input.laz", data);
    let _ = mvpcc::io::read_cloud(&path, None);
});
