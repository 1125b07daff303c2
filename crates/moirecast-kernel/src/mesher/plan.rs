//! Planning the mesh: a curvature survey of every lens (pure and twist
//! terms against a split of the tolerance) gives each lens its columns and
//! the rows their stations; base rows are added where a base crease crosses
//! an x-wall, so those corners are exact.

use crate::design::Design;
use crate::error::Result;
use crate::model::BaseSection;
use crate::progress::Progress;
use crate::solve::bracketed_secant;
use crate::tolerance::WALL_SNAP_MM;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Share of the tolerance given to the chordal error across a lens.
pub(super) const ACROSS_SHARE: f64 = 0.45;
/// Share of the tolerance given to the chordal error along a lens. The two
/// add at most at a triangle's interior; the rest is margin for the twist.
pub(super) const ALONG_SHARE: f64 = 0.4;
/// Stations crowding in y to this share of their spacing in v (dy/dv ≥
/// 0.95) are surveyed as if they did not: the curvature per unit y is then
/// at most 11 % over the one per unit v, which the tolerance's margin
/// (1 − [`ACROSS_SHARE`] − [`ALONG_SHARE`]) absorbs. Crowding beyond it
/// scales the survey's curvature (found-9363d5ee1df920e3: a base 15–24 mm
/// under a saddle of radius 48 mm, dy/dv ≈ 0.6, missed the tolerance by 12 %).
const COMPRESSION_SLACK: f64 = 0.95;
/// How far over its share a segment's chordal error bound may go before
/// [`split_where_curvature_peaks`] splits it: the tolerance's margin
/// (1 − [`ACROSS_SHARE`] − [`ALONG_SHARE`]) takes a quarter of the along share.
const PEAK_SLACK: f64 = 1.25;
/// Chordal error across a lens (as a share of the tolerance) that a row's
/// shear (see [`sheared_columns`]) may add before the lens gets more
/// columns: a small part of the tolerance's margin.
const SHEAR_SLACK: f64 = 0.02;
/// Cells of the curvature survey along y, at least: a long layout gets
/// cells no longer than [`SURVEY_CELL_PERIODS`] periods.
const SURVEY_CELLS: usize = 256;
/// Longest survey cell (periods). A second difference over cells wider
/// than a bend sees a fraction of its curvature: 256 cells over a layout
/// 570 mm long are 2.2 mm, and the rows they placed over a bump 1.5 mm
/// wide missed the tolerance by 34 % (found-49fb65d011976b14). A lens array
/// cannot follow a surface that bends within a lens, so bends a lens wide
/// or wider are the ones to see.
const SURVEY_CELL_PERIODS: f64 = 0.5;
/// Most cells of the base's survey, however fine its profile.
const MAX_SURVEY_CELLS: usize = 16384;

/// Where the rows and columns go.
pub(super) struct MeshPlan {
    /// Columns per revealer lens.
    pub revealer_columns: Vec<usize>,
    /// Revealer row stations (the first and last are solved onto y = ±H/2).
    pub revealer_rows: Vec<f64>,
    /// Largest effective curvature along the revealer lenses (1/mm).
    pub revealer_kmax: f64,
    /// Where the lenses' middles reach a whole spacing or more past a
    /// wall row: the stations below the first (above the second) of
    /// these, rows put in at the edge, are solved onto heights between the
    /// wall and that row, column by column ([`edge_stations`]).
    pub revealer_edge_blend: EdgeBlend,
    /// Columns per base lens (lenses entirely outside the outline included).
    pub base_columns: BTreeMap<i64, usize>,
    /// Base row heights y, crossing rows included.
    pub base_rows: Vec<f64>,
    /// Rows a uniform base grid would need for the same tolerance.
    pub uniform_base_rows: usize,
    /// Rows placed where a base crease crosses an x-wall.
    pub crossing_rows: usize,
}

/// Per wall (the first, the last), the station of the row that rows put
/// in at that edge blend to, if any were ([`edge_stations`]).
pub(super) type EdgeBlend = (Option<f64>, Option<f64>);

impl MeshPlan {
    /// Triangles the plan makes, before the rows a wall's trim adds:
    /// every revealer lens's columns on every revealer strip, every base
    /// lens's on every base strip (as many base lenses as revealer lenses
    /// cross a row), and the walls.
    pub fn estimated_triangles(&self, lenses: usize) -> u64 {
        let strips = |rows: &[f64]| rows.len().saturating_sub(1) as u64;
        let revealer: u64 = self.revealer_columns.iter().map(|&c| c as u64).sum();
        let base_mean = self.base_columns.values().map(|&c| c as f64).sum::<f64>()
            / self.base_columns.len().max(1) as f64;
        let base = (base_mean * lenses as f64).ceil() as u64;
        let walls =
            2 * (self.revealer_rows.len() + self.base_rows.len()) as u64 + 2 * (revealer + base);
        2 * revealer * strips(&self.revealer_rows) + 2 * base * strips(&self.base_rows) + walls
    }

    /// Adds revealer rows at stations `ys` (for the built-in surfaces a
    /// crease's y is its station), strictly inside the walls and clear of
    /// the rows already there.
    pub fn add_revealer_rows(&mut self, ys: &[f64], half_height: f64) {
        let rows = &mut self.revealer_rows;
        let min_gap = 1e-3 * (2.0 * half_height) / rows.len() as f64;
        for &y in ys {
            let at = rows.partition_point(|&r| r < y);
            let clear =
                at > 0 && at < rows.len() && y - rows[at - 1] > min_gap && rows[at] - y > min_gap;
            if clear {
                rows.insert(at, y);
            }
        }
    }

