//! `report.json`: what was built, the design's derived numbers, what was
//! measured, and every check with its value. Deterministic: no timings, no
//! paths beyond the spec's own name.

use crate::DeviceBuild;
use moirecast_kernel::check::CheckResult;
use moirecast_kernel::measure::{self, Range};
use moirecast_kernel::{BaseKind, Mesh, PitchSurface};
use moirecast_spec::Spec;
use serde::Serialize;
use std::collections::BTreeMap;

#[derive(Serialize)]
pub struct MinMax {
    pub min: f64,
    pub max: f64,
}

impl From<Range> for MinMax {
    fn from(r: Range) -> Self {
        MinMax {
            min: r.min,
            max: r.max,
        }
    }
}

#[derive(Serialize)]
pub struct FileReport {
    pub bytes: usize,
    pub triangles: usize,
    pub volume_mm3: f64,
    pub bbox_min: [f64; 3],
    pub bbox_max: [f64; 3],
}

impl FileReport {
    pub fn of(mesh: &Mesh, bytes: usize) -> Self {
        let (lo, hi) = mesh.bounds();
        FileReport {
            bytes,
            triangles: mesh.triangles.len(),
            volume_mm3: mesh.volume(),
            bbox_min: lo.to_array(),
            bbox_max: hi.to_array(),
        }
    }
}

/// How a height map was fitted: its extent, its samples and their
/// spacing, the smoothing, and the fit's largest deviation from its
/// samples.
#[derive(Serialize)]
pub struct HeightMapEcho {
    pub extent_mm: [f64; 2],
    pub spacing_mm: [f64; 2],
    pub smoothing_mm: f64,
    pub max_deviation_mm: f64,
}

#[derive(Serialize)]
pub struct DesignEcho {
    pub surface: &'static str,
    pub surface_radius_mm: Option<f64>,
    pub surface_formula: Option<String>,
    /// A height map's fit (kind = "heightmap" only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surface_heightmap: Option<HeightMapEcho>,
    pub width_mm: f64,
    pub height_mm: f64,
    pub period_mm: f64,
    pub afov_deg: f64,
    pub index: f64,
    pub material: Option<String>,
    pub lens_rule: &'static str,
    pub base_kind: &'static str,
    pub base_a: f64,
    pub base_d_mm: f64,
    pub base_levels: f64,
    /// Base lenses only (dual-lens).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_afov_deg: Option<f64>,
    /// The band layer (printed bases only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_duty: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_band_thickness_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_backing_mm: Option<f64>,
    pub profile: String,
    pub tolerance_mm: f64,
}

/// The derived numbers of METHOD §2: N and the standard lens.
#[derive(Serialize)]
#[allow(non_snake_case)]
pub struct Derived {
    pub N: usize,
    pub w_s: f64,
    pub r_s: f64,
    pub s_s: f64,
    pub F_s: f64,
    pub D_s: f64,
    pub max_surface_slope_deg: f64,
    pub max_surface_curvature_per_mm: f64,
}

#[derive(Serialize)]
pub struct MeshReport {
    pub triangles: usize,
    pub vertices: usize,
    pub revealer_triangles: usize,
    pub base_triangles: usize,
    pub wall_triangles: usize,
    pub revealer_rows: usize,
    pub base_rows: usize,
    pub base_crossing_rows: usize,
    pub revealer_columns: [usize; 2],
    pub base_columns: [usize; 2],
    /// Triangles a uniform grid would need for the same tolerance.
    pub uniform_triangles: usize,
    /// The budget's estimate, before meshing, of a mold run's peak memory.
    pub estimated_mold_peak_mb: f64,
}

/// Revealer lens geometry measured from the mesh.
#[derive(Serialize)]
pub struct LensReport {
    pub arcs_measured: usize,
    pub pitch_mm: MinMax,
    pub radius_mm: MinMax,
    pub afov_deg: MinMax,
    pub sag_mm: MinMax,
    pub focal_depth_mm: MinMax,
}

#[derive(Serialize)]
pub struct CheckReport {
    pub name: &'static str,
    /// The registry's human label (docs/checks.md).
    pub label: &'static str,
    /// The part it is about: device, mold top, mold bottom, mold, cavity,
    /// device B-rep or mold B-rep.
    pub part: &'static str,
    pub value: f64,
    /// How the value is held against the limit: "at most", "at least",
    /// "exactly" or "more than".
    pub bound: &'static str,
    pub limit: f64,
    pub unit: &'static str,
    pub passed: bool,
    pub detail: String,
}

