//! The design view and the view-compensated base (docs/method.md, "The
//! view compensation").
//!
//! A viewer meets each revealer lens at the angle between the view and the
//! lens's axis, and a lens seen at an angle shows its base at a lateral
//! offset. On a flat device seen straight on that offset is zero
//! everywhere; on a curved one it drifts across the surface and adds its
//! own phase to the moiré, which then draws the level lines of E − C, not
//! of E. The compensated base takes the offset out:
//!
//! φ(u, v) = (u − E(u, v) + C(u, v)) / T,
//!
//! where C(u, v) is, at the base point (u, v), the layout distance along u
//! from where the design view's light lands to where the lens's own axial
//! light lands, both through the revealer lens whose design-view light
//! lands at (u, v). From the design view every lens then shows the phase a
//! flat device shows straight on.
//!
//! "Where light lands" is the flux-weighted mean, over a Gauss–Legendre
//! rule across the lens's exact arc, of where the refracted rays meet the
//! base surface s (the pitch surface of the base lenses, or the tops of a
//! printed base's bands): each ray's weight is the light it carries
//! through the arc, its projected area times the Fresnel transmission.
//! The lens is the exact revealer lens of METHOD §2 centred on the layout
//! point (a real lens where that is a lens's middle), swept along its
//! station derivative, so C is a smooth function of (u, v). It is sampled
//! on a square grid and read by Catmull-Rom interpolation; the grid is
//! refined until the interpolant is within [`FIT_SHARE`] of the mesh
//! tolerance of C at every cell centre, and the base is built from the
//! interpolant: the exact model is the interpolated C, its distance from
//! the traced one is the stated error.

use crate::design::Design;
use crate::error::{DesignError, Param};
use crate::grid::CubicGrid;
use crate::lens::LensArc;
use glam::{DMat3, DVec2, DVec3};

/// The view the base is compensated for: the render's camera at tilt 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DesignView {
    /// Tilt about the lens axis (y), radians, as `moirecast render --tilts`.
    pub tilt: f64,
    /// Tilt about the x axis, radians, as `moirecast render --tilt-along`.
    pub tilt_along: f64,
    /// The eye's distance from the device's centre (mm); `None`: an
    /// orthographic view, every point seen along the same direction.
    pub distance: Option<f64>,
    /// Whether the base is compensated for this view (`false`: the
    /// uncompensated base, φ = (u − E)/T).
    pub compensate: bool,
}

impl Default for DesignView {
    /// Straight down (−z), orthographic, compensated.
    fn default() -> Self {
        DesignView {
            tilt: 0.0,
            tilt_along: 0.0,
            distance: None,
            compensate: true,
        }
    }
}

impl DesignView {
    /// The rotation that takes the straight-down camera to this view: about
    /// y by the tilt, after about x by the tilt along (the render's order).
    pub fn rotation(&self) -> DMat3 {
        DMat3::from_rotation_y(self.tilt) * DMat3::from_rotation_x(self.tilt_along)
    }

    /// The direction light travels from the eye into the device (unit),
    /// for an orthographic view.
    pub fn direction(&self) -> DVec3 {
        self.rotation() * DVec3::NEG_Z
    }

    /// Whether every lens of a plane is seen along its axis: there the
    /// offset is zero by symmetry and nothing is compensated.
    pub fn is_straight_down(&self) -> bool {
        self.tilt == 0.0 && self.tilt_along == 0.0 && self.distance.is_none()
    }
}

/// The share of the mesh tolerance the interpolated C may stray from the
/// traced one: base creases move by C's error, so it is spent like the
/// mesher's own shares of the tolerance, but far smaller.
pub const FIT_SHARE: f64 = 0.1;

/// Gauss–Legendre rule across a lens (nodes on [−1, 1], weights): eight
/// rays, exact for the flux through an arc up to degree 15 in its angle.
const GAUSS_8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_3, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (0.960_289_856_497_536_3, 0.101_228_536_290_376_26),
];

/// Newton steps for a ray's landing on the base surface, and the distance
/// (mm) at which it has landed.
const LANDING_STEPS: usize = 30;
const LANDING_RESIDUAL_MM: f64 = 1e-12;
/// Fixed-point steps that find the lens whose view light lands on a grid
/// node, and how close (mm) it must land.
const LENS_STEPS: usize = 40;
const LENS_RESIDUAL_MM: f64 = 1e-9;
/// The largest angle (degrees) between the design view and a lens axis,
/// across the lenses, at which a lens keeps three quarters of the
/// level-line contrast it shows straight on: measured on planes tilted
/// under a straight-down view, compensated (docs/decisions.md). Past it
/// the `view-angle` warning names the place.
pub const KEEPS_CONTRAST_DEG: f64 = 35.0;

