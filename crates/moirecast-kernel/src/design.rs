//! A validated design: the parameters of METHOD §1–§5 plus everything
//! derived from them. [`Design::new`] is the only way in, and it enforces
//! every validity rule of METHOD with a [`DesignError`] naming the parameter,
//! the value, the allowed range and the fix.

use crate::error::{DesignError, Param};
use crate::lens::ArcRule;
use crate::profile::Profile;
use crate::surface::PitchSurface;
use crate::tolerance::Tolerance;
use crate::view::{DesignView, ViewCompensation};
use glam::{DVec2, DVec3};

/// How revealer lens radii are chosen (METHOD §2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LensRule {
    /// Constant angular field of view (the paper's choice, the default).
    ConstantAfov,
    /// Every lens has the standard radius r_s (Fig. 4b, for comparison).
    EqualRadius,
}

#[derive(Clone, Copy, Debug)]
pub struct LensParams {
    /// Angular field of view α (rad).
    pub afov: f64,
    /// Refractive index n_l.
    pub index: f64,
    pub rule: LensRule,
}

/// What the base layer is (METHOD §5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BaseKind {
    /// A second lens array over s, one clear material (§5.1): the cast device.
    DualLens,
    /// Black bands on s inside a clear body, for multi-material printers (§5.2).
    Printed(PrintedBase),
}

/// The band layer of a printed device (METHOD §5.2). Layers are measured
/// along −z, the print and draw direction (see `printed.rs` for why).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrintedBase {
    /// Black share of each period: bands are where frac(φ) < duty.
    pub duty: f64,
    /// Thickness t_b of the black band layer below s (mm).
    pub band_thickness: f64,
    /// Thickness t_back of the clear backing below the bands (mm).
    pub backing: f64,
}

impl Default for PrintedBase {
    /// METHOD §5.2's defaults: duty 0.5, t_b = 0.2 mm; a 1 mm backing.
    fn default() -> Self {
        PrintedBase {
            duty: 0.5,
            band_thickness: 0.2,
            backing: 1.0,
        }
    }
}

#[derive(Clone, Copy, Debug)]
pub struct BaseParams {
    pub kind: BaseKind,
    /// Weight between the offset (0) and focal (1) surface.
    pub a: f64,
    /// Offset distance d (mm); `None` means the standard focal depth D_s.
    pub d: Option<f64>,
    /// Elevation amplitude A, in periods.
    pub levels: f64,
    /// AFOV of the base lenses (rad); `None` means the revealer's α.
    pub afov: Option<f64>,
}

/// The raw inputs of a design, in mm and radians.
#[derive(Clone, Debug)]
pub struct DesignParams {
    pub surface: PitchSurface,
    pub width: f64,
    pub height: f64,
    pub period: f64,
    pub lens: LensParams,
    pub base: BaseParams,
    pub profile: Profile,
    pub tolerance: f64,
    /// The view the base is compensated for (docs/method.md).
    pub view: DesignView,
}

impl DesignParams {
    /// A design on `surface` with METHOD's defaults: α = 60°, n_l = 1.41
    /// (Sylgard 184), constant AFOV, a = 0, d = D_s, one level, a flat
    /// profile and a 2 µm tolerance. Change fields to taste.
    pub fn with_defaults(surface: PitchSurface, width: f64, height: f64, period: f64) -> Self {
        DesignParams {
            surface,
            width,
            height,
            period,
            lens: LensParams {
                afov: 60f64.to_radians(),
                index: 1.41,
                rule: LensRule::ConstantAfov,
            },
            base: BaseParams {
                kind: BaseKind::DualLens,
                a: 0.0,
                d: None,
                levels: 1.0,
                afov: None,
            },
            profile: Profile::Flat,
            tolerance: 0.002,
            view: DesignView::default(),
        }
    }
}

/// The standard lens: the lens of the flat device, w_s = T (METHOD §2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StandardLens {
    pub width: f64,
    pub radius: f64,
    pub sag: f64,
    pub focal_length: f64,
    pub focal_depth: f64,
}

impl StandardLens {
    pub fn new(period: f64, afov: f64, index: f64) -> Self {
        let radius = period / (2.0 * (afov / 2.0).sin());
        let sag = radius * (1.0 - (afov / 2.0).cos());
        let focal_length = index * radius / (index - 1.0);
        StandardLens {
            width: period,
            radius,
            sag,
            focal_length,
            focal_depth: focal_length - sag,
        }
    }
}

/// Allowed ranges, written once, used by validation and documentation.
pub mod limits {
    /// AFOV (degrees). Below 10° lenses are nearly flat; above 120° their
    /// flanks are too steep to demould or to stay graphs on curved surfaces.
    pub const AFOV_DEG: (f64, f64) = (10.0, 120.0);
    pub const INDEX: (f64, f64) = (1.0, 3.0);
    pub const PERIOD_MM: (f64, f64) = (0.05, 20.0);
    pub const MAX_LENSES: f64 = 20000.0;
    /// Largest layout width or height (mm): a metre is beyond any printer
    /// or mold; larger lengths are typing mistakes.
    pub const MAX_LAYOUT_MM: f64 = 1000.0;
    /// Largest surface slope plus half the AFOV (degrees): beyond this a lens
    /// flank turns past vertical-ish and the device is no longer a graph over xy.
    pub const MAX_FLANK_DEG: f64 = 80.0;
    /// Largest d·κ of the offset and focal surfaces (METHOD §3 asks < 1; we
    /// keep 10 % so base lenses have room).
    pub const MAX_FOLD: f64 = 0.9;
    /// Least depth of the base below the pitch surface, in mesh
    /// tolerances: the two meshes may each stray by one tolerance.
    pub const MIN_DEPTH_TOLERANCES: f64 = 4.0;
    /// Deepest base, in focal depths D_s: at depth d a revealer lens's
    /// bundle spans T·|d − D_s|/D_s, a whole period at 2 D_s, so a deeper
    /// base averages every band away (no moiré).
    pub const MAX_DEPTH_FOCAL: f64 = 2.0;
    /// Longest focal depth D_s, in periods: a lens this weak (an index
    /// near 1) needs a device hundreds of periods thick.
    pub const MAX_FOCAL_PERIODS: f64 = 50.0;
    /// Largest A·T·∂e/∂u (METHOD §4 asks < 1 − ε; ε = 0.1 keeps base lenses
    /// at most 10 periods wide).
    pub const MAX_SHIFT_SLOPE: f64 = 0.9;
    pub const MAX_LEVELS: f64 = 100.0;
    /// Duty cycle of printed bands: narrower bands than 5 % of a period
    /// are below what multi-material printers resolve at usual periods.
    pub const DUTY: (f64, f64) = (0.05, 0.95);
    /// Band layer thickness (mm): at least a few print layers.
    pub const BAND_THICKNESS_MM: (f64, f64) = (0.01, 10.0);
    /// Clear backing thickness (mm).
    pub const BACKING_MM: (f64, f64) = (0.01, 50.0);
}

