//! Seeing the moiré before printing (METHOD §8): a ray tracer over the very
//! meshes moirecast fabricates, and the moiré fidelity number. No I/O.
//!
//! This is the foundation of `moirecast render`: the scene (a BVH over the
//! device mesh, exact f64 intersections), dielectric optics (Snell,
//! Fresnel, total internal reflection), a deterministic tracer, and
//! [`fidelity`]; [`frame`] lights and views it (a lateral light for the
//! dual-lens device, a backlight behind a printed device's absorbing bands).

pub mod fidelity;
pub mod frame;
pub mod optics;
pub mod scene;
pub mod sheet;
pub mod trace;

pub use fidelity::fidelity;
pub use scene::{Hit, Scene};