/// Points per side of the lattice on which an image shift's parting from
/// C's own interpolant is measured.
const RESAMPLE_LATTICE: usize = 97;

/// Points per side of the lattice on which the largest view angle is found.
const ANGLE_LATTICE: usize = 65;

/// Cells across the longer side of the first grid, and the most halvings.
const FIRST_CELLS: f64 = 8.0;
const MAX_HALVINGS: usize = 5;

/// The traced offset C at one base point, with the lens it was traced
/// through.
#[derive(Clone, Copy, Debug)]
struct Offset {
    /// C (mm).
    c: f64,
    /// Where the view's light lands less where its lens is (layout mm).
    drift: DVec2,
}

/// C(u, v) over the extended layout, as the base is built from it, and
/// what it measured.
#[derive(Clone, Debug)]
pub struct ViewCompensation {
    grid: CubicGrid,
    /// Largest |C| on the grid (mm): bounds the crease solver's bracket.
    pub max_abs_mm: f64,
    /// Largest |C| over the layout Ω (mm).
    pub max_abs_layout_mm: f64,
    /// Largest |∂C/∂u| over Ω.
    pub max_slope: f64,
    /// Largest |∂C/∂u| at the grid's nodes and cell centres, over the
    /// whole grid (C is smooth on the grid's scale).
    pub max_slope_grid: f64,
    /// Largest distance of the interpolant from the traced C at the
    /// grid's cell centres over Ω (mm).
    pub fit_error_mm: f64,
    /// Where an image's shift carries C on the image's grid, how far that
    /// parts from C's own interpolant (mm; 0 otherwise).
    pub resample_error_mm: f64,
    /// The view's largest angle to a lens axis across the lenses over Ω
    /// (rad), and where (layout mm).
    pub max_angle: (f64, DVec2),
}

impl ViewCompensation {
    /// C and ∇C at the base point (u, v) (mm, and per mm).
    pub fn offset(&self, u: f64, v: f64) -> (f64, DVec2) {
        self.grid.eval(u, v)
    }

    /// C at (u, v) (mm).
    pub fn value(&self, u: f64, v: f64) -> f64 {
        self.grid.value(u, v)
    }

    /// Grid spacing (mm).
    pub fn spacing(&self) -> f64 {
        self.grid.spacing()
    }
}

/// Where light along a direction lands through one lens, and how.
struct Landing {
    /// Flux-weighted mean layout point on the base surface.
    at: DVec2,
}

impl Design {
    /// The exact revealer lens centred on layout (u, v): a real lens where
    /// u is a lens's middle.
    fn lens_centred_at(&self, u: f64, v: f64) -> LensArc {
        let t = self.params.period;
        let (p0, p1) = (
            self.surface().point(u - t / 2.0, v),
            self.surface().point(u + t / 2.0, v),
        );
        LensArc::new(p0, p1, self.surface().normal(u, v), self.revealer_rule)
    }

    /// The direction the design view's light travels at `point` (unit).
    fn view_direction_at(&self, point: DVec3) -> DVec3 {
        let view = &self.params.view;
        match view.distance {
            None => view.direction(),
            Some(distance) => (point - self.view_eye(distance)).normalize(),
        }
    }

    /// The device's centre a perspective view looks at: the pitch
    /// surface's point at the layout's centre.
    pub fn view_pivot(&self) -> DVec3 {
        self.surface().point(0.0, 0.0)
    }

    /// The eye of a perspective design view `distance` mm from the
    /// device's centre ([`Design::view_pivot`]), along the view direction.
    pub fn view_eye(&self, distance: f64) -> DVec3 {
        self.view_pivot() - distance * self.params.view.direction()
    }