/// The largest run the mesher starts for a design. Not a validity rule: a
/// design over it is sound but would take more time and memory than a
/// user expects (`--allow-large` lifts it, on the command line and the
/// studio's).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshBudget {
    /// Most bytes a mold run of the design may hold at its peak, estimated
    /// from the curvature survey before any vertex is made
    /// ([`MeshBudget::estimated_bytes`]); `None`: no limit.
    pub max_bytes: Option<f64>,
    /// Most survey cells (lenses × cells along each): the survey that makes
    /// the estimate costs about 0.6 µs a cell, so past this it is the
    /// runaway (20,000 lenses over 1000 mm: 500 s); `None`: no limit.
    pub max_survey_cells: Option<u64>,
}

impl MeshBudget {
    /// 4 GB at a mold run's peak (the 180 mm reference mold: 1.6 GB), and
    /// 64 M survey cells (about 40 s of survey).
    pub const DEFAULT: MeshBudget = MeshBudget {
        max_bytes: Some(4e9),
        max_survey_cells: Some(64_000_000),
    };
    pub const UNLIMITED: MeshBudget = MeshBudget {
        max_bytes: None,
        max_survey_cells: None,
    };
    /// Bytes a mold run holds at its peak per device triangle (the mesh,
    /// its checks and the halves cut from it).
    pub const BYTES_PER_TRIANGLE: f64 = 600.0;
    /// Bytes per lens station of the B-rep (NURBS, topology, STEP text).
    pub const BYTES_PER_LENS_STATION: f64 = 2200.0;
    /// Bytes a run holds whatever the design (the process, the profile).
    pub const BYTES_BASE: f64 = 30e6;

    /// The bytes a mold run of `design` holds at its peak, for a mesh of
    /// `triangles`: the mesh's share and the B-rep's, whose lenses each
    /// hold about 2 (H / spacing + 10) stations, the spacing 2 mm or a
    /// procedural profile's detail (docs/benchmarks.md measures it
    /// against the peak RSS).
    pub fn estimated_bytes(design: &Design, triangles: u64) -> f64 {
        let detail = match design.params.profile {
            Profile::Sampled(_) => None,
            ref procedural => procedural.detail_mm(),
        };
        let spacing = detail.map_or(2.0, |d| d.min(2.0));
        let stations = 2.0 * (design.params.height / spacing + 10.0);
        Self::BYTES_BASE
            + Self::BYTES_PER_TRIANGLE * triangles as f64
            + Self::BYTES_PER_LENS_STATION * design.lenses as f64 * stations
    }
}

impl Default for MeshBudget {
    fn default() -> Self {
        MeshBudget::DEFAULT
    }
}

/// A design that satisfies every rule of METHOD. Geometry lives in `model.rs`.
#[derive(Clone, Debug)]
pub struct Design {
    pub params: DesignParams,
    pub standard: StandardLens,
    pub tolerance: Tolerance,
    /// Number of revealer lenses N = W / T.
    pub lenses: usize,
    /// Offset distance actually used (mm).
    pub d: f64,
    pub(crate) revealer_rule: ArcRule,
    pub(crate) base_rule: ArcRule,
    /// Outline: x of the first and last crease, and ±H/2.
    pub outline_x: (f64, f64),
    pub half_height: f64,
    /// Extra layout (mm) around Ω over which the arrays are built before trimming.
    pub margin: f64,
    /// Base crease indices that can matter: k in this range.
    pub base_creases: (i64, i64),
    /// Largest principal curvature of f found on the layout (1/mm).
    pub max_curvature: f64,
    /// Largest slope of f on the layout (rad).
    pub max_slope: f64,
    /// The largest mesh to make of it ([`MeshBudget::DEFAULT`] unless set).
    pub mesh_budget: MeshBudget,
    /// The base's view compensation C (`None`: C ≡ 0).
    pub view: Option<ViewCompensation>,
    /// E − C on an image profile's grid, where the base is compensated:
    /// the shift read in one interpolation instead of two.
    pub(crate) shift_grid: Option<crate::grid::CubicGrid>,
}

fn err(
    param: Param,
    value: impl ToString,
    problem: impl Into<String>,
    fix: impl Into<String>,
) -> DesignError {
    DesignError {
        param,
        value: value.to_string(),
        problem: problem.into(),
        fix: fix.into(),
    }
}

fn finite(param: Param, v: f64) -> Result<f64, DesignError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(err(param, v, "must be a finite number", "write a number"))
    }
}

fn in_range(
    param: Param,
    v: f64,
    (lo, hi): (f64, f64),
    unit: &str,
    fix: &str,
) -> Result<f64, DesignError> {
    finite(param, v)?;
    if v < lo || v > hi {
        return Err(err(
            param,
            v,
            format!("must be between {lo} and {hi} {unit}"),
            fix,
        ));
    }
    Ok(v)
}

impl Design {
    pub fn new(p: DesignParams) -> Result<Design, DesignError> {
        let (n, index, base_afov) = Self::check_ranges(&p)?;
        let standard = StandardLens::new(p.period, p.lens.afov, index);
        Self::check_focal_depth(&p, &standard, index)?;
        let (d, tolerance) = Self::depth_and_tolerance(&p, &standard)?;
        let revealer_rule = match p.lens.rule {
            LensRule::ConstantAfov => ArcRule::ConstantAfov {
                half_angle: p.lens.afov / 2.0,
            },
            LensRule::EqualRadius => ArcRule::EqualRadius {
                radius: standard.radius,
            },
        };
        let base_rule = ArcRule::ConstantAfov {
            half_angle: base_afov / 2.0,
        };
        let n = n as usize;
        let provisional_margin = d + (p.base.levels + 2.0) * p.period;
        let mut design = Design {
            tolerance,
            lenses: n,
            d,
            revealer_rule,
            base_rule,
            outline_x: (0.0, 0.0),
            half_height: p.height / 2.0,
            margin: provisional_margin,
            base_creases: (0, 0),
            max_curvature: 0.0,
            max_slope: 0.0,
            mesh_budget: MeshBudget::DEFAULT,
            view: None,
            shift_grid: None,
            standard,
            params: p,
        };
        design.outline_x = (
            design.surface().x_of_u(design.crease_u(0)),
            design.surface().x_of_u(design.crease_u(n as i64)),
        );
        design.settle_margin(base_afov)?;
        design.view = design.compute_view_compensation()?;
        design.shift_grid = design.sampled_shift_grid();
        design.validate_profile()?;
        // Base creases that can reach the extended layout: φ = (u + W/2 − E + C)/T,
        // E ∈ [0, A·T], |C| ≤ C_max.
        let a_t = design.params.base.levels * design.params.period;
        let c_max = design.view.as_ref().map_or(0.0, |c| c.max_abs_mm);
        let t = design.params.period;
        let k_lo = ((-design.margin - 1.5 * a_t - c_max) / t).floor() as i64 - 1;
        let k_hi =
            ((design.params.width + design.margin + 0.5 * a_t + c_max) / t).ceil() as i64 + 1;
        // a printed base has two band edges per period: φ = k and φ = k + duty
        design.base_creases = match design.params.base.kind {
            BaseKind::DualLens => (k_lo, k_hi),
            BaseKind::Printed(_) => (2 * k_lo, 2 * k_hi),
        };
        Ok(design)
    }

