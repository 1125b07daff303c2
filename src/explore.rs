//! `moirecast explore`: the (a, d) design space of METHOD §3 as a grid, as
//! in the paper's Fig. 7, scored by moiré fidelity: `grid.png` (each cell's
//! best frame, labelled "a d/D_s"), `report.json` (fidelity, local
//! fidelity, level-line contrast and kept contrast per cell) and
//! `best.toml`, the spec of the best cell. Cells are ranked by level-line
//! contrast ([`moirecast_render::fidelity::level_line_contrast`]): on a
//! curved device the global fidelity of METHOD §8 mixes level lines seen at
//! different angles, and both fidelities are correlations, which a
//! noise-free frame of a defocused base (a faint, smooth moiré) satisfies
//! as well as a sharp one. The contrast peaks where the base is in focus
//! (d = D_s). Each cell's **kept contrast** divides its contrast by that of
//! the [`FlatSheet`]: the same optics and profile on a plane, in focus. It
//! ranks as the contrast does, and reads as a share: how much of what the
//! lenses can show flat survives the surface and the base's placement.

use crate::commit_with_report;
use crate::render::png;
use anyhow::{Context, Result};
use moirecast_export::OutputSet;
use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::progress::{Progress, Silent};
use moirecast_kernel::Design;
use moirecast_render::frame::render_scored;
use moirecast_render::frame::traced_mesh;
use moirecast_render::sheet::{contact_sheet, to_rgb8, Rgb8};
use moirecast_render::Scene;
use moirecast_spec::Spec;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The weights a between the offset (0) and the focal (1) surface.
pub const A_VALUES: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];
/// Offsets d as multiples of the standard lens's focal depth D_s.
pub const D_RATIOS: [f64; 5] = [0.6, 0.8, 1.0, 1.2, 1.4];
/// Cells of the grid.
pub const CELLS: usize = A_VALUES.len() * D_RATIOS.len();

/// The mesh tolerance (mm) of explore's cells when the spec asks for a finer
/// one: a preview does not need the 2 µm of a cast device. On the reference
/// it halves explore's time and moves the level-line contrast of the best
/// cell from 0.245 to 0.235, with the same best cell (docs/decisions.md).
pub const PREVIEW_TOLERANCE_MM: f64 = 0.01;

/// Cell size, samples, the tilts tried per cell (the best counts), seed.
pub type ExploreOptions = crate::render::RenderOptions;

#[derive(Clone, Serialize)]
pub struct Cell {
    pub a: f64,
    pub d_over_ds: f64,
    pub d_mm: f64,
    /// Best fidelity over the tilts (METHOD §8); `None` if the design is invalid.
    pub fidelity: Option<f64>,
    /// Best local fidelity over the tilts (fidelity within windows of the
    /// frame, beside METHOD §8).
    pub local_fidelity: Option<f64>,
    /// Best level-line contrast over the tilts
    /// (`moirecast_render::fidelity::level_line_contrast`), which ranks the
    /// cells, and its tilt.
    pub contrast: Option<f64>,
    /// The share of the flat sheet's contrast that this cell keeps:
    /// `contrast` over [`FlatSheet::contrast`] (see the module's doc).
    pub kept_contrast: Option<f64>,
    pub best_tilt_deg: Option<f64>,
    /// Why the design is invalid (METHOD's validity rules), if it is.
    pub invalid: Option<String>,
}

#[derive(Serialize)]
struct ExploreReport {
    moirecast: &'static str,
    spec: String,
    size_px: usize,
    samples_per_pixel: usize,
    sampling: String,
    /// The mesh tolerance of the cells (mm): the spec's, or
    /// [`PREVIEW_TOLERANCE_MM`] if that is coarser.
    tolerance_mm: f64,
    tilts_deg: Vec<f64>,
    seed: u64,
    /// What each cell's kept contrast is measured against.
    flat_sheet: FlatSheet,
    /// Row-major: rows are d/D_s, columns are a.
    cells: Vec<Cell>,
    /// The cell with the highest level-line contrast.
    best: usize,
}

pub struct ExploreOutcome {
    pub written: Vec<PathBuf>,
    pub bytes: usize,
    /// The best cell's (a, d in mm, level-line contrast).
    pub best: (f64, f64, f64),
    /// The best cell's kept contrast, if the flat sheet has one.
    pub kept_contrast: Option<f64>,
}

/// `text` with `[base] a` and `d` set; a relative profile image is made
/// absolute against `spec_dir`, so the spec loads from anywhere.
fn spec_with_base(text: &str, a: f64, d: f64, spec_dir: Option<&Path>) -> Result<String> {
    let mut table: toml::Table = toml::from_str(text).context("re-reading the spec")?;
    let base = table
        .entry("base")
        .or_insert_with(|| toml::Value::Table(Default::default()))
        .as_table_mut()
        .context("[base] is a table")?;
    base.insert("a".into(), toml::Value::Float(a));
    base.insert("d".into(), toml::Value::Float(d));
    if let (Some(dir), Some(profile)) = (
        spec_dir,
        table.get_mut("profile").and_then(|p| p.as_table_mut()),
    ) {
        if let Some(toml::Value::String(image)) = profile.get_mut("image") {
            if Path::new(image.as_str()).is_relative() {
                *image = dir.join(&*image).display().to_string();
            }
        }
    }
    Ok(format!(
        "# The best cell of `moirecast explore`: a = {a}, d = {d} mm.\n{}",
        toml::to_string(&table)?
    ))
}