    /// Where light along `dir` (or, with `None`, along the lens's own axis)
    /// lands on the base surface through the lens centred on (u, v).
    fn landing(&self, u: f64, v: f64, dir: Option<DVec3>) -> Option<Landing> {
        let arc = self.lens_centred_at(u, v);
        let dir = dir.unwrap_or_else(|| self.view_direction_at(arc.point(0.5)));
        let dir = if dir.is_finite() { dir } else { return None };
        // the lens surface is swept along v: its tangent there from the
        // arcs a small step either side (central differences)
        let h = 1e-3 * self.params.period;
        let (before, after) = (
            self.lens_centred_at(u, v - h),
            self.lens_centred_at(u, v + h),
        );
        let index = self.params.lens.index;
        let (mut sum, mut weight) = (DVec2::ZERO, 0.0);
        for (node, w) in GAUSS_8 {
            let t = 0.5 * (node + 1.0);
            let theta = arc.half_angle * node;
            let point = arc.point(t);
            let across = arc.radius * (theta.cos() * arc.chord_dir - theta.sin() * arc.bulge);
            let along = (after.point(t) - before.point(t)) / (2.0 * h);
            let mut normal = across.cross(along);
            let area = normal.length();
            normal /= area;
            if normal.dot(point - arc.centre()) < 0.0 {
                normal = -normal;
            }
            let cos_in = -dir.dot(normal);
            if cos_in <= 0.0 {
                continue; // the lens's back: no light enters there
            }
            let (refracted, transmitted) = refract(dir, normal, cos_in, index);
            let landed = self.land_on_base(point, refracted, DVec2::new(u, v))?;
            let flux = w * area * cos_in * transmitted;
            sum += flux * landed;
            weight += flux;
        }
        (weight > 0.0).then(|| Landing { at: sum / weight })
    }

    /// The layout point where the ray from `origin` along `dir` meets the
    /// base surface s, by Newton from `start`.
    fn land_on_base(&self, origin: DVec3, dir: DVec3, start: DVec2) -> Option<DVec2> {
        let (mut q, mut t) = (start, self.base_offset(start.x, start.y));
        for _ in 0..LANDING_STEPS {
            let (s, s_u, s_v) = self.base_frame(q);
            let miss = s - (origin + t * dir);
            let step = DMat3::from_cols(s_u, s_v, -dir).inverse() * miss;
            if !step.is_finite() {
                return None;
            }
            q -= DVec2::new(step.x, step.y);
            t -= step.z;
            if step.length() < LANDING_RESIDUAL_MM {
                return Some(q);
            }
        }
        None
    }

    /// The base surface's point and tangents at layout `q`: for an offset
    /// surface (a = 0) from one jet of f, s = f − d·n, s_u = f_u − d·n_u
    /// (likewise in v), else from [`Design::base_tangents`].
    fn base_frame(&self, q: DVec2) -> (DVec3, DVec3, DVec3) {
        if self.params.base.a != 0.0 {
            let (s_u, s_v) = self.base_tangents(q.x, q.y);
            return (self.base_surface(q.x, q.y), s_u, s_v);
        }
        let jet = self.surface().jet(q.x, q.y);
        let (n, n_u, n_v) = jet.normal_derivatives();
        (
            jet.p - self.d * n,
            jet.du - self.d * n_u,
            jet.dv - self.d * n_v,
        )
    }

    /// The traced C at base point `at`: finds the lens whose design-view
    /// light lands there (from the guess that it lands `drift` from its
    /// lens), then where that lens's axial light lands.
    fn traced_offset(&self, at: DVec2, drift: DVec2) -> Option<Offset> {
        let mut lens = at - drift;
        for _ in 0..LENS_STEPS {
            let landed = self.landing(lens.x, lens.y, None)?;
            let miss = landed.at - at;
            if miss.length() < LENS_RESIDUAL_MM {
                let arc = self.lens_centred_at(lens.x, lens.y);
                let axial = self.landing(lens.x, lens.y, Some(-arc.bulge))?;
                return Some(Offset {
                    c: axial.at.x - landed.at.x,
                    drift: landed.at - lens,
                });
            }
            lens -= miss;
        }
        None
    }
}

/// The refracted direction from air into `index` at a surface of outward
/// `normal`, with `cos_in` = −dir·normal > 0, and the unpolarised Fresnel
/// transmission.
fn refract(dir: DVec3, normal: DVec3, cos_in: f64, index: f64) -> (DVec3, f64) {
    let eta = 1.0 / index;
    let cos_out = (1.0 - eta * eta * (1.0 - cos_in * cos_in)).sqrt();
    let refracted = eta * dir + (eta * cos_in - cos_out) * normal;
    let rs = (cos_in - index * cos_out) / (cos_in + index * cos_out);
    let rp = (index * cos_in - cos_out) / (index * cos_in + cos_out);
    (refracted, 1.0 - 0.5 * (rs * rs + rp * rp))
}

/// The traced offsets on one grid: nodes `origin + (i, j)·spacing`.
struct TracedGrid {
    origin: DVec2,
    spacing: f64,
    nx: usize,
    ny: usize,
    /// Per node; `None` where no light path was found.
    offsets: Vec<Option<Offset>>,
}