    /// Every parameter against its own range: the lens count N, the
    /// index and the base lenses' AFOV.
    fn check_ranges(p: &DesignParams) -> Result<(f64, f64, f64), DesignError> {
        use limits::*;
        let deg = |r: f64| r.to_degrees();
        in_range(
            Param::Period,
            p.period,
            PERIOD_MM,
            "mm",
            "choose a lens period in that range",
        )?;
        let w = finite(Param::Width, p.width)?;
        let h = finite(Param::Height, p.height)?;
        if w <= 0.0 {
            return Err(err(
                Param::Width,
                w,
                "must be positive",
                "give the layout width in mm",
            ));
        }
        if h <= 0.0 {
            return Err(err(
                Param::Height,
                h,
                "must be positive",
                "give the layout height in mm",
            ));
        }
        // a layout shorter than a lens is wide has no lens to see, and
        // its wall triangles degenerate
        if h < p.period {
            return Err(err(
                Param::Height,
                h,
                format!("is shorter than one lens period ({} mm)", p.period),
                format!("use a height of at least {} mm", p.period),
            ));
        }
        for (param, v) in [(Param::Width, w), (Param::Height, h)] {
            if v > MAX_LAYOUT_MM {
                return Err(err(
                    param,
                    v,
                    format!("is over {MAX_LAYOUT_MM} mm, larger than any printer or mold"),
                    format!("use at most {MAX_LAYOUT_MM} mm"),
                ));
            }
        }
        let periods = w / p.period;
        let n = periods.round();
        if (periods - n).abs() > 1e-9 * periods.max(1.0) || n < 1.0 {
            let (lo, hi) = (
                (periods.floor().max(1.0)) * p.period,
                (periods.ceil().max(1.0)) * p.period,
            );
            return Err(err(
                Param::Width,
                w,
                format!(
                    "is {periods:.4} lens periods of {} mm; it must be a whole number",
                    p.period
                ),
                format!("use a width of {lo} or {hi} mm, or change the period"),
            ));
        }
        if n > MAX_LENSES {
            return Err(err(
                Param::Width,
                w,
                format!("gives {n} lenses, more than {MAX_LENSES}"),
                "use a larger period",
            ));
        }
        in_range(
            Param::Afov,
            deg(p.lens.afov),
            AFOV_DEG,
            "degrees",
            "60 degrees is the paper's choice",
        )?;
        let index = finite(Param::Index, p.lens.index)?;
        if index <= INDEX.0 || index > INDEX.1 {
            return Err(err(
                Param::Index,
                index,
                format!("must be above {} and at most {}", INDEX.0, INDEX.1),
                "Sylgard 184 is 1.41",
            ));
        }
        let base_afov = p.base.afov.unwrap_or(p.lens.afov);
        in_range(
            Param::BaseAfov,
            deg(base_afov),
            AFOV_DEG,
            "degrees",
            "leave it out to use the revealer's AFOV",
        )?;
        in_range(
            Param::BaseA,
            p.base.a,
            (0.0, 1.0),
            "",
            "0 is the offset surface, 1 the focal surface",
        )?;
        in_range(
            Param::Levels,
            p.base.levels,
            (0.0, MAX_LEVELS),
            "periods",
            "1 level is the usual choice",
        )?;
        if let BaseKind::Printed(pb) = p.base.kind {
            in_range(
                Param::Duty,
                pb.duty,
                DUTY,
                "",
                "0.5 gives equal black and clear bands",
            )?;
            in_range(
                Param::BandThickness,
                pb.band_thickness,
                BAND_THICKNESS_MM,
                "mm",
                "0.2 mm is the default",
            )?;
            in_range(
                Param::Backing,
                pb.backing,
                BACKING_MM,
                "mm",
                "1 mm is the default",
            )?;
        }
        Ok((n, index, base_afov))
    }

    /// The standard lens must focus within [`limits::MAX_FOCAL_PERIODS`]
    /// periods (an index near 1 focuses hundreds of periods deep).
    fn check_focal_depth(
        p: &DesignParams,
        standard: &StandardLens,
        index: f64,
    ) -> Result<(), DesignError> {
        use limits::MAX_FOCAL_PERIODS;
        let periods = standard.focal_depth / p.period;
        if periods > MAX_FOCAL_PERIODS {
            return Err(err(
                Param::Index,
                index,
                format!(
                    "lenses of index {index} and {:.1}° AFOV focus {periods:.0} periods deep (D_s = {:.4} mm); at most {MAX_FOCAL_PERIODS} periods are allowed",
                    p.lens.afov.to_degrees(),
                    standard.focal_depth
                ),
                "use a higher index (cast silicone is 1.41) or another lens.afov",
            ));
        }
        Ok(())
    }