    /// Refuses a plan over the design's budget of bytes, naming the
    /// estimate, the limit and the fix.
    pub fn within_budget(&self, design: &Design) -> Result<()> {
        let Some(limit) = design.mesh_budget.max_bytes else {
            return Ok(());
        };
        let triangles = self.estimated_triangles(design.lenses);
        let bytes = crate::MeshBudget::estimated_bytes(design, triangles);
        if bytes <= limit {
            return Ok(());
        }
        // triangles fall as 1/tolerance along and across the lenses
        let coarser = design.tolerance.mm() * bytes / limit;
        Err(crate::DesignError {
            param: crate::Param::Tolerance,
            value: design.tolerance.mm().to_string(),
            problem: format!(
                "the design would take about {:.1} GB at a mold run's peak ({:.1} M triangles, {} lenses), over the budget of {:.1} GB",
                bytes / 1e9,
                triangles as f64 / 1e6,
                design.lenses,
                limit / 1e9
            ),
            fix: format!(
                "use a coarser mesh.tolerance (about {:.4} mm), a smaller layout or a larger period, or pass --allow-large",
                coarser.min(crate::Tolerance::MAX_MM)
            ),
        }
        .into())
    }
}

/// Refuses a design whose curvature survey alone is past the budget of
/// survey cells (lenses × cells along them, both arrays), before it runs.
fn survey_within_budget(design: &Design, planner: &Planner) -> Result<()> {
    let Some(limit) = design.mesh_budget.max_survey_cells else {
        return Ok(());
    };
    let cells = planner.cells_over(2.0 * design.half_height, SURVEY_CELLS) as u64;
    let work = 2 * design.lenses as u64 * cells;
    if work <= limit {
        return Ok(());
    }
    Err(crate::DesignError {
        param: crate::Param::Width,
        value: design.params.width.to_string(),
        problem: format!(
            "{} lenses over {:.0} mm need a survey of {:.0} M cells before meshing, over the budget of {:.0} M (about {:.0} s); the design is larger than a run should take",
            design.lenses,
            design.params.height,
            work as f64 / 1e6,
            limit as f64 / 1e6,
            limit as f64 * 0.6e-6
        ),
        fix: "use a smaller layout or a larger period, or pass --allow-large".into(),
    }
    .into())
}

/// Surveys every lens and plans the rows and columns of `design`'s mesh.
pub(super) fn plan(design: &Design, progress: &dyn Progress) -> Result<MeshPlan> {
    let planner = Planner { design };
    survey_within_budget(design, &planner)?;
    let hh = design.half_height;
    progress.stage("surveying curvature", 2);
    let (revealer_columns, (revealer_rows, revealer_edge_blend), revealer_kmax) =
        planner.revealer_plan();
    progress.tick(1);
    if progress.cancelled() {
        return Err(crate::KernelError::Cancelled);
    }
    let (base_columns, base_k, crease_samples) = planner.base_survey()?;
    progress.tick(1);
    let mut base_rows = rows_from_curvature(-hh, hh, &base_k, ALONG_SHARE * planner.tol(), 1);
    let uniform_base_rows = {
        let kmax = base_k.iter().cloned().fold(0.0, f64::max);
        ((2.0 * hh) * (kmax / (8.0 * ALONG_SHARE * planner.tol())).sqrt())
            .ceil()
            .max(1.0) as usize
    };
    let crossings = planner.crossings(&crease_samples)?;
    insert_rows(&mut base_rows, &crossings);
    Ok(MeshPlan {
        revealer_columns,
        revealer_rows,
        revealer_kmax,
        revealer_edge_blend,
        base_columns,
        base_rows,
        uniform_base_rows,
        crossing_rows: crossings.len(),
    })
}

/// Rows between `lo` and `hi` (both included) such that a segment through
/// cell c with second derivative K[c] has chordal error ≤ e: equidistributes
/// √(K/8e) (rows per mm), with at least `min_segments` segments. `k` holds
/// one value per cell of a uniform grid.
fn rows_from_curvature(lo: f64, hi: f64, k: &[f64], e: f64, min_segments: usize) -> Vec<f64> {
    let cells = k.len();
    let h = (hi - lo) / cells as f64;
    // a cell's density uses the worst of itself and its neighbours
    let density: Vec<f64> = (0..cells)
        .map(|c| {
            let kk = k[c.saturating_sub(1)]
                .max(k[c])
                .max(k[(c + 1).min(cells - 1)]);
            (kk / (8.0 * e)).sqrt()
        })
        .collect();
    let mut cum = vec![0.0; cells + 1];
    for c in 0..cells {
        cum[c + 1] = cum[c] + density[c] * h;
    }
    let mut total = cum[cells];
    let n = (total.ceil() as usize).max(min_segments).max(1);
    if total == 0.0 {
        // flat: spread the minimum rows evenly
        for (c, v) in cum.iter_mut().enumerate() {
            *v = c as f64 * h;
        }
        total = cum[cells];
    }
    let mut rows = Vec::with_capacity(n + 1);
    rows.push(lo);
    let mut c = 0;
    for r in 1..n {
        let target = total * r as f64 / n as f64;
        while cum[c + 1] < target {
            c += 1;
        }
        let step = cum[c + 1] - cum[c];
        let frac = if step > 0.0 {
            (target - cum[c]) / step
        } else {
            0.0
        };
        rows.push(lo + (c as f64 + frac) * h);
    }
    rows.push(hi);
    rows.dedup_by(|a, b| *a <= *b);
    split_where_curvature_peaks(rows, lo, h, k, e)
}

