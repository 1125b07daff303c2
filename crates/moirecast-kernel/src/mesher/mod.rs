//! A mesher straight from the exact model (METHOD §5.1, §5.3).
//!
//! **Guarantees.** Every vertex lies on its exact surface (to the solver
//! residual); the mesh is closed and consistently oriented *by construction*,
//! because every vertex on a crease, a trim line or a wall is computed once
//! and shared by index; the triangle count is close to the fewest that meet
//! the tolerance, because rows and columns are spaced by the local curvature,
//! and rows are added where the placed ones, measured, still miss it
//! (`bend`).
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

mod base;
mod bend;
mod plan;
mod revealer;
mod walls;
mod zip;

use crate::design::Design;
use crate::error::Result;
use crate::progress::Progress;
use base::BaseRow;
use plan::{MeshPlan, ALONG_SHARE};
use revealer::RevealerRow;
use std::collections::BTreeMap;

pub use crate::device_mesh::{DeviceMesh, MeshStats, Patch, Side, VertexOrigin};

/// Builds the device mesh of `design`: plan the rows and columns, solve
/// the revealer's and the base's vertices, then zip the lens strips and
/// the walls between them.
pub fn mesh_device(design: &Design, progress: &dyn Progress) -> Result<DeviceMesh> {
    let stop = || match progress.cancelled() {
        true => Err(crate::KernelError::Cancelled),
        false => Ok(()),
    };
    let mut plan = plan::plan(design, progress)?;
    plan.within_budget(design)?;
    let estimated_peak_bytes =
        crate::MeshBudget::estimated_bytes(design, plan.estimated_triangles(design.lenses));
    stop()?;
    let mut revealer = revealer::vertices(design, &plan, progress)?;
    for _ in 0..bend::MAX_BEND_PASSES {
        let bent = bend::revealer_rows(
            design,
            (&plan.revealer_rows, &plan.revealer_columns),
            &revealer,
        );
        let before = plan.revealer_rows.len();
        plan.add_revealer_rows(&bent, design.half_height);
        if plan.revealer_rows.len() == before {
            break;
        }
        revealer = revealer::vertices(design, &plan, &crate::progress::Silent)?;
    }
    stop()?;
    let (base_ys, mut base_rows) = base::rows(design, &plan, progress)?;
    stop()?;
    progress.stage("triangles", 1);
    // Where an x-wall folds (a sparse revealer edge over a steep, wavy
    // base edge), revealer rows are added there and the top remade; where
    // a front or back wall folds (a sparse base edge under the wavy
    // revealer one), its base row gets vertices there and is solved again.
    let mut wall_row_extra: BTreeMap<usize, BTreeMap<i64, Vec<f64>>> = BTreeMap::new();
    for pass in 0.. {
        let (mut dm, base_offsets) = with_vertices(design, &plan, &revealer, &base_rows);
        let wall_part = walls::strips(&dm, &base_rows, &base_offsets);
        let folds = walls::folds(&dm, &wall_part);
        let under_creases = walls::base_vertices_under_creases(
            &dm,
            (&base_rows, &base_offsets),
            &walls::sparse_bottoms(&dm, &wall_part),
        );
        if (!folds.is_empty() || !under_creases.is_empty()) && pass < MAX_FOLD_PASSES {
            if !folds.is_empty() {
                plan.add_revealer_rows(&folds, design.half_height);
                revealer = revealer::vertices(design, &plan, &crate::progress::Silent)?;
            }
            for (r, k, t) in under_creases {
                let ts = wall_row_extra.entry(r).or_default().entry(k).or_default();
                ts.push(t);
                ts.sort_by(f64::total_cmp);
            }
            for (&r, extra) in &wall_row_extra {
                base_rows[r] = base::wall_row_with(design, &plan, base_ys[r], extra)?;
            }
            continue;
        }
        let revealer_parts = revealer::strips(&dm);
        let base_parts = base::strips(&dm, &base_ys, &base_rows, &base_offsets)?;
        progress.tick(1);
        let counts = [
            revealer_parts.iter().map(|s| s.0.len()).sum(),
            base_parts.iter().map(|s| s.0.len()).sum(),
            wall_part.0.len(),
        ];
        let (mut tris, mut patches) = (Vec::new(), Vec::new());
        for (t, p) in revealer_parts
            .into_iter()
            .chain(base_parts)
            .chain([wall_part])
        {
            tris.extend(t);
            patches.extend(p);
        }
        dm.stats = stats(
            design,
            &plan,
            (&base_ys, &base_rows),
            dm.mesh.positions.len(),
            counts,
        );
        dm.stats.estimated_peak_bytes = estimated_peak_bytes;
        dm.mesh.triangles = tris;
        dm.patches = patches;
        return Ok(dm);
    }
    unreachable!("the passes end")
}