    /// The offset distance d actually used and the mesh tolerance, with
    /// the surface's radius checked.
    fn depth_and_tolerance(
        p: &DesignParams,
        standard: &StandardLens,
    ) -> Result<(f64, Tolerance), DesignError> {
        use limits::MAX_DEPTH_FOCAL;
        let d = match p.base.d {
            None => standard.focal_depth,
            Some(d) => {
                finite(Param::BaseD, d)?;
                if d <= 0.0 {
                    return Err(err(
                        Param::BaseD,
                        d,
                        "the base must lie below the pitch surface: d > 0",
                        format!("use \"focal\" (D_s = {:.4} mm)", standard.focal_depth),
                    ));
                }
                if d > MAX_DEPTH_FOCAL * standard.focal_depth {
                    return Err(err(
                        Param::BaseD,
                        d,
                        format!(
                            "the base lies more than {MAX_DEPTH_FOCAL} focal depths (D_s = {:.4} mm) below the surface: each lens's bundle then spans a whole period or more, and the moiré averages away",
                            standard.focal_depth
                        ),
                        format!(
                            "use d ≤ {:.4} mm, or \"focal\"",
                            MAX_DEPTH_FOCAL * standard.focal_depth
                        ),
                    ));
                }
                d
            }
        };
        let tol = finite(Param::Tolerance, p.tolerance)?;
        let tolerance = Tolerance::from_mm(tol).ok_or_else(|| {
            err(
                Param::Tolerance,
                tol,
                format!(
                    "must be between {} and {} mm",
                    Tolerance::MIN_MM,
                    Tolerance::MAX_MM
                ),
                "0.002 mm is the reference",
            )
        })?;
        if tol >= standard.sag / 2.0 {
            return Err(err(
                Param::Tolerance,
                tol,
                format!(
                    "must be below half the lens sag ({:.4} mm), or the lenses are not represented",
                    standard.sag
                ),
                format!("use at most {:.4} mm", standard.sag / 4.0),
            ));
        }
        match &p.surface {
            PitchSurface::Plane | PitchSurface::Formula(_) | PitchSurface::HeightMap(_) => {}
            PitchSurface::Saddle { radius: r }
            | PitchSurface::Paraboloid { radius: r }
            | PitchSurface::Cylinder { radius: r }
            | PitchSurface::Sphere { radius: r } => {
                finite(Param::SurfaceRadius, *r)?;
                if *r == 0.0 {
                    return Err(err(
                        Param::SurfaceRadius,
                        r,
                        "must not be zero",
                        "give a radius in mm",
                    ));
                }
            }
        }
        Ok((d, tolerance))
    }

    /// Samples along each edge of the layout for
    /// [`Design::base_covers_outline`].
    const BASE_REACH_SAMPLES: usize = 32;
    /// Growth steps (×1.25 plus a period each) of the layout beyond its
    /// edge before [`Design::settle_margin`] takes over.
    const BASE_REACH_STEPS: usize = 16;

    /// The base lies up to d_eff below f, so the surface is needed (and
    /// validated) over a margin around the layout that depends on d_eff,
    /// which with a > 0 depends on the surface out there: grows the margin
    /// until the validated region covers the base it finds.
    fn settle_margin(&mut self, base_afov: f64) -> Result<(), DesignError> {
        let mut covered = false;
        // the revealer's dip depends on the layout only, not the margin
        let mut dip = None;
        for _ in 0..6 {
            let validated = self.margin;
            self.validate_surface(base_afov, &mut dip)?;
            if self.margin <= validated {
                self.margin = validated;
                covered = true;
                break;
            }
            // validate a padded region next, so the search settles quickly
            self.margin *= 1.25;
        }
        if !covered {
            return Err(err(
                Param::BaseA,
                self.params.base.a,
                format!("the focal surface keeps moving away from the layout as the layout grows (base depth over {:.1} mm)", self.margin),
                "use a smaller a, or a flatter surface",
            ));
        }
        Ok(())
    }

    pub fn surface(&self) -> &PitchSurface {
        &self.params.surface
    }