/// Equidistributing √K bounds a segment's chordal error only where K is
/// even along it: a bend confined to a quarter of a long segment deviates
/// up to 8 × e from the chord (found-736d4dd464ec037e: rows 10 mm apart over
/// an image's 1 mm bends, 1.4 % over the whole tolerance). A segment whose
/// length L and largest K over its cells give L²·K / 8 beyond
/// [`PEAK_SLACK`] × e is split evenly until each piece is within e.
fn split_where_curvature_peaks(rows: Vec<f64>, lo: f64, h: f64, k: &[f64], e: f64) -> Vec<f64> {
    let cells = k.len();
    let cell = |y: f64| (((y - lo) / h).floor().max(0.0) as usize).min(cells - 1);
    let mut out = Vec::with_capacity(rows.len());
    for pair in rows.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let peak = k[cell(a)..=cell(b)].iter().cloned().fold(0.0, f64::max);
        let length = b - a;
        out.push(a);
        if length * length * peak / 8.0 > PEAK_SLACK * e {
            let pieces = (length * (peak / (8.0 * e)).sqrt()).ceil() as usize;
            out.extend((1..pieces).map(|p| a + length * p as f64 / pieces as f64));
        }
    }
    out.extend(rows.last());
    out
}

/// What the survey of one lens found.
struct LensSurvey {
    columns: usize,
    /// Effective curvature along the lens at each station (1/mm).
    k_eff: Vec<f64>,
    /// y of the lens's first crease at each station.
    ys: Vec<f64>,
    /// The first crease point at each station.
    first: Vec<DVec3>,
    /// Per station, the lowest and highest y across the lens: where its
    /// bulge leans in y, it spans more than its crease's y.
    y_spans: Vec<(f64, f64)>,
    /// How far (in v) a row solved onto the first and the last station's
    /// y reaches beyond that station, at most across the lens: where the
    /// lens's bulge leans in y, its middle lies off its creases' y.
    overshoot: (f64, f64),
}

struct Planner<'a> {
    design: &'a Design,
}

/// Overshoot (as a share of the first or last row spacing) the edge rows
/// may add to that spacing before a station is put in: a tenth more
/// spacing is a fifth more chordal error along, within the margin.
const OVERSHOOT_SLACK: f64 = 0.1;

/// The revealer's first and last rows are solved onto y = ±H/2, and where
/// the lenses' bulge leans in y their middles lie `overshoot` (lo, hi) of
/// station beyond the edge: the strip to the next station is that much
/// wider there than planned (found-1a8d59fd9f631a5f: 0.138 mm on a
/// 0.16 mm spacing at a paraboloid's edge, 9 % over the tolerance). A
/// station is put in so that the strip is no wider than planned, where
/// the overshoot is less than the spacing. Where it is not, no station
/// can narrow the strip (its middle already spans the overshoot): rows are
/// put in at the edge, evenly, as many as split the strip's middle into
/// planned spacings, and returned as the station of the first row beyond
/// them, for the revealer to solve them onto heights between the wall and
/// that row (found-c59dc5572fb6e245: a paraboloid's lens 0.22 mm of
/// station past a 0.205 mm spacing, 5 % over the tolerance).
fn edge_stations(rows: &mut Vec<f64>, (lo, hi): (f64, f64)) -> EdgeBlend {
    let n = rows.len();
    if n < 2 {
        return (None, None);
    }
    let (first, last) = (rows[1] - rows[0], rows[n - 1] - rows[n - 2]);
    let extra =
        |overshoot: f64, spacing: f64| ((spacing + overshoot) / spacing).ceil() as usize - 1;
    let mut blend = (None, None);
    if hi > OVERSHOOT_SLACK * last && hi < last {
        rows.insert(n - 1, rows[n - 1] - (last - hi));
    } else if hi >= last && n > 2 {
        blend.1 = Some(rows[n - 2]);
        let m = extra(hi, last);
        for k in 1..=m {
            rows.insert(n - 2 + k, rows[n - 2] + last * k as f64 / (m + 1) as f64);
        }
    }
    if lo > OVERSHOOT_SLACK * first && lo < first {
        rows.insert(1, rows[0] + (first - lo));
    } else if lo >= first && rows.len() > 2 {
        blend.0 = Some(rows[1]);
        let m = extra(lo, first);
        for k in 1..=m {
            rows.insert(k, rows[0] + first * k as f64 / (m + 1) as f64);
        }
    }
    blend
}

