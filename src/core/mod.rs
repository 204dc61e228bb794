//! The shared basis: point clouds ([`cloud`]), nearest neighbours ([`knn`]), the unit-box frame
//! and headings ([`frame`]), the camera rig ([`camera`]), seeded randomness ([`rng`]),
//! third-party panics turned into errors ([`guard`]) and a pixel font ([`glyphs`]).

pub mod camera;
pub mod cloud;
pub mod frame;
pub mod glyphs;
pub mod guard;
pub mod knn;
pub mod rng;
