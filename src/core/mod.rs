//! The shared basis: point clouds ([`cloud`]), nearest neighbours ([`knn`]), the unit-box frame
//! and headings ([`frame`]), the camera rig ([`camera`]) and seeded randomness ([`rng`]).

pub mod camera;
pub mod cloud;
pub mod frame;
pub mod knn;
pub mod rng;