/// The columns a lens needs, from the `columns` its station arcs need for
/// the across share `e_across`, where its rows shear. Rows are placed in y,
/// and a lens whose bulge leans in y (under a normal that leans along v)
/// runs across a row through stations v(t), dv/dt = −(∂y/∂t)/(∂y/∂v). A
/// row's chord then also bends with the lens's curvature along v and its
/// twist: |f_tt| + |f_vv|·v′² + 2·|f_tv|·|v′| in place of |f_tt| (found-
/// 9b26cfc8245536c2, a base 3.4 mm under a plane sloping 0.54 along y,
/// v′ = 0.45: 15 % over the tolerance; found-1a8d59fd9f631a5f, the
/// revealer at a paraboloid's edge). `pts[s][j]` are the lens's points at
/// `TS` even t on stations `h` apart.
fn sheared_columns<const TS: usize>(
    pts: &[[DVec3; TS]],
    h: f64,
    columns: usize,
    e_across: f64,
) -> usize {
    let dt = 1.0 / (TS - 1) as f64;
    let (mut shear_err, mut scale) = (0.0f64, 1.0f64);
    for s in 1..pts.len().saturating_sub(1) {
        for j in 1..TS - 1 {
            let (p, up, down) = (pts[s], pts[s + 1], pts[s - 1]);
            let ftt = (p[j + 1] - 2.0 * p[j] + p[j - 1]).length() / (dt * dt);
            let fvv = (up[j] - 2.0 * p[j] + down[j]).length() / (h * h);
            let ftv =
                ((up[j + 1] - down[j + 1]) - (up[j - 1] - down[j - 1])).length() / (4.0 * h * dt);
            let dy_dv = ((up[j].y - down[j].y) / (2.0 * h))
                .abs()
                .max(COMPRESSION_SLACK);
            let shear = ((p[j + 1].y - p[j - 1].y) / (2.0 * dt)).abs() / dy_dv;
            let added = fvv * shear * shear + 2.0 * ftv * shear;
            shear_err = shear_err.max(added / (8.0 * (columns * columns) as f64));
            if ftt > 0.0 {
                scale = scale.max(1.0 + added / ftt);
            }
        }
    }
    if shear_err <= SHEAR_SLACK * e_across / ACROSS_SHARE {
        return columns;
    }
    (columns as f64 * scale.sqrt()).ceil() as usize
}

impl<'a> Planner<'a> {
    fn tol(&self) -> f64 {
        self.design.tolerance.mm()
    }

    /// Survey stations: `cells` uniform cells over [−H/2 − pad, H/2 + pad].
    /// Cells over `length` (mm): `usual`, or more where those would be
    /// longer than [`SURVEY_CELL_PERIODS`].
    fn cells_over(&self, length: f64, usual: usize) -> usize {
        let by_period = (length / (SURVEY_CELL_PERIODS * self.design.params.period)).ceil();
        (by_period.min(MAX_SURVEY_CELLS as f64) as usize).max(usual)
    }

    fn survey_stations(&self, pad: f64, cells: usize) -> (Vec<f64>, f64) {
        let hh = self.design.half_height + pad;
        let h = 2.0 * hh / cells as f64;
        ((0..=cells).map(|s| -hh + s as f64 * h).collect(), h)
    }

    /// Cells of the base's survey: [`SURVEY_CELLS`] (more over a long layout,
    /// see [`Self::cells_over`]), or as many as it takes
    /// for a cell to be a quarter of the profile's detail where the usual
    /// cells are coarser than the survey can follow
    /// ([`crate::profile::Profile::coarsest_survey_cell_mm`]), so the base creases'
    /// curvature along y is seen. A second difference
    /// over cells of a ring's wavelength / 2.65 sees 61 % of the crease's
    /// curvature, and the rows it places missed the tolerance by 62 %
    /// (found-2576c6b693dacdf6); over λ / 8, 95 %.
    ///
    /// A pad beyond the layout's own height (a base lying far off its
    /// stations) adds cells in proportion, so the cells over the layout
    /// stay as fine as the usual ones.
    fn base_survey_cells(&self, pad: f64) -> usize {
        let hh = self.design.half_height;
        let length = 2.0 * (hh + pad);
        let over_layout = self.cells_over(2.0 * hh, SURVEY_CELLS);
        let usual = ((over_layout as f64 * (hh + pad) / (hh + pad.min(hh))).ceil() as usize)
            .clamp(SURVEY_CELLS, MAX_SURVEY_CELLS);
        let profile = &self.design.params.profile;
        match (profile.detail_mm(), profile.coarsest_survey_cell_mm()) {
            (Some(detail), Some(coarsest)) if length / usual as f64 > coarsest => {
                ((4.0 * length / detail).ceil() as usize).clamp(usual, MAX_SURVEY_CELLS)
            }
            _ => usual,
        }
    }

