//! A mesher straight from the exact model (METHOD §5.1, §5.3).
//!
//! **Guarantees.** Every vertex lies on its exact surface (to the solver
//! residual); the mesh is closed and consistently oriented *by construction*,
//! because every vertex on a crease, a trim line or a wall is computed once
//! and shared by index; the triangle count is close to the fewest that meet
//! the tolerance, because rows and columns are spaced by the local curvature.
//! [`crate::measure`] measures all of this independently.
//!
//! **Layout of the mesh.**
//! - Revealer: per lens, `n_i` columns uniform in arc angle (chordal error),
//!   rows at *stations* v (so every interior row is an exact lens arc, and
//!   AFOV can be measured from the vertices), plus two boundary rows solved
//!   to lie exactly on the walls y = ±H/2. Creases project to x = const, so
//!   the outermost creases are the x-walls' top edges.
//! - Base: rows at exact y (solved per vertex), per lens the columns that lie
//!   inside the outline; where a base lens is cut by an x-wall, the cut vertex
//!   is solved onto the wall. Where a base crease crosses an x-wall, a row is
//!   placed at the crossing so the corner is exact.
//! - Walls: planar strips zipped between the top and bottom boundary polylines.

use crate::check::{triangle_altitude, MIN_ALTITUDE_MM};
use crate::design::Design;
use crate::error::{KernelError, Result};
use crate::mesh::Mesh;
use crate::model::{BaseSection, LensRef};
use crate::progress::Progress;
use crate::solve::{bracketed_secant, newton_2d};
use crate::tolerance::{SOLVE_RESIDUAL_MM, WALL_SNAP_MM};
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Share of the tolerance given to the chordal error across a lens.
const ACROSS_SHARE: f64 = 0.45;
/// Share of the tolerance given to the chordal error along a lens. The two
/// add at most at a triangle's interior; the rest is margin for the twist.
const ALONG_SHARE: f64 = 0.4;
/// How far (mm) an interior base vertex may lie from its row's plane y = const.
const INTERIOR_ROW_RESIDUAL_MM: f64 = 1e-6;
/// Cells of the curvature survey along y.
const SURVEY_CELLS: usize = 256;
/// A wall triangle thinner than this (mm) is avoided where the zip has a
/// thicker choice: four times [`MIN_ALTITUDE_MM`], as the mold halves the
/// wall's rungs at mid-height and fans to those points at an angle (the
/// same margin as [`WALL_SNAP_MM`]).
const WALL_SLIVER_MM: f64 = 4.0 * MIN_ALTITUDE_MM;

/// Where a vertex comes from: its exact surface and parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VertexOrigin {
    /// On revealer crease `i` (between lenses i−1 and i) at station v.
    RevealerCrease { i: i64, v: f64 },
    /// Inside revealer lens `i` at arc parameter t, station v.
    RevealerLens { i: i64, t: f64, v: f64 },
    /// On base crease `k` at station v.
    BaseCrease { k: i64, v: f64 },
    /// Inside base lens `k` (including where an x-wall cuts it).
    BaseLens { k: i64, t: f64, v: f64 },
}

impl VertexOrigin {
    /// The (t, v) parameters of this vertex on `lens`, if it lies on it.
    pub fn params_on(&self, lens: LensRef) -> Option<DVec2> {
        match (*self, lens) {
            (VertexOrigin::RevealerCrease { i, v }, LensRef::Revealer(l))
            | (VertexOrigin::BaseCrease { k: i, v }, LensRef::Base(l)) => {
                if i == l {
                    Some(DVec2::new(0.0, v))
                } else if i == l + 1 {
                    Some(DVec2::new(1.0, v))
                } else {
                    None
                }
            }
            (VertexOrigin::RevealerLens { i, t, v }, LensRef::Revealer(l))
            | (VertexOrigin::BaseLens { k: i, t, v }, LensRef::Base(l)) => {
                (i == l).then_some(DVec2::new(t, v))
            }
            _ => None,
        }
    }
}

/// A vertical side wall of the device (METHOD §5.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Side {
    /// x = outline_x.0
    Left,
    /// x = outline_x.1
    Right,
    /// y = −H/2
    Front,
    /// y = +H/2
    Back,
}

/// The face a triangle belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Patch {
    Lens(LensRef),
    Wall(Side),
}

/// Counts that describe a device mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshStats {
    pub triangles: usize,
    pub vertices: usize,
    pub revealer_triangles: usize,
    pub base_triangles: usize,
    pub wall_triangles: usize,
    pub revealer_rows: usize,
    pub base_rows: usize,
    /// Rows placed where a base crease crosses an x-wall.
    pub crossing_rows: usize,
    pub revealer_columns: (usize, usize),
    pub base_columns: (usize, usize),
    /// Triangles a uniform grid needs for the same tolerance: the finest
    /// column count on every lens and the finest row spacing everywhere.
    pub uniform_triangles: usize,
}

