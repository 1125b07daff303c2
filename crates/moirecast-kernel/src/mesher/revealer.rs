//! The revealer: per lens, columns uniform in arc angle; rows at stations,
//! so every interior row is an exact lens arc, plus two boundary rows
//! solved onto the walls y = ±H/2.
//!
//! Where a lens leans in y by more than the first row spacing (a surface
//! sloping along v near a wall, its normal leaning the bulge toward the
//! wall), the exact arcs of the first rows would reach past the wall row.
//! Those rows are solved onto heights between the wall and the first row
//! that clears it, column by column ([`blend_edge_rows`]): they are on the
//! lens, but no arcs of one station.

use super::plan::MeshPlan;
use super::zip::{zip, Strip};
use crate::design::Design;
use crate::device_mesh::{DeviceMesh, Patch, VertexOrigin};
use crate::error::{KernelError, Result};
use crate::model::LensRef;
use crate::progress::Progress;
use glam::DVec3;
use rayon::prelude::*;

/// One row of revealer vertices, lens after lens, creases shared.
pub(super) type RevealerRow = Vec<(DVec3, VertexOrigin)>;

/// Every revealer vertex, row by row, solved on its exact lens; the rows
/// must not cross.
pub(super) fn vertices(
    d: &Design,
    plan: &MeshPlan,
    progress: &dyn Progress,
) -> Result<Vec<RevealerRow>> {
    let n = d.lenses;
    let hh = d.half_height;
    let (rev_rows, rev_columns) = (&plan.revealer_rows, &plan.revealer_columns);
    let row_len = rev_columns.iter().sum::<usize>() + 1;
    let last_row = rev_rows.len() - 1;
    progress.stage("revealer vertices", rev_rows.len() as u64);
    let mut rev_vertices: Vec<RevealerRow> = rev_rows
        .par_iter()
        .enumerate()
        .map(|(r, &v)| {
            // the wall rows are solved onto y = ±H/2, the others are arcs
            let row = if r == 0 || r == last_row {
                let y = if r == 0 { -hh } else { hh };
                row_onto(d, rev_columns, v, |_| y)?
            } else {
                let mut out = Vec::with_capacity(row_len);
                for (i, &cols) in rev_columns.iter().enumerate().take(n) {
                    let arc = d.revealer_arc(i as i64, v);
                    let first = if i == 0 { 0 } else { 1 };
                    for j in first..=cols {
                        let t = j as f64 / cols as f64;
                        out.push((arc.point(t), origin(i, j, cols, t, v)));
                    }
                }
                out
            };
            progress.tick(1);
            Ok(row)
        })
        .collect::<Result<_>>()?;
    blend_edge_rows(d, plan, &mut rev_vertices)?;
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
    Ok(rev_vertices)
}

/// How far the lowest point of a station row must clear the wall row (as
/// a share of how far its creases clear it) to stay an exact arc: a row
/// leaning closer would make slivers, or cross the wall row.
const CLEAR_SHARE: f64 = 0.1;

