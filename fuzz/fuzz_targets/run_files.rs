#![no_main]
//! The JSON files a tool run reads back: a view directory's `frame.json`, and a training run's
//! `train.json`, `config.json`, `checkpoints/*/state.json` and `log.jsonl`.

use libfuzzer_sys::fuzz_target;
use mvpcc::model::ModelConfig;
use mvpcc::train::checkpoint::TrainState;
use mvpcc::train::{parse_log, TrainSettings};
use mvpcc::views::ViewsInfo;

fuzz_target!(|data: &[u8]| {
    if let Ok(info) = ViewsInfo::from_json(data) {
        let _ = info.frame.to_input([0.5, -0.25, 0.125]);
    }
    if let Ok(config) = serde_json::from_slice::<ModelConfig>(data) {
        let _ = config.validate();
    }
    let _ = serde_json::from_slice::<TrainSettings>(data);
    let _ = serde_json::from_slice::<TrainState>(data);
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = parse_log(text, u64::MAX);
    }
});
