//! The `moirecast` pipelines behind the command line: spec → exact model →
//! mesh → checks → files. The binary (`main.rs`) only parses arguments and
//! draws progress.
//!
//! ```
//! use moirecast_kernel::progress::Silent;
//!
//! let spec = moirecast_spec::parse(
//!     "[surface]\nkind = \"plane\"\n[layout]\nwidth = 3\nheight = 3\n[profile]\nkind = \"flat\"\n[mesh]\ntolerance = 0.01",
//!     "small.toml",
//!     moirecast_spec::ImageSource::Embedded,
//! )
//! .unwrap();
//! let out = std::env::temp_dir().join("moirecast-doc-device");
//! let done = moirecast::run_device(&spec, &out, Default::default(), Default::default(), &Silent).unwrap();
//! assert!(out.join("device.stl").exists() && out.join("device.step").exists());
//! assert!(done.checks > 10);
//! ```

pub mod errors;
pub mod explore;
pub mod mold_report;
pub mod printed;
pub mod render;
pub mod report;
pub mod studio;

use anyhow::{bail, Context, Result};
use moirecast_export::{stl_bytes, OutputSet};
use moirecast_kernel::check::{CheckResult, SolidMesh, SolidSpec};
use moirecast_kernel::mesher::{mesh_device, DeviceMesh};
use moirecast_kernel::progress::Progress;
use moirecast_kernel::{measure, Design};
use moirecast_spec::Spec;
use std::path::{Path, PathBuf};

pub use errors::RunError;

/// Vertices re-projected onto their exact surfaces for the report
/// (tests check every vertex; this keeps the command fast).
const REPORT_VERTEX_SAMPLES: usize = 5000;
/// Lens triangles sampled for the surface-to-mesh bound in the report.
const REPORT_TRIANGLE_SAMPLES: usize = 20000;

/// Everything measured about one device build.
pub struct DeviceBuild {
    pub mesh: DeviceMesh,
    pub lens_stats: measure::LensStats,
    /// Measurements against the exact model (METHOD §7.2–§7.3).
    pub checks: Vec<CheckResult>,
}

impl DeviceBuild {
    /// Runs the solid checks (METHOD §7.1) once: all checks, solid ones
    /// first, and the mesh as a [`SolidMesh`] if those passed.
    pub fn validated(&self) -> (Vec<CheckResult>, Option<SolidMesh<'_>>) {
        let (mut checks, solid) = SolidMesh::validate(&self.mesh.mesh);
        checks.extend(self.checks.iter().cloned());
        (checks, solid)
    }
}

/// The measured-AFOV check: every measured revealer arc spans α
/// (constant-AFOV lenses only; equal-radius lenses vary by design).
fn afov_check(design: &Design, stats: &measure::LensStats) -> Option<CheckResult> {
    if design.params.lens.rule != moirecast_kernel::LensRule::ConstantAfov {
        return None;
    }
    let alpha = design.params.lens.afov.to_degrees();
    let dev = (stats.afov_deg.min - alpha)
        .abs()
        .max((stats.afov_deg.max - alpha).abs());
    Some(CheckResult::at_most(
        "measured-afov",
        dev,
        1e-6,
        "degrees",
        format!("largest |measured − α| over {} arcs", stats.arcs),
    ))
}

/// How thoroughly the measurements against the exact model run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Thoroughness {
    /// Sampled: a few thousand vertices and lens triangles (fast).
    #[default]
    Sampled,
    /// Every vertex and every lens triangle.
    Full,
}

/// Builds and checks the device mesh (METHOD §7.1–§7.3) with sampled
/// measurements. Checks that fail are returned, not raised: the caller decides.
pub fn build_device(design: &Design, progress: &dyn Progress) -> Result<DeviceBuild> {
    build_device_checked(design, Thoroughness::Sampled, progress)
}

/// [`build_device`] with a choice of how thoroughly to measure.
pub fn build_device_checked(
    design: &Design,
    thoroughness: Thoroughness,
    progress: &dyn Progress,
) -> Result<DeviceBuild> {
    let mesh = mesh_device(design, progress).context("meshing the device")?;
    progress.stage("checking", 1);
    let (lens_stats, checks) = measure_device(design, &mesh, thoroughness);
    progress.tick(1);
    Ok(DeviceBuild {
        mesh,
        lens_stats,
        checks,
    })
}