impl TracedGrid {
    /// The drift traced at the node nearest `q` (zero where none was found).
    fn drift_near(&self, q: DVec2) -> DVec2 {
        let at = ((q - self.origin) / self.spacing).round();
        let i = (at.x.max(0.0) as usize).min(self.nx - 1);
        let j = (at.y.max(0.0) as usize).min(self.ny - 1);
        self.offsets[j * self.nx + i].map_or(DVec2::ZERO, |o| o.drift)
    }
}

impl Design {
    /// Whether a layout point lies on the layout Ω grown by one period:
    /// where a base point must have a traced C.
    fn needs_offset(&self, q: DVec2) -> bool {
        let grow = self.params.period;
        q.x.abs() <= self.params.width / 2.0 + grow && q.y.abs() <= self.half_height + grow
    }

    /// Traces C at every node of a grid of `spacing` over the extended layout.
    fn trace_grid(&self, spacing: f64) -> TracedGrid {
        use rayon::prelude::*;
        let (hw, hh) = (
            self.params.width / 2.0 + self.margin,
            self.half_height + self.margin,
        );
        let nx = ((2.0 * hw / spacing).ceil() as usize + 1).max(2);
        let ny = ((2.0 * hh / spacing).ceil() as usize + 1).max(2);
        let origin = DVec2::new(-hw, -hh);
        // row by row, each node starting from its neighbour's drift
        let rows: Vec<Vec<Option<Offset>>> = (0..ny)
            .into_par_iter()
            .map(|j| {
                let mut drift = DVec2::ZERO;
                (0..nx)
                    .map(|i| {
                        let q = origin + spacing * DVec2::new(i as f64, j as f64);
                        let offset = self.traced_offset(q, drift);
                        if let Some(o) = offset {
                            drift = o.drift;
                        }
                        offset
                    })
                    .collect()
            })
            .collect();
        let offsets = rows.into_iter().flatten().collect();
        TracedGrid {
            origin,
            spacing,
            nx,
            ny,
            offsets,
        }
    }

    /// The view compensation of this design, or `None` where nothing is
    /// compensated (`compensate = false`, or a plane seen straight down,
    /// where C ≡ 0). Refused by `view.compensate` where the design view's
    /// light finds no path through a lens on the layout.
    pub(crate) fn compute_view_compensation(
        &self,
    ) -> Result<Option<ViewCompensation>, DesignError> {
        if !self.params.view.compensate || self.view_offset_vanishes() {
            return Ok(None);
        }
        self.validate_view_angle()?;
        self.trace_view_compensation()
    }

    /// The view compensation, whether or not the base uses it: for
    /// reports of an uncompensated base (`None` where C ≡ 0, or where it
    /// cannot be traced).
    pub fn view_compensation_traced(&self) -> Option<ViewCompensation> {
        match &self.view {
            Some(view) => Some(view.clone()),
            None => self.trace_view_compensation().ok().flatten(),
        }
    }

    /// E − C on the nodes of an image profile's grid, for a compensated
    /// base, so that the shift is one interpolation, not two. C, far
    /// smoother than the image, is read off its own grid at each node;
    /// between the nodes the two interpolants part by a little (C's own
    /// second derivative jumps at its cells' edges), which is measured at
    /// the image cells' centres over a lattice on the layout and added to
    /// C's stated error. Kept only while that sum stays in the budget.
    pub(crate) fn sampled_shift_grid(&mut self) -> Option<CubicGrid> {
        use rayon::prelude::*;
        let (crate::Profile::Sampled(profile), Some(view)) = (&self.params.profile, &self.view)
        else {
            return None;
        };
        let e = profile.grid();
        let a_t = self.params.base.levels * self.params.period;
        let node =
            |k: usize| e.origin + e.spacing * DVec2::new((k % e.nx) as f64, (k / e.nx) as f64);
        let values = e
            .values()
            .par_iter()
            .enumerate()
            .map(|(k, value)| {
                let q = node(k);
                a_t * value - view.value(q.x, q.y)
            })
            .collect();
        let grid = CubicGrid::new(e.origin, e.spacing, e.nx, e.ny, values);
        // the parting, at image cells' centres on a lattice over the layout
        let (hw, hh, n) = (self.params.width / 2.0, self.half_height, RESAMPLE_LATTICE);
        let parting = (0..n * n)
            .into_par_iter()
            .map(|k| {
                let f = |i: usize, half: f64| half * (2.0 * i as f64 / (n - 1) as f64 - 1.0);
                let at = DVec2::new(f(k % n, hw), f(k / n, hh));
                let cell = ((at - e.origin) / e.spacing).floor() + DVec2::splat(0.5);
                let q = e.origin + e.spacing * cell;
                let apart = a_t * profile.value(q.x, q.y) - view.value(q.x, q.y);
                (grid.value(q.x, q.y) - apart).abs()
            })
            .reduce(|| 0.0, f64::max);
        let budget = FIT_SHARE * self.tolerance.mm();
        let view = self.view.as_mut().expect("compensated");
        (view.fit_error_mm + parting <= budget).then(|| {
            view.resample_error_mm = parting;
            grid
        })
    }

