//! `moirecast device` for a printed (multi-material) design (METHOD §5.2):
//! the clear body and the black bands as two STLs and one 3MF, checked
//! before anything is written.

use crate::report::{self, DutyReport, FileReport, PrintedBrepReport, PrintedReport};
use crate::{
    commit_with_report, measure_device, refuse_failed, DeviceBuild, DeviceOutcome, RunError,
    StepFile, Thoroughness,
};
use anyhow::{Context, Result};
use moirecast_export::{stl_bytes, threemf_file, Material, Object, OutputSet, ThreemfFile};
use moirecast_kernel::check::{CheckResult, SolidMesh, SolidSpec};
use moirecast_kernel::mesher::DeviceMesh;
use moirecast_kernel::printed::{duty_along_lines, printed_bodies, LineDuty, PrintedBodies};
use moirecast_kernel::progress::Progress;
use moirecast_kernel::{BaseKind, Design, PrintedBase};
use moirecast_spec::Spec;
use std::path::Path;

/// Sample lines for the duty cycle along lines.
const DUTY_LINES: usize = 33;
/// How closely the two bodies must add up to the whole device (relative):
/// they share every vertex, so only round-off separates the sums.
const FILL_RELATIVE: f64 = 1e-9;

/// The clear material's display colour: a light, translucent blue-grey.
pub const CLEAR: Material = Material {
    name: "clear",
    display_color: [0xE6, 0xF0, 0xFA, 0x80],
};
/// The black material.
pub const BLACK: Material = Material {
    name: "black",
    display_color: [0x10, 0x10, 0x10, 0xFF],
};

/// The two bodies of a printed design, with what was measured of them
/// (their solid checks come with [`PrintedBuild::solids`]).
pub struct PrintedBuild {
    pub bodies: PrintedBodies,
    pub checks: Vec<CheckResult>,
    pub report: PrintedReport,
}