/// Meshes `spec`'s device; a design rule the mesher finds broken (the
/// mesh budget) is the spec's error, anything else a bug.
pub fn mesh_spec(spec: &Spec, progress: &dyn Progress) -> Result<DeviceMesh, RunError> {
    mesh_device(&spec.design, progress).map_err(|e| RunError::kernel(spec, "meshing the device", e))
}

/// Measures the device mesh `mesh` against the exact model of `design`
/// (METHOD §7.2–§7.3): the lens statistics and the checks, passed or not.
pub fn measure_device(
    design: &Design,
    mesh: &DeviceMesh,
    thoroughness: Thoroughness,
) -> (measure::LensStats, Vec<CheckResult>) {
    let mut checks = Vec::new();
    let (v_stride, t_stride) = match thoroughness {
        Thoroughness::Full => (1, 1),
        Thoroughness::Sampled => (
            (mesh.mesh.positions.len() / REPORT_VERTEX_SAMPLES).max(1),
            (mesh.mesh.triangles.len() / REPORT_TRIANGLE_SAMPLES).max(1),
        ),
    };
    checks.push(measure::vertex_on_surface(design, mesh, v_stride));
    checks.push(measure::surface_to_mesh(design, mesh, t_stride));
    checks.push(measure::walls_on_outline(design, mesh));
    checks.push(measure::walls_face_out(mesh));
    checks.push(measure::creases_shared(design, mesh));
    checks.push(measure::base_creases_follow_shift(design, mesh, v_stride));
    checks.push(measure::surfaces_are_graphs(mesh));
    checks.push(measure::min_thickness(design, mesh, v_stride));
    let lens_stats = measure::revealer_lens_stats(design, mesh);
    checks.extend(afov_check(design, &lens_stats));
    checks.push(CheckResult::at_most(
        "arcs-are-circles",
        lens_stats.circle_residual,
        1e-9,
        "mm",
        "largest distance of a station-row vertex from its lens circle".into(),
    ));
    (lens_stats, checks)
}

/// What `moirecast device` wrote, for the summary it prints.
pub struct DeviceOutcome {
    pub written: Vec<PathBuf>,
    pub triangles: usize,
    pub volume_mm3: f64,
    pub bytes: usize,
    pub checks: usize,
    pub worst_surface_error_mm: f64,
}

impl DeviceOutcome {
    fn new(
        written: Vec<PathBuf>,
        triangles: usize,
        volume_mm3: f64,
        bytes: usize,
        checks: &[CheckResult],
    ) -> Self {
        DeviceOutcome {
            written,
            triangles,
            volume_mm3,
            bytes,
            checks: checks.len(),
            worst_surface_error_mm: checks
                .iter()
                .find(|c| c.name == "surface-to-mesh")
                .map_or(f64::NAN, |c| c.value),
        }
    }
}

/// Which path from the exact model to `device.stl`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mesher {
    /// Our mesher, straight from the exact model (the production mesh).
    #[default]
    Direct,
    /// truck-meshalgo's tessellation of the B-rep, welded, and
    /// cross-checked against the direct mesh (slow; an independent path).
    Brep,
}