    /// Whether C ≡ 0 by symmetry: a plane seen straight down.
    pub fn view_offset_vanishes(&self) -> bool {
        matches!(self.surface(), crate::PitchSurface::Plane) && self.params.view.is_straight_down()
    }

    fn trace_view_compensation(&self) -> Result<Option<ViewCompensation>, DesignError> {
        if self.view_offset_vanishes() {
            return Ok(None);
        }
        let budget = FIT_SHARE * self.tolerance.mm();
        let longer = (self.params.width.max(self.params.height) + 2.0 * self.margin).max(1e-9);
        let mut spacing = longer / FIRST_CELLS;
        for halving in 0..=MAX_HALVINGS {
            let traced = self.trace_grid(spacing);
            let grid = self.fill_grid(&traced)?;
            let fit = self.fit_error(&grid, &traced)?;
            if fit.error <= budget || halving == MAX_HALVINGS {
                if fit.error > budget {
                    return Err(self.view_error(
                        format!("the lateral offset C changes too fast across the surface to follow: on a grid of {spacing:.3} mm it is still {:.3} µm from the traced offset at layout ({:.1}, {:.1}) mm, over {:.3} µm ({FIT_SHARE} of the mesh tolerance)", 1e3 * fit.error, fit.at.x, fit.at.y, 1e3 * budget),
                        "use a surface whose curvature changes more slowly, a coarser mesh.tolerance, or compensate = false",
                    ));
                }
                return Ok(Some(self.measured(grid, &traced, fit.error)));
            }
            spacing /= 2.0;
        }
        unreachable!("the last halving returns")
    }

    /// The grid of C, nodes without a light path off the layout taken from
    /// the nearest node that has one; refused where one on the layout has none.
    fn fill_grid(&self, traced: &TracedGrid) -> Result<CubicGrid, DesignError> {
        let node = |k: usize| {
            traced.origin
                + traced.spacing * DVec2::new((k % traced.nx) as f64, (k / traced.nx) as f64)
        };
        let found: Vec<usize> = (0..traced.offsets.len())
            .filter(|&k| traced.offsets[k].is_some())
            .collect();
        let mut values = Vec::with_capacity(traced.offsets.len());
        for (k, offset) in traced.offsets.iter().enumerate() {
            let q = node(k);
            let c = match offset {
                Some(o) => o.c,
                None if self.needs_offset(q) => return Err(self.no_path_error(q)),
                None => {
                    let nearest = found
                        .iter()
                        .min_by(|&&a, &&b| {
                            q.distance_squared(node(a))
                                .total_cmp(&q.distance_squared(node(b)))
                        })
                        .ok_or_else(|| self.no_path_error(q))?;
                    traced.offsets[*nearest].expect("found").c
                }
            };
            values.push(c);
        }
        Ok(CubicGrid::new(
            traced.origin,
            traced.spacing,
            traced.nx,
            traced.ny,
            values,
        ))
    }

    /// The interpolant's largest distance from the traced C at the
    /// centres of the grid's cells that lie on the layout Ω.
    fn fit_error(&self, grid: &CubicGrid, traced: &TracedGrid) -> Result<FitError, DesignError> {
        let spacing = traced.spacing;
        use rayon::prelude::*;
        let (hw, hh) = (self.params.width / 2.0, self.half_height);
        let (nx, ny) = (grid.nx - 1, grid.ny - 1);
        let centres: Vec<DVec2> = (0..nx * ny)
            .map(|k| {
                grid.origin + spacing * DVec2::new((k % nx) as f64 + 0.5, (k / nx) as f64 + 0.5)
            })
            .filter(|q| q.x.abs() <= hw && q.y.abs() <= hh)
            .collect();
        let errors: Vec<Result<(f64, DVec2), DVec2>> = centres
            .into_par_iter()
            .map(|q| match self.traced_offset(q, traced.drift_near(q)) {
                Some(o) => Ok(((grid.value(q.x, q.y) - o.c).abs(), q)),
                None => Err(q),
            })
            .collect();
        let mut worst = FitError {
            error: 0.0,
            at: DVec2::ZERO,
        };
        for e in errors {
            let (error, at) = e.map_err(|q| self.no_path_error(q))?;
            if error > worst.error {
                worst = FitError { error, at };
            }
        }
        Ok(worst)
    }