impl PrintedBuild {
    /// The solid checks (METHOD §7.1) of the clear body (its genus: one
    /// tunnel per band that runs wall to wall), the black bands (one shell
    /// each) and the whole device, run once; the two bodies as solids if
    /// they all passed.
    pub fn solids(&self) -> (Vec<CheckResult>, Option<[SolidMesh<'_>; 2]>) {
        let (checks, solids) = body_solids(&self.bodies);
        (checks, solids.map(|[clear, black, _]| [clear, black]))
    }
}

/// [`PrintedBuild::solids`] of `b`.
fn body_solids(b: &PrintedBodies) -> (Vec<CheckResult>, Option<[SolidMesh<'_>; 3]>) {
    let spec = |genus, shells| SolidSpec {
        genus,
        shells,
        ..SolidSpec::DEVICE
    };
    // the three meshes are checked at once, reported in this order
    use rayon::prelude::*;
    let results: Vec<_> = [
        ("device-clear.stl", &b.clear, spec(b.clear_genus, 1)),
        ("device-black.stl", &b.black, spec(0, b.bands)),
        ("the whole device", &b.slab, spec(0, 1)),
    ]
    .into_par_iter()
    .map(|(file, mesh, spec)| {
        let (found, solid) = SolidMesh::validate_for(mesh, spec);
        let found: Vec<CheckResult> = found
            .into_iter()
            .map(|mut c| {
                c.detail = format!("{file}: {}", c.detail);
                c
            })
            .collect();
        (found, solid)
    })
    .collect();
    let (checks, solids): (Vec<Vec<CheckResult>>, Vec<_>) = results.into_iter().unzip();
    let checks = checks.concat();
    let all = match solids[..] {
        [Some(clear), Some(black), Some(slab)] => Some([clear, black, slab]),
        _ => None,
    };
    (checks, all)
}

fn printed_base(design: &Design) -> PrintedBase {
    match design.params.base.kind {
        BaseKind::Printed(pb) => pb,
        BaseKind::DualLens => unreachable!("callers build printed designs only"),
    }
}

/// Builds the clear and black bodies from the checked device mesh and
/// measures them: together exactly the device, and the duty cycle by
/// volume and along lines.
pub fn build_printed(design: &Design, mesh: &DeviceMesh) -> Result<PrintedBuild> {
    let bodies = printed_bodies(design, mesh).context("building the printed bodies")?;
    let (volumes, lines) = rayon::join(
        || [&bodies.clear, &bodies.black, &bodies.slab].map(|m| m.volume()),
        || duty_along_lines(design, mesh, DUTY_LINES),
    );
    let (checks, report) = measure_printed(design, &bodies, volumes, &lines);
    Ok(PrintedBuild {
        bodies,
        checks,
        report,
    })
}

/// What is measured of the bodies, given the volumes (mm³) of the clear
/// body, the black bands and the whole device, and the duty along lines:
/// the fill check (clear and black add up to the device) and the report's
/// volumes and duty cycle.
fn measure_printed(
    design: &Design,
    bodies: &PrintedBodies,
    [clear, black, slab]: [f64; 3],
    lines: &LineDuty,
) -> (Vec<CheckResult>, PrintedReport) {
    let pb = printed_base(design);
    let mut checks = Vec::new();
    checks.push(CheckResult::at_most(
        "bodies-fill-device",
        ((clear + black) - slab).abs() / slab,
        FILL_RELATIVE,
        "relative",
        format!("|V(clear) + V(black) − V(device)| / V(device); V(device) = {slab:.6} mm³"),
    ));
    let layer = bodies.layer_area * pb.band_thickness;
    // over whole periods: the walls cut the first and last period anywhere
    let by_volume = bodies.black_area_whole / bodies.layer_area_whole;
    let report = PrintedReport {
        bands: bodies.bands,
        clear_genus: bodies.clear_genus,
        clear_volume_mm3: clear,
        black_volume_mm3: black,
        device_volume_mm3: slab,
        band_layer_volume_mm3: layer,
        duty: DutyReport {
            asked: pb.duty,
            by_volume,
            by_volume_whole_layer: black / layer,
            along_lines: lines.duty,
            worst_line_deviation: lines.worst_line_deviation,
            lines: lines.lines,
            periods: lines.periods,
        },
        wall_touches: bodies.wall_touches.touches,
        wall_touch_shift_mm: bodies.wall_touches.max_shift_mm,
        brep: None,
    };
    (checks, report)
}

/// The printed device's files, encoded, and what was checked of them.
struct PrintedFiles {
    bodies: PrintedBodies,
    /// The bodies' solid checks, passed or not, and (if they passed) the
    /// fill check.
    checks: Vec<CheckResult>,
    /// The report's numbers and `device-clear.stl`, `device-black.stl` and
    /// `device.3mf`, if the bodies passed their solid checks.
    solid: Option<(PrintedReport, Encoded)>,
    step: Result<moirecast_brep::PrintedStep>,
}

/// The two STLs (with their reports) and the 3MF.
struct Encoded {
    stls: [(&'static str, FileReport, Vec<u8>); 2],
    threemf: ThreemfFile,
}

/// Builds the bodies from the device mesh `mesh` (solid, not yet
/// measured), then side by side: their B-rep and STEP; the duty cycle
/// along lines; their solid checks and, if passed, their STLs and 3MF. The
/// B-rep's lens and band surfaces are fitted while the bodies are built;
/// the volumes are those the solid checks measured.
fn printed_files(spec: &Spec, mesh: &DeviceMesh) -> Result<PrintedFiles> {
    let design = &spec.design;
    // the bodies first on this thread: everything after waits for them,
    // while the B-rep's surfaces are needed only for their B-rep
    let (bodies, surfaces) = rayon::join(
        || {
            printed_bodies(design, mesh)
                .map_err(|e| RunError::kernel(spec, "building the printed bodies", e))
        },
        || moirecast_brep::PrintedSurfaces::fit(design, mesh),
    );
    let bodies = bodies?;
    let (step, (lines, (mut checks, solids))) = rayon::join(
        || {
            surfaces
                .and_then(|surfaces| moirecast_brep::printed_step(&surfaces, mesh, &bodies))
                .context("building the printed bodies' B-rep")
        },
        || {
            rayon::join(
                || duty_along_lines(design, mesh, DUTY_LINES),
                || {
                    let (checks, solids) = body_solids(&bodies);
                    let encoded = solids.map(|[clear, black, slab]| {
                        let volumes = [clear, black, slab].map(|s| s.volume());
                        (volumes, encode([clear, black]))
                    });
                    (checks, encoded)
                },
            )
        },
    );
    let solid = match solids {
        Some((volumes, encoded)) => {
            let (fill, report) = measure_printed(design, &bodies, volumes, &lines);
            checks.extend(fill);
            Some((report, encoded?))
        }
        None => None,
    };
    Ok(PrintedFiles {
        bodies,
        checks,
        solid,
        step,
    })
}

/// The bodies' STLs and 3MF, encoded side by side.
fn encode([clear, black]: [SolidMesh; 2]) -> Result<Encoded> {
    let ((clear_stl, black_stl), threemf) = rayon::join(
        || {
            rayon::join(
                || stl_bytes("device-clear.stl", clear),
                || stl_bytes("device-black.stl", black),
            )
        },
        || {
            threemf_file(
                "device.3mf",
                &[
                    Object {
                        name: "clear",
                        solid: clear,
                        material: CLEAR,
                    },
                    Object {
                        name: "black",
                        solid: black,
                        material: BLACK,
                    },
                ],
            )
        },
    );
    let stl = |name, solid: SolidMesh, bytes: Vec<u8>| {
        (name, FileReport::of(solid.mesh(), bytes.len()), bytes)
    };
    Ok(Encoded {
        stls: [
            stl("device-clear.stl", clear, clear_stl?),
            stl("device-black.stl", black, black_stl?),
        ],
        threemf: threemf?,
    })
}

/// Writes `device-clear.stl`, `device-black.stl`, `device.3mf`,
/// `device-clear.step`, `device-black.step` and `report.json` for a
/// printed design meshed as `mesh`: the device mesh's solid checks first
/// (the bodies are cut from it), then its measurements beside the bodies'
/// whole build; every check passed before anything is written.
pub(crate) fn write_printed_device(
    spec: &Spec,
    mesh: DeviceMesh,
    thoroughness: Thoroughness,
    out: &Path,
    progress: &dyn Progress,
) -> Result<DeviceOutcome> {
    let design = &spec.design;
    progress.stage("checking", 1);
    let (mut checks, _) = SolidMesh::validate(&mesh.mesh);
    refuse_failed(&checks)?;
    progress.tick(1);
    progress.stage("measuring; printed bodies, B-rep and STEP", 1);
    // the bodies' build on this thread: it is the longer, and its serial
    // stretches leave room for the measurements
    let (printed, (lens_stats, measured)) = rayon::join(
        || printed_files(spec, &mesh),
        || measure_device(design, &mesh, thoroughness),
    );
    // reported in the order they ran before: the device's, then the bodies'
    checks.extend(measured.iter().cloned());
    refuse_failed(&checks)?;
    let printed = printed?;
    checks.extend(printed.checks.iter().cloned());
    refuse_failed(&checks)?;
    let (mut printed_report, encoded) = printed
        .solid
        .context("the printed bodies passed their solid checks")?;
    let step = printed.step?;
    refuse_failed(&step.checks)?;
    checks.extend(step.checks.iter().cloned());
    progress.tick(1);
    progress.stage("writing", 1);
    let mut files = OutputSet::new();
    let mut reports = std::collections::BTreeMap::new();
    for (name, report, bytes) in encoded.stls {
        reports.insert(name.to_string(), report);
        files.add(name, bytes);
    }
    files.add("device.3mf", encoded.threemf);
    let device_volume = printed_report.device_volume_mm3;
    printed_report.brep = Some(PrintedBrepReport {
        clear_step_bytes: step.clear_step.len(),
        black_step_bytes: step.black_step.len(),
        stats: step.brep.stats.clone(),
    });
    files.add("device-clear.step", StepFile(step.clear_step));
    files.add("device-black.step", StepFile(step.black_step));
    let build = DeviceBuild {
        mesh,
        lens_stats,
        checks: measured,
    };
    let report = report::device_report(
        spec,
        &build,
        &checks,
        report::DeviceOutputs {
            files: reports,
            step: None,
            printed: Some(printed_report),
            crosscheck: None,
        },
    );
    let (written, bytes) = commit_with_report(files, spec, &report, out)?;
    progress.tick(1);
    let b = &printed.bodies;
    let outcome = DeviceOutcome::new(
        written,
        b.clear.triangles.len() + b.black.triangles.len(),
        device_volume,
        bytes,
        &checks,
    );
    moirecast_export::free_in_background((build, printed.bodies, step.brep));
    Ok(outcome)
}