/// `moirecast device`: builds the device of `spec` and writes
/// `device.stl`, `device.step` and `report.json` into `out` — all of them,
/// or nothing.
pub fn run_device(
    spec: &Spec,
    out: &Path,
    thoroughness: Thoroughness,
    mesher: Mesher,
    progress: &dyn Progress,
) -> Result<DeviceOutcome> {
    if let moirecast_kernel::BaseKind::Printed(_) = spec.design.params.base.kind {
        if mesher == Mesher::Brep {
            bail!("--mesher brep writes the truck-meshalgo tessellation of a dual-lens device's B-rep as its STL; a printed device's two bodies come from the direct mesher only (their B-rep is written as STEP); leave it out for a printed device");
        }
        let mesh = mesh_spec(spec, progress)?;
        return printed::write_printed_device(spec, mesh, thoroughness, out, progress);
    }
    let design = &spec.design;
    let mesh = mesh_spec(spec, progress)?;
    progress.stage("checking, B-rep and STEP", 1);
    // the B-rep is built from the mesh only once it is solid; the
    // measurements, which only read it, and the STL run beside it
    let (mut checks, solid) = SolidMesh::validate(&mesh.mesh);
    refuse_failed(&checks)?;
    let ((lens_stats, measured), (step, direct_stl)) = rayon::join(
        || measure_device(design, &mesh, thoroughness),
        || {
            rayon::join(
                || moirecast_brep::device_step(design, &mesh, "device.step"),
                || {
                    (mesher == Mesher::Direct)
                        .then(|| stl_bytes("device.stl", solid.expect("the solid checks passed")))
                },
            )
        },
    );
    // refused in the order they are reported: solid checks, measurements,
    // then the B-rep's
    checks.extend(measured.iter().cloned());
    refuse_failed(&checks)?;
    let step = step.map_err(|e| RunError::Internal {
        stage: "building the B-rep",
        detail: e.to_string(),
    })?;
    refuse_failed(&step.checks)?;
    checks.extend(step.checks.iter().cloned());
    let build = DeviceBuild {
        mesh,
        lens_stats,
        checks: measured,
    };
    progress.tick(1);
    let cross = match mesher {
        Mesher::Direct => None,
        Mesher::Brep => {
            progress.stage("truck-meshalgo", 1);
            let design = &spec.design;
            let tol = design.tolerance.mm();
            let mesh = moirecast_brep::tessellate(&step.brep.solid, tol)
                .context("tessellating the B-rep with truck-meshalgo")?;
            let cross = moirecast_brep::compare(&mesh, &build.mesh.mesh);
            let verdicts = moirecast_brep::verdicts(&mesh, &cross, tol, lens_area(&build.mesh));
            refuse_failed(&verdicts)?;
            checks.extend(verdicts);
            progress.tick(1);
            Some((mesh, cross))
        }
    };
    progress.stage("writing", 1);
    let (stl, stl_mesh) = match &cross {
        None => (
            direct_stl.expect("encoded for the direct mesher")?,
            &build.mesh.mesh,
        ),
        Some((mesh, _)) => {
            let (_, solid) = SolidMesh::validate(mesh);
            let solid = solid.context("the welded tessellation passed brep-mesh-solid")?;
            (stl_bytes("device.stl", solid)?, mesh)
        }
    };
    let report = report::device_report(
        spec,
        &build,
        &checks,
        report::DeviceOutputs {
            files: [(
                "device.stl".to_string(),
                report::FileReport::of(stl_mesh, stl.len()),
            )]
            .into(),
            step: Some(&step),
            printed: None,
            crosscheck: cross.as_ref().map(|(_, c)| c),
        },
    );
    let mut files = OutputSet::new();
    files.add("device.stl", stl);
    files.add("device.step", StepFile(step.step));
    let (written, bytes) = commit_with_report(files, spec, &report, out)?;
    progress.tick(1);
    let outcome = DeviceOutcome::new(
        written,
        stl_mesh.triangles.len(),
        report.files["device.stl"].volume_mm3,
        bytes,
        &checks,
    );
    moirecast_export::free_in_background((build, step.brep, cross));
    Ok(outcome)
}

/// A STEP file staged in its pieces (never joined in memory).
pub(crate) struct StepFile(pub moirecast_brep::StepText);

impl moirecast_export::FileContent for StepFile {
    fn size(&self) -> usize {
        self.0.len()
    }
    fn pieces(&self) -> Vec<&[u8]> {
        self.0.pieces().map(str::as_bytes).collect()
    }
}

/// Area (mm²) of the lens faces of the direct mesh.
fn lens_area(dm: &DeviceMesh) -> f64 {
    dm.mesh
        .triangles
        .iter()
        .zip(&dm.patches)
        .filter(|(_, p)| matches!(p, moirecast_kernel::mesher::Patch::Lens(_)))
        .map(|(t, _)| dm.mesh.triangle_area(t))
        .sum()
}

/// An error naming the first failed check and its evidence, if one failed:
/// on an accepted spec, a bug.
pub(crate) fn refuse_failed(checks: &[CheckResult]) -> Result<(), RunError> {
    RunError::first_failed(checks, "")
}

/// Adds `report.json` to `files` and writes them all (or none) into `out`;
/// returns the paths written and their total size.
pub(crate) fn commit_with_report(
    mut files: OutputSet,
    spec: &Spec,
    report: &impl serde::Serialize,
    out: &Path,
) -> Result<(Vec<PathBuf>, usize)> {
    add_spec(&mut files, &spec.source)?;
    // the report lists every other file of the run with its SHA-256
    #[derive(serde::Serialize)]
    struct WithDigests<'a, R: serde::Serialize> {
        #[serde(flatten)]
        report: &'a R,
        sha256: std::collections::BTreeMap<String, String>,
    }
    let sha256 = files.digests().into_iter().collect();
    let text = serde_json::to_string_pretty(&WithDigests { report, sha256 })?;
    files.add("report.json", (text + "\n").into_bytes());
    let bytes = files.sizes().iter().map(|(_, b)| b).sum();
    Ok((files.commit_run(out)?, bytes))
}