    /// What the compensation measured over the layout.
    fn measured(&self, grid: CubicGrid, traced: &TracedGrid, fit_error: f64) -> ViewCompensation {
        let max_abs_mm = grid.values().iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let (mut max_abs_layout_mm, mut max_slope) = (0.0f64, 0.0f64);

        for (k, offset) in traced.offsets.iter().enumerate() {
            let q = traced.origin
                + traced.spacing * DVec2::new((k % traced.nx) as f64, (k / traced.nx) as f64);
            let on_layout = q.x.abs() <= self.params.width / 2.0 && q.y.abs() <= self.half_height;
            if let (true, Some(o)) = (on_layout, offset) {
                max_abs_layout_mm = max_abs_layout_mm.max(o.c.abs());
                max_slope = max_slope.max(grid.eval(q.x, q.y).1.x.abs());
            }
        }
        let (nx, ny) = (grid.nx, grid.ny);
        let max_slope_grid = (0..nx * ny)
            .flat_map(|k| {
                let node =
                    grid.origin + grid.spacing * DVec2::new((k % nx) as f64, (k / nx) as f64);
                [node, node + DVec2::splat(0.5 * grid.spacing)]
            })
            .map(|q| grid.eval(q.x, q.y).1.x.abs())
            .fold(0.0f64, f64::max);
        ViewCompensation {
            max_slope_grid,
            grid,
            max_abs_mm,
            max_abs_layout_mm,
            max_slope,
            fit_error_mm: fit_error,
            resample_error_mm: 0.0,
            max_angle: self.max_view_angle(),
        }
    }

    /// The design view's largest angle to a lens axis across the lenses
    /// over the lenses' middles, on a lattice of [`ANGLE_LATTICE`]² points
    /// that includes the layout's edges, and where.
    fn max_view_angle(&self) -> (f64, DVec2) {
        self.view_angles().0
    }

    /// [`Design::max_view_angle`], and the largest view angle plus the
    /// lens's half angle, and where: at 90° the view grazes the lens's far
    /// flank, and past it that flank turns away from the eye.
    fn view_angles(&self) -> ((f64, DVec2), (f64, DVec2)) {
        let (hw, hh) = (
            self.params.width / 2.0 - self.params.period / 2.0,
            self.half_height,
        );
        let n = ANGLE_LATTICE;
        let (mut widest, mut grazing) = ((0.0f64, DVec2::ZERO), (0.0f64, DVec2::ZERO));
        for k in 0..n * n {
            let f = |i: usize| 2.0 * i as f64 / (n - 1) as f64 - 1.0;
            let q = DVec2::new(hw * f(k % n), hh * f(k / n));
            let arc = self.lens_centred_at(q.x, q.y);
            let dir = self.view_direction_at(arc.point(0.5));
            let angle = dir.dot(arc.chord_dir).atan2(-dir.dot(arc.bulge)).abs();
            if angle > widest.0 {
                widest = (angle, q);
            }
            // a NaN (no lens there) wins and stays, so the rule refuses it
            let wider = angle + arc.half_angle;
            if wider > grazing.0 || wider.is_nan() {
                grazing = (wider, q);
            }
        }
        (widest, grazing)
    }

    /// Refuses a design view that meets a lens past grazing its far flank
    /// (or where the angle is not defined): there the lens shows no period
    /// of its own base, and no offset is defined.
    fn validate_view_angle(&self) -> Result<(), DesignError> {
        let (_, (grazing, at)) = self.view_angles();
        if grazing >= std::f64::consts::FRAC_PI_2 || grazing.is_nan() {
            return Err(self.view_error(
                format!("the design view meets the lens at layout ({:.1}, {:.1}) mm so obliquely that the view angle plus the lens's half field of view reaches {:.1}°: past 90° the lens's far flank turns away from the eye, and the lens shows no period of the base", at.x, at.y, grazing.to_degrees()),
                "use a larger surface.radius, a smaller field (lens.afov), a view closer to the surface's normal, or compensate = false",
            ));
        }
        Ok(())
    }