impl From<&CheckResult> for CheckReport {
    fn from(c: &CheckResult) -> Self {
        use moirecast_kernel::checks::{check_doc, part_of};
        let doc = check_doc(c.name);
        CheckReport {
            name: c.name,
            label: doc.map_or(c.name, |d| d.label),
            part: part_of(c.name, &c.detail),
            value: c.value,
            bound: doc.map_or("", |d| d.bound.words()),
            limit: c.limit,
            unit: c.unit,
            passed: c.passed,
            detail: c.detail.clone(),
        }
    }
}

#[derive(Serialize)]
pub struct DeviceReport {
    pub moirecast: &'static str,
    pub spec: String,
    pub design: DesignEcho,
    pub derived: Derived,
    pub files: BTreeMap<String, FileReport>,
    pub mesh: MeshReport,
    pub lenses: LensReport,
    /// The base's shift E − C (C: the view compensation).
    pub base_shift_mm: MinMax,
    pub base_shift_periods: MinMax,
    pub view: ViewReport,
    /// The device as a B-rep (dual-lens devices).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub brep: Option<BrepReport>,
    /// The two bodies of a printed device.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub printed: Option<PrintedReport>,
    /// With `--mesher brep`: truck-meshalgo's tessellation (then
    /// `device.stl`) against the direct mesh.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub crosscheck: Option<moirecast_brep::CrossCheck>,
    pub checks: Vec<CheckReport>,
}

/// The design view and the base's compensation for it (docs/decisions.md,
/// "The view-compensated base").
#[derive(Serialize)]
pub struct ViewReport {
    /// Tilts about y (across the lenses) and x, as `render --tilts` and
    /// `--tilt-along` take them.
    pub tilt_deg: f64,
    pub tilt_along_deg: f64,
    /// The view direction (unit, from the eye into the device).
    pub direction: [f64; 3],
    /// The eye's distance from the device's centre; `null`: orthographic.
    pub distance_mm: Option<f64>,
    /// Whether the base is compensated for the design view (on a plane
    /// seen straight down C ≡ 0: nothing moves).
    pub compensated: bool,
    /// Largest |C| over the layout, in periods (0 where C ≡ 0: a plane seen
    /// straight down), whether the base is compensated or not.
    pub max_offset_periods: f64,
    /// Largest |∂C/∂u| over the layout.
    pub max_offset_slope: f64,
    /// C's grid and the interpolant's largest distance from the traced C
    /// at the grid's cell centres over the layout.
    pub offset_grid_mm: Option<f64>,
    pub offset_fit_um: Option<f64>,
    /// The largest angle between the view and a lens axis, across the
    /// lenses, and where (layout mm).
    pub max_view_angle_deg: f64,
    pub max_view_angle_at_mm: [f64; 2],
    /// Past this angle a lens keeps less than three quarters of its
    /// straight-on contrast (`view-angle` warns).
    pub keeps_contrast_deg: f64,
    /// Named warnings: the design builds, but does not show what a user
    /// expects everywhere.
    pub warnings: Vec<String>,
}

impl ViewReport {
    pub fn of(design: &moirecast_kernel::Design) -> Self {
        let view = &design.params.view;
        let c = design.view_compensation_traced();
        let t = design.params.period;
        let (angle, at) = c.as_ref().map_or((0.0, [0.0, 0.0]), |c| {
            (c.max_angle.0.to_degrees(), c.max_angle.1.to_array())
        });
        ViewReport {
            tilt_deg: view.tilt.to_degrees(),
            tilt_along_deg: view.tilt_along.to_degrees(),
            direction: view.direction().to_array(),
            distance_mm: view.distance,
            compensated: view.compensate,
            max_offset_periods: c.as_ref().map_or(0.0, |c| c.max_abs_layout_mm / t),
            max_offset_slope: c.as_ref().map_or(0.0, |c| c.max_slope),
            offset_grid_mm: c.as_ref().map(|c| c.spacing()),
            offset_fit_um: c
                .as_ref()
                .map(|c| 1e3 * (c.fit_error_mm + c.resample_error_mm)),
            max_view_angle_deg: angle,
            max_view_angle_at_mm: at,
            keeps_contrast_deg: moirecast_kernel::view::KEEPS_CONTRAST_DEG,
            warnings: view_warnings(c.as_ref()),
        }
    }
}