    /// A (cells+1)² grid over the extended layout.
    fn grid(&self, cells: usize) -> impl Iterator<Item = DVec2> + '_ {
        let (hw, hh, m) = (
            self.params.width / 2.0 + self.margin,
            self.half_height + self.margin,
            cells as f64,
        );
        (0..=cells).flat_map(move |j| {
            (0..=cells).map(move |i| {
                DVec2::new(-hw + 2.0 * hw * i as f64 / m, -hh + 2.0 * hh * j as f64 / m)
            })
        })
    }

    /// Stations along v and points across each lens at which
    /// [`Design::revealer_dip`] measures.
    const DIP_STATIONS: usize = 33;
    const DIP_POINTS: [f64; 5] = [0.25, 0.375, 0.5, 0.625, 0.75];

    /// The revealer's greatest depth below the pitch surface (mm, ≤ 0 where
    /// it stays above), and the layout point where it is. A lens rises its
    /// sag above its chord, but where the surface is convex along u the
    /// chord cuts about κ·w²/8 under it; where that is more, the lens's
    /// middle lies below f, and a base crease under it is nearer than its
    /// depth (found-84500bc4b4ea7934: 0.13 mm on a bump, with d = 0.0056).
    /// Measured along f's normal from the point of f at the same fraction
    /// of the lens's layout span, at [`Self::DIP_POINTS`] across every lens
    /// and [`Self::DIP_STATIONS`] stations. Skipped (0) where the surface's
    /// largest curvature `kmax` bounds the dip at half the sag: with chords
    /// w ≤ T / cos(slope), a constant-AFOV sag is w·tan(α/4)/2 and an
    /// equal-radius one w²/(8 r_s).
    fn revealer_dip(&self, kmax: f64, max_slope: f64) -> (f64, DVec2) {
        let period = self.params.period;
        let shallow = match self.revealer_rule {
            ArcRule::ConstantAfov { half_angle } => {
                let widest = period / max_slope.cos().max(1e-6);
                kmax * widest <= 2.0 * (half_angle / 2.0).tan()
            }
            ArcRule::EqualRadius { radius } => 2.0 * kmax * radius <= 1.0,
        };
        if shallow {
            return (0.0, DVec2::ZERO);
        }
        let mut deepest = (f64::NEG_INFINITY, DVec2::ZERO);
        let stations = Self::DIP_STATIONS;
        for j in 0..stations {
            let v = self.half_height * (2.0 * j as f64 / (stations - 1) as f64 - 1.0);
            for i in 0..self.lenses as i64 {
                let arc = self.revealer_arc(i, v);
                for t in Self::DIP_POINTS {
                    let u = self.crease_u(i) + t * period;
                    let (p, n) = self.surface().point_and_normal(u, v);
                    let depth = (p - arc.point(t)).dot(n);
                    // NaN (a surface undefined there) is left to the survey
                    if depth > deepest.0 {
                        deepest = (depth, DVec2::new(u, v));
                    }
                }
            }
        }
        deepest
    }

    /// The revealer and the base meshes, each within the tolerance of its
    /// surface, must not meet: the base (shallowest at `shallowest`) at
    /// least MIN_DEPTH_TOLERANCES tolerances below the pitch surface, and
    /// below the revealer's `dip` ([`Design::revealer_dip`]).
    fn validate_depth(
        &self,
        shallowest: (f64, DVec2),
        (dip, dip_at): (f64, DVec2),
    ) -> Result<(), DesignError> {
        use limits::MIN_DEPTH_TOLERANCES;
        let min_depth = MIN_DEPTH_TOLERANCES * self.tolerance.mm();
        let needed = min_depth + dip.max(0.0);
        if shallowest.0 < needed {
            let at = shallowest.1;
            let (why, fix) = if dip > 0.0 {
                (
                    format!("the revealer's lenses dip up to {dip:.4} mm below the pitch surface at layout ({:.1}, {:.1}) mm, where it is convex along u (their chords cut under it), so the base must lie at least that plus {MIN_DEPTH_TOLERANCES} × the mesh tolerance ({needed:.4} mm) below it", dip_at.x, dip_at.y),
                    format!("use d ≥ {needed:.4} mm (D_s = {:.4} mm is the focal depth), a smaller period or a larger AFOV", self.standard.focal_depth),
                )
            } else {
                (
                    format!("it must lie at least {MIN_DEPTH_TOLERANCES} × the mesh tolerance ({min_depth} mm) below it"),
                    format!("use d ≥ {min_depth} mm (D_s = {:.4} mm is the focal depth), or a finer mesh.tolerance", self.standard.focal_depth),
                )
            };
            Err(err(
                Param::BaseD,
                format!("{:.4}", self.d),
                format!(
                    "the base lies only {:.4} mm below the pitch surface at layout ({:.1}, {:.1}) mm; {why}, or the revealer and the base meet",
                    shallowest.0, at.x, at.y
                ),
                fix,
            ))
        } else {
            Ok(())
        }
    }

    fn validate_surface(
        &mut self,
        base_afov: f64,
        dip: &mut Option<(f64, DVec2)>,
    ) -> Result<(), DesignError> {
        use limits::*;
        let radius_param = match self.surface() {
            PitchSurface::Formula(_) => Param::SurfaceFormula,
            PitchSurface::HeightMap(_) => Param::SurfaceHeightMap,
            _ => Param::SurfaceRadius,
        };
        let gentler = self.surface().gentler();
        let radius_value = match self.surface() {
            PitchSurface::Saddle { radius }
            | PitchSurface::Paraboloid { radius }
            | PitchSurface::Cylinder { radius }
            | PitchSurface::Sphere { radius } => radius.to_string(),
            PitchSurface::Formula(f) => f.source.clone(),
            PitchSurface::HeightMap(m) => format!(
                "a height map over {} × {} mm, smoothing {} mm",
                m.extent().0,
                m.extent().1,
                m.smoothing()
            ),
            PitchSurface::Plane => "plane".into(),
        };
        let (mut kmax, mut smax, mut dmax, mut fold_at) = (0.0f64, 0.0f64, 0.0f64, DVec2::ZERO);
        let mut shallowest = (f64::INFINITY, DVec2::ZERO);
        let (mut smax_inside, mut steep_at) = (0.0f64, DVec2::ZERO);
        let mut steepest_base = (0.0f64, DVec2::ZERO);
        let (hw, hh) = (self.params.width / 2.0, self.half_height);
        let mut worst_fold = 0.0f64;
        let pts: Vec<DVec2> = self.grid(64).collect();
        for q in pts {
            let jet = self.surface().jet(q.x, q.y);
            let n = jet.normal();
            if !jet.p.is_finite() || !n.is_finite() || !jet.duu.is_finite() || !jet.dvv.is_finite()
            {
                return Err(err(
                    radius_param,
                    radius_value,
                    format!("the surface is not defined at layout point ({:.2}, {:.2}) mm (the layout plus a {:.2} mm margin for the base)", q.x, q.y, self.margin),
                    format!("{gentler}, or a smaller layout"),
                ));
            }
            if self.surface().x_of_u(q.x + 1e-6) <= self.surface().x_of_u(q.x - 1e-6) {
                return Err(err(
                    radius_param,
                    radius_value,
                    "the surface folds back over itself in x",
                    format!("{gentler}, or a smaller width"),
                ));
            }
            let slope = n.z.clamp(-1.0, 1.0).acos();
            let k = jet.max_abs_curvature();
            let d_eff = self.base_offset(q.x, q.y);
            dmax = dmax.max(d_eff);
            if d_eff < shallowest.0 {
                shallowest = (d_eff, q);
            }
            if d_eff * k > worst_fold {
                worst_fold = d_eff * k;
                fold_at = q;
            }
            if self.params.base.a > 0.0 {
                let base_slope = self.base_normal(q.x, q.y).z.clamp(-1.0, 1.0).acos();
                if base_slope.is_nan() || base_slope > steepest_base.0 {
                    steepest_base = (base_slope, q);
                }
            }
            kmax = kmax.max(k);
            if slope > smax {
                smax = slope;
                steep_at = q;
            }
            if q.x.abs() <= hw && q.y.abs() <= hh {
                smax_inside = smax_inside.max(slope);
            }
        }
        self.max_curvature = kmax;
        self.max_slope = smax;
        let dip = *dip.get_or_insert_with(|| self.revealer_dip(kmax, smax));
        self.validate_depth(shallowest, dip)?;
        // The fold is checked first: a folding base is the root cause when both fail.
        if worst_fold >= MAX_FOLD {
            let allowed = MAX_FOLD / kmax;
            let d_note = if self.params.base.a > 0.0 {
                " (with a > 0 the focal surface also counts)"
            } else {
                ""
            };
            return Err(err(
                Param::BaseD,
                format!("{:.4}", self.d),
                format!(
                    "the base surface folds: d·κ = {worst_fold:.3} at layout ({:.1}, {:.1}) mm, where the surface curvature is {:.4}/mm; it must stay below {MAX_FOLD}{d_note}",
                    fold_at.x, fold_at.y, kmax
                ),
                format!("use d ≤ {allowed:.3} mm, or a flatter surface"),
            ));
        }
        let half_afov = self.params.lens.afov.max(base_afov) / 2.0;
        let flank = (smax + half_afov).to_degrees();
        let d_is_the_cause = self.params.base.d.is_some() && self.d > self.standard.focal_depth;
        if flank > MAX_FLANK_DEG
            && d_is_the_cause
            && (smax_inside + half_afov).to_degrees() <= MAX_FLANK_DEG
        {
            return Err(err(
                Param::BaseD,
                format!("{:.4}", self.d),
                format!(
                    "the base lies up to {dmax:.2} mm below the surface, so the surface is needed {:.2} mm beyond the layout; at layout ({:.1}, {:.1}) mm it slopes {:.1}° and lens flanks would reach {flank:.1}°, over the {MAX_FLANK_DEG}° limit",
                    self.margin,
                    steep_at.x,
                    steep_at.y,
                    smax.to_degrees()
                ),
                format!("use a smaller d (D_s = {:.4} mm is the focal depth)", self.standard.focal_depth),
            ));
        }
        if flank > MAX_FLANK_DEG {
            return Err(err(
                radius_param,
                radius_value,
                format!(
                    "the surface slopes {:.1}° and the lenses add {:.1}°: lens flanks reach {flank:.1}°, over the {MAX_FLANK_DEG}° limit (the device must stay a graph over xy, with vertical walls, or it cannot release from a two-piece mold along z)",
                    smax.to_degrees(),
                    self.params.lens.afov.max(base_afov).to_degrees() / 2.0
                ),
                format!("{gentler}, a smaller layout or a smaller AFOV"),
            ));
        }
        self.validate_base_flank(steepest_base, base_afov)?;
        // The layout beyond the edge must hold the base's own points under
        // the outline. Where the base lies well inside a tight cylinder, it
        // spreads less in x than the layout does in u, and d_max of layout
        // is not enough (found-2edb06875b8a5108: 6.1 mm needed, d = 4.1 mm).
        let mut reach = dmax;
        for _ in 0..Self::BASE_REACH_STEPS {
            if self.base_covers_outline(reach) {
                break;
            }
            reach = 1.25 * reach + self.params.period;
        }
        self.margin = reach + (self.params.base.levels + 2.0) * self.params.period;
        self.validate_equal_radius_chords()
    }

    /// With a > 0 the base surface is no offset of f: its depth D_s·λ
    /// changes across the surface, and where the curvature changes fast it
    /// tilts further than f does (found-07be06007bd9ec48: 49° under a bump
    /// of 34°). Its lenses' flanks count from its own slope.
    fn validate_base_flank(
        &self,
        (slope, at): (f64, DVec2),
        base_afov: f64,
    ) -> Result<(), DesignError> {
        let half_afov = match self.params.base.kind {
            BaseKind::DualLens => base_afov / 2.0,
            BaseKind::Printed(_) => 0.0,
        };
        let flank = (slope + half_afov).to_degrees();
        if flank.is_nan() || flank > limits::MAX_FLANK_DEG {
            return Err(err(
                Param::BaseA,
                self.params.base.a,
                format!(
                    "the base surface between the offset and the focal surface slopes {:.1}° at layout ({:.1}, {:.1}) mm, and its lenses add {:.1}°: their flanks reach {flank:.1}°, over the {}° limit (the device must stay a graph over xy)",
                    slope.to_degrees(),
                    at.x,
                    at.y,
                    half_afov.to_degrees(),
                    limits::MAX_FLANK_DEG
                ),
                "use a smaller a, a smaller AFOV or a surface whose curvature changes more slowly",
            ));
        }
        Ok(())
    }

    /// Whether the base surface `reach` beyond the layout's edges lies
    /// beyond the outline, all along each edge (NaN, where the surface is
    /// not defined out there, does not).
    fn base_covers_outline(&self, reach: f64) -> bool {
        let (hw, hh) = (self.params.width / 2.0, self.half_height);
        let (xl, xr) = self.outline_x;
        (0..=Self::BASE_REACH_SAMPLES).all(|i| {
            let s = 2.0 * i as f64 / Self::BASE_REACH_SAMPLES as f64 - 1.0;
            let (u, v) = (s * hw, s * hh);
            self.base_surface(-hw - reach, v).x <= xl
                && self.base_surface(hw + reach, v).x >= xr
                && self.base_surface(u, -hh - reach).y <= -hh
                && self.base_surface(u, hh + reach).y >= hh
        })
    }

    /// Equal-radius lenses must span their chords (a lens of radius r
    /// cannot bridge a chord longer than 2r).
    fn validate_equal_radius_chords(&self) -> Result<(), DesignError> {
        if self.params.lens.rule == LensRule::EqualRadius {
            let mut wmax = 0.0f64;
            for i in 0..self.lenses as i64 {
                for v in [-self.half_height, 0.0, self.half_height] {
                    wmax =
                        wmax.max((self.crease_point(i + 1, v) - self.crease_point(i, v)).length());
                }
            }
            if wmax > 2.0 * self.standard.radius * 0.999 {
                return Err(err(
                    Param::Afov,
                    self.params.lens.afov.to_degrees(),
                    format!(
                        "equal-radius lenses of r_s = {:.4} mm cannot span chords of {wmax:.4} mm",
                        self.standard.radius
                    ),
                    "use constant AFOV lenses, or a smaller AFOV",
                ));
            }
            // a longer chord at the same radius is a wider arc: its flanks
            // turn by more than AFOV/2 (found by the design fuzzer:
            // tests/design-corpus/found-b6be704196c67c49.toml)
            let half_arc = (wmax / (2.0 * self.standard.radius)).min(1.0).asin();
            let flank = (self.max_slope + half_arc).to_degrees();
            if flank > limits::MAX_FLANK_DEG {
                return Err(err(
                    Param::Afov,
                    self.params.lens.afov.to_degrees(),
                    format!(
                        "equal-radius lenses of r_s = {:.4} mm span chords up to {wmax:.4} mm on this surface, so their arcs open to {:.1}° each side; with the surface's slope of {:.1}° their flanks reach {flank:.1}°, over the {}° limit (the device must stay a graph over xy)",
                        self.standard.radius,
                        half_arc.to_degrees(),
                        self.max_slope.to_degrees(),
                        limits::MAX_FLANK_DEG
                    ),
                    "use constant AFOV lenses (lens.rule = \"constant-afov\"), a smaller AFOV or a flatter surface",
                ));
            }
        }
        Ok(())
    }

    fn validate_profile(&self) -> Result<(), DesignError> {
        let a_t = self.params.base.levels * self.params.period;
        if a_t == 0.0 && self.view.is_none() {
            return Ok(());
        }
        let (hw, hh) = (
            self.params.width / 2.0 + self.margin,
            self.half_height + self.margin,
        );
        let (slope, at) = self.params.profile.max_slope_x(hw, hh);
        let shift_slope = a_t * slope;
        if shift_slope >= limits::MAX_SHIFT_SLOPE {
            let max_levels = limits::MAX_SHIFT_SLOPE / (self.params.period * slope);
            return Err(err(
                Param::Levels,
                self.params.base.levels,
                format!(
                    "the elevation is too steep for its period: A·T·∂e/∂u = {shift_slope:.3} at layout ({:.1}, {:.1}) mm; it must stay below {} or the base lenses fold",
                    at.x,
                    at.y,
                    limits::MAX_SHIFT_SLOPE
                ),
                format!("use levels ≤ {max_levels:.3}, or more profile blur"),
            ));
        }
        if let Some(view) = &self.view {
            if shift_slope + view.max_slope_grid >= limits::MAX_SHIFT_SLOPE {
                self.validate_compensated_slope(view.spacing())?;
            }
        }
        self.validate_leaning_lenses(a_t)
    }

    /// The compensated phase must rise with u as the elevation's alone
    /// must: |∂(E − C)/∂u| below [`limits::MAX_SHIFT_SLOPE`], scanned over
    /// the extended layout at a quarter of the finer of the profile's detail
    /// and C's grid. Only run where the two slopes' sum could reach it.
    fn validate_compensated_slope(&self, c_spacing: f64) -> Result<(), DesignError> {
        let detail = self.params.profile.detail_mm().unwrap_or(f64::INFINITY);
        let (hw, hh) = (
            self.params.width / 2.0 + self.margin,
            self.half_height + self.margin,
        );
        let longer = 2.0 * hw.max(hh);
        let step = (0.25 * detail.min(c_spacing)).max(longer / COMPENSATED_SLOPE_CELLS);
        let (nx, ny) = (
            (2.0 * hw / step).ceil() as usize,
            (2.0 * hh / step).ceil() as usize,
        );
        let steepest = (0..=ny)
            .flat_map(|j| (0..=nx).map(move |i| (i, j)))
            .map(|(i, j)| {
                let q = DVec2::new(-hw + i as f64 * step, -hh + j as f64 * step);
                (self.shift_and_gradient(q.x, q.y).1.x.abs(), q)
            })
            .fold((0.0f64, DVec2::ZERO), |a, b| if b.0 > a.0 { b } else { a });
        if steepest.0 >= limits::MAX_SHIFT_SLOPE {
            return Err(err(
                Param::ViewCompensate,
                true,
                format!(
                    "the view compensation C makes the base phase stop rising with u: ∂(E − C)/∂u = {:.3} at layout ({:.1}, {:.1}) mm; it must stay below {} or the base lenses fold",
                    steepest.0,
                    steepest.1.x,
                    steepest.1.y,
                    limits::MAX_SHIFT_SLOPE
                ),
                "use a larger radius, fewer levels, a smaller field (lens.afov), or compensate = false",
            ));
        }
        Ok(())
    }

    /// Base lenses leaning over themselves. A crease slanted in xy (the
    /// shift changing along v: du/dv = s = A·T·∂e/∂v / (1 − A·T·∂e/∂u))
    /// turns each base lens's flanks: along the crease the flank runs
    /// along s_v + s·s_u instead of s_v, while across it the arc leaves
    /// its chord at β/2 towards −n (β the base lenses' AFOV). Where the
    /// base surface slopes too, the flank steepens past slope + β/2 and
    /// can overhang: found-94ef9d50cd986eb0 (a plane sloping 53° along y,
    /// 6 levels of a gray image) and found-567ae25e16016c83 (a plane
    /// sloping 39°, mostly along x, under a bump: flanks of 92°). The
    /// flank's exact normal, from those two tangents, must stay within
    /// [`limits::MAX_FLANK_DEG`] of vertical, like every other flank.
    fn validate_leaning_lenses(&self, a_t: f64) -> Result<(), DesignError> {
        let half_afov = match (self.params.base.kind, self.base_rule) {
            (BaseKind::DualLens, ArcRule::ConstantAfov { half_angle }) => half_angle,
            (BaseKind::DualLens, ArcRule::EqualRadius { .. }) => return Ok(()),
            (BaseKind::Printed(_), _) => 0.0,
        };
        let frames: Vec<LeanFrame> = self
            .grid(LEAN_GRID_CELLS)
            .map(|q| {
                let (s_u, s_v) = self.base_tangents(q.x, q.y);
                let (_, grad) = self.params.profile.value_grad(q.x, q.y);
                let view_grad = self
                    .view
                    .as_ref()
                    .map_or(DVec2::ZERO, |c| c.offset(q.x, q.y).1);
                LeanFrame {
                    at: q,
                    s_u,
                    s_v,
                    grad,
                    view_grad,
                }
            })
            .collect();
        let steepest = |scale: f64| {
            frames
                .iter()
                .map(|f| (f.flank(scale * a_t, half_afov), f.at))
                .fold(
                    (0.0f64, DVec2::ZERO),
                    |a, b| if steeper(b.0, a.0) { b } else { a },
                )
        };
        let (flank, at) = steepest(1.0);
        let limit = limits::MAX_FLANK_DEG.to_radians();
        let by_view = self.view.as_ref().map(|_| steepest(0.0));
        if let Some((by_view, by_view_at)) = by_view.filter(|(f, _)| f.is_nan() || *f > limit) {
            return Err(err(
                Param::ViewCompensate,
                true,
                format!(
                    "the view compensation slants the base creases across the layout so far that at layout ({:.1}, {:.1}) mm the base lenses' flanks reach {:.1}°, over the {}° limit (the device must stay a graph over xy)",
                    by_view_at.x,
                    by_view_at.y,
                    by_view.to_degrees(),
                    limits::MAX_FLANK_DEG
                ),
                "use a larger radius, a smaller field (lens.afov), or compensate = false",
            ));
        }
        if flank.is_nan() || flank > limit {
            // the largest share of the levels that keeps every flank in
            // the limit (the flanks steepen with the slant, and it with A),
            // less 1 %: the grid moves with the margin, which grows with A
            let (mut ok, mut bad) = (0.0, 1.0);
            for _ in 0..LEAN_BISECTIONS {
                let mid = 0.5 * (ok + bad);
                if steepest(mid).0 <= limit {
                    ok = mid;
                } else {
                    bad = mid;
                }
            }
            return Err(err(
                Param::Levels,
                self.params.base.levels,
                format!(
                    "the base lenses lean over themselves: their creases slant across the layout (the elevation changes along v) on a sloping surface, and at layout ({:.1}, {:.1}) mm their flanks reach {:.1}°, over the {}° limit (the device must stay a graph over xy)",
                    at.x,
                    at.y,
                    flank.to_degrees(),
                    limits::MAX_FLANK_DEG
                ),
                format!(
                    "use levels ≤ {:.3}, more profile blur, or a surface that slopes less",
                    (0.99e3 * ok * self.params.base.levels).floor() / 1e3
                ),
            ));
        }
        Ok(())
    }
}

