//! The shared basis: point clouds ([`cloud`]), nearest neighbours ([`knn`]), the unit-box frame
//! and headings ([`frame`]), the camera rig ([`camera`]), seeded randomness ([`rng`]) and
//! third-party panics turned into errors ([`guard`]).

pub mod camera;
pub mod cloud;
pub mod frame;
pub mod guard;
pub mod knn;
pub mod rng;