/// The run's own copy of the spec that made it, so that its folder can be
/// rebuilt (`moirecast device DIR/spec.toml`): `spec.toml`, the exact text,
/// and the images it read (a profile's, a height map's), at the paths the
/// spec names. An image named outside the folder (`..`, an absolute path)
/// or by a run's own file name is kept as `profiles/NAME` (a profile) or
/// `surfaces/NAME` (a height map) instead, and only the copy's key says so.
fn add_spec(files: &mut OutputSet, source: &moirecast_spec::SpecSource) -> Result<()> {
    use moirecast_spec::{EditValue, SpecEdit};
    use std::path::Component;
    let mut text = source.text.clone();
    for image in &source.images {
        let (name, path) = (&image.name, Path::new(&image.name));
        let taken = files.sizes().iter().any(|(n, _)| n == name) || name == "spec.toml";
        let inside = path.components().all(|c| matches!(c, Component::Normal(_)));
        let kept = if inside && !taken {
            name.clone()
        } else {
            let folder = if image.key == "surface.image" {
                "surfaces"
            } else {
                "profiles"
            };
            let file = path
                .file_name()
                .map_or("image.png".into(), |f| f.to_string_lossy());
            let kept = format!("{folder}/{file}");
            let edit = SpecEdit {
                key: image.key.into(),
                value: Some(EditValue::Text(kept.clone())),
            };
            text = moirecast_spec::apply_edits(&text, &[edit])?;
            kept
        };
        files.add(&kept, image.bytes.clone());
    }
    files.add("spec.toml", text.into_bytes());
    Ok(())
}

/// What `moirecast mold` wrote, for the summary it prints.
pub struct MoldOutcome {
    pub written: Vec<PathBuf>,
    pub bytes: usize,
    pub checks: usize,
    /// Checks that failed (only with `force`).
    pub failed: Vec<&'static str>,
    pub warnings: Vec<String>,
    pub volumes: moirecast_mold::Volumes,
    pub triangles: [usize; 3],
    /// What to weigh out, in one line.
    pub casting: String,
}