/// The base surface's frame and the elevation's gradient at one point of
/// [`Design::validate_leaning_lenses`]' grid.
struct LeanFrame {
    at: DVec2,
    s_u: DVec3,
    s_v: DVec3,
    grad: DVec2,
    /// ∇C, the view compensation's gradient (zero without it).
    view_grad: DVec2,
}

impl LeanFrame {
    /// The steeper of the two flanks of a base lens here, as an angle from
    /// horizontal (over 90°: it overhangs), for shift amplitude `a_t` (mm)
    /// and base half-AFOV `half_afov`.
    fn flank(&self, a_t: f64, half_afov: f64) -> f64 {
        // the shift's gradient, A·T·∇e − ∇C
        let (along, across) = (
            a_t * self.grad.y - self.view_grad.y,
            a_t * self.grad.x - self.view_grad.x,
        );
        let slant = along / (1.0 - across).max(1.0 - limits::MAX_SHIFT_SLOPE);
        let n = self.s_u.cross(self.s_v).normalize();
        let across = self.s_u.normalize();
        let along = self.s_v + slant * self.s_u;
        let (sin, cos) = half_afov.sin_cos();
        [1.0, -1.0]
            .map(|side| {
                let flank_normal = (cos * across - side * sin * n).cross(along).normalize();
                flank_normal.z.clamp(-1.0, 1.0).acos()
            })
            .into_iter()
            .fold(0.0f64, |a, b| if steeper(b, a) { b } else { a })
    }
}