    /// Surveys one lens from its station arcs: the columns that meet the
    /// across share of the tolerance at every station, and per station the
    /// effective curvature along the lens, K_eff = 8·e / Δv², where Δv is the
    /// largest row spacing with K_vv·Δv² + 2·Δt·K_tv·Δv ≤ 8·e (the pure and
    /// twist terms of a triangle's interpolation error; Δt = 1/columns).
    fn survey_lens(&self, sections: &[BaseSection], h: f64) -> LensSurvey {
        const TS: usize = 9;
        let e_along = ALONG_SHARE * self.tol();
        let mut columns = 1;
        let pts: Vec<[DVec3; TS]> = sections
            .iter()
            .map(|section| {
                columns = columns.max(section.columns(ACROSS_SHARE * self.tol()));
                std::array::from_fn(|j| section.point(j as f64 / (TS - 1) as f64))
            })
            .collect();
        let columns = sheared_columns(&pts, h, columns, ACROSS_SHARE * self.tol());
        let dt = 1.0 / columns as f64;
        let n = pts.len();
        let mut k_eff = vec![0.0; n];
        for s in 1..n - 1 {
            let mut worst = 0.0f64;
            for j in 0..TS {
                // rows are placed in y: where the lens's stations crowd
                // in y (a deep base under a surface that is convex along
                // y), a row spacing Δy spans Δy / (dy/dv) of station, and
                // the curvature per unit y is K_vv / (dy/dv)². Crowding to
                // COMPRESSION_SLACK stays within the tolerance's margin.
                let dy_dv = ((pts[s + 1][j].y - pts[s - 1][j].y) / (2.0 * h)).abs();
                let crowding = (COMPRESSION_SLACK / dy_dv).max(1.0);
                let kvv = (pts[s - 1][j] - 2.0 * pts[s][j] + pts[s + 1][j]).length() / (h * h)
                    * crowding
                    * crowding;
                let (ja, jb) = (j.saturating_sub(1), (j + 1).min(TS - 1));
                let ktv = ((pts[s + 1][jb] - pts[s - 1][jb]) - (pts[s + 1][ja] - pts[s - 1][ja]))
                    .length()
                    / (2.0 * h * (jb - ja) as f64 / (TS - 1) as f64)
                    * crowding;
                // largest Δv with kvv Δv² + 2 dt ktv Δv = 8 e
                let b = dt * ktv;
                let c = 8.0 * kvv * e_along;
                let dv = if c < 1e-6 * b * b {
                    // nearly no pure curvature beside the twist: the form
                    // below would cancel (to Δv = 0 where kvv is 1e-19,
                    // found-43f707a12508b8cb); this one does not
                    8.0 * e_along / (b + (b * b + c).sqrt())
                } else if kvv > 0.0 {
                    (-b + (b * b + 8.0 * kvv * e_along).sqrt()) / kvv
                } else if b > 0.0 {
                    4.0 * e_along / b
                } else {
                    f64::INFINITY
                };
                worst = worst.max(8.0 * e_along / (dv * dv));
            }
            k_eff[s] = worst;
        }
        if n > 2 {
            k_eff[0] = k_eff[1];
            k_eff[n - 1] = k_eff[n - 2];
        }
        // first order: a point dy off its crease's y is dy / (dy/dv) of
        // station away from the row through the crease
        let overshoot = |end: usize, next: usize, outward: f64| {
            let (p, q) = (&pts[end], &pts[next]);
            (0..TS)
                .map(|j| {
                    let dy_dv = ((q[j].y - p[j].y) / h).abs().max(COMPRESSION_SLACK);
                    outward * (p[0].y - p[j].y) / dy_dv
                })
                .fold(0.0, f64::max)
        };
        LensSurvey {
            columns,
            k_eff,
            ys: pts.iter().map(|p| p[0].y).collect(),
            first: pts.iter().map(|p| p[0]).collect(),
            y_spans: pts
                .iter()
                .map(|p| {
                    p.iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                            (lo.min(q.y), hi.max(q.y))
                        })
                })
                .collect(),
            overshoot: if n > 1 {
                (overshoot(0, 1, -1.0), overshoot(n - 1, n - 2, 1.0))
            } else {
                (0.0, 0.0)
            },
        }
    }

    /// Revealer: columns per lens, and rows (stations).
    fn revealer_plan(&self) -> (Vec<usize>, (Vec<f64>, EdgeBlend), f64) {
        let d = self.design;
        let cells = self.cells_over(2.0 * d.half_height, SURVEY_CELLS);
        let (stations, h) = self.survey_stations(0.0, cells);
        let surveys: Vec<LensSurvey> = (0..d.lenses as i64)
            .into_par_iter()
            .map(|i| {
                let arcs: Vec<BaseSection> = stations
                    .iter()
                    .map(|&v| BaseSection::Lens(d.revealer_arc(i, v)))
                    .collect();
                self.survey_lens(&arcs, h)
            })
            .collect();
        let columns: Vec<usize> = surveys.iter().map(|s| s.columns).collect();
        let k: Vec<f64> = (0..cells)
            .map(|c| {
                surveys
                    .iter()
                    .map(|s| s.k_eff[c].max(s.k_eff[c + 1]))
                    .fold(0.0, f64::max)
            })
            .collect();
        let kmax = k.iter().cloned().fold(0.0, f64::max);
        // At least one interior station row, so every lens has an exact arc
        // in the mesh to measure.
        let mut rows = rows_from_curvature(
            -d.half_height,
            d.half_height,
            &k,
            ALONG_SHARE * self.tol(),
            2,
        );
        let overshoot = surveys.iter().fold((0.0f64, 0.0f64), |(lo, hi), s| {
            (lo.max(s.overshoot.0), hi.max(s.overshoot.1))
        });
        let blend = edge_stations(&mut rows, overshoot);
        (columns, (rows, blend), kmax)
    }

    /// Base: columns per lens, effective curvature per y-cell, and crease
    /// samples for finding crossings with the x-walls.
    #[allow(clippy::type_complexity)]
    fn base_survey(
        &self,
    ) -> Result<(
        BTreeMap<i64, usize>,
        Vec<f64>,
        Vec<(i64, Vec<(f64, DVec3)>)>,
    )> {
        let d = self.design;
        // the base lies up to the margin off its station (a base offset
        // along a normal that leans in y): survey every station that can
        // land inside the outline
        let pad = d.margin;
        let cells = self.base_survey_cells(pad);
        let (stations, h) = self.survey_stations(pad, cells);
        let (xl, xr) = d.outline_x;
        let hh = d.half_height;
        let (k0, k1) = d.base_creases;
        let cell_of = |y: f64| {
            (((y + hh) / (2.0 * hh) * cells as f64).floor() as isize).clamp(0, cells as isize - 1)
                as usize
        };
        // every crease once per station (two lenses share it), each solve
        // starting from the crease's last
        let crease_u: Vec<Vec<f64>> = (k0..=k1)
            .into_par_iter()
            .map(|c| {
                let mut near = None;
                stations
                    .iter()
                    .map(|&v| {
                        let u = d.base_crease_u_near(c, v, near)?;
                        near = Some(u);
                        Ok(u)
                    })
                    .collect()
            })
            .collect::<Result<_>>()?;
        let surveys: Vec<(i64, LensSurvey)> = (k0..k1)
            .into_par_iter()
            .map(|k| {
                let (u0, u1) = (
                    &crease_u[(k - k0) as usize],
                    &crease_u[(k - k0 + 1) as usize],
                );
                let arcs: Vec<BaseSection> = stations
                    .iter()
                    .enumerate()
                    .map(|(s, &v)| d.base_section_between(u0[s], u1[s], v))
                    .collect();
                (k, self.survey_lens(&arcs, h))
            })
            .collect();
        let mut columns = BTreeMap::new();
        let mut kcell = vec![0.0f64; cells];
        let mut creases = Vec::new();
        for (k, s) in &surveys {
            columns.insert(*k, s.columns);
            // Where the base lies far off its stations in y (an offset
            // along a normal that leans in y), neighbouring stations land
            // several cells apart: the cells between take their larger
            // curvature (a gap of one or two cells is covered by the
            // neighbours the row spacing reads anyway).
            let mut last: Option<(usize, usize)> = None; // (station, cell)
            for (idx, (&y, p)) in s.ys.iter().zip(&s.first).enumerate() {
                let inside = p.x >= xl - d.params.period * 10.0
                    && p.x <= xr + d.params.period * 10.0
                    && y.abs() <= hh + h;
                if inside {
                    let c = cell_of(y);
                    // the station's curvature holds across the lens, over
                    // every y it spans (found-9b5f449fadf0b102: a lens
                    // 0.06 mm wide in y under a plane sloping 0.55 along
                    // y, and a coin's edge blurred 0.076 mm, got its rows
                    // from cells 0.06 mm off its peak: 38 % over)
                    let (lo, hi) = s.y_spans[idx];
                    for cell in &mut kcell[cell_of(lo)..=cell_of(hi)] {
                        *cell = cell.max(s.k_eff[idx]);
                    }
                    if let Some((i0, c0)) = last.filter(|&(i0, _)| i0 + 1 == idx) {
                        if c.abs_diff(c0) >= 4 {
                            let k = s.k_eff[i0].max(s.k_eff[idx]);
                            for cell in &mut kcell[c.min(c0) + 1..c.max(c0)] {
                                *cell = cell.max(k);
                            }
                        }
                    }
                    last = Some((idx, c));
                }
            }
            // beyond the extended layout a crease is outside, on its side
            let u = &crease_u[(k - k0) as usize];
            creases.push((
                *k,
                stations
                    .iter()
                    .zip(&s.first)
                    .zip(u)
                    .map(|((&v, &p), &u)| match d.beyond_extended_layout(u) {
                        Some(side) => (v, DVec3::new(side, p.y, p.z)),
                        None => (v, p),
                    })
                    .collect(),
            ));
        }
        // the last crease k1 bounds lens k1 − 1
        let last = stations
            .iter()
            .map(|&v| Ok((v, d.base_crease_point(k1, v)?)))
            .collect::<Result<Vec<_>>>()?;
        creases.push((k1, last));
        Ok((columns, kcell, creases))
    }

    /// Where base creases cross an x-wall: the exact y, and how fast the
    /// crease leaves the wall there.
    fn crossings(&self, creases: &[(i64, Vec<(f64, DVec3)>)]) -> Result<Vec<Crossing>> {
        let d = self.design;
        let mut ys = Vec::new();
        for (k, samples) in creases {
            for wall in [d.outline_x.0, d.outline_x.1] {
                // Samples are inside, outside, or within the snap band of the
                // wall. A crossing is a move from clearly inside to clearly
                // outside (or back), possibly through band samples; a crease
                // that only touches the band (a tangential touch) needs no row.
                let mut last: Option<(f64, f64)> = None; // (v, signed distance) of the last clear sample
                for &(v, p) in samples {
                    let s = p.x - wall;
                    if !s.is_finite() {
                        // beyond a sphere's rim, far outside the layout:
                        // no crossing is bracketed across it
                        last = None;
                        continue;
                    }
                    if s.abs() <= WALL_SNAP_MM {
                        continue;
                    }
                    if let Some((v0, s0)) = last {
                        if (s0 > 0.0) != (s > 0.0) {
                            // the root bracketed by these two samples, not another one
                            ys.extend(self.crossing(*k, wall, (v0, v))?);
                        }
                    }
                    last = Some((v, s));
                }
            }
        }
        for (k, samples) in creases {
            for wall in [d.outline_x.0, d.outline_x.1] {
                ys.extend(self.touches(*k, samples, wall)?);
            }
        }
        ys.sort_by(|a, b| a.y.total_cmp(&b.y));
        Ok(ys)
    }

    /// Where base crease `k` crosses the wall at x = `wall` between the
    /// stations `v0` and `v1`, which bracket one crossing: the crossing, if
    /// it lies between the layout's y-walls.
    fn crossing(&self, k: i64, wall: f64, (v0, v): (f64, f64)) -> Result<Option<Crossing>> {
        let d = self.design;
        let hh = d.half_height;
        let root = bracketed_secant(
            v0,
            v,
            &|| format!("base crease {k} meeting the wall x = {wall}"),
            |v| {
                d.base_crease_point(k, v)
                    .map(|p| p.x - wall)
                    .unwrap_or(f64::NAN)
            },
        )?;
        let y = d.base_crease_point(k, root)?.y;
        if !(y > -hh && y < hh) {
            return Ok(None);
        }
        // |dx/dy| of the crease, by central differences
        let h = 1e-6 * (v - v0).abs().max(1e-3);
        let (a, b) = (
            d.base_crease_point(k, root - h)?,
            d.base_crease_point(k, root + h)?,
        );
        let slope = ((b.x - a.x) / (b.y - a.y)).abs();
        Ok(Some(Crossing {
            y,
            slope: if slope.is_finite() {
                slope
            } else {
                f64::INFINITY
            },
        }))
    }

    /// Where base crease `k` (sampled at `samples`) comes within the wall
    /// snap of the wall at x = `wall` between its samples without crossing
    /// it: a row there, so that the crease's vertex touches the wall and the
    /// lens piece beside it pinches at that vertex instead of narrowing to
    /// a neck a few nanometres wide between rows (which no B-rep trim can
    /// follow: OpenCascade found such a face's wire self-intersecting on a
    /// random design, tests/python/test_mold_oracles.py).
    fn touches(&self, k: i64, samples: &[(f64, DVec3)], wall: f64) -> Result<Vec<Crossing>> {
        let d = self.design;
        let hh = d.half_height;
        let gap = |v: f64| -> Result<f64> { Ok(d.base_crease_point(k, v)?.x - wall) };
        let mut found = Vec::new();
        for w in samples.windows(3) {
            let [(va, pa), (_, pb), (vc, pc)] = [w[0], w[1], w[2]];
            let (sa, sb, sc) = (pa.x - wall, pb.x - wall, pc.x - wall);
            // (the middle one may lie in the snap band on the other side:
            // found-d40d1b6250ce1ad8, a crease dipping 5e-5 mm past the wall)
            let one_side =
                (sa > 0.0) == (sc > 0.0) && ((sb > 0.0) == (sa > 0.0) || sb.abs() <= WALL_SNAP_MM);
            // a local minimum of the distance, near the wall, between
            // samples clear of it (a crease that lies along the wall over
            // samples is the rows' business already)
            let clear = |s: f64| s.is_finite() && s.abs() > WALL_SNAP_MM;
            if !(clear(sa) && sb.is_finite() && clear(sc) && one_side)
                || sb.abs() > sa.abs()
                || sb.abs() > sc.abs()
                || sb.abs() > TOUCH_SEARCH_MM
            {
                continue;
            }
            // golden-section search for the closest approach in [va, vc],
            // on the side of the samples: past the wall it goes on to the
            // deepest point, so that a crease dipping across the wall and
            // back between samples is seen to cross twice
            let side = sa.signum();
            let toward = |v: f64| -> Result<f64> { Ok(side * gap(v)?) };
            let (mut lo, mut hi) = (va, vc);
            const R: f64 = 0.618_033_988_749_894_9;
            let (mut x1, mut x2) = (hi - R * (hi - lo), lo + R * (hi - lo));
            let (mut f1, mut f2) = (toward(x1)?, toward(x2)?);
            for _ in 0..60 {
                if f1 < f2 {
                    (hi, x2, f2) = (x2, x1, f1);
                    x1 = hi - R * (hi - lo);
                    f1 = toward(x1)?;
                } else {
                    (lo, x1, f1) = (x1, x2, f2);
                    x2 = lo + R * (hi - lo);
                    f2 = toward(x2)?;
                }
            }
            let v = 0.5 * (lo + hi);
            let closest = toward(v)?;
            if closest < -WALL_SNAP_MM {
                // across the wall and back: two crossings, one on each side
                for bracket in [(va, v), (v, vc)] {
                    found.extend(self.crossing(k, wall, bracket)?);
                }
            } else if closest <= WALL_SNAP_MM {
                let y = d.base_crease_point(k, v)?.y;
                if y > -hh && y < hh {
                    found.push(Crossing { y, slope: 0.0 });
                }
            }
        }
        Ok(found)
    }
}