/// The device mesh with the provenance of every vertex and triangle.
#[derive(Clone, Debug)]
pub struct DeviceMesh {
    pub mesh: Mesh,
    pub origins: Vec<VertexOrigin>,
    pub patches: Vec<Patch>,
    pub stats: MeshStats,
    /// Revealer row stations (the first and last rows are solved onto y = ±H/2).
    pub revealer_rows: Vec<f64>,
    /// Columns per revealer lens.
    pub revealer_columns: Vec<usize>,
    /// Columns per base lens (lenses entirely outside the outline included).
    pub base_columns: BTreeMap<i64, usize>,
    /// Columns of the revealer lenses before lens i (i = 0..=n): where lens
    /// i starts in a row, and the row's length less one.
    revealer_starts: Vec<usize>,
}

impl DeviceMesh {
    /// Index of revealer vertex (row r, lens i, column j ∈ 0..=n_i).
    pub fn revealer_vertex(&self, r: usize, i: usize, j: usize) -> u32 {
        (r * self.revealer_row_len() + self.revealer_starts[i] + j) as u32
    }

    fn revealer_row_len(&self) -> usize {
        self.revealer_starts
            .last()
            .expect("one start per lens and one past")
            + 1
    }
}

/// Columns needed across an arc of radius `r` spanning `angle` (rad) for a
/// chordal error of at most `e`.
pub(crate) fn columns_for(r: f64, angle: f64, e: f64) -> usize {
    let step = if e >= r {
        std::f64::consts::PI
    } else {
        2.0 * (1.0 - e / r).acos()
    };
    ((angle / step).ceil() as usize).max(2)
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
    rows
}

/// Triangulates the strip between polylines `a` and `b` (both ordered by
/// `key`), advancing along whichever has the nearer next vertex. Triangles
/// are (a_i, a_{i+1}, b_j) and (a_i, b_{j+1}, b_j), reversed if `flip`.
///
/// A wall passes `facing`: the positions and its outward normal. Where one
/// edge is sparse (three vertices along a straight revealer edge) and the
/// other wavy, the nearer-vertex rule can fan a sparse vertex over a steep
/// stretch of the wavy edge that faces away from it: triangles folded over
/// their neighbours, the wall overlapping itself in its plane. There the
/// other advance is taken when its triangle faces out. Likewise where the
/// wavy edge has two vertices very close together (a base row placed where
/// a crease crosses the *other* wall, just inside a boundary row), a far
/// sparse vertex fanned over them makes a sliver thinner than
/// [`WALL_SLIVER_MM`]; the other advance is taken when its triangle is
/// thicker and faces out.
fn zip(
    a: &[u32],
    b: &[u32],
    key: &dyn Fn(u32) -> f64,
    flip: bool,
    patch: Patch,
    facing: Option<(&[DVec3], DVec3)>,
    (out, patches): (&mut Vec<[u32; 3]>, &mut Vec<Patch>),
) {
    let oriented = |t: [u32; 3]| if flip { [t[0], t[2], t[1]] } else { t };
    let faces_out = |t: [u32; 3]| {
        facing.is_none_or(|(pos, outward)| {
            let [p, q, r] = oriented(t).map(|v| pos[v as usize]);
            (q - p).cross(r - p).dot(outward) > 0.0
        })
    };
    // a lens strip's rows are far apart: only walls can fan into slivers
    let thickness = |t: [u32; 3]| {
        facing.map_or(f64::INFINITY, |(pos, _)| {
            triangle_altitude(t.map(|v| pos[v as usize]))
        })
    };
    let (mut i, mut j) = (0, 0);
    while i + 1 < a.len() || j + 1 < b.len() {
        let along_a = [a[i], a[(i + 1).min(a.len() - 1)], b[j]];
        let along_b = [a[i], b[(j + 1).min(b.len() - 1)], b[j]];
        let advance_a = if i + 1 == a.len() {
            false
        } else if j + 1 == b.len() {
            true
        } else {
            let nearer = key(a[i + 1]) <= key(b[j + 1]);
            let (preferred, other) = if nearer {
                (along_a, along_b)
            } else {
                (along_b, along_a)
            };
            let folds = !faces_out(preferred);
            let thin = thickness(preferred);
            let sliver = thin < WALL_SLIVER_MM && thickness(other) > thin;
            nearer != ((folds || sliver) && faces_out(other))
        };
        let tri = if advance_a {
            i += 1;
            along_a
        } else {
            j += 1;
            along_b
        };
        out.push(oriented(tri));
        patches.push(patch);
    }
}