/// Times revealer rows or base wall-row vertices are added where a wall
/// folds before the mesh is left to the `walls-face-out` check.
const MAX_FOLD_PASSES: usize = 8;

/// The mesh's vertices, revealer rows first, then the base rows; and the
/// index of each base row's first vertex.
fn with_vertices(
    design: &Design,
    plan: &MeshPlan,
    revealer: &[RevealerRow],
    base_rows: &[BaseRow],
) -> (DeviceMesh, Vec<u32>) {
    let hh = design.half_height;
    let row_len = plan.revealer_columns.iter().sum::<usize>() + 1;
    let rev_count = plan.revealer_rows.len() * row_len;
    let mut positions =
        Vec::with_capacity(rev_count + base_rows.iter().map(|r| r.positions.len()).sum::<usize>());
    let mut origins = Vec::with_capacity(positions.capacity());
    for row in revealer {
        for (p, o) in row {
            positions.push(*p);
            origins.push(*o);
        }
    }
    let mut base_offsets = Vec::with_capacity(base_rows.len());
    for row in base_rows {
        base_offsets.push(positions.len() as u32);
        positions.extend_from_slice(&row.positions);
        origins.extend_from_slice(&row.origins);
    }
    let last_row = plan.revealer_rows.len() - 1;
    let stations = plan
        .revealer_rows
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
        .collect();
    let dm = DeviceMesh::with_vertices(
        positions,
        origins,
        stations,
        plan.revealer_columns.clone(),
        plan.base_columns.clone(),
    );
    (dm, base_offsets)
}

/// The counts that describe the mesh, with the triangles a uniform grid
/// would need; `vertices` and `[revealer, base, wall]` triangles counted.
fn stats(
    design: &Design,
    plan: &MeshPlan,
    (base_ys, base_rows): (&[f64], &[BaseRow]),
    vertices: usize,
    [revealer_triangles, base_triangles, wall_triangles]: [usize; 3],
) -> MeshStats {
    let n = design.lenses;
    let hh = design.half_height;
    let tol = design.tolerance.mm();
    let rev_columns = &plan.revealer_columns;
    let rev_cols_max = *rev_columns.iter().max().unwrap_or(&0);
    let base_cols_inside: Vec<usize> = plan.base_columns.values().cloned().collect();
    let base_cols_max = *base_cols_inside.iter().max().unwrap_or(&0);
    let uniform_rev_rows = ((2.0 * hh) * (plan.revealer_kmax / (8.0 * ALONG_SHARE * tol)).sqrt())
        .ceil()
        .max(1.0) as usize;
    let base_lenses_inside = base_rows
        .iter()
        .map(|r| r.lenses.values().filter(|l| l.len() > 1).count())
        .max()
        .unwrap_or(0);
    MeshStats {
        triangles: revealer_triangles + base_triangles + wall_triangles,
        vertices,
        revealer_triangles,
        base_triangles,
        wall_triangles,
        revealer_rows: plan.revealer_rows.len(),
        base_rows: base_ys.len(),
        crossing_rows: plan.crossing_rows,
        revealer_columns: (*rev_columns.iter().min().unwrap_or(&0), rev_cols_max),
        base_columns: (*base_cols_inside.iter().min().unwrap_or(&0), base_cols_max),
        uniform_triangles: 2 * n * rev_cols_max * uniform_rev_rows
            + 2 * base_lenses_inside * base_cols_max * plan.uniform_base_rows
            + wall_triangles,
        estimated_peak_bytes: 0.0,
    }
}