/// The scored (a, d) grid: one cell per (d/D_s, a), row-major (rows are
/// d/D_s, columns a), each with its best frame and label "a d/D_s".
pub struct ExploreGrid {
    pub flat_sheet: FlatSheet,
    pub cells: Vec<Cell>,
    pub frames: Vec<(Rgb8, String)>,
    /// The cell with the highest level-line contrast.
    pub best: usize,
}

/// A design's best frame over the options' tilts.
struct BestFrame {
    /// The highest level-line contrast, its tilt and its frame.
    contrast: f64,
    tilt_deg: f64,
    frame: Rgb8,
    /// The highest fidelity and local fidelity over the tilts.
    fidelity: f64,
    local_fidelity: f64,
}

/// Renders `design` at every tilt of `options` and keeps the best.
fn best_over_tilts(
    design: &Design,
    options: &ExploreOptions,
    lighting: moirecast_render::frame::Lighting,
) -> Result<BestFrame> {
    // A dual-lens design seen as the sections allow needs no mesh: its
    // frames are traced through its exact cross-sections alone.
    let sections = options.tracer.sections(design, options.size);
    let sections_alone = sections
        .as_ref()
        .filter(|_| options.sections_trace_every_frame(design))
        .and_then(|s| s.bounds());
    let (dm, mesh, absorbing);
    let scene = match sections_alone {
        Some(bounds) => Scene::framing(bounds),
        None => {
            dm = mesh_device(design, &Silent).context("meshing a cell")?;
            (mesh, absorbing) =
                traced_mesh(design, &dm).context("building a cell's traced bodies")?;
            Scene::with_absorbing(&mesh, absorbing)
        }
    };
    let mut best: Option<BestFrame> = None;
    let (mut fidelity, mut local_fidelity) = (0.0f64, 0.0f64);
    for &tilt in &options.tilts_deg {
        let view = options.view(design, tilt, lighting);
        let (f, global) = render_scored(design, &scene, sections.as_ref(), view);
        fidelity = fidelity.max(global);
        local_fidelity = local_fidelity.max(f.local_fidelity());
        let contrast = f.level_line_contrast();
        if best.as_ref().is_none_or(|b| contrast > b.contrast) {
            best = Some(BestFrame {
                contrast,
                tilt_deg: tilt,
                frame: to_rgb8(f.width, f.height, &f.rgb),
                fidelity: 0.0,
                local_fidelity: 0.0,
            });
        }
    }
    let best = best.context("at least one tilt")?;
    Ok(BestFrame {
        fidelity,
        local_fidelity,
        ..best
    })
}

/// The flat sheet a design's level-line contrast is measured against: the
/// same layout, lens, base kind, levels and profile on a plane, its base at
/// a = 0, d = D_s (in focus), seen at the same tilts and lights. Its best
/// contrast is what these optics show without a curved surface.
#[derive(Clone, Serialize)]
pub struct FlatSheet {
    /// Its best level-line contrast over the tilts; `None` if the flat
    /// sheet is not a valid design, or shows no level lines.
    pub contrast: Option<f64>,
    /// Why the flat sheet is not a valid design, if it is not.
    pub invalid: Option<String>,
}

impl FlatSheet {
    fn of(
        design: &Design,
        options: &ExploreOptions,
        lighting: moirecast_render::frame::Lighting,
    ) -> Result<FlatSheet> {
        let mut params = design.params.clone();
        params.surface = moirecast_kernel::PitchSurface::Plane;
        params.base.a = 0.0;
        params.base.d = None;
        params.tolerance = params.tolerance.max(PREVIEW_TOLERANCE_MM);
        Ok(match Design::new(params) {
            Err(e) => FlatSheet {
                contrast: None,
                invalid: Some(e.to_string()),
            },
            Ok(flat) => {
                let contrast = best_over_tilts(&flat, options, lighting)?.contrast;
                FlatSheet {
                    contrast: (contrast > 0.0).then_some(contrast),
                    invalid: None,
                }
            }
        })
    }
}

