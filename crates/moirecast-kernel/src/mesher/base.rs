//! The base: rows at exact heights y (every vertex solved onto its row),
//! per lens the columns that lie inside the outline; where an x-wall cuts a
//! base lens the cut vertex is solved onto the wall, and rows are added
//! until each trim edge meets the same chordal bound as the lens columns.

use super::bend::{self, Corner};
use super::plan::{MeshPlan, MERGE_CROSSING_MM};
use super::zip::{zip, Strip};
use crate::design::Design;
use crate::device_mesh::{DeviceMesh, Patch, Side, VertexOrigin};
use crate::error::{KernelError, Result};
use crate::model::{BaseSection, LensRef};
use crate::progress::Progress;
use crate::solve::{newton_1d, newton_2d};
use crate::tolerance::{SOLVE_RESIDUAL_MM, WALL_SNAP_MM};
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// How far (mm) an interior base vertex may lie from its row's plane y = const.
const INTERIOR_ROW_RESIDUAL_MM: f64 = 1e-6;

/// One base row: its vertices (left to right) and, per base lens, the
/// polyline of its vertices on this row.
pub(super) struct BaseRow {
    pub positions: Vec<DVec3>,
    pub origins: Vec<VertexOrigin>,
    /// Per lens k: None (absent) or local indices left to right (one index
    /// when the lens only touches the row at a crease on a wall).
    pub lenses: BTreeMap<i64, Vec<u32>>,
    /// Local indices of the leftmost and rightmost vertex.
    pub ends: (u32, u32),
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

/// Every base row, solved, with rows added where a wall's trim curve would
/// be too coarse: the row heights and their vertices, bottom to top.
pub(super) fn rows(
    d: &Design,
    plan: &MeshPlan,
    progress: &dyn Progress,
) -> Result<(Vec<f64>, Vec<BaseRow>)> {
    let (xl, xr) = d.outline_x;
    let base_columns = &plan.base_columns;
    let mut base_rows = plan.base_rows.clone();
    progress.stage("base vertices", base_rows.len() as u64);
    let compute_rows = |ys: &[f64]| -> Result<Vec<BaseRow>> {
        ys.par_iter()
            .map(|&y| {
                let row = base_row(d, base_columns, y, (xl, xr), &BTreeMap::new());
                progress.tick(1);
                row
            })
            .collect()
    };
    let mut base_row_data = compute_rows(&base_rows)?;
    // Where an x-wall cuts a base lens, the trim curve between two rows is
    // one edge: refine until its cut moves by at most one column per strip,
    // so the trim edge meets the same chordal bound as the lens columns.
    // A crease that crosses an x-wall and back within one survey cell was
    // missed by the plan: such a pair of rows disagrees on which lenses
    // are inside, and the crossings between them are found and added.
    for _pass in 0..8 {
        let mut extra = trim_rows(&base_rows, &base_row_data, base_columns);
        if extra.is_empty() {
            extra = missed_crossings(d, &base_rows, &base_row_data)?;
        }
        if extra.is_empty() {
            extra = bent_strips(d, &base_rows, &base_row_data);
        }
        if extra.is_empty() {
            break;
        }
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
    Ok((base_rows, base_row_data))
}

/// Heights y (sorted, distinct) where a base crease crosses an x-wall
/// between two rows that disagree on whether a lens is inside the
/// outline: found by sampling the crease's distance to each wall finely
/// over the stations that can reach between the rows.
fn missed_crossings(d: &Design, ys: &[f64], rows: &[BaseRow]) -> Result<Vec<f64>> {
    // a lens with two or more vertices on one row and none on the next
    // (what `strips` cannot zip)
    let unmatched = |a: &BaseRow, b: &BaseRow| -> Vec<i64> {
        a.lenses
            .iter()
            .filter(|(k, poly)| poly.len() > 1 && !b.lenses.contains_key(k))
            .map(|(&k, _)| k)
            .collect()
    };
    let mut found = Vec::new();
    for r in 0..rows.len() - 1 {
        let (y0, y1) = (ys[r], ys[r + 1]);
        let mut lenses = unmatched(&rows[r], &rows[r + 1]);
        lenses.extend(unmatched(&rows[r + 1], &rows[r]));
        for k in lenses {
            for crease in [k, k + 1] {
                for wall in [d.outline_x.0, d.outline_x.1] {
                    // the base lies up to the margin off its station in y
                    let wide = (y0 - d.margin, y1 + d.margin);
                    let coarse = crease_meets_wall(d, crease, wall, wide, (y0, y1))?;
                    // a crease that only grazes the wall dips past it over
                    // a stretch far shorter than the margin's samples
                    // (found-65c62ceab58111fa: 4 µm of v); the stations
                    // whose crease points lie between the rows are sampled
                    // as finely again, and what they add is kept where the
                    // coarse pass found nothing
                    if let Some(stations) = crease_stations(d, crease, y0, y1) {
                        for y in crease_meets_wall(d, crease, wall, stations, (y0, y1))? {
                            if coarse.iter().all(|c| (c - y).abs() > SAME_CROSSING_MM) {
                                found.push(y);
                            }
                        }
                    }
                    found.extend(coarse);
                }
            }
        }
    }
    found.sort_by(f64::total_cmp);
    found.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    Ok(found)
}

/// Two crossings of one crease and wall closer than this in y (mm) are one,
/// found from two brackets; where the crease grazes the wall the root's y
/// is only known to about the solver's residual over the crease's slant.
const SAME_CROSSING_MM: f64 = 1e-6;

/// The stations (v0 < v1) at which base crease `crease` reaches heights
/// y0 and y1, padded by a tenth of their span; `None` if either solve fails.
fn crease_stations(d: &Design, crease: i64, y0: f64, y1: f64) -> Option<(f64, f64)> {
    let station = |y: f64| {
        crate::solve::newton_1d(y, &String::new, |v| {
            d.base_crease_point(crease, v)
                .map(|p| p.y - y)
                .unwrap_or(f64::NAN)
        })
        .ok()
    };
    let (va, vb) = (station(y0)?, station(y1)?);
    let pad = 0.1 * (vb - va).abs();
    Some((va.min(vb) - pad, va.max(vb) + pad))
}

/// Heights strictly between `heights` at which base crease `crease`
/// crosses the wall x = `wall`, sampled over the stations `stations`.
fn crease_meets_wall(
    d: &Design,
    crease: i64,
    wall: f64,
    (v0, v1): (f64, f64),
    (y0, y1): (f64, f64),
) -> Result<Vec<f64>> {
    const SAMPLES: usize = 512;
    let g = |v: f64| {
        d.base_crease_point(crease, v)
            .map(|p| p.x - wall)
            .unwrap_or(f64::NAN)
    };
    let mut found = Vec::new();
    let mut last = g(v0);
    for i in 1..=SAMPLES {
        let v = v0 + (v1 - v0) * i as f64 / SAMPLES as f64;
        let here = g(v);
        if (last > 0.0) != (here > 0.0) && last.is_finite() && here.is_finite() {
            let root = crate::solve::bracketed_secant(
                v - (v1 - v0) / SAMPLES as f64,
                v,
                &|| format!("base crease {crease} meeting the wall x = {wall}"),
                g,
            )?;
            let y = d.base_crease_point(crease, root)?.y;
            if y > y0 + 1e-9 && y < y1 - 1e-9 {
                found.push(y);
            }
        }
        last = here;
    }
    Ok(found)
}

/// Heights of the rows to add (sorted): the middle of every strip in
/// which a lens's column edge or quad misses the exact base (see
/// [`super::bend`]). A lens's columns are matched between the two rows by
/// their t, so cut vertices on a wall are left out. A base point costs a
/// section solved between two creases, so each column's middle gets one,
/// and a quad's centre is read off its two columns' sections (their
/// stations differ by the row's spread in v over one column).
fn bent_strips(d: &Design, ys: &[f64], rows: &[BaseRow]) -> Vec<f64> {
    (0..rows.len() - 1)
        .into_par_iter()
        .filter(|&r| ys[r + 1] - ys[r] > bend::MIN_SPLIT)
        .filter(|&r| {
            let (a, b) = (&rows[r], &rows[r + 1]);
            a.lenses.iter().any(|(&k, column_a)| {
                let Some(column_b) = b.lenses.get(&k) else {
                    return false;
                };
                let lens = LensRef::Base(k);
                let corner = |row: &BaseRow, i: u32| {
                    let params = row.origins[i as usize].params_on(lens)?;
                    Some(Corner {
                        params,
                        p: row.positions[i as usize],
                    })
                };
                // both rows list the lens's columns left to right, in t
                let mut next_b = column_b.iter().filter_map(|&i| corner(b, i)).peekable();
                let pairs = column_a
                    .iter()
                    .filter_map(|&i| corner(a, i))
                    .filter_map(|ca| {
                        while next_b.next_if(|cb| cb.params.x < ca.params.x).is_some() {}
                        let cb = *next_b.peek()?;
                        (cb.params.x == ca.params.x).then_some((ca, cb))
                    });
                // each section's creases start from the last one's
                let mut near = (None, None);
                let mut last = None;
                for (ca, cb) in pairs {
                    let q = 0.5 * (ca.params + cb.params);
                    let Ok((section, u0, u1)) = d.base_section_and_creases(k, q.y, near) else {
                        last = None;
                        continue;
                    };
                    near = (Some(u0), Some(u1));
                    if bend::column_misses(d, bend::on_device(d, section.point(q.x)), ca, cb) {
                        return true;
                    }
                    if let Some((before, pa, pb)) = last.take() {
                        let (pa, pb): (Corner, Corner) = (pa, pb);
                        let t = 0.5 * (pa.params.x + ca.params.x);
                        let centre = 0.5 * (section.point(t) + BaseSection::point(&before, t));
                        if bend::centre_misses(d, bend::on_device(d, centre), [pa, ca, pb, cb]) {
                            return true;
                        }
                    }
                    last = Some((section, ca, cb));
                }
                false
            })
        })
        .map(|r| 0.5 * (ys[r] + ys[r + 1]))
        .collect()
}

/// Heights of the rows to add (sorted, distinct) so that, between two
/// rows, the cut of a base lens by an x-wall moves by at most one column.
fn trim_rows(
    base_rows: &[f64],
    base_row_data: &[BaseRow],
    base_columns: &BTreeMap<i64, usize>,
) -> Vec<f64> {
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
    extra.sort_by(f64::total_cmp);
    extra.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    extra
}

/// The base's triangles: each lens's strip between neighbouring rows,
/// row pairs in parallel. `offsets[r]` is the index of row r's first vertex.
pub(super) fn strips(
    dm: &DeviceMesh,
    base_rows: &[f64],
    rows: &[BaseRow],
    offsets: &[u32],
) -> Result<Vec<Strip>> {
    let key_t =
        |o: &VertexOrigin, lens: LensRef| o.params_on(lens).map(|p| p.x).unwrap_or(f64::NAN);
    (0..rows.len() - 1)
        .into_par_iter()
        .map(|r| {
            let (ra, rb) = (&rows[r], &rows[r + 1]);
            let (oa, ob) = (offsets[r], offsets[r + 1]);
            let (mut t, mut p) = (Vec::new(), Vec::new());
            let lenses: std::collections::BTreeSet<i64> =
                ra.lenses.keys().chain(rb.lenses.keys()).cloned().collect();
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
                zip(
                    &a,
                    &b,
                    &|v| key_t(&dm.origins[v as usize], lens),
                    true,
                    Patch::Lens(lens),
                    None,
                    (&mut t, &mut p),
                );
            }
            Ok((t, p))
        })
        .collect()
}

/// Samples along a lens for the start of a wall cut where a crease's x
/// is not known.
const CUT_SCAN: usize = 16;

/// Base row `r` (a wall row, y = ±H/2) solved again with vertices added
/// at the lens parameters `extra` (per lens k, sorted), beside its columns.
pub(super) fn wall_row_with(
    d: &Design,
    plan: &MeshPlan,
    y: f64,
    extra: &BTreeMap<i64, Vec<f64>>,
) -> Result<BaseRow> {
    base_row(d, &plan.base_columns, y, d.outline_x, extra)
}

/// Computes one base row at exact height y: crease vertices, cut vertices on
/// the x-walls and interior vertices, each solved onto its exact surface;
/// per lens k, vertices also at the parameters `extra[k]`.
fn base_row(
    d: &Design,
    columns: &BTreeMap<i64, usize>,
    y: f64,
    (xl, xr): (f64, f64),
    extra: &BTreeMap<i64, Vec<f64>>,
) -> Result<BaseRow> {
    let (k0, k1) = d.base_creases;
    let mut creases = row_creases(d, y)?;
    onto_near_crossings(d, y, &mut creases);
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
            let what = || format!("base lens {k} meeting the wall x = {wall} at y = {y}");
            // a crease beyond the extended layout has x = ±∞: the lens's
            // own points say where along it the wall is (found-
            // 2f6764c926fcd185: a base lens 7.4 mm wide reaching into a
            // layout 0.8 mm wide from beyond its margin)
            let t0 = if t0.is_finite() {
                t0
            } else {
                (0..=CUT_SCAN)
                    .map(|j| j as f64 / CUT_SCAN as f64)
                    .filter_map(|t| {
                        let x = d.base_point(k, t, y).ok()?.x;
                        x.is_finite().then_some(((x - wall).abs(), t))
                    })
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .map_or(0.5, |(_, t)| t)
            };
            let g = |q: DVec2| {
                d.base_point(k, q.x, q.y)
                    .map(|p| DVec2::new(p.x - wall, p.y - y))
                    .unwrap_or(DVec2::NAN)
            };
            // from the creases' mean station, else from the row's y and
            // from each crease's station: a lens 7 mm wide whose creases
            // solve to stations far apart can send Newton off from their
            // mean (found-2f6764c926fcd185)
            let p = [
                DVec2::new(t0, 0.5 * (c0.0 + c1.0)),
                DVec2::new(t0, y),
                DVec2::new(t0, c0.0),
                DVec2::new(t0, c1.0),
            ]
            .into_iter()
            .find_map(|guess| newton_2d(guess, &what, g).ok())
            .ok_or_else(|| KernelError::Solver(what()))?;
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
        let extra = extra.get(&k).map_or(&[][..], |ts| &ts[..]);
        let only_one = poly.len() == 1;
        for (p, o) in lens_interior(d, k, (c0.0, c1.0), (cols, extra), y, (t_lo, t_hi), only_one)? {
            poly.push(push(&mut row, p, o));
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

/// The base creases k0..=k1 at height y: each one's station and point,
/// solved onto the row.
fn row_creases(d: &Design, y: f64) -> Result<Vec<(f64, DVec3)>> {
    // crease vertices (k0..=k1), solved to lie at height y; neighbouring
    // creases have nearly the same station, so each starts from the last,
    // with its layout u predicted from the last solve
    let (k0, k1) = d.base_creases;
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
        let mut last_residual = f64::INFINITY;
        for _ in 0..40 {
            // beyond the extended layout the surface may not be defined
            // (a small sphere: found-85f5e81e0faf8692, a crease 14 periods
            // out stepped to v = NaN); the crease is outside there anyway
            let (p, u) = match point(v, u_near) {
                Ok((p, u)) if p.is_finite() => (p, u),
                Ok(_) | Err(_) if u_near.is_some_and(|u| d.beyond_extended_layout(u).is_some()) => {
                    break;
                }
                result => result?,
            };
            u_near = Some(u);
            let r = p.y - y;
            if r.abs() <= SOLVE_RESIDUAL_MM {
                found = Some(p);
                break;
            }
            // the slope is shared by the row's creases; where it no longer
            // fits this crease (the residual fell by less than half: a
            // surface whose dy/dv changes across the row), it is measured
            // again here
            if r.abs() > 0.5 * last_residual {
                slope = None;
            }
            last_residual = r.abs();
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
        // beyond the extended layout a crease is outside, on its side,
        // whether or not its row's height was found there
        let beyond = u_near.and_then(|u| d.beyond_extended_layout(u));
        let p = match (found, beyond) {
            (Some(p), None) => p,
            (Some(_), Some(side)) => DVec3::new(side, y, f64::NAN),
            (None, Some(side)) => {
                // the next crease starts from the last one solved
                slope = None;
                creases.push((v_guess, DVec3::new(side, y, f64::NAN)));
                continue;
            }
            (None, None) => return Err(KernelError::Solver(format!("base crease {k} at y = {y}"))),
        };
        v_guess = v;
        creases.push((v, p));
    }
    Ok(creases)
}

/// Moves each crease that crosses an x-wall less than
/// [`MERGE_CROSSING_MM`] from the interior row at height y onto its exact
/// crossing. The plan lets such a row stand for the crossing, and a steep
/// crease is then `slope × gap` from the wall, past the wall snap
/// (found-57d2c7c0717920f4: 40.3 nm at slope 3.9 and a gap of 10.3 nm);
/// its own row that far away would leave a strip as thin as the gap. The
/// vertex stays on its crease and on the wall, off the row's height by
/// the gap.
fn onto_near_crossings(d: &Design, y: f64, creases: &mut [(f64, DVec3)]) {
    if y.abs() >= d.half_height {
        // the outline's corners stay on the y-walls
        return;
    }
    let (k0, _) = d.base_creases;
    for (k, crease) in (k0..).zip(creases.iter_mut()) {
        let (v, p) = *crease;
        for wall in [d.outline_x.0, d.outline_x.1] {
            let gap = (p.x - wall).abs();
            if !(gap > WALL_SNAP_MM && gap <= CROSSING_REACH_MM) {
                continue;
            }
            let x_off = |v: f64| d.base_crease_point(k, v).map_or(f64::NAN, |q| q.x - wall);
            let Ok(vc) = newton_1d(v, &String::new, x_off) else {
                continue;
            };
            if let Ok(q) = d.base_crease_point(k, vc) {
                if (q.y - y).abs() < MERGE_CROSSING_MM {
                    *crease = (vc, q);
                }
            }
        }
    }
}

/// How far (mm) from a wall a crease on a row is looked at for a crossing
/// near the row: a crease leaving the wall 50,000 times faster in x than
/// in y still has its crossing within [`MERGE_CROSSING_MM`] seen.
const CROSSING_REACH_MM: f64 = 1e-3;

/// The interior vertices of base lens k on the row at height y, left to
/// right: its columns between the parameters `t_lo` and `t_hi` of its
/// ends on this row (a crease or a wall cut), whose creases lie at
/// stations `v0` and `v1`, and the parameters `extra` strictly between
/// those ends. `only_one`: the lens has a single vertex so far.
fn lens_interior(
    d: &Design,
    k: i64,
    (v0, v1): (f64, f64),
    (cols, extra): (usize, &[f64]),
    y: f64,
    (t_lo, t_hi): (f64, f64),
    only_one: bool,
) -> Result<Vec<(DVec3, VertexOrigin)>> {
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
    // Columns closer than this to a cut are dropped (no slivers); the span
    // next to a cut is then at most 1.1 columns.
    let margin = 0.1 / cols as f64;
    // Interior vertices: solve the station v at which (t, v) has height y.
    // Three exact arcs around the middle station give, per column, a
    // quadratic model of y(v) that starts Newton within ~1e-8 mm, and a
    // linear predictor of the crease positions that warm-starts every
    // crease solve; then exact Newton steps to the solver residual.
    let mut out = Vec::new();
    if only_one || t_hi - t_lo > 2.0 * margin {
        let vm = 0.5 * (v0 + v1);
        let hq = 0.05f64.min(d.params.period);
        let (am, u0m, u1m) = d.base_section_and_creases(k, vm, (None, None))?;
        let (ap, u0p, u1p) = d.base_section_and_creases(k, vm + hq, (Some(u0m), Some(u1m)))?;
        let (an, u0n, u1n) = d.base_section_and_creases(k, vm - hq, (Some(u0m), Some(u1m)))?;
        let (du0, du1) = ((u0p - u0n) / (2.0 * hq), (u1p - u1n) / (2.0 * hq));
        let predict = |v: f64| (Some(u0m + du0 * (v - vm)), Some(u1m + du1 * (v - vm)));
        let columns = (1..cols)
            .map(|j| j as f64 / cols as f64)
            .filter(|&t| t > t_lo + margin && t < t_hi - margin);
        let mut ts: Vec<f64> = columns
            .chain(extra.iter().copied().filter(|&t| t > t_lo && t < t_hi))
            .collect();
        ts.sort_by(f64::total_cmp);
        for t in ts {
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
            let (p, v) = match found {
                Some(p) => (p, v),
                // the quadratic model's slope led astray (stations that
                // crowd and spread within a few hq: found-b4638aa7d0cbda69): the
                // chord method, its slope measured where it stalls
                None => {
                    let what = || format!("base lens {k} at t = {t}, y = {y}");
                    let height = |v: f64| {
                        d.base_section_near(k, v, predict(v))
                            .map(|s| s.point(t).y - y)
                            .unwrap_or(f64::NAN)
                    };
                    let v = crate::solve::newton_1d(vm + dv, &what, height)?;
                    (d.base_section_near(k, v, predict(v))?.point(t), v)
                }
            };
            out.push((p, VertexOrigin::BaseLens { k, t, v }));
        }
    }
    Ok(out)
}
