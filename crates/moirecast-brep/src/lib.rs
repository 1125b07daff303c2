//! The moirecast device as an exact B-rep solid (truck), its STEP text, and
//! an independent tessellation of it (truck-meshalgo) to cross-check the
//! direct mesher. No I/O: STEP comes out as a `String`.
//!
//! The B-rep is built from the same exact model as the mesh, with the
//! topology of the mesher's face partition ([`topology`]); see [`solid`]
//! for what each face and edge is and what is guaranteed.
//!
//! [`mold`] builds a parting region of the mold (the block on one side of
//! the parting surface, floored by the device's faces) the same way, from
//! the region mesh's surface labels.
//!
//! ```
//! use moirecast_kernel::{mesher::mesh_device, progress::Silent, Design, DesignParams, PitchSurface};
//!
//! let mut params = DesignParams::with_defaults(PitchSurface::Saddle { radius: 60.0 }, 2.0, 2.0, 0.5);
//! params.tolerance = 0.01;
//! let design = Design::new(params).unwrap();
//! let device = mesh_device(&design, &Silent).unwrap();
//! let step = moirecast_brep::device_step(&design, &device, "device.step").unwrap();
//! assert_eq!(step.brep.stats.faces, 4 + 4 + 4); // revealer and base lenses, walls
//! assert!(step.step.len() > 0);
//! ```

pub(crate) mod channels;
pub mod crosscheck;
pub mod error;
pub mod lenses;
pub mod mold;
pub mod printed;
pub mod solid;
pub mod spline;
pub mod step;
pub mod topology;

pub use crosscheck::{compare, tessellate, verdicts, CrossCheck};
pub use error::BrepError;
pub use printed::{
    build_printed_brep, build_printed_brep_on, PrintedBrep, PrintedBrepStats, PrintedSurfaces,
};
pub use solid::{build_brep, BrepStats, DeviceBrep};
pub use step::{read_back_faces, step_file_of, step_text, step_text_of, StepText};

use moirecast_kernel::check::CheckResult;
use moirecast_kernel::mesher::DeviceMesh;
use moirecast_kernel::printed::PrintedBodies;
use moirecast_kernel::Design;

/// The device's B-rep, its STEP text and the check of its faces.
pub struct DeviceStep {
    pub brep: DeviceBrep,
    pub step: StepText,
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
    device_step_mapped(
        design,
        dm,
        (file_name, "moirecast device: level-line moire lens arrays"),
        None,
    )
}

/// [`device_step`] with the solid moved by `map` (a proper similarity, as
/// the mold's pose: it keeps the solid's orientation), exactly: NURBS
/// control points, planes and trims map as points.
pub fn device_step_mapped(
    design: &Design,
    dm: &DeviceMesh,
    (file_name, description): (&str, &str),
    map: Option<glam::DAffine3>,
) -> Result<DeviceStep, BrepError> {
    let mut brep = build_brep(design, dm)?;
    if let Some(map) = map {
        brep.solid = truck_modeling::builder::transformed(&brep.solid, mold::matrix_of(map));
    }
    let step = step_file_of(std::slice::from_ref(&brep.solid), file_name, description);
    let s = &brep.stats;
    let checks = vec![surface_fit_check(
        design,
        (
            s.max_surface_deviation_mm,
            &s.worst_surface,
            s.surface_fit_mm,
        ),
    )];
    Ok(DeviceStep { brep, step, checks })
}

/// The B-rep solids of a printed device's two bodies and their STEP texts.
pub struct PrintedStep {
    pub brep: PrintedBrep,
    /// `device-clear.step`: the clear body.
    pub clear_step: StepText,
    /// `device-black.step`: one solid per black band.
    pub black_step: StepText,
    /// `brep-surface-fit`, with its evidence.
    pub checks: Vec<CheckResult>,
}

/// Builds the B-rep of a printed design's bodies (meshed as `dm`, its
/// bodies `bodies`, its lens and band surfaces `surfaces`, fitted while
/// the bodies were built) and writes them as two STEP texts.
pub fn printed_step(
    surfaces: &PrintedSurfaces,
    dm: &DeviceMesh,
    bodies: &PrintedBodies,
) -> Result<PrintedStep, BrepError> {
    let design = surfaces.design();
    let brep = build_printed_brep_on(surfaces, dm, bodies)?;
    let (clear_step, black_step) = rayon::join(
        || {
            step_file_of(
                std::slice::from_ref(&brep.clear),
                "device-clear.step",
                "moirecast printed device: the clear body (lenses and backing)",
            )
        },
        || {
            step_file_of(
                &brep.bands,
                "device-black.step",
                "moirecast printed device: the black bands, one solid each",
            )
        },
    );
    let s = &brep.stats;
    let fit = (
        s.max_surface_deviation_mm,
        s.worst_surface.as_str(),
        s.surface_fit_mm,
    );
    let checks = vec![surface_fit_check(design, fit)];
    Ok(PrintedStep {
        brep,
        clear_step,
        black_step,
        checks,
    })
}

/// `brep-surface-fit`: the worst sampled distance (mm) of a lens or band
/// face from its exact section, where it is, and the fit the stations were
/// refined to; within the tolerance.
fn surface_fit_check(design: &Design, (deviation, worst, fit_mm): (f64, &str, f64)) -> CheckResult {
    CheckResult::at_most(
        "brep-surface-fit",
        deviation,
        design.tolerance.mm(),
        "mm",
        format!(
            "worst sampled distance of a lens or band face from its exact section, {worst}; stations refined to {fit_mm} mm"
        ),
    )
}
