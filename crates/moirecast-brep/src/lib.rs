//! The moirecast device as an exact B-rep solid (truck), its STEP text, and
//! an independent tessellation of it (truck-meshalgo) to cross-check the
//! direct mesher. No I/O: STEP comes out as a `String`.
//!
//! The B-rep is built from the same exact model as the mesh, with the
//! topology of the mesher's face partition ([`topology`]); see [`solid`]
//! for what each face and edge is and what is guaranteed.

pub mod crosscheck;
pub mod error;
pub mod lenses;
pub mod solid;
pub mod spline;
pub mod step;
pub mod topology;

pub use crosscheck::{compare, tessellate, verdicts, CrossCheck};
pub use error::BrepError;
pub use solid::{build_brep, BrepStats, DeviceBrep};
pub use step::{read_back_faces, step_text};

use moirecast_kernel::check::CheckResult;
use moirecast_kernel::mesher::DeviceMesh;
use moirecast_kernel::Design;

/// The device's B-rep, its STEP text and the check of its faces.
pub struct DeviceStep {
    pub brep: DeviceBrep,
    pub step: String,
    /// `brep-surface-fit`, with its evidence. (A shell that is not closed
    /// is an error of [`build_brep`] itself.)
    pub checks: Vec<CheckResult>,
}

/// Builds the B-rep of the device meshed as `dm` and writes it as STEP
/// text named `file_name`. Reading the text back ([`read_back_faces`]) is
/// left to the tests: it takes three times as long as building and writing.
pub fn device_step(
    design: &Design,
    dm: &DeviceMesh,
    file_name: &str,
) -> Result<DeviceStep, BrepError> {
    let brep = build_brep(design, dm)?;
    let step = step_text(
        &brep.solid,
        file_name,
        "moirecast device: level-line moire lens arrays",
    );
    let s = &brep.stats;
    let checks = vec![CheckResult::at_most(
        "brep-surface-fit",
        s.max_surface_deviation_mm,
        design.tolerance.mm(),
        "mm",
        format!(
            "worst sampled distance of a lens face from its exact lens, {}; stations refined to {} mm",
            s.worst_surface, s.surface_fit_mm
        ),
    )];
    Ok(DeviceStep { brep, step, checks })
}
