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

pub mod check;
pub mod design;
pub mod device_mesh;
pub mod error;
pub mod lens;
pub mod measure;
pub mod mesh;
pub mod mesher;
pub mod model;
pub mod printed;
pub mod profile;
pub mod progress;
pub mod solve;
#[cfg(feature = "strategies")]
pub mod strategies;
pub mod surface;
pub mod tolerance;

pub use design::{
    BaseKind, BaseParams, Design, DesignParams, LensParams, LensRule, PrintedBase, StandardLens,
};
pub use error::{DesignError, KernelError, Param};
pub use mesh::Mesh;
pub use mesher::{DeviceMesh, MeshStats};
pub use model::BaseSection;
pub use profile::{Profile, ProfileMode, Raster};
pub use surface::PitchSurface;
pub use tolerance::Tolerance;