/// The design's named warnings about its view: `view-angle` where the
/// design view meets a lens past the angle at which it keeps its contrast.
pub fn view_warnings(c: Option<&moirecast_kernel::ViewCompensation>) -> Vec<String> {
    let limit = moirecast_kernel::view::KEEPS_CONTRAST_DEG;
    match c {
        Some(c) if c.max_angle.0.to_degrees() > limit => vec![format!(
            "view-angle: the design view meets the lenses at up to {:.1}° from their axes (at layout ({:.1}, {:.1}) mm); past {limit}° a lens keeps less than three quarters of its straight-on contrast, so the level lines fade there. Fix: a larger surface.radius, a smaller layout, or a view.tilt towards that place",
            c.max_angle.0.to_degrees(),
            c.max_angle.1.x,
            c.max_angle.1.y
        )],
        _ => vec![],
    }
}

/// The device as a B-rep solid (`device.step`).
#[derive(Serialize)]
pub struct BrepReport {
    pub step_bytes: usize,
    #[serde(flatten)]
    pub stats: moirecast_brep::BrepStats,
}

impl BrepReport {
    pub fn of(step: &moirecast_brep::DeviceStep) -> Self {
        BrepReport {
            step_bytes: step.step.len(),
            stats: step.brep.stats.clone(),
        }
    }
}

/// The spec's file name (no directories: reports and files stay byte-identical
/// wherever the spec lives).
pub fn spec_name(spec: &Spec) -> String {
    std::path::Path::new(&spec.origin)
        .file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_else(|| spec.origin.clone())
}

pub fn design_echo(spec: &Spec) -> DesignEcho {
    let d = &spec.design;
    let p = &d.params;
    let printed = match p.base.kind {
        BaseKind::Printed(b) => Some(b),
        BaseKind::DualLens => None,
    };
    let (radius, formula) = match &p.surface {
        PitchSurface::Plane => (None, None),
        PitchSurface::Saddle { radius }
        | PitchSurface::Paraboloid { radius }
        | PitchSurface::Cylinder { radius }
        | PitchSurface::Sphere { radius } => (Some(*radius), None),
        PitchSurface::Formula(f) => (None, Some(f.source.clone())),
        PitchSurface::HeightMap(_) => (None, None),
    };
    let heightmap = match &p.surface {
        PitchSurface::HeightMap(m) => Some(HeightMapEcho {
            extent_mm: [m.extent().0, m.extent().1],
            spacing_mm: [m.spacing().0, m.spacing().1],
            smoothing_mm: m.smoothing(),
            max_deviation_mm: m.max_deviation(),
        }),
        _ => None,
    };
    DesignEcho {
        surface: p.surface.kind(),
        surface_radius_mm: radius,
        surface_formula: formula,
        surface_heightmap: heightmap,
        width_mm: p.width,
        height_mm: p.height,
        period_mm: p.period,
        afov_deg: p.lens.afov.to_degrees(),
        index: p.lens.index,
        material: spec.material.clone(),
        lens_rule: match p.lens.rule {
            moirecast_kernel::LensRule::ConstantAfov => "constant-afov",
            moirecast_kernel::LensRule::EqualRadius => "equal-radius",
        },
        base_kind: match p.base.kind {
            BaseKind::DualLens => "dual-lens",
            BaseKind::Printed(_) => "printed",
        },
        base_a: p.base.a,
        base_d_mm: d.d,
        base_levels: p.base.levels,
        base_afov_deg: matches!(p.base.kind, BaseKind::DualLens)
            .then(|| p.base.afov.unwrap_or(p.lens.afov).to_degrees()),
        base_duty: printed.map(|b| b.duty),
        base_band_thickness_mm: printed.map(|b| b.band_thickness),
        base_backing_mm: printed.map(|b| b.backing),
        profile: spec.profile_source.clone(),
        tolerance_mm: d.tolerance.mm(),
    }
}

/// What a device run wrote and measured beyond the device mesh itself.
pub struct DeviceOutputs<'a> {
    pub files: BTreeMap<String, FileReport>,
    pub step: Option<&'a moirecast_brep::DeviceStep>,
    pub printed: Option<PrintedReport>,
    pub crosscheck: Option<&'a moirecast_brep::CrossCheck>,
}