    fn no_path_error(&self, q: DVec2) -> DesignError {
        self.view_error(
            format!("the design view's light finds no path through the revealer lens at layout ({:.1}, {:.1}) mm to the base (it meets the lens from behind, or misses the base)", q.x, q.y),
            "use a larger radius, a smaller layout, a view closer to the surface's normal, or compensate = false",
        )
    }

    fn view_error(&self, problem: String, fix: &str) -> DesignError {
        DesignError {
            param: Param::ViewCompensate,
            value: self.params.view.compensate.to_string(),
            problem,
            fix: fix.to_string(),
        }
    }
}

/// The interpolant's worst distance from the traced C, and where.
struct FitError {
    error: f64,
    at: DVec2,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{DesignParams, PitchSurface};

    /// The landing of light falling straight down (−z) through the lens
    /// centred at arc length `u` of a cylinder of radius `radius` (its
    /// axis along y at z = −R), in the cylinder's cross-section: circles
    /// and Snell's law in closed form, the same eight rays.
    fn cylinder_landing(design: &Design, radius: f64, u: f64, axial: bool) -> f64 {
        let (t, index, depth) = (design.params.period, design.params.lens.index, design.d);
        let half = design.params.lens.afov / 2.0;
        let centre = glam::DVec2::new(0.0, -radius);
        let on_circle = |psi: f64| centre + radius * glam::DVec2::new(psi.sin(), psi.cos());
        let (p0, p1) = (
            on_circle((u - t / 2.0) / radius),
            on_circle((u + t / 2.0) / radius),
        );
        let (mid, chord) = (0.5 * (p0 + p1), (p1 - p0).normalize());
        let bulge = (mid - centre).normalize();
        let r = (p1 - p0).length() / (2.0 * half.sin());
        let lens_centre = mid - r * half.cos() * bulge;
        let dir = if axial {
            -bulge
        } else {
            glam::DVec2::new(0.0, -1.0)
        };
        let (mut sum, mut weight) = (0.0, 0.0);
        for (node, w) in GAUSS_8 {
            let theta = half * node;
            let x = mid + r * (theta.cos() - half.cos()) * bulge + r * theta.sin() * chord;
            let normal = (x - lens_centre) / r;
            let cos_in = -dir.dot(normal);
            let eta = 1.0 / index;
            let cos_out = (1.0 - eta * eta * (1.0 - cos_in * cos_in)).sqrt();
            let inside = eta * dir + (eta * cos_in - cos_out) * normal;
            let rs = (cos_in - index * cos_out) / (cos_in + index * cos_out);
            let rp = (index * cos_in - cos_out) / (index * cos_in + cos_out);
            // the base: the circle of radius R − d about the axis
            let o = x - centre;
            let (b, c) = (o.dot(inside), o.length_squared() - (radius - depth).powi(2));
            let hit = o + (-b - (b * b - c).sqrt()) * inside;
            let flux = w * r * cos_in * (1.0 - 0.5 * (rs * rs + rp * rp));
            sum += flux * radius * hit.x.atan2(hit.y);
            weight += flux;
        }
        sum / weight
    }

    #[test]
    fn a_cylinder_matches_its_cross_section_in_closed_form() {
        let radius = 30.0;
        let p = DesignParams::with_defaults(PitchSurface::Cylinder { radius }, 16.0, 4.0, 0.5);
        let design = Design::new(p).expect("a valid design");
        let view = design
            .view
            .as_ref()
            .expect("a curved device is compensated");
        let budget = FIT_SHARE * design.tolerance.mm();
        let mut worst = 0.0f64;
        for k in 0..=60 {
            let u_lens = -7.5 + 15.0 * k as f64 / 60.0;
            // C at the base point where this lens's light lands
            let landed = cylinder_landing(&design, radius, u_lens, false);
            let expected = cylinder_landing(&design, radius, u_lens, true) - landed;
            for v in [-2.0, 0.3, 2.0] {
                worst = worst.max((view.value(landed, v) - expected).abs());
            }
        }
        // the offset is a good fraction of a period here, and the grid's
        // interpolant holds it to the budget
        assert!(view.max_abs_layout_mm > 0.1, "{}", view.max_abs_layout_mm);
        eprintln!(
            "C within {worst:e} mm of the closed form (budget {budget:e}; max {} mm)",
            view.max_abs_layout_mm
        );
        assert!(
            worst <= budget,
            "C is {worst:e} mm from the closed form (budget {budget:e})"
        );
    }

