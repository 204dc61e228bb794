//! mvpcc: multi-view point cloud completion (MVPCC-Net) for mobile laser scans.
//!
//! The pipeline stages are modules of their own: [`io`] reads and writes clouds, [`frame`] maps a
//! cloud into the unit box and back, [`camera`] and [`projection`] turn it into view images,
//! [`views`] stores those images in the original dataset's PNG layout, [`reprojection`] and
//! [`filter`] turn views back into a cloud, and [`metrics`] scores the result. [`model`] is the
//! inpainting network, [`inpaint`] runs it on view images and [`device`] picks where it runs.
//! Training data comes from meshes ([`mesh`], [`synth`]): [`raster`] renders them, [`scan`]
//! samples ground truth and partial scans, and [`data`] writes the dataset; [`train`] trains the
//! network on it. [`complete`] is the whole pipeline a user runs, with [`clean`] removing what
//! segmentation left around the vehicle, [`orient`] finding which way it faces, [`symmetry`]
//! finding its plane of symmetry and [`preview`] drawing the result.

pub mod batch;
pub mod camera;
pub mod clean;
pub mod cli;
pub mod cloud;
pub mod commands;
pub mod complete;
pub mod data;
pub mod device;
pub mod filter;
pub mod frame;
pub mod inpaint;
pub mod io;
pub mod knn;
pub mod mesh;
pub mod metrics;
pub mod model;
pub mod orient;
pub mod preview;
pub mod projection;
pub mod raster;
pub mod reprojection;
pub mod scan;
pub mod shapes;
pub mod symmetry;
pub mod synth;
pub mod train;
pub mod views;