/// The derived numbers of `spec`'s design (METHOD §2).
pub fn derived(spec: &Spec) -> Derived {
    let d = &spec.design;
    let s = &d.standard;
    Derived {
        N: d.lenses,
        w_s: s.width,
        r_s: s.radius,
        s_s: s.sag,
        F_s: s.focal_length,
        D_s: s.focal_depth,
        max_surface_slope_deg: d.max_slope.to_degrees(),
        max_surface_curvature_per_mm: d.max_curvature,
    }
}

pub fn device_report(
    spec: &Spec,
    build: &DeviceBuild,
    checks: &[CheckResult],
    outputs: DeviceOutputs,
) -> DeviceReport {
    let d = &spec.design;
    let st = &build.mesh.stats;
    let ls = &build.lens_stats;
    let shift = measure::shift_range(d);
    let t = d.params.period;
    DeviceReport {
        moirecast: env!("CARGO_PKG_VERSION"),
        spec: spec_name(spec),
        design: design_echo(spec),
        derived: derived(spec),
        files: outputs.files,
        mesh: MeshReport {
            triangles: st.triangles,
            vertices: st.vertices,
            revealer_triangles: st.revealer_triangles,
            base_triangles: st.base_triangles,
            wall_triangles: st.wall_triangles,
            revealer_rows: st.revealer_rows,
            base_rows: st.base_rows,
            base_crossing_rows: st.crossing_rows,
            revealer_columns: [st.revealer_columns.0, st.revealer_columns.1],
            base_columns: [st.base_columns.0, st.base_columns.1],
            uniform_triangles: st.uniform_triangles,
            estimated_mold_peak_mb: (st.estimated_peak_bytes / 1e6).round(),
        },
        lenses: LensReport {
            arcs_measured: ls.arcs,
            pitch_mm: ls.pitch.into(),
            radius_mm: ls.radius.into(),
            afov_deg: ls.afov_deg.into(),
            sag_mm: ls.sag.into(),
            focal_depth_mm: ls.focal_depth.into(),
        },
        view: ViewReport::of(d),
        base_shift_mm: shift.into(),
        base_shift_periods: MinMax {
            min: shift.min / t,
            max: shift.max / t,
        },
        brep: outputs.step.map(BrepReport::of),
        printed: outputs.printed,
        crosscheck: outputs.crosscheck.cloned(),
        checks: checks.iter().map(CheckReport::from).collect(),
    }
}

/// The printed device's numbers in `report.json`.
#[derive(Serialize, Clone, Debug)]
pub struct PrintedReport {
    /// Band shells in `device-black.stl`.
    pub bands: u32,
    /// Through-holes of `device-clear.stl` (bands that tunnel through it).
    pub clear_genus: u32,
    pub clear_volume_mm3: f64,
    pub black_volume_mm3: f64,
    /// The whole device (clear and black together) as one solid.
    pub device_volume_mm3: f64,
    /// The band layer: the outline's area of s times t_b.
    pub band_layer_volume_mm3: f64,
    pub duty: DutyReport,
    /// Places where a band edge touched a side wall without crossing it,
    /// and how far closing each pinch moved the band's outline (mm; at
    /// most the tolerance).
    pub wall_touches: usize,
    pub wall_touch_shift_mm: f64,
    /// The bodies as B-rep solids in `device-clear.step` and
    /// `device-black.step` (once written).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub brep: Option<PrintedBrepReport>,
}

/// The printed bodies' B-rep and STEP files.
#[derive(Serialize, Clone, Debug)]
pub struct PrintedBrepReport {
    pub clear_step_bytes: usize,
    pub black_step_bytes: usize,
    #[serde(flatten)]
    pub stats: moirecast_brep::PrintedBrepStats,
}

/// The duty cycle, asked and measured two ways on the output. These are
/// measurements, not checks: the invariant is that band edges lie on
/// φ ∈ ℤ and φ ∈ ℤ + duty (`base-creases-follow-shift`, to 1e-8 periods).
/// Where the elevation bends within a period, a band's share of its period
/// in x departs from its share in φ: by 0.1 % on the shipped example, by
/// 1.5 % on a 4 mm design with a 1.5 mm bump.
#[derive(Serialize, Clone, Debug)]
pub struct DutyReport {
    pub asked: f64,
    /// Black volume / band-layer volume over whole periods (the walls cut
    /// the first and last period of each line anywhere).
    pub by_volume: f64,
    /// The same over the whole layer, partial periods at the walls included.
    pub by_volume_whole_layer: f64,
    /// Black share along lines y = const over whole periods.
    pub along_lines: f64,
    pub worst_line_deviation: f64,
    pub lines: usize,
    pub periods: usize,
}