/// Re-solves the rows next to each wall row whose lens leans past it (or
/// within [`CLEAR_SHARE`] of it): each column of such a row goes onto a
/// height evenly between the wall and the same column of the first row that
/// clears it (found-5ccf2202e1fe4549: a lens leaning 0.027 mm in y against
/// a first spacing of 0.0257 mm). Every strip is then no wider, column by
/// column, than the planned spacing at the creases.
///
/// Likewise the rows the plan put in where the lenses' middles reach a
/// whole spacing past a wall row (`revealer_edge_blend`): the first row
/// at or past its station is the row they blend to.
fn blend_edge_rows(d: &Design, plan: &MeshPlan, vertices: &mut [RevealerRow]) -> Result<()> {
    let (rows, columns) = (&plan.revealer_rows, &plan.revealer_columns);
    let last = vertices.len() - 1;
    if last < 2 {
        return Ok(());
    }
    let hh = d.half_height;
    // whether a row lies inside the wall at `wall` (inward: the side the
    // layout is on), its nearest point at least CLEAR_SHARE as far from it
    // as its nearest crease
    let clears = |row: &RevealerRow, wall: f64, inward: f64| {
        let mut nearest = f64::INFINITY;
        let mut crease = f64::INFINITY;
        for (p, o) in row {
            let away = (p.y - wall) * inward;
            nearest = nearest.min(away);
            if matches!(o, VertexOrigin::RevealerCrease { .. }) {
                crease = crease.min(away);
            }
        }
        nearest > 0.0 && nearest >= CLEAR_SHARE * crease
    };
    let (blend_low, blend_high) = plan.revealer_edge_blend;
    let low = (1..last)
        .find(|&r| clears(&vertices[r], -hh, 1.0) && blend_low.is_none_or(|v| rows[r] >= v));
    let high = (1..last)
        .rev()
        .find(|&r| clears(&vertices[r], hh, -1.0) && blend_high.is_none_or(|v| rows[r] <= v));
    let (Some(low), Some(high)) = (low, high) else {
        return Ok(());
    };
    if low >= high {
        return Ok(());
    }
    for (wall, wall_row, clear_row) in [(-hh, 0, low), (hh, last, high)] {
        let steps = wall_row.abs_diff(clear_row);
        for k in 1..steps {
            let r = if wall_row == 0 { k } else { last - k };
            let share = k as f64 / steps as f64;
            let targets: Vec<f64> = vertices[clear_row]
                .iter()
                .map(|p| wall + share * (p.0.y - wall))
                .collect();
            vertices[r] = row_onto(d, columns, rows[r], |c| targets[c])?;
        }
    }
    Ok(())
}

/// A revealer row with each column c solved onto height `y(c)`, starting
/// from station `v`.
fn row_onto(
    d: &Design,
    columns: &[usize],
    v: f64,
    y: impl Fn(usize) -> f64,
) -> Result<RevealerRow> {
    let mut out = Vec::with_capacity(columns.iter().sum::<usize>() + 1);
    for (i, &cols) in columns.iter().enumerate().take(d.lenses) {
        let first = if i == 0 { 0 } else { 1 };
        for j in first..=cols {
            let t = j as f64 / cols as f64;
            let vv = d.solve_station_for_y(LensRef::Revealer(i as i64), t, y(out.len()), v)?;
            out.push((d.revealer_point(i as i64, t, vv), origin(i, j, cols, t, vv)));
        }
    }
    Ok(out)
}

/// The origin of column j of lens i's `cols`, at (t, v).
fn origin(i: usize, j: usize, cols: usize, t: f64, v: f64) -> VertexOrigin {
    if j == 0 {
        VertexOrigin::RevealerCrease { i: i as i64, v }
    } else if j == cols {
        VertexOrigin::RevealerCrease { i: i as i64 + 1, v }
    } else {
        VertexOrigin::RevealerLens { i: i as i64, t, v }
    }
}

/// The revealer's triangles: each lens's strip between neighbouring rows,
/// rows in parallel, concatenated in row order.
pub(super) fn strips(dm: &DeviceMesh) -> Vec<Strip> {
    let key_t =
        |o: &VertexOrigin, lens: LensRef| o.params_on(lens).map(|p| p.x).unwrap_or(f64::NAN);
    let last_row = dm.revealer_rows.len() - 1;
    (0..last_row)
        .into_par_iter()
        .map(|r| {
            let (mut t, mut p) = (Vec::new(), Vec::new());
            for (i, &cols) in dm.revealer_columns.iter().enumerate() {
                let a: Vec<u32> = (0..=cols).map(|j| dm.revealer_vertex(r, i, j)).collect();
                let b: Vec<u32> = (0..=cols)
                    .map(|j| dm.revealer_vertex(r + 1, i, j))
                    .collect();
                let lens = LensRef::Revealer(i as i64);
                zip(
                    &a,
                    &b,
                    &|v| key_t(&dm.origins[v as usize], lens),
                    false,
                    Patch::Lens(lens),
                    None,
                    (&mut t, &mut p),
                );
            }
            (t, p)
        })
        .collect()
}