/// Scores every cell of the (a, d) grid of `spec` (see the module's doc).
pub fn explore_grid(
    spec: &Spec,
    options: &ExploreOptions,
    progress: &dyn Progress,
) -> Result<ExploreGrid> {
    let base = &spec.design;
    let ds = base.standard.focal_depth;
    progress.stage("exploring (a, d)", CELLS as u64);
    let lighting = options.lights.lighting(base)?;
    let blank = Rgb8 {
        width: options.size,
        height: options.size,
        pixels: vec![[128; 3]; options.size * options.size],
    };
    // One cell: its scores and its best frame, labelled.
    let explore_cell = |ratio: f64, a: f64| -> Result<(Cell, (Rgb8, String))> {
        if progress.cancelled() {
            anyhow::bail!("cancelled: the grid was no longer wanted");
        }
        let mut params = base.params.clone();
        params.base.a = a;
        params.base.d = Some(ratio * ds);
        params.tolerance = params.tolerance.max(PREVIEW_TOLERANCE_MM);
        let label = format!("{a:.2} {ratio:.1}");
        let cell = |fidelity, local_fidelity, contrast, best_tilt_deg, invalid| Cell {
            a,
            d_over_ds: ratio,
            d_mm: ratio * ds,
            fidelity,
            local_fidelity,
            contrast,
            kept_contrast: None,
            best_tilt_deg,
            invalid,
        };
        let design = match Design::new(params) {
            Err(e) => {
                return Ok((
                    cell(None, None, None, None, Some(e.to_string())),
                    (blank.clone(), label),
                ))
            }
            Ok(design) => design,
        };
        let s = best_over_tilts(&design, options, lighting)?;
        Ok((
            cell(
                Some(s.fidelity),
                Some(s.local_fidelity),
                Some(s.contrast),
                Some(s.tilt_deg),
                None,
            ),
            (s.frame, label),
        ))
    };
    // Cells in parallel: meshing a cell and building its BVH are partly
    // serial, so one cell at a time left a core idle. Row-major order.
    use rayon::prelude::*;
    let grid: Vec<(f64, f64)> = D_RATIOS
        .iter()
        .flat_map(|&ratio| A_VALUES.iter().map(move |&a| (ratio, a)))
        .collect();
    let (cells, flat_sheet) = rayon::join(
        || {
            grid.into_par_iter()
                .map(|(ratio, a)| {
                    let cell = explore_cell(ratio, a);
                    progress.tick(1);
                    cell
                })
                .collect::<Result<Vec<_>>>()
        },
        || FlatSheet::of(base, options, lighting),
    );
    let (mut cells, frames): (Vec<Cell>, Vec<(Rgb8, String)>) = cells?.into_iter().unzip();
    let flat_sheet = flat_sheet?;
    for c in &mut cells {
        c.kept_contrast = c
            .contrast
            .zip(flat_sheet.contrast)
            .map(|(c, flat)| c / flat);
    }
    let best = (0..cells.len())
        .filter(|&i| cells[i].contrast.is_some())
        .fold(None, |b: Option<usize>, i| match b {
            Some(j) if cells[j].contrast >= cells[i].contrast => Some(j),
            _ => Some(i),
        })
        .context("no cell of the (a, d) grid is a valid design")?;
    Ok(ExploreGrid {
        flat_sheet,
        cells,
        frames,
        best,
    })
}

/// `moirecast explore`: [`explore_grid`], written as `grid.png`,
/// `report.json` and `best.toml` into `out`.
pub fn run_explore(
    spec: &Spec,
    out: &Path,
    options: &ExploreOptions,
    progress: &dyn Progress,
) -> Result<ExploreOutcome> {
    let base = &spec.design;
    let ExploreGrid {
        flat_sheet,
        cells,
        frames,
        best,
    } = explore_grid(spec, options, progress)?;
    let spec_text = match Path::new(&spec.origin) {
        p if p.is_file() => std::fs::read_to_string(p)?,
        _ => moirecast_spec::DEFAULT_SPEC.to_owned(),
    };
    let spec_dir = Path::new(&spec.origin)
        .is_file()
        .then(|| Path::new(&spec.origin).parent().map(|p| p.canonicalize()))
        .flatten()
        .transpose()?;
    let b = &cells[best];
    let mut files = OutputSet::new();
    files.add("grid.png", png(&contact_sheet(&frames, A_VALUES.len()))?);
    files.add(
        "best.toml",
        spec_with_base(&spec_text, b.a, b.d_mm, spec_dir.as_deref())?.into_bytes(),
    );
    let outcome_best = (b.a, b.d_mm, b.contrast.unwrap_or(0.0));
    let kept_contrast = b.kept_contrast;
    let report = ExploreReport {
        moirecast: env!("CARGO_PKG_VERSION"),
        spec: crate::report::spec_name(spec),
        size_px: options.size,
        samples_per_pixel: options.samples * options.samples,
        sampling: options.sampling().describe(),
        tolerance_mm: base.params.tolerance.max(PREVIEW_TOLERANCE_MM),
        tilts_deg: options.tilts_deg.clone(),
        seed: options.seed,
        flat_sheet,
        cells,
        best,
    };
    let (written, bytes) = commit_with_report(files, spec, &report, out)?;
    Ok(ExploreOutcome {
        written,
        bytes,
        best: outcome_best,
        kept_contrast,
    })
}
