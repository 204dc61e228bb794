//! Batches assembled on worker threads while the network trains: a producer thread draws the
//! samples of each step in [`DrawOrder`], renders them on its own thread pool and queues up to
//! `prefetch` steps ahead.

use super::dataset::{
    load_sample, AugmentSettings, Cache, DataError, DrawOrder, Rendered, SampleRef,
};
use crate::core::camera::Camera;
use crate::model::gan::Batch;
use crate::model::inpaint::{encode_input, encode_target};
use crate::model::loss::Target;
use crate::model::Channels;
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::Arc;

/// One micro-batch in host memory.
///
/// # Shapes
/// `input`: `[B, V, C+1, S, S]`, `images`: `[B, V, C, S, S]`, `occupancy`: `[B, V, 1, S, S]`
#[derive(Debug, Clone, PartialEq)]
pub struct HostBatch {
    pub input: Vec<f32>,
    pub images: Vec<f32>,
    pub occupancy: Vec<f32>,
    /// `[B, V, C, S]`.
    pub dims: [usize; 4],
}

impl HostBatch {
    /// The objects in `parts` runs as even as they go (the first ones one larger), one per
    /// data-parallel replica; an empty part where there are fewer objects than parts.
    pub fn split(self, parts: usize) -> Vec<HostBatch> {
        let b = self.dims[0];
        let (each, extra) = (b / parts, b % parts);
        let mut start = 0;
        (0..parts)
            .map(|k| {
                let n = each + usize::from(k < extra);
                let cut = |data: &[f32]| {
                    let stride = data.len() / b.max(1);
                    data[start * stride..(start + n) * stride].to_vec()
                };
                let part = HostBatch {
                    input: cut(&self.input),
                    images: cut(&self.images),
                    occupancy: cut(&self.occupancy),
                    dims: [n, self.dims[1], self.dims[2], self.dims[3]],
                };
                start += n;
                part
            })
            .collect()
    }

    pub fn to_device(self, device: &Device) -> Batch {
        let [b, v, c, s] = self.dims;
        let tensor = |data: Vec<f32>, planes: usize| {
            Tensor::<5>::from_data(TensorData::new(data, [b, v, planes, s, s]), device)
        };
        Batch {
            input: tensor(self.input, c + 1),
            target: Target::new(tensor(self.images, c), tensor(self.occupancy, 1)),
        }
    }
}

/// What one optimizer step trains on.
#[derive(Debug, Clone, PartialEq)]
pub struct StepData {
    pub step: u64,
    pub micro: Vec<HostBatch>,
}

/// The most loader threads: 10⁸ spawned threads for over 100 s without a step.
pub const MAX_WORKERS: usize = 256;
/// The most steps prepared ahead: the queue is allocated whole, and 10⁹ aborted the process.
pub const MAX_PREFETCH: usize = 256;

#[derive(Debug, Clone, Copy)]
pub struct LoaderPlan {
    pub seed: u64,
    pub batch: usize,
    pub accumulate: usize,
    /// The first step to produce (0-based): a resumed run starts where it left off.
    pub first_step: u64,
    pub augment: AugmentSettings,
    pub channels: Channels,
    pub prefetch: usize,
    pub workers: usize,
}

/// One micro-batch's rendered samples encoded into the host buffers the network's tensors are
/// made from.
fn host_batch(chunk: &[Rendered], cameras: &[Camera], channels: Channels) -> HostBatch {
    let mut batch = HostBatch {
        input: Vec::new(),
        images: Vec::new(),
        occupancy: Vec::new(),
        dims: [
            chunk.len(),
            cameras.len(),
            channels.count(),
            cameras[0].size,
        ],
    };
    for r in chunk {
        encode_input(&r.input, channels, &mut batch.input);
        encode_target(&r.target, channels, &mut batch.images, &mut batch.occupancy);
    }
    batch
}

pub struct Loader {
    rx: Receiver<Result<StepData, DataError>>,
}

impl Loader {
    pub fn spawn(
        samples: Arc<Vec<SampleRef>>,
        cameras: Vec<Camera>,
        cache: Arc<Cache>,
        plan: LoaderPlan,
    ) -> Loader {
        let (tx, rx) = sync_channel(plan.prefetch.clamp(1, MAX_PREFETCH));
        std::thread::spawn(move || {
            let pool = match rayon::ThreadPoolBuilder::new()
                .num_threads(plan.workers.clamp(1, MAX_WORKERS))
                .thread_name(|i| format!("mvpcc-loader-{i}"))
                .build()
            {
                Ok(pool) => pool,
                Err(e) => {
                    let _ = tx.send(Err(DataError::Io {
                        path: "loader threads".into(),
                        source: std::io::Error::other(e),
                    }));
                    return;
                }
            };
            let mut order = DrawOrder::new(plan.seed, samples.len());
            let per_step = (plan.batch * plan.accumulate) as u64;
            for step in plan.first_step.. {
                let draws: Vec<_> = (0..per_step)
                    .map(|j| {
                        let (index, mut rng) = order.draw(step * per_step + j);
                        (index, plan.augment.draw(&mut rng))
                    })
                    .collect();
                let rendered = pool.install(|| {
                    draws
                        .par_iter()
                        .map(|(index, augment)| {
                            load_sample(&samples[*index], &cameras, augment, &cache)
                        })
                        .collect::<Result<Vec<_>, _>>()
                });
                let data = rendered.map(|rendered| StepData {
                    step,
                    micro: rendered
                        .chunks(plan.batch)
                        .map(|chunk| host_batch(chunk, &cameras, plan.channels))
                        .collect(),
                });
                let failed = data.is_err();
                // The receiver is gone when training ended: stop producing.
                if tx.send(data).is_err() || failed {
                    return;
                }
            }
        });
        Loader { rx }
    }

    /// The next step's data, waiting for it if the workers are behind.
    pub fn next(&self) -> Result<StepData, DataError> {
        self.rx.recv().unwrap_or_else(|_| {
            Err(DataError::Io {
                path: "loader threads".into(),
                source: std::io::Error::other("the data loader stopped"),
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_splits_into_even_runs_of_whole_objects_in_order() {
        // Five objects of one view, two planes (one input plane more) of 1×1 pixels, each
        // object's values its index.
        let object = |planes: usize| -> Vec<f32> {
            (0..5)
                .flat_map(|k| std::iter::repeat_n(k as f32, planes))
                .collect()
        };
        let batch = HostBatch {
            input: object(3),
            images: object(2),
            occupancy: object(1),
            dims: [5, 1, 2, 1],
        };
        let parts = batch.split(3);
        let sizes: Vec<usize> = parts.iter().map(|p| p.dims[0]).collect();
        assert_eq!(sizes, [2, 2, 1]);
        assert_eq!(parts[1].input, [2.0, 2.0, 2.0, 3.0, 3.0, 3.0]);
        assert_eq!(parts[2].images, [4.0, 4.0]);
        assert_eq!(parts[0].occupancy, [0.0, 1.0]);
        assert!(parts.iter().all(|p| p.dims[1..] == [1, 2, 1]));
    }
}
