//! Training data: meshes read ([`mesh`]) or generated ([`synth`]), rasterized ([`raster`]) into
//! ground truth and partial scans ([`scan`]) and written in the original dataset's layout
//! ([`data`]); [`shapes`] are small procedural objects for tests and the shipped example.

pub mod data;
pub mod mesh;
pub mod raster;
pub mod scan;
pub mod shapes;
pub mod synth;
