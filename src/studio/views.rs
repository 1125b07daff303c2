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
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

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

/// The explore grid of one revision: scored once on request, with its
/// progress (cells done) readable meanwhile, and a cancel that stops every
/// request made before it, running or still waiting to start, after the
/// cells being scored. A cancelled grid is not kept: a later request scores
/// it afresh.
#[derive(Default)]
pub struct Scoring {
    done: AtomicU64,
    running: AtomicBool,
    /// Requests made so far (each one's ticket is its number).
    requested: AtomicU64,
    /// Requests still waiting or running.
    pending: AtomicU64,
    /// Requests up to this ticket are cancelled.
    cancelled_upto: AtomicU64,
    /// Whether the last request answered was cancelled.
    last_cancelled: AtomicBool,
    grid: Mutex<Option<Result<Arc<ExploreView>, String>>>,
}

/// What [`Scoring::progress`] reports.
#[derive(serde::Serialize)]
pub struct ScoringProgress {
    pub done: u64,
    pub total: u64,
    pub running: bool,
    /// Requests the server has, waiting or running.
    pub pending: u64,
    pub scored: bool,
    /// Whether the last request answered was cancelled.
    pub cancelled: bool,
}

/// One request's scoring: ticks count the cells done; it is cancelled by
/// the page (a cancel after its request) or by a newer revision.
struct Ticks<'a> {
    scoring: &'a Scoring,
    ticket: u64,
    replaced: &'a AtomicBool,
}

impl Progress for Ticks<'_> {
    fn tick(&self, n: u64) {
        self.scoring.done.fetch_add(n, Ordering::Relaxed);
    }
    fn cancelled(&self) -> bool {
        self.scoring.cancelled_upto.load(Ordering::SeqCst) >= self.ticket
            || self.replaced.load(Ordering::SeqCst)
    }
}

/// Counts a request as pending until it is answered.
struct Pending<'a>(&'a AtomicU64);

impl Drop for Pending<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

impl Scoring {
    /// A request for the grid, made now: its ticket for
    /// [`grid`](Self::grid), which a cancel from now on stops. It is
    /// pending until `grid` answers it.
    pub fn request(&self) -> u64 {
        self.pending.fetch_add(1, Ordering::SeqCst);
        self.requested.fetch_add(1, Ordering::SeqCst) + 1
    }

    /// The grid for `ticket`, scored now if it has not been (blocking; one
    /// scoring at a time, a later caller waits for the first's grid).
    /// `words` puts an error in the page's words.
    pub fn grid(
        &self,
        ticket: u64,
        spec: &Spec,
        replaced: &AtomicBool,
        words: impl Fn(anyhow::Error) -> String,
    ) -> Result<Arc<ExploreView>, String> {
        const CANCELLED: &str = "cancelled: the grid was not scored";
        let _answered = Pending(&self.pending);
        let mut grid = self.grid.lock().expect("not poisoned");
        if let Some(scored) = grid.as_ref() {
            return scored.clone();
        }
        let ticks = Ticks {
            scoring: self,
            ticket,
            replaced,
        };
        if !ticks.cancelled() {
            self.done.store(0, Ordering::Relaxed);
            self.last_cancelled.store(false, Ordering::SeqCst);
            self.running.store(true, Ordering::SeqCst);
            let scored = ExploreView::build(spec, &ticks)
                .map(Arc::new)
                .map_err(&words);
            self.running.store(false, Ordering::SeqCst);
            if !(ticks.cancelled() && scored.is_err()) {
                *grid = Some(scored.clone());
                return scored;
            }
        }
        self.last_cancelled.store(true, Ordering::SeqCst);
        Err(CANCELLED.into())
    }

    /// The grid once scored, without scoring it.
    pub fn scored(&self) -> Option<Result<Arc<ExploreView>, String>> {
        self.grid.try_lock().ok().and_then(|g| g.clone())
    }

    pub fn progress(&self) -> ScoringProgress {
        ScoringProgress {
            done: self.done.load(Ordering::Relaxed),
            total: crate::explore::CELLS as u64,
            running: self.running.load(Ordering::SeqCst),
            pending: self.pending.load(Ordering::SeqCst),
            scored: self.scored().is_some(),
            cancelled: self.last_cancelled.load(Ordering::SeqCst),
        }
    }

    /// Cancels every request made so far; whether one was waiting or
    /// running.
    pub fn cancel(&self) -> bool {
        let made = self.requested.load(Ordering::SeqCst);
        self.cancelled_upto.fetch_max(made, Ordering::SeqCst);
        self.pending.load(Ordering::SeqCst) > 0
    }
}
