//! mvpcc: multi-view point cloud completion (MVPCC-Net) for mobile laser scans.
//!
//! The folders are the layers, each using only those listed before it:
//!
//! - [`core`]: point clouds, nearest neighbours, the unit-box frame, the camera rig, seeded
//!   randomness.
//! - [`io`]: cloud formats (PLY, PCD, LAS/LAZ, XYZ), atomic writes, file lists and shards for
//!   batches.
//! - [`metrics`]: Chamfer distances, F-scores and image metrics.
//! - [`views`]: projection into view images, the dataset's PNG layout, re-projection.
//! - [`model`]: the inpainting GAN, its weights files, running it on views ([`model::inpaint`])
//!   and choosing the device ([`model::device`]).
//! - [`complete`]: the completion pipeline a user runs, with its stages: cleaning, orientation,
//!   symmetry, outlier filter, merge and preview.
//! - [`datagen`]: training data from meshes or procedural vehicles: reading meshes,
//!   rasterizing, ground truth and partial scans, the dataset layout.
//! - [`train`]: training the GAN and the orientation network.
//! - [`app`]: what each command does, without parsing or printing: batch completion, scoring,
//!   reports exported as tables or JSON.

pub mod app;
pub mod complete;
pub mod core;
pub mod datagen;
pub mod io;
pub mod metrics;
pub mod model;
pub mod scene;
pub mod train;
pub mod views;
