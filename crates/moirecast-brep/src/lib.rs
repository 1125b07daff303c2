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

mod array;
pub(crate) mod channels;
pub mod crosscheck;
pub mod ends;
pub mod error;
pub mod lenses;
pub mod mold;
mod patch;
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

/// The mold's halves as exact B-rep solids, their STEP texts, and their
/// checks.
pub struct MoldStep {
    pub top: mold::RegionBrep,
    pub bottom: mold::RegionBrep,
    /// `mold-top.step` and `mold-bottom.step`.
    pub top_step: StepText,
    pub bottom_step: StepText,
    /// `mold-brep-euler`, `mold-brep-fit`, `mold-brep-channels-fit`,
    /// `mold-brep-samples-fit`, `mold-brep-channel-samples-fit` and
    /// `mold-brep-device-samples-fit`, with
    /// their evidence. (A shell that is not closed is an error of
    /// [`mold::half_brep`] itself.)
    pub checks: Vec<CheckResult>,
}

/// Builds both halves of `mold` (of the device meshed as `dm`) as exact
/// B-rep solids ([`mold::half_brep`]) on `device`'s lens surfaces (built
/// once for the device and both halves), and writes each as STEP text.
pub fn mold_step(
    design: &Design,
    dm: &DeviceMesh,
    mold: &moirecast_mold::Mold,
    device: &DeviceBrep,
) -> Result<MoldStep, BrepError> {
    let half = |top: bool| -> Result<(mold::RegionBrep, StepText), BrepError> {
        let b = mold::half_brep(design, dm, mold, (device, top))?;
        let (name, description) = if top {
            (
                "mold-top.step",
                "moirecast mold: the top half, with its sprue, pour cone, vents and key sockets",
            )
        } else {
            (
                "mold-bottom.step",
                "moirecast mold: the bottom half, with its key bumps",
            )
        };
        let step = step_file_of(std::slice::from_ref(&b.solid), name, description);
        Ok((b, step))
    };
    let (top, bottom) = rayon::join(|| half(true), || half(false));
    let ((top, top_step), (bottom, bottom_step)) = (top?, bottom?);
    let checks = mold_brep_checks(design, mold, (&top, &bottom));
    Ok(MoldStep {
        top,
        bottom,
        top_step,
        bottom_step,
        checks,
    })
}

/// Facets on a full circle of the mesh halves' channels and keys.
const CHANNEL_FACETS: f64 = 48.0;

/// The checks of the halves' B-reps against their meshes.
fn mold_brep_checks(
    design: &Design,
    mold: &moirecast_mold::Mold,
    (top, bottom): (&mold::RegionBrep, &mold::RegionBrep),
) -> Vec<CheckResult> {
    let euler = |b: &mold::RegionBrep, genus: u32| {
        let chi = b.vertices as i64 - b.edges as i64 + b.faces as i64 - b.rings as i64;
        (
            (chi - 2 * (1 - i64::from(genus))).abs(),
            format!(
                "V {} - E {} + F {} - inner loops {} = {chi}, genus {genus}",
                b.vertices, b.edges, b.faces, b.rings
            ),
        )
    };
    let (et, dt) = euler(top, mold.genus_top);
    let (eb, db) = euler(bottom, mold.genus_bottom);
    // the worse half's measure
    let worst = |of: fn(&mold::Fit) -> (f64, glam::DVec3)| {
        let (a, b) = (of(&top.fit), of(&bottom.fit));
        if b.0 > a.0 {
            b
        } else {
            a
        }
    };
    let (block, block_at) = worst(|f| (f.block_mm, f.block_at));
    let (channels, channels_at) = worst(|f| (f.channels_mm, f.channels_at));
    let (samples, samples_at) = worst(|f| (f.samples_mm, f.samples_at));
    let (channel_samples, channel_samples_at) =
        worst(|f| (f.channel_samples_mm, f.channel_samples_at));
    let (device_samples, device_samples_at) = worst(|f| (f.device_samples_mm, f.device_samples_at));
    let sampled = top.fit.samples + bottom.fit.samples;
    // the widest channel or key, whose 48-gon's flats sag most
    let exact = &mold.exact;
    let widest = exact
        .channels
        .iter()
        .map(|c| c.radii.0.max(c.radii.1))
        .chain(
            exact
                .bumps
                .iter()
                .map(|b| b.bottom[0].truncate().distance(b.centre)),
        )
        .fold(0.0f64, f64::max);
    let sag = widest * (1.0 - (std::f64::consts::PI / CHANNEL_FACETS).cos());
    // f32 rounding of the mesh's vertices, a few steps at the block's extent
    let extent = exact
        .footprint
        .x0
        .abs()
        .max(exact.footprint.x1.abs())
        .max(exact.footprint.y0.abs())
        .max(exact.footprint.y1.abs());
    let f32_step = 4.0 * extent * f64::from(f32::EPSILON);
    vec![
        CheckResult::at_most(
            "mold-brep-euler",
            (et + eb) as f64,
            0.0,
            "",
            format!("each half's B-rep is one closed shell; top: {dt}; bottom: {db}"),
        ),
        CheckResult::at_most(
            "mold-brep-fit",
            block,
            design.tolerance.mm(),
            "mm",
            format!(
                "worst distance of a mesh half's vertex from its B-rep face's exact surface (walls, skirt, block, and lens vertices the channels made), at ({:.3}, {:.3}, {:.3})",
                block_at.x, block_at.y, block_at.z
            ),
        ),
        CheckResult::at_most(
            "mold-brep-channels-fit",
            channels,
            sag + f32_step,
            "mm",
            format!(
                "worst distance of a mesh half's vertex on a channel or key from its exact cylinder or cone, at ({:.3}, {:.3}, {:.3}); the limit is the sag of the widest one's 48-gon ({sag:.6} mm) and f32 rounding",
                channels_at.x, channels_at.y, channels_at.z
            ),
        ),
        CheckResult::at_most(
            "mold-brep-samples-fit",
            samples,
            design.tolerance.mm() + f32_step,
            "mm",
            format!(
                "worst distance from the mesh half of {sampled} points sampled on both halves' B-rep faces (each mesh triangle's centroid carried onto its face's exact surface, and points along every edge's curve; here those on the mold's own faces and edges, off the channels, keys and lenses), at ({:.3}, {:.3}, {:.3}); the limit is the tolerance and the f32 rounding of the half's vertices",
                samples_at.x, samples_at.y, samples_at.z
            ),
        ),
        CheckResult::at_most(
            "mold-brep-channel-samples-fit",
            channel_samples,
            sag + design.tolerance.mm() + f32_step,
            "mm",
            format!(
                "the same on the channels' and keys' sides and ends, at ({:.3}, {:.3}, {:.3}); the limit is the widest 48-gon's sag, the tolerance (an edge where a channel meets a lens is within the sag of one and the tolerance of the other) and f32 rounding",
                channel_samples_at.x, channel_samples_at.y, channel_samples_at.z
            ),
        ),
        CheckResult::at_most(
            "mold-brep-device-samples-fit",
            device_samples,
            2.0 * design.tolerance.mm() + f32_step,
            "mm",
            format!(
                "the same on the device's lens faces and the creases and rims they bound, at ({:.3}, {:.3}, {:.3}); these carry the device B-rep's NURBS, which lie within the tolerance of the exact model (brep-surface-fit), as the mesh does: the limit is twice the tolerance and f32 rounding (found-759cc4db2bedb3ff: a fitted crease 1.54 µm from its mesh run, at a tolerance of 1.43 µm)",
                device_samples_at.x, device_samples_at.y, device_samples_at.z
            ),
        ),
    ]
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
