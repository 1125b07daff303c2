//! What the studio builds from a revision on first request: the device
//! (mesh, STL, report), the mold halves, the explore grid.

use crate::explore::{explore_grid, Cell, FlatSheet};
use crate::render::{png, RenderOptions};
use crate::report::{device_report, CheckReport, DeviceOutputs, FileReport};
use crate::{measure_device, mesh_spec, refuse_failed, DeviceBuild, RunError, Thoroughness};
use anyhow::{Context, Result};
use moirecast_export::stl_bytes;
use moirecast_kernel::check::SolidMesh;
use moirecast_kernel::progress::{Progress, Silent};
use moirecast_spec::Spec;

/// The device as the page shows it: its STL and its report.
pub struct DeviceView {
    pub stl: Vec<u8>,
    /// `moirecast device`'s report, without the STEP file's part (the
    /// B-rep is built when the files are written).
    pub report: serde_json::Value,
}

impl DeviceView {
    pub fn build(spec: &Spec, progress: &dyn Progress) -> Result<DeviceView> {
        let mesh = mesh_spec(spec, progress)?;
        let (mut checks, solid) = SolidMesh::validate(&mesh.mesh);
        refuse_failed(&checks)?;
        let stl = stl_bytes("device.stl", solid.context("the solid checks passed")?)?;
        let (lens_stats, measured) = measure_device(&spec.design, &mesh, Thoroughness::Sampled);
        checks.extend(measured.iter().cloned());
        let file = FileReport::of(&mesh.mesh, stl.len());
        let build = DeviceBuild {
            mesh,
            lens_stats,
            checks: measured,
        };
        let report = device_report(
            spec,
            &build,
            &checks,
            DeviceOutputs {
                files: [("device.stl".to_string(), file)].into(),
                step: None,
                printed: None,
                crosscheck: None,
            },
        );
        Ok(DeviceView {
            stl,
            report: serde_json::to_value(report)?,
        })
    }
}

/// The mold's halves and cavity as STL, with its checks and warnings.
pub struct MoldView {
    pub top: Vec<u8>,
    pub bottom: Vec<u8>,
    /// The device in the mold's frame (flipped, scaled): the cavity.
    pub device: Vec<u8>,
    pub checks: Vec<CheckReport>,
    pub warnings: Vec<String>,
}

impl MoldView {
    pub fn build(spec: &Spec, progress: &dyn Progress) -> Result<MoldView> {
        if let moirecast_kernel::BaseKind::Printed(_) = spec.design.params.base.kind {
            return Err(RunError::mold(spec, moirecast_mold::MoldError::NotCastable).into());
        }
        let mesh = mesh_spec(spec, progress)?;
        if progress.cancelled() {
            anyhow::bail!("cancelled: a newer design replaced this one");
        }
        let mold = moirecast_mold::build_mold(&spec.design, &mesh, &spec.mold, &Silent)
            .map_err(|e| RunError::mold(spec, e))?;
        let half = |name: &str, half: &moirecast_kernel::check::CheckedMesh| -> Result<Vec<u8>> {
            match half.solid() {
                Some(solid) => Ok(stl_bytes(name, solid)?),
                None => {
                    RunError::first_failed(half.checks(), "")?;
                    unreachable!("{name} is a solid when its checks pass")
                }
            }
        };
        let (device_checks, device) = SolidMesh::validate(mold.device());
        refuse_failed(&device_checks)?;
        Ok(MoldView {
            top: half("mold-top.stl", &mold.top)?,
            bottom: half("mold-bottom.stl", &mold.bottom)?,
            device: stl_bytes("device.stl", device.context("the cavity is a solid")?)?,
            checks: mold.checks.iter().map(CheckReport::from).collect(),
            warnings: mold.features.warnings.clone(),
        })
    }
}

/// The (a, d) grid with `moirecast explore`'s defaults.
pub struct ExploreView {
    pub flat_sheet: FlatSheet,
    pub cells: Vec<Cell>,
    pub thumbnails: Vec<Vec<u8>>,
    pub best: usize,
}

impl ExploreView {
    pub fn build(spec: &Spec, progress: &dyn Progress) -> Result<ExploreView> {
        let options = RenderOptions::preview(96, 2, vec![-5.0, 0.0, 5.0]);
        let grid = explore_grid(spec, &options, progress)?;
        Ok(ExploreView {
            thumbnails: grid
                .frames
                .iter()
                .map(|(image, _)| png(image))
                .collect::<Result<_>>()?,
            flat_sheet: grid.flat_sheet,
            cells: grid.cells,
            best: grid.best,
        })
    }
}
