//! The geometry kernel of moirecast: the exact model of a curved-surface
//! level-line moiré device (METHOD §1–§5) and a mesher that works straight
//! from it.
//!
//! The kernel does no I/O: it knows nothing of files, TOML or the command
//! line. Images arrive as [`profile::Raster`]s; progress leaves through
//! [`progress::Progress`].
//!
//! Coordinates: lengths in mm, angles in radians. The layout is centred:
//! `u ∈ [−W/2, W/2]`, `v ∈ [−H/2, H/2]` (METHOD's `u` is ours plus `W/2`),
//! so that for graph surfaces `x = u` and `y = v` exactly.
//!
//! A design is validated once, by [`Design::new`], and meshed straight from
//! its exact model; the mesh is a solid by construction, which
//! [`check::solid_checks`] measures:
//!
//! ```
//! use moirecast_kernel::{mesher::mesh_device, progress::Silent, Design, DesignParams, PitchSurface};
//!
//! // 8 lenses of 0.5 mm on a saddle, 4 mm long, meshed to 10 µm
//! let mut params = DesignParams::with_defaults(PitchSurface::Saddle { radius: 60.0 }, 4.0, 4.0, 0.5);
//! params.tolerance = 0.01;
//! let design = Design::new(params).expect("a valid design");
//! assert_eq!(design.lenses, 8);
//! let device = mesh_device(&design, &Silent).expect("meshed");
//! let checks = moirecast_kernel::check::solid_checks(&device.mesh);
//! assert!(checks.iter().all(|c| c.passed), "{checks:?}");
//! ```

pub mod check;
pub mod checks;
pub mod design;
pub mod device_mesh;
pub mod error;
pub mod formula;
pub mod grid;
pub mod heightmap;
pub mod lens;
pub mod measure;
pub mod mesh;
pub mod mesher;
pub mod model;
pub mod patch;
pub mod printed;
pub mod profile;
pub mod progress;
pub mod solve;
#[cfg(feature = "strategies")]
pub mod strategies;
pub mod surface;
pub mod tolerance;
pub mod view;

pub use design::{
    BaseKind, BaseParams, Design, DesignParams, LensParams, LensRule, MeshBudget, PrintedBase,
    StandardLens,
};
pub use error::{DesignError, KernelError, Param};
pub use mesh::Mesh;
pub use mesher::{DeviceMesh, MeshStats};
pub use model::BaseSection;
pub use profile::{Profile, ProfileMode, Raster};
pub use surface::PitchSurface;
pub use tolerance::Tolerance;
pub use view::{DesignView, ViewCompensation};