/// Closest sampled distance (mm) of a base crease to a wall at which its
/// closest approach between samples is searched for a touch.
const TOUCH_SEARCH_MM: f64 = 0.05;

/// Where a base crease crosses an x-wall: at height `y`, leaving the wall
/// by `slope` mm in x per mm in y.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Crossing {
    y: f64,
    slope: f64,
}

/// Inserts crossing rows into `rows` (sorted, boundaries first and last).
/// A crossing close to a free interior row replaces it, so no sliver strips
/// appear; boundary rows never move.
/// Crossings closer than this (mm) to a pinned row join it: half the wall
/// snap, twice the least triangle altitude. The row puts a joined crease
/// that it leaves past the snap at the crease's exact crossing
/// (`base::onto_near_crossings`).
pub(super) const MERGE_CROSSING_MM: f64 = WALL_SNAP_MM / 2.0;
/// A crossing up to this far (mm) from a row also joins it if its crease,
/// followed along its slope, stays within half the wall snap of the wall
/// at that row: the row's crease vertex snaps onto the wall and stands for
/// the crossing. Two rows a few times the least triangle altitude apart
/// would leave the wall's fan triangles below it (found by the design
/// fuzzer: two creases crossing a wall 2.7e-5 mm apart,
/// tests/design-corpus/found-9e054658bb6abd84.toml). At this distance a
/// crease's bend, κ·δ²/2, stays far below the snap for any κ under 100/mm.
const MERGE_GRAZING_MM: f64 = 5e-4;

