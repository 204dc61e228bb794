#![no_main]
//! A view pair: `locations_001.png \n%%\n color_001.png`, read as the dataset reader and
//! `reproject` read them.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (locations, color) = mvpcc_fuzz::halves(data);
    let dir = mvpcc_fuzz::scratch().join("views");
    std::fs::create_dir_all(&dir).expect("scratch directory");
    std::fs::write(mvpcc::views::locations_path(&dir, 1), locations).expect("scratch file");
    let color_path = mvpcc::views::color_path(&dir, 1);
    if color.is_empty() {
        let _ = std::fs::remove_file(&color_path);
    } else {
        std::fs::write(&color_path, color).expect("scratch file");
    }
    let _ = mvpcc::views::read_views(&dir, None);
});
