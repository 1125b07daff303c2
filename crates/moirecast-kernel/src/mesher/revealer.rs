//! The revealer: per lens, columns uniform in arc angle; rows at stations,
//! so every interior row is an exact lens arc, plus two boundary rows
//! solved onto the walls y = ±H/2.

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
    let rev_vertices: Vec<RevealerRow> = rev_rows
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
    Ok(rev_vertices)
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