    /// An image's shift is E − C on the image's grid: at its nodes it is E
    /// and C read off their own grids, and between them within the
    /// parting the design states, which with C's own fit stays in budget.
    #[test]
    fn an_image_shift_carries_c_on_its_own_grid() {
        let (w, h) = (64, 48);
        let luminance = (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f32 / w as f32, (k / w) as f32 / h as f32);
                0.5 + 0.4 * (6.0 * x).sin() * (4.0 * y).cos()
            })
            .collect();
        let raster = crate::Raster {
            width: w,
            height: h,
            luminance,
        };
        let profile = crate::profile::SampledProfile::from_raster(
            &raster,
            crate::ProfileMode::Gray,
            false,
            0.8,
            12.0,
            9.0,
        )
        .unwrap();
        let mut p =
            DesignParams::with_defaults(PitchSurface::Saddle { radius: 40.0 }, 12.0, 9.0, 0.5);
        p.profile = crate::Profile::Sampled(profile);
        let design = Design::new(p).unwrap();
        let view = design.view.as_ref().expect("compensated");
        assert!(design.shift_grid.is_some());
        let a_t = design.params.base.levels * design.params.period;
        let mut worst = 0.0f64;
        for k in 0..400 {
            let (u, v) = (
                -6.0 + 12.0 * (k % 20) as f64 / 19.3,
                -4.5 + 9.0 * (k / 20) as f64 / 19.7,
            );
            let apart = a_t * design.params.profile.value(u, v) - view.value(u, v);
            let (shift, _) = design.shift_and_gradient(u, v);
            assert_eq!(
                shift,
                design.shift(u, v),
                "one shift for the solver and the checks"
            );
            worst = worst.max((shift - apart).abs());
        }
        let stated = view.resample_error_mm;
        assert!(
            worst <= 1.5 * stated.max(1e-12),
            "{worst:e} mm against {stated:e} stated"
        );
        assert!(view.fit_error_mm + stated <= FIT_SHARE * design.tolerance.mm());
    }

    #[test]
    fn a_plane_seen_straight_down_is_not_compensated() {
        let p = DesignParams::with_defaults(PitchSurface::Plane, 8.0, 4.0, 0.5);
        assert!(Design::new(p).unwrap().view.is_none());
    }

    #[test]
    fn a_plane_seen_at_a_tilt_shifts_by_a_constant() {
        let mut p = DesignParams::with_defaults(PitchSurface::Plane, 8.0, 4.0, 0.5);
        p.view.tilt = 10f64.to_radians();
        let design = Design::new(p).unwrap();
        let view = design.view.as_ref().expect("compensated");
        let c0 = view.value(0.0, 0.0);
        assert!(c0.abs() > 0.05, "{c0}");
        assert!((view.value(3.0, -1.5) - c0).abs() < 1e-9 && view.max_slope < 1e-9);
    }

    #[test]
    fn a_compensation_that_folds_the_base_is_refused() {
        // rings whose own shift slope is 0.88, on a saddle whose C slopes
        // about −0.03 across its middle: the sum passes 0.9
        let mut p =
            DesignParams::with_defaults(PitchSurface::Saddle { radius: 30.0 }, 30.0, 10.0, 0.5);
        p.profile = crate::Profile::Rings { wavelength: 2.0 };
        p.base.levels = 1.12;
        let e = Design::new(p.clone()).expect_err("the compensated phase folds");
        assert_eq!(e.param, Param::ViewCompensate);
        assert!(
            e.problem.contains("stop rising with u") && e.fix.contains("fewer levels"),
            "{e}"
        );
        p.view.compensate = false;
        assert!(
            Design::new(p.clone()).is_ok(),
            "the elevation alone stays below 0.9"
        );
        p.view.compensate = true;
        p.base.levels = 1.08;
        assert!(Design::new(p).is_ok(), "with fewer levels it builds");
    }

    #[test]
    fn a_view_past_grazing_the_lenses_is_refused() {
        let mut p = DesignParams::with_defaults(PitchSurface::Plane, 8.0, 4.0, 0.5);
        p.lens.afov = 70f64.to_radians();
        p.view.tilt = 58f64.to_radians();
        let e = Design::new(p.clone()).expect_err("58° + 35° is past grazing");
        assert_eq!(e.param, Param::ViewCompensate);
        assert!(
            e.problem.contains("far flank") && e.fix.contains("compensate = false"),
            "{e}"
        );
        p.view.compensate = false;
        assert!(Design::new(p).is_ok());
    }
}
