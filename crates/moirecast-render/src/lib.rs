//! Seeing the moiré before printing (METHOD §8): a ray tracer over the very
//! meshes moirecast fabricates, and the moiré fidelity number. No I/O.
//!
//! This is the foundation of `moirecast render`: the scene (a BVH over the
//! device mesh, exact f64 intersections), dielectric optics (Snell,
//! Fresnel, total internal reflection), a deterministic tracer, and
//! [`fidelity()`]; [`frame`] lights and views it (a lateral light for the
//! dual-lens device, a backlight behind a printed device's absorbing bands).
//!
//! ```
//! use moirecast_kernel::{mesher::mesh_device, progress::Silent, Design, DesignParams, PitchSurface, Profile};
//! use moirecast_render::frame::{render, Camera, Lighting, View};
//!
//! let mut params = DesignParams::with_defaults(PitchSurface::Plane, 4.0, 4.0, 0.5);
//! params.tolerance = 0.01;
//! params.profile = Profile::Rings { wavelength: 2.0 };
//! let design = Design::new(params).unwrap();
//! let device = mesh_device(&design, &Silent).unwrap();
//! let scene = moirecast_render::Scene::new(&device.mesh);
//! let frame = render(&design, &scene, View {
//!     width: 32,
//!     height: 32,
//!     sampling: Default::default(),
//!     tilt_across: 0.0,
//!     tilt_along: 0.0,
//!     camera: Camera::Orthographic,
//!     lighting: Lighting::default_for(&design),
//!     integrator: Default::default(),
//!     seed: 1,
//! });
//! assert_eq!(frame.rgb.len(), 32 * 32);
//! ```

pub mod fidelity;
pub mod frame;
pub mod optics;
pub mod scene;
pub mod section;
pub mod sheet;
pub mod trace;

pub use fidelity::fidelity;
pub use scene::{Hit, Scene};