/// Whether flank angle `b` replaces `a` as the steepest: a NaN (a normal
/// that is not defined) wins and stays, so the rule refuses it.
fn steeper(b: f64, a: f64) -> bool {
    b > a || b.is_nan()
}

/// Halvings of the levels' share in the fix [`Design::validate_leaning_lenses`] suggests.
const LEAN_BISECTIONS: usize = 30;

/// Cells per side of the grid [`Design::validate_leaning_lenses`] samples.
const LEAN_GRID_CELLS: usize = 128;

/// Most cells along the longer side of the scan of
/// [`Design::validate_compensated_slope`].
const COMPENSATED_SLOPE_CELLS: f64 = 2048.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// Worked by hand: T = 0.5 mm, α = 60°, n = 1.41.
    /// r = T / (2 sin 30°) = 0.5; s = 0.5 (1 − cos 30°) = 0.0669872981;
    /// F = 1.41 · 0.5 / 0.41 = 1.7195121951; D = F − s = 1.6525248970.
    #[test]
    fn standard_lens_by_hand() {
        let s = StandardLens::new(0.5, 60f64.to_radians(), 1.41);
        assert!((s.radius - 0.5).abs() < 1e-15);
        assert!((s.sag - 0.066_987_298_107_780_7).abs() < 1e-15);
        assert!((s.focal_length - 1.719_512_195_121_951).abs() < 1e-12);
        assert!((s.focal_depth - 1.652_524_897_014_17).abs() < 1e-12);
        // α = 90°, T = 1: r = 1/√2, s = r(1 − 1/√2), n = 1.5: F = 3r.
        let s = StandardLens::new(1.0, 90f64.to_radians(), 1.5);
        assert!((s.radius - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-15);
        assert!((s.sag - (std::f64::consts::FRAC_1_SQRT_2 - 0.5)).abs() < 1e-15);
        assert!((s.focal_length - 3.0 * std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-14);
    }

    /// On a dome cylinder of radius R, a lens spanning T of arc has the
    /// chord w = 2R·sin(T/2R), which cuts R(1 − cos(T/2R)) under the
    /// surface at its middle, where the lens rises its sag w·tan(α/4)/2
    /// above it: the revealer dips by the difference, and a base shallower
    /// than that plus MIN_DEPTH_TOLERANCES tolerances is refused by base.d
    /// (found-84500bc4b4ea7934).
    #[test]
    fn a_lens_dips_below_a_dome_by_hand() {
        let (r, t, afov) = (10.0, 2.5, 10f64.to_radians());
        let mut p = DesignParams::with_defaults(PitchSurface::Cylinder { radius: r }, 5.0, 3.0, t);
        p.lens.afov = afov;
        p.base.levels = 0.0;
        p.base.d = Some(0.2);
        let w = 2.0 * r * (t / (2.0 * r)).sin();
        let dip = r * (1.0 - (t / (2.0 * r)).cos()) - w * (afov / 4.0).tan() / 2.0;
        let design = Design::new(p.clone()).unwrap();
        let (got, at) = design.revealer_dip(design.max_curvature, design.max_slope);
        assert!((got - dip).abs() < 1e-12, "{got} vs {dip} by hand");
        // at the middle of a lens
        assert!(((at.x + 2.5) / t - 0.5).fract().abs() < 1e-9, "{at}");
        let needed = dip + limits::MIN_DEPTH_TOLERANCES * p.tolerance;
        p.base.d = Some(needed * 0.99);
        let refused = Design::new(p.clone()).unwrap_err();
        assert_eq!(refused.param, Param::BaseD, "{refused}");
        p.base.d = Some(needed * 1.01);
        Design::new(p).unwrap();
    }

    /// On a flat base a crease slanting by s turns the flank's tangent
    /// along it to (s, 1, 0), so tan(flank) = tan(β/2)·√(1 + s²) by hand;
    /// on a base sloping along u without slant it is slope + β/2 exactly.
    #[test]
    fn a_leaning_flank_by_hand() {
        let half = 40f64.to_radians();
        let flat = |grad: DVec2| LeanFrame {
            at: DVec2::ZERO,
            s_u: DVec3::X,
            s_v: DVec3::Y,
            grad,
            view_grad: DVec2::ZERO,
        };
        for s in [0.0f64, 0.5, 2.0, -3.0] {
            let expected = (half.tan() * (1.0 + s * s).sqrt()).atan();
            // a_t = 0.5 mm, ∂e/∂v = 2s, ∂e/∂u = 0: slant s
            let got = flat(DVec2::new(0.0, 2.0 * s)).flank(0.5, half);
            assert!(
                (got - expected).abs() < 1e-12,
                "s = {s}: {got} vs {expected}"
            );
        }
        // a plane sloping 30° along u, no slant: 30° + 40°
        let slope = 30f64.to_radians();
        let tilted = LeanFrame {
            at: DVec2::ZERO,
            s_u: DVec3::new(slope.cos(), 0.0, slope.sin()),
            s_v: DVec3::Y,
            grad: DVec2::ZERO,
            view_grad: DVec2::ZERO,
        };
        assert!((tilted.flank(0.5, half) - 70f64.to_radians()).abs() < 1e-12);
        // a slant turns a flank about the crease's normal plane, so over a
        // slope along u alone it never overhangs; over a plane sloping along
        // v too it does (found-567ae25e16016c83: z = −0.688x + 0.403y, β/2 =
        // 41.3°, slant 2: one flank passes vertical)
        assert!(
            LeanFrame {
                grad: DVec2::new(0.0, 4.0),
                ..tilted
            }
            .flank(0.5, half)
                < 80f64.to_radians()
        );
        let two_way = |grad: DVec2| LeanFrame {
            at: DVec2::ZERO,
            s_u: DVec3::new(1.0, 0.0, -0.688195),
            s_v: DVec3::new(0.0, 1.0, 0.403014),
            grad,
            view_grad: DVec2::ZERO,
        };
        let half = 41.314931f64.to_radians();
        assert!(two_way(DVec2::ZERO).flank(0.5, half) < 80f64.to_radians());
        assert!(two_way(DVec2::new(0.0, 4.0)).flank(0.5, half) > 90f64.to_radians());
    }
}