/// Whether crossing `c` may be stood for by a row at height `y`.
fn joins(c: &Crossing, y: f64) -> bool {
    let gap = (c.y - y).abs();
    gap < MERGE_CROSSING_MM || (gap < MERGE_GRAZING_MM && c.slope * gap <= WALL_SNAP_MM / 2.0)
}

/// What holds a row where it is.
enum Pin {
    /// Placed by the curvature survey: a crossing may move it.
    Free,
    /// A boundary row: never moves.
    Boundary,
    /// Stands for these crossings: it may move only where all of them
    /// still join it.
    Crossings(Vec<Crossing>),
}

fn insert_rows(rows: &mut Vec<f64>, crossings: &[Crossing]) {
    let mut pins: Vec<Pin> = rows.iter().map(|_| Pin::Free).collect();
    pins[0] = Pin::Boundary;
    *pins.last_mut().unwrap() = Pin::Boundary;
    for &c in crossings {
        let pos = rows.partition_point(|&r| r < c.y);
        let (lo, hi) = (pos - 1, pos.min(rows.len() - 1));
        let gap = rows[hi] - rows[lo];
        // the neighbours, nearer first
        let mut near = [lo, hi];
        if rows[hi] - c.y < c.y - rows[lo] {
            near.swap(0, 1);
        }
        let mut placed = false;
        for n in near {
            if (rows[n] - c.y).abs() < 1e-9 || joins(&c, rows[n]) {
                // it joins the row where the row is (a boundary row, or the
                // other crossing of a crease grazing the wall)
                match &mut pins[n] {
                    Pin::Free => pins[n] = Pin::Crossings(vec![c]),
                    Pin::Boundary => {}
                    Pin::Crossings(list) => list.push(c),
                }
                placed = true;
            } else if let Pin::Crossings(list) = &mut pins[n] {
                // or the row moves to it, if that keeps its own crossings
                if (rows[n] - c.y).abs() < MERGE_GRAZING_MM && list.iter().all(|o| joins(o, c.y)) {
                    list.push(c);
                    rows[n] = c.y;
                    placed = true;
                }
            }
            if placed {
                break;
            }
        }
        if placed {
            continue;
        }
        if matches!(pins[lo], Pin::Free) && c.y - rows[lo] < 0.1 * gap {
            rows[lo] = c.y;
            pins[lo] = Pin::Crossings(vec![c]);
        } else if matches!(pins[hi], Pin::Free) && rows[hi] - c.y < 0.1 * gap {
            rows[hi] = c.y;
            pins[hi] = Pin::Crossings(vec![c]);
        } else {
            rows.insert(pos, c.y);
            pins.insert(pos, Pin::Crossings(vec![c]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{insert_rows, Crossing};

    fn steep(ys: &[f64]) -> Vec<Crossing> {
        ys.iter().map(|&y| Crossing { y, slope: 1.0 }).collect()
    }

    #[test]
    fn crossing_rows_are_never_moved() {
        let mut rows = vec![-1.0, 0.0, 1.0];
        insert_rows(&mut rows, &steep(&[0.05, 0.09, -0.5]));
        assert_eq!(rows, vec![-1.0, -0.5, 0.05, 0.09, 1.0]);
    }

    /// A grazing crease's second crossing, 3e-5 mm past its first, joins
    /// the first's row; steep ones do not (their creases would leave the
    /// wall); a steep one next to a grazing one takes the row, whichever
    /// comes first.
    #[test]
    fn grazing_crossings_share_a_row() {
        let mut rows = vec![-1.0, 0.0, 1.0];
        let grazing = [0.5, 0.50003].map(|y| Crossing { y, slope: 0.01 });
        insert_rows(&mut rows, &grazing);
        assert_eq!(rows, vec![-1.0, 0.0, 0.5, 1.0]);
        let mut rows = vec![-1.0, 0.0, 1.0];
        insert_rows(&mut rows, &steep(&[0.5, 0.50003]));
        assert_eq!(rows, vec![-1.0, 0.0, 0.5, 0.50003, 1.0]);
        let (graze, cross) = (
            Crossing {
                y: 0.5,
                slope: 0.01,
            },
            Crossing {
                y: 0.50003,
                slope: 1.0,
            },
        );
        for order in [[graze, cross], [cross, graze]] {
            let mut rows = vec![-1.0, 0.0, 1.0];
            insert_rows(&mut rows, &order);
            assert_eq!(rows, vec![-1.0, 0.0, 0.50003, 1.0]);
        }
    }
}