/// An STL the mold command writes: a half, checked when it was cut, or a
/// construction solid, to be checked as it is written.
enum ToWrite<'m> {
    Checked(&'m moirecast_kernel::check::CheckedMesh),
    Unchecked(&'m moirecast_kernel::Mesh, SolidSpec),
}

/// The STL bytes of the solid `job` and its file report, or the first of
/// its solid checks that failed.
fn encoded_stl(name: &str, job: &ToWrite) -> Result<(Vec<u8>, report::FileReport)> {
    let fresh;
    let (checks, solid) = match job {
        ToWrite::Checked(mesh) => (mesh.checks(), mesh.solid()),
        ToWrite::Unchecked(mesh, spec) => {
            fresh = SolidMesh::validate_for(mesh, *spec);
            (&fresh.0[..], fresh.1)
        }
    };
    let Some(solid) = solid else {
        RunError::first_failed(checks, "")?;
        unreachable!("{name} is a solid when its checks pass");
    };
    let bytes = stl_bytes(name, solid)?;
    let file = report::FileReport::of(solid.mesh(), bytes.len());
    Ok((bytes, file))
}

/// `moirecast mold`: builds the device of `spec` and its two-piece mold and
/// writes `device.stl`, `mold-top.stl`, `mold-bottom.stl`, their exact
/// B-reps `device.step`, `mold-top.step` and `mold-bottom.step`,
/// `assembly.scad` and `report.json` into `out` — all of them, or nothing.
///
/// Every check runs before anything is written. A failed check is an error
/// naming it and the place; with `force` the files are written anyway and
/// the failures are listed in the report. The solid checks of each STL
/// (METHOD §7.1) are never forced: a broken mesh is not written.
pub fn run_mold(
    spec: &Spec,
    out: &Path,
    force: bool,
    progress: &dyn Progress,
) -> Result<MoldOutcome> {
    if let moirecast_kernel::BaseKind::Printed(_) = spec.design.params.base.kind {
        // refused before any meshing: the mold crate would refuse it too
        return Err(RunError::mold(spec, moirecast_mold::MoldError::NotCastable).into());
    }
    let mesh = mesh_spec(spec, progress)?;
    progress.stage("checking", 1);
    let (lens_stats, measured) = measure_device(&spec.design, &mesh, Thoroughness::Sampled);
    progress.tick(1);
    let build = DeviceBuild {
        mesh,
        lens_stats,
        checks: measured,
    };
    // The cavity's exact shape, device.step in the mold frame, is built
    // beside the mold's mesh work.
    let pose = moirecast_mold::Pose::of(&spec.design, spec.mold.flip, spec.mold.shrink_scale);
    let (mold, step) = rayon::join(
        || moirecast_mold::build_mold(&spec.design, &build.mesh, &spec.mold, progress),
        || {
            moirecast_brep::device_step_mapped(
                &spec.design,
                &build.mesh,
                (
                    "device.step",
                    "moirecast mold: the cavity's shape, the device in the mold frame",
                ),
                Some(pose.affine()),
            )
        },
    );
    let mold = mold.map_err(|e| RunError::mold(spec, e))?;
    let step = step.map_err(|e| RunError::Internal {
        stage: "building the device's B-rep",
        detail: e.to_string(),
    })?;
    progress.stage("writing", 1);
    let mut checks: Vec<CheckResult> = build.checks.clone();
    checks.extend(mold.checks.iter().cloned());
    checks.extend(step.checks.iter().cloned());
    // Every STL is encoded in parallel: the halves as they were checked
    // when cut (their checks are in `checks` already), the construction
    // solids validated here.
    let mut jobs: Vec<(String, ToWrite)> = vec![
        ("mold-top.stl".into(), ToWrite::Checked(&mold.top)),
        ("mold-bottom.stl".into(), ToWrite::Checked(&mold.bottom)),
    ];
    for c in &mold.construction {
        jobs.push((
            format!("construction-{}.stl", c.name),
            ToWrite::Unchecked(&c.mesh, SolidSpec::boolean_results(0, c.shells)),
        ));
    }
    use rayon::prelude::*;
    // The halves' exact B-reps are built beside the STL encoding.
    let (((device_checks, device), encoded), halves) = rayon::join(
        || {
            rayon::join(
                || SolidMesh::validate(mold.device()),
                || {
                    jobs.par_iter()
                        .map(|(name, job)| encoded_stl(name, job))
                        .collect::<Vec<_>>()
                },
            )
        },
        || moirecast_brep::mold_step(&spec.design, &build.mesh, &mold, &step.brep),
    );
    let halves = halves.map_err(|e| RunError::Internal {
        stage: "building the mold halves' B-reps",
        detail: e.to_string(),
    })?;
    checks.extend(halves.checks.iter().cloned());
    let device_check_count = device_checks.len();
    checks.splice(0..0, device_checks);
    if !force {
        RunError::first_failed(
            &checks,
            " (--force writes the files and marks the failure in report.json)",
        )?;
    }
    let Some(device) = device else {
        RunError::first_failed(&checks[..device_check_count], "")?;
        unreachable!("the device is a solid when its checks pass");
    };
    let mut files = OutputSet::new();
    let mut reports = std::collections::BTreeMap::new();
    let device_bytes = stl_bytes("device.stl", device)?;
    reports.insert(
        "device.stl".to_string(),
        report::FileReport::of(device.mesh(), device_bytes.len()),
    );
    files.add("device.stl", device_bytes);
    for ((name, _), done) in jobs.iter().zip(encoded) {
        let (bytes, file) = done?;
        reports.insert(name.clone(), file);
        files.add(name, bytes);
    }
    let f = &mold.features;
    files.add(
        "assembly.scad",
        moirecast_export::assembly_scad(
            &format!("moirecast mold of {}", report::spec_name(spec)),
            f.block_lo.to_array(),
            (f.block_hi - f.block_lo).to_array(),
        )
        .into_bytes(),
    );
    let report = mold_report::mold_report(spec, &mold, &checks, reports, (&step, &halves));
    files.add("device.step", StepFile(step.step));
    files.add("mold-top.step", StepFile(halves.top_step));
    files.add("mold-bottom.step", StepFile(halves.bottom_step));
    moirecast_export::free_in_background(step.brep);
    let casting = report.casting.line();
    let (written, bytes) = commit_with_report(files, spec, &report, out)?;
    progress.tick(1);
    Ok(MoldOutcome {
        written,
        bytes,
        checks: checks.len(),
        failed: report.failed.clone(),
        warnings: mold.features.warnings.clone(),
        volumes: mold.volumes,
        triangles: [
            mold.device().triangles.len(),
            mold.top.mesh().triangles.len(),
            mold.bottom.mesh().triangles.len(),
        ],
        casting,
    })
}