/// One base row: its vertices (left to right) and, per base lens, the
/// polyline of its vertices on this row.
struct BaseRow {
    positions: Vec<DVec3>,
    origins: Vec<VertexOrigin>,
    /// Per lens k: None (absent) or local indices left to right (one index
    /// when the lens only touches the row at a crease on a wall).
    lenses: BTreeMap<i64, Vec<u32>>,
    /// Local indices of the leftmost and rightmost vertex.
    ends: (u32, u32),
}

impl BaseRow {
    /// The lens that meets `side`'s x-wall on this row and the vertex where
    /// it does. A lens that only touches the wall with a crease (one vertex)
    /// counts: that crease also starts the next lens, which the next row may cut.
    fn wall_vertex(&self, side: Side) -> Option<(i64, VertexOrigin)> {
        let (k, poly) = match side {
            Side::Left => self.lenses.iter().next()?,
            _ => self.lenses.iter().next_back()?,
        };
        let v = if side == Side::Left {
            poly[0]
        } else {
            *poly.last()?
        };
        Some((*k, self.origins[v as usize]))
    }
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
}

struct Planner<'a> {
    design: &'a Design,
}

impl<'a> Planner<'a> {
    fn tol(&self) -> f64 {
        self.design.tolerance.mm()
    }

    /// Survey stations: uniform over [−H/2 − pad, H/2 + pad].
    fn survey_stations(&self, pad: f64) -> (Vec<f64>, f64) {
        let hh = self.design.half_height + pad;
        let h = 2.0 * hh / SURVEY_CELLS as f64;
        ((0..=SURVEY_CELLS).map(|s| -hh + s as f64 * h).collect(), h)
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
        let dt = 1.0 / columns as f64;
        let n = pts.len();
        let mut k_eff = vec![0.0; n];
        for s in 1..n - 1 {
            let mut worst = 0.0f64;
            for j in 0..TS {
                let kvv = (pts[s - 1][j] - 2.0 * pts[s][j] + pts[s + 1][j]).length() / (h * h);
                let (ja, jb) = (j.saturating_sub(1), (j + 1).min(TS - 1));
                let ktv = ((pts[s + 1][jb] - pts[s - 1][jb]) - (pts[s + 1][ja] - pts[s - 1][ja]))
                    .length()
                    / (2.0 * h * (jb - ja) as f64 / (TS - 1) as f64);
                // largest Δv with kvv Δv² + 2 dt ktv Δv = 8 e
                let b = dt * ktv;
                let dv = if kvv > 0.0 {
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
        LensSurvey {
            columns,
            k_eff,
            ys: pts.iter().map(|p| p[0].y).collect(),
            first: pts.iter().map(|p| p[0]).collect(),
        }
    }

    /// Revealer: columns per lens, and rows (stations).
    fn revealer_plan(&self) -> (Vec<usize>, Vec<f64>, f64) {
        let d = self.design;
        let (stations, h) = self.survey_stations(0.0);
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
        let k: Vec<f64> = (0..SURVEY_CELLS)
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
        let rows = rows_from_curvature(
            -d.half_height,
            d.half_height,
            &k,
            ALONG_SHARE * self.tol(),
            2,
        );
        (columns, rows, kmax)
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
        let pad = d.margin.min(d.half_height);
        let (stations, h) = self.survey_stations(pad);
        let (xl, xr) = d.outline_x;
        let hh = d.half_height;
        let (k0, k1) = d.base_creases;
        let cell_of = |y: f64| {
            (((y + hh) / (2.0 * hh) * SURVEY_CELLS as f64).floor() as isize)
                .clamp(0, SURVEY_CELLS as isize - 1) as usize
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
        let mut kcell = vec![0.0f64; SURVEY_CELLS];
        let mut creases = Vec::new();
        for (k, s) in &surveys {
            columns.insert(*k, s.columns);
            for (idx, (&y, p)) in s.ys.iter().zip(&s.first).enumerate() {
                let inside = p.x >= xl - d.params.period * 10.0
                    && p.x <= xr + d.params.period * 10.0
                    && y.abs() <= hh + h;
                if inside {
                    let c = cell_of(y);
                    kcell[c] = kcell[c].max(s.k_eff[idx]);
                }
            }
            creases.push((
                *k,
                stations
                    .iter()
                    .cloned()
                    .zip(s.first.iter().cloned())
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

    /// Exact y-values where a base crease crosses an x-wall.
    fn crossings(&self, creases: &[(i64, Vec<(f64, DVec3)>)]) -> Result<Vec<f64>> {
        let d = self.design;
        let hh = d.half_height;
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
                    if s.abs() <= WALL_SNAP_MM {
                        continue;
                    }
                    if let Some((v0, s0)) = last {
                        if (s0 > 0.0) != (s > 0.0) {
                            // the root bracketed by these two samples, not another one
                            let root = bracketed_secant(
                                v0,
                                v,
                                &|| format!("base crease {k} meeting the wall x = {wall}"),
                                |v| {
                                    d.base_crease_point(*k, v)
                                        .map(|p| p.x - wall)
                                        .unwrap_or(f64::NAN)
                                },
                            )?;
                            let y = d.base_crease_point(*k, root)?.y;
                            if y > -hh && y < hh {
                                ys.push(y);
                            }
                        }
                    }
                    last = Some((v, s));
                }
            }
        }
        ys.sort_by(f64::total_cmp);
        Ok(ys)
    }
}

/// Inserts crossing rows into `rows` (sorted, boundaries first and last).
/// A crossing close to a free interior row replaces it, so no sliver strips
/// appear; boundary rows and crossings already placed are never moved.
fn insert_rows(rows: &mut Vec<f64>, crossings: &[f64]) {
    let mut pinned = vec![false; rows.len()];
    pinned[0] = true;
    *pinned.last_mut().unwrap() = true;
    for &y in crossings {
        let pos = rows.partition_point(|&r| r < y);
        let (lo, hi) = (rows[pos - 1], rows[pos.min(rows.len() - 1)]);
        let gap = hi - lo;
        if (y - lo).abs() < 1e-9 || (hi - y).abs() < 1e-9 {
            continue;
        }
        if !pinned[pos - 1] && y - lo < 0.1 * gap {
            rows[pos - 1] = y;
            pinned[pos - 1] = true;
        } else if !pinned[pos] && hi - y < 0.1 * gap {
            rows[pos] = y;
            pinned[pos] = true;
        } else {
            rows.insert(pos, y);
            pinned.insert(pos, true);
        }
    }
}

/// Builds the device mesh of `design`.
pub fn mesh_device(design: &Design, progress: &dyn Progress) -> Result<DeviceMesh> {
    let planner = Planner { design };
    let d = design;
    let (xl, xr) = d.outline_x;
    let hh = d.half_height;

    progress.stage("surveying curvature", 2);
    let (rev_columns, rev_rows, rev_kmax) = planner.revealer_plan();
    progress.tick(1);
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

    // ---- revealer vertices -------------------------------------------------
    let n = d.lenses;
    let row_len = rev_columns.iter().sum::<usize>() + 1;
    let last_row = rev_rows.len() - 1;
    progress.stage("revealer vertices", rev_rows.len() as u64);
    let rev_vertices: Vec<Vec<(DVec3, VertexOrigin)>> = rev_rows
        .par_iter()
        .enumerate()
        .map(|(r, &v)| {
            let boundary = (r == 0 || r == last_row).then_some(if r == 0 { -hh } else { hh });
            let mut out = Vec::with_capacity(row_len);
            for (i, &cols) in rev_columns.iter().enumerate().take(n) {
                let arc = d.revealer_arc(i as i64, v);
                let first = if i == 0 { 0 } else { 1 };
                for j in first..=cols {
                    let t = j as f64 / cols as f64;
                    let (p, vv) = match boundary {
                        None => (arc.point(t), v),
                        Some(y) => {
                            let vv = d.solve_station_for_y(LensRef::Revealer(i as i64), t, y, v)?;
                            (d.revealer_point(i as i64, t, vv), vv)
                        }
                    };
                    let origin = if j == 0 {
                        VertexOrigin::RevealerCrease { i: i as i64, v: vv }
                    } else if j == cols {
                        VertexOrigin::RevealerCrease {
                            i: i as i64 + 1,
                            v: vv,
                        }
                    } else {
                        VertexOrigin::RevealerLens {
                            i: i as i64,
                            t,
                            v: vv,
                        }
                    };
                    out.push((p, origin));
                }
            }
            progress.tick(1);
            Ok(out)
        })
        .collect::<Result<_>>()?;
    // rows must not cross: every column's y increases from row to row
    for r in 0..last_row {
        for (a, b) in rev_vertices[r].iter().zip(&rev_vertices[r + 1]) {
            if b.0.y <= a.0.y {
                return Err(KernelError::MeshCheck {
                    name: "rows-ordered",
                    detail: format!("revealer rows {r} and {} cross at x = {:.4}", r + 1, a.0.x),
                });
            }
        }
    }

    // ---- base vertices -----------------------------------------------------
    progress.stage("base vertices", base_rows.len() as u64);
    let compute_rows = |ys: &[f64]| -> Result<Vec<BaseRow>> {
        ys.par_iter()
            .map(|&y| {
                let row = base_row(d, &base_columns, y, xl, xr);
                progress.tick(1);
                row
            })
            .collect()
    };
    let mut base_row_data = compute_rows(&base_rows)?;
    // Where an x-wall cuts a base lens, the trim curve between two rows is
    // one edge: refine until its cut moves by at most one column per strip,
    // so the trim edge meets the same chordal bound as the lens columns.
    for _pass in 0..8 {
        let mut extra = Vec::new();
        for r in 0..base_rows.len() - 1 {
            for side in [Side::Left, Side::Right] {
                let (Some((ka, oa)), Some((kb, ob))) = (
                    base_row_data[r].wall_vertex(side),
                    base_row_data[r + 1].wall_vertex(side),
                ) else {
                    continue;
                };
                // the lens both wall vertices lie on (a crease lies on two);
                // none means a crease crosses between, and its row bounds the strip
                let shared = [ka, kb].into_iter().find_map(|k| {
                    let lens = LensRef::Base(k);
                    Some((k, oa.params_on(lens)?.x, ob.params_on(lens)?.x))
                });
                let Some((k, ta, tb)) = shared else { continue };
                let cols = base_columns.get(&k).copied().unwrap_or(2) as f64;
                let pieces = ((ta - tb).abs() * cols).ceil() as usize;
                for p in 1..pieces {
                    extra.push(
                        base_rows[r] + (base_rows[r + 1] - base_rows[r]) * p as f64 / pieces as f64,
                    );
                }
            }
        }
        if extra.is_empty() {
            break;
        }
        extra.sort_by(f64::total_cmp);
        extra.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        let new_rows = compute_rows(&extra)?;
        let mut merged: Vec<(f64, BaseRow)> = base_rows
            .drain(..)
            .zip(base_row_data.drain(..))
            .chain(extra.into_iter().zip(new_rows))
            .collect();
        merged.sort_by(|a, b| a.0.total_cmp(&b.0));
        merged.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-9);
        for (y, row) in merged {
            base_rows.push(y);
            base_row_data.push(row);
        }
    }

    // ---- assemble ----------------------------------------------------------
    progress.stage("triangles", 1);
    let rev_count = rev_rows.len() * row_len;
    let mut positions = Vec::with_capacity(
        rev_count
            + base_row_data
                .iter()
                .map(|r| r.positions.len())
                .sum::<usize>(),
    );
    let mut origins = Vec::with_capacity(positions.capacity());
    for row in &rev_vertices {
        for (p, o) in row {
            positions.push(*p);
            origins.push(*o);
        }
    }
    let mut base_offsets = Vec::with_capacity(base_row_data.len());
    for row in &base_row_data {
        base_offsets.push(positions.len() as u32);
        positions.extend_from_slice(&row.positions);
        origins.extend_from_slice(&row.origins);
    }
    let mut dm = DeviceMesh {
        mesh: Mesh {
            positions,
            triangles: Vec::new(),
        },
        origins,
        patches: Vec::new(),
        stats: MeshStats::default(),
        revealer_rows: rev_rows
            .iter()
            .enumerate()
            .map(|(r, &v)| {
                if r == 0 {
                    -hh
                } else if r == last_row {
                    hh
                } else {
                    v
                }
            })
            .collect(),
        revealer_columns: rev_columns.clone(),
        base_columns: base_columns.clone(),
        revealer_starts: std::iter::once(0)
            .chain(rev_columns.iter().scan(0, |sum, &c| {
                *sum += c;
                Some(*sum)
            }))
            .collect(),
    };
    let mut tris = Vec::new();
    let mut patches = Vec::new();
    let key_t =
        |o: &VertexOrigin, lens: LensRef| o.params_on(lens).map(|p| p.x).unwrap_or(f64::NAN);

    // revealer strips: per row in parallel, concatenated in row order
    type Strip = (Vec<[u32; 3]>, Vec<Patch>);
    let concat = |parts: Vec<Strip>, tris: &mut Vec<[u32; 3]>, patches: &mut Vec<Patch>| {
        for (t, p) in parts {
            tris.extend(t);
            patches.extend(p);
        }
    };
    let dm_ref = &dm;
    let revealer_parts: Vec<Strip> = (0..last_row)
        .into_par_iter()
        .map(|r| {
            let (mut t, mut p) = (Vec::new(), Vec::new());
            for (i, &cols) in rev_columns.iter().enumerate().take(n) {
                let a: Vec<u32> = (0..=cols)
                    .map(|j| dm_ref.revealer_vertex(r, i, j))
                    .collect();
                let b: Vec<u32> = (0..=cols)
                    .map(|j| dm_ref.revealer_vertex(r + 1, i, j))
                    .collect();
                let lens = LensRef::Revealer(i as i64);
                zip(
                    &a,
                    &b,
                    &|v| key_t(&dm_ref.origins[v as usize], lens),
                    false,
                    Patch::Lens(lens),
                    None,
                    (&mut t, &mut p),
                );
            }
            (t, p)
        })
        .collect();
    concat(revealer_parts, &mut tris, &mut patches);
    let revealer_triangles = tris.len();

    // base strips: per row pair in parallel
    let base_parts: Vec<Strip> = (0..base_row_data.len() - 1)
        .into_par_iter()
        .map(|r| {
            let (ra, rb) = (&base_row_data[r], &base_row_data[r + 1]);
            let (oa, ob) = (base_offsets[r], base_offsets[r + 1]);
            let (mut t, mut p) = (Vec::new(), Vec::new());
            let lenses: std::collections::BTreeSet<i64> = ra.lenses.keys().chain(rb.lenses.keys()).cloned().collect();
            for k in lenses {
                let (a, b) = match (ra.lenses.get(&k), rb.lenses.get(&k)) {
                    (Some(a), Some(b)) if a.len() > 1 || b.len() > 1 => (a, b),
                    (Some(a), None) | (None, Some(a)) if a.len() > 1 => {
                        return Err(KernelError::MeshCheck {
                            name: "base-crossings",
                            detail: format!("base lens {k} enters the outline between y = {} and {} without a crease crossing being found", base_rows[r], base_rows[r + 1]),
                        })
                    }
                    _ => continue,
                };
                let a: Vec<u32> = a.iter().map(|i| i + oa).collect();
                let b: Vec<u32> = b.iter().map(|i| i + ob).collect();
                let lens = LensRef::Base(k);
                zip(&a, &b, &|v| key_t(&dm_ref.origins[v as usize], lens), true, Patch::Lens(lens), None, (&mut t, &mut p));
            }
            Ok((t, p))
        })
        .collect::<Result<_>>()?;
    concat(base_parts, &mut tris, &mut patches);
    let base_triangles = tris.len() - revealer_triangles;

    // walls
    let pos = &dm.mesh.positions;
    let key_x = |v: u32| pos[v as usize].x;
    let key_y = |v: u32| pos[v as usize].y;
    let left_top: Vec<u32> = (0..=last_row)
        .map(|r| dm.revealer_vertex(r, 0, 0))
        .collect();
    let right_top: Vec<u32> = (0..=last_row)
        .map(|r| dm.revealer_vertex(r, n - 1, rev_columns[n - 1]))
        .collect();
    let left_bottom: Vec<u32> = base_row_data
        .iter()
        .zip(&base_offsets)
        .map(|(row, o)| row.ends.0 + o)
        .collect();
    let right_bottom: Vec<u32> = base_row_data
        .iter()
        .zip(&base_offsets)
        .map(|(row, o)| row.ends.1 + o)
        .collect();
    let front_top: Vec<u32> = (0..row_len as u32).collect();
    let back_top: Vec<u32> = (0..row_len as u32)
        .map(|c| c + (last_row * row_len) as u32)
        .collect();
    let row_span = |r: usize| {
        let row = &base_row_data[r];
        (row.ends.0..=row.ends.1)
            .map(|i| i + base_offsets[r])
            .collect::<Vec<u32>>()
    };
    let front_bottom = row_span(0);
    let back_bottom = row_span(base_row_data.len() - 1);
    zip(
        &left_bottom,
        &left_top,
        &key_y,
        true,
        Patch::Wall(Side::Left),
        Some((pos, DVec3::NEG_X)),
        (&mut tris, &mut patches),
    );
    zip(
        &right_bottom,
        &right_top,
        &key_y,
        false,
        Patch::Wall(Side::Right),
        Some((pos, DVec3::X)),
        (&mut tris, &mut patches),
    );
    zip(
        &front_bottom,
        &front_top,
        &key_x,
        false,
        Patch::Wall(Side::Front),
        Some((pos, DVec3::NEG_Y)),
        (&mut tris, &mut patches),
    );
    zip(
        &back_bottom,
        &back_top,
        &key_x,
        true,
        Patch::Wall(Side::Back),
        Some((pos, DVec3::Y)),
        (&mut tris, &mut patches),
    );
    let wall_triangles = tris.len() - revealer_triangles - base_triangles;
    progress.tick(1);

    let rev_cols_max = *rev_columns.iter().max().unwrap_or(&0);
    let base_cols_inside: Vec<usize> = base_columns.values().cloned().collect();
    let base_cols_max = *base_cols_inside.iter().max().unwrap_or(&0);
    let uniform_rev_rows = ((2.0 * hh) * (rev_kmax / (8.0 * ALONG_SHARE * planner.tol())).sqrt())
        .ceil()
        .max(1.0) as usize;
    let base_lenses_inside = base_row_data
        .iter()
        .map(|r| r.lenses.values().filter(|l| l.len() > 1).count())
        .max()
        .unwrap_or(0);
    dm.stats = MeshStats {
        triangles: tris.len(),
        vertices: dm.mesh.positions.len(),
        revealer_triangles,
        base_triangles,
        wall_triangles,
        revealer_rows: rev_rows.len(),
        base_rows: base_rows.len(),
        crossing_rows: crossings.len(),
        revealer_columns: (*rev_columns.iter().min().unwrap_or(&0), rev_cols_max),
        base_columns: (*base_cols_inside.iter().min().unwrap_or(&0), base_cols_max),
        uniform_triangles: 2 * n * rev_cols_max * uniform_rev_rows
            + 2 * base_lenses_inside * base_cols_max * uniform_base_rows
            + wall_triangles,
    };
    dm.mesh.triangles = tris;
    dm.patches = patches;
    Ok(dm)
}

/// Computes one base row at exact height y: crease vertices, cut vertices on
/// the x-walls and interior vertices, each solved onto its exact surface.
fn base_row(
    d: &Design,
    columns: &BTreeMap<i64, usize>,
    y: f64,
    xl: f64,
    xr: f64,
) -> Result<BaseRow> {
    let (k0, k1) = d.base_creases;
    // An interior vertex is on its exact surface at whatever station it is
    // evaluated; the residual only says how far it is from its row's plane.
    // That must be round-off on the wall rows y = ±H/2, while elsewhere a
    // nanometre changes nothing.
    let on_wall = y.abs() == d.half_height;
    let row_residual = if on_wall {
        SOLVE_RESIDUAL_MM
    } else {
        INTERIOR_ROW_RESIDUAL_MM
    };
    // crease vertices (k0..=k1), solved to lie at height y; neighbouring
    // creases have nearly the same station, so each starts from the last,
    // with its layout u predicted from the last solve
    let mut creases: Vec<(f64, DVec3)> = Vec::with_capacity((k1 - k0 + 1) as usize);
    let mut v_guess = y;
    let mut slope = None;
    for k in k0..=k1 {
        let mut u_near = None;
        let point = |v: f64, near: Option<f64>| -> Result<(DVec3, f64)> {
            let u = d.base_crease_u_near(k, v, near)?;
            Ok((d.base_surface(u, v), u))
        };
        let mut v = v_guess;
        let mut found = None;
        for _ in 0..40 {
            let (p, u) = point(v, u_near)?;
            u_near = Some(u);
            let r = p.y - y;
            if r.abs() <= SOLVE_RESIDUAL_MM {
                found = Some(p);
                break;
            }
            let dydv = match slope {
                Some(s) => s,
                None => {
                    let h = 1e-6;
                    let s = (point(v + h, u_near)?.0.y - point(v - h, u_near)?.0.y) / (2.0 * h);
                    slope = Some(s);
                    s
                }
            };
            v -= r / dydv;
        }
        let p = found.ok_or_else(|| KernelError::Solver(format!("base crease {k} at y = {y}")))?;
        v_guess = v;
        creases.push((v, p));
    }
    let crease = |k: i64| creases[(k - k0) as usize];
    let mut row = BaseRow {
        positions: Vec::new(),
        origins: Vec::new(),
        lenses: BTreeMap::new(),
        ends: (u32::MAX, 0),
    };
    let mut crease_index: BTreeMap<i64, u32> = BTreeMap::new();
    let push = |row: &mut BaseRow, p: DVec3, o: VertexOrigin| -> u32 {
        row.positions.push(p);
        row.origins.push(o);
        (row.positions.len() - 1) as u32
    };
    let snap = |x: f64, wall: f64| (x - wall).abs() <= WALL_SNAP_MM;
    for k in k0..k1 {
        let (c0, c1) = (crease(k), crease(k + 1));
        let (x0, x1) = (c0.1.x, c1.1.x);
        let mut crease_vertex = |row: &mut BaseRow, kk: i64| -> u32 {
            if let Some(&i) = crease_index.get(&kk) {
                return i;
            }
            let (v, p) = crease(kk);
            let i = push(row, p, VertexOrigin::BaseCrease { k: kk, v });
            crease_index.insert(kk, i);
            i
        };
        if x1 <= xl + WALL_SNAP_MM {
            if snap(x1, xl) {
                let i = crease_vertex(&mut row, k + 1);
                row.lenses.insert(k, vec![i]);
            }
            continue;
        }
        if x0 >= xr - WALL_SNAP_MM {
            if snap(x0, xr) {
                let i = crease_vertex(&mut row, k);
                row.lenses.insert(k, vec![i]);
            }
            continue;
        }
        let cols = *columns
            .get(&k)
            .ok_or_else(|| KernelError::Solver(format!("base lens {k} was not surveyed")))?;
        let cut = |wall: f64, t0: f64| -> Result<(DVec3, VertexOrigin, f64)> {
            let guess = DVec2::new(t0, 0.5 * (c0.0 + c1.0));
            let p = newton_2d(
                guess,
                &|| format!("base lens {k} meeting the wall x = {wall} at y = {y}"),
                |q| {
                    d.base_point(k, q.x, q.y)
                        .map(|p| DVec2::new(p.x - wall, p.y - y))
                        .unwrap_or(DVec2::NAN)
                },
            )?;
            let pt = d.base_point(k, p.x, p.y)?;
            Ok((pt, VertexOrigin::BaseLens { k, t: p.x, v: p.y }, p.x))
        };
        let mut poly = Vec::with_capacity(cols + 1);
        let t_lo = if x0 >= xl - WALL_SNAP_MM {
            poly.push(crease_vertex(&mut row, k));
            0.0
        } else {
            let (p, o, t) = cut(xl, (xl - x0) / (x1 - x0))?;
            poly.push(push(&mut row, p, o));
            t
        };
        let (right_cut, t_hi) = if x1 <= xr + WALL_SNAP_MM {
            (None, 1.0)
        } else {
            let (p, o, t) = cut(xr, (xr - x0) / (x1 - x0))?;
            (Some((p, o)), t)
        };
        // Columns closer than this to a cut are dropped (no slivers); the span
        // next to a cut is then at most 1.1 columns.
        let margin = 0.1 / cols as f64;
        // Interior vertices: solve the station v at which (t, v) has height y.
        // Three exact arcs around the middle station give, per column, a
        // quadratic model of y(v) that starts Newton within ~1e-8 mm, and a
        // linear predictor of the crease positions that warm-starts every
        // crease solve; then exact Newton steps to the solver residual.
        if poly.len() == 1 || t_hi - t_lo > 2.0 * margin {
            let vm = 0.5 * (c0.0 + c1.0);
            let hq = 0.05f64.min(d.params.period);
            let (am, u0m, u1m) = d.base_section_and_creases(k, vm, (None, None))?;
            let (ap, u0p, u1p) = d.base_section_and_creases(k, vm + hq, (Some(u0m), Some(u1m)))?;
            let (an, u0n, u1n) = d.base_section_and_creases(k, vm - hq, (Some(u0m), Some(u1m)))?;
            let (du0, du1) = ((u0p - u0n) / (2.0 * hq), (u1p - u1n) / (2.0 * hq));
            let predict = |v: f64| (Some(u0m + du0 * (v - vm)), Some(u1m + du1 * (v - vm)));
            for j in 1..cols {
                let t = j as f64 / cols as f64;
                if t <= t_lo + margin || t >= t_hi - margin {
                    continue;
                }
                let (yn, y0, yp) = (an.point(t).y, am.point(t).y, ap.point(t).y);
                let (jm, km) = ((yp - yn) / (2.0 * hq), (yp - 2.0 * y0 + yn) / (hq * hq));
                let mut dv = (y - y0) / jm;
                for _ in 0..3 {
                    dv -= (y0 + jm * dv + 0.5 * km * dv * dv - y) / (jm + km * dv);
                }
                let mut v = vm + dv;
                let mut found = None;
                for _ in 0..12 {
                    let p = d.base_section_near(k, v, predict(v))?.point(t);
                    let r = p.y - y;
                    if r.abs() <= row_residual {
                        found = Some(p);
                        break;
                    }
                    v -= r / (jm + km * (v - vm));
                }
                let p = found.ok_or_else(|| {
                    KernelError::Solver(format!("base lens {k} at t = {t}, y = {y}"))
                })?;
                poly.push(push(&mut row, p, VertexOrigin::BaseLens { k, t, v }));
            }
        }
        match right_cut {
            None => poly.push(crease_vertex(&mut row, k + 1)),
            Some((p, o)) => poly.push(push(&mut row, p, o)),
        }
        row.ends.0 = row.ends.0.min(poly[0]);
        row.ends.1 = row.ends.1.max(*poly.last().unwrap());
        row.lenses.insert(k, poly);
    }
    if row.ends.0 == u32::MAX {
        return Err(KernelError::MeshCheck {
            name: "base-row",
            detail: format!("no base lens lies inside the outline at y = {y}"),
        });
    }
    // vertices were pushed left to right, so the row's span is ends.0..=ends.1
    Ok(row)
}

#[cfg(test)]
mod tests {
    use super::insert_rows;

    #[test]
    fn crossing_rows_are_never_moved() {
        let mut rows = vec![-1.0, 0.0, 1.0];
        insert_rows(&mut rows, &[0.05, 0.09, -0.5]);
        assert_eq!(rows, vec![-1.0, -0.5, 0.05, 0.09, 1.0]);
    }
}
