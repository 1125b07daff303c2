//! A mesh patch as a height map: a triangulated height field (a surface
//! exported from a CAD tool, the top of a scan) sampled along z onto a
//! grid over the layout, for [`crate::heightmap::HeightMap::fit`].
//!
//! Each sample is where the vertical line through it meets the patch. A
//! line that meets it at two heights (an overhang) or not at all (a hole,
//! or a patch short of the layout) is refused, with its place.

use crate::heightmap::HeightSamples;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use thiserror::Error;

/// One triangle of a patch (mm).
pub type Facet = [DVec3; 3];

/// Heights closer than this (mm) are one meeting: a line through an edge
/// or a vertex meets every triangle there at the same height, up to the
/// rounding of f32 vertices.
const SAME_HEIGHT_MM: f64 = 1e-5;

/// How far (in barycentric weight) outside a triangle a line may pass and
/// still count as meeting it: lines through shared edges meet both sides.
const EDGE_SLACK: f64 = 1e-9;

/// Why a patch is no height field over the layout.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum PatchError {
    #[error("it is no height field: at ({x:.2}, {y:.2}) mm a vertical line meets it at z = {low:.3} and at z = {high:.3} mm (an overhang)")]
    Overhang { x: f64, y: f64, low: f64, high: f64 },
    #[error("it leaves a gap at ({x:.2}, {y:.2}) mm over the layout (a hole, or a patch that does not reach there)")]
    Gap { x: f64, y: f64 },
    #[error("a vertex is not finite")]
    NotFinite,
}

/// The grid a patch is sampled on: `columns` × `rows` pixel centres over
/// `extent` (mm), centred on the origin, row 0 at the largest y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchGrid {
    pub columns: usize,
    pub rows: usize,
    pub extent: (f64, f64),
}

impl PatchGrid {
    /// A grid over a `width` × `height` mm layout, `spacing` mm apart at
    /// most, whose samples all lie on the layout.
    pub fn over(width: f64, height: f64, spacing: f64) -> PatchGrid {
        let (columns, rows) = (
            (width / spacing).ceil().max(1.0),
            (height / spacing).ceil().max(1.0),
        );
        PatchGrid {
            columns: columns as usize,
            rows: rows as usize,
            extent: (width, height),
        }
    }

    fn x(&self, i: usize) -> f64 {
        -self.extent.0 / 2.0 + (i as f64 + 0.5) * self.extent.0 / self.columns as f64
    }

    fn y(&self, j: usize) -> f64 {
        self.extent.1 / 2.0 - (j as f64 + 0.5) * self.extent.1 / self.rows as f64
    }
}

/// The heights of `facets` at `grid`'s samples; the first sample (row by
/// row) where the patch overhangs or leaves a gap, if any.
pub fn sample_patch(facets: &[Facet], grid: PatchGrid) -> Result<HeightSamples, PatchError> {
    if facets.iter().flatten().any(|p| !p.is_finite()) {
        return Err(PatchError::NotFinite);
    }
    // each row's facets: those whose y extent holds the row's y
    let dy = grid.extent.1 / grid.rows as f64;
    let mut by_row: Vec<Vec<usize>> = vec![Vec::new(); grid.rows];
    for (f, facet) in facets.iter().enumerate() {
        let (lo, hi) = facet
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.y), hi.max(p.y))
            });
        // row j's y falls from the top: j = (top − y)/dy − 1/2
        let row_of = |y: f64| (grid.extent.1 / 2.0 - y) / dy - 0.5;
        let (first, last) = (
            row_of(hi).ceil().max(0.0),
            row_of(lo).floor().min(grid.rows as f64 - 1.0),
        );
        if last >= first {
            for row in &mut by_row[first as usize..=last as usize] {
                row.push(f);
            }
        }
    }
    let rows: Vec<Result<Vec<f64>, PatchError>> = (0..grid.rows)
        .into_par_iter()
        .map(|j| sample_row(facets, &by_row[j], grid, j))
        .collect();
    let mut z = Vec::with_capacity(grid.columns * grid.rows);
    for row in rows {
        z.extend(row?);
    }
    Ok(HeightSamples {
        columns: grid.columns,
        rows: grid.rows,
        z,
        extent: grid.extent,
    })
}

/// Row `j`'s heights from the facets that reach it.
fn sample_row(
    facets: &[Facet],
    reach: &[usize],
    grid: PatchGrid,
    j: usize,
) -> Result<Vec<f64>, PatchError> {
    let y = grid.y(j);
    let dx = grid.extent.0 / grid.columns as f64;
    let mut met: Vec<Option<f64>> = vec![None; grid.columns];
    for &f in reach {
        let [a, b, c] = facets[f];
        let (a2, b2, c2) = (a.truncate(), b.truncate(), c.truncate());
        let area = (b2 - a2).perp_dot(c2 - a2);
        if area.abs() < f64::EPSILON * (b2 - a2).length_squared().max(1e-30) {
            continue; // vertical or degenerate: it covers no area of the grid
        }
        let (lo, hi) = (a2.x.min(b2.x).min(c2.x), a2.x.max(b2.x).max(c2.x));
        let first = ((lo + grid.extent.0 / 2.0) / dx - 0.5).ceil().max(0.0) as usize;
        let last = ((hi + grid.extent.0 / 2.0) / dx - 0.5).floor();
        if last < 0.0 {
            continue;
        }
        let end = (last as usize).min(grid.columns - 1);
        for (i, slot) in met.iter_mut().enumerate().take(end + 1).skip(first) {
            let q = DVec2::new(grid.x(i), y);
            let (wb, wc) = (
                (q - a2).perp_dot(c2 - a2) / area,
                (b2 - a2).perp_dot(q - a2) / area,
            );
            let wa = 1.0 - wb - wc;
            if wa < -EDGE_SLACK || wb < -EDGE_SLACK || wc < -EDGE_SLACK {
                continue;
            }
            let h = wa * a.z + wb * b.z + wc * c.z;
            match *slot {
                None => *slot = Some(h),
                Some(other) if (other - h).abs() > SAME_HEIGHT_MM => {
                    return Err(PatchError::Overhang {
                        x: q.x,
                        y,
                        low: other.min(h),
                        high: other.max(h),
                    })
                }
                Some(_) => {}
            }
        }
    }
    met.iter()
        .enumerate()
        .map(|(i, h)| h.ok_or(PatchError::Gap { x: grid.x(i), y }))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of `n` × `n` squares over `size` mm, two triangles each, at
    /// heights `f`.
    fn patch(n: usize, size: f64, f: impl Fn(f64, f64) -> f64) -> Vec<Facet> {
        let at = |i: usize, j: usize| {
            let (x, y) = (
                -size / 2.0 + size * i as f64 / n as f64,
                -size / 2.0 + size * j as f64 / n as f64,
            );
            DVec3::new(x, y, f(x, y))
        };
        (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .flat_map(|(i, j)| {
                [
                    [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                    [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
                ]
            })
            .collect()
    }

    #[test]
    fn a_plane_patch_gives_its_heights_at_every_sample() {
        let facets = patch(10, 20.0, |x, y| 0.1 * x - 0.2 * y + 3.0);
        let grid = PatchGrid::over(12.0, 8.0, 0.5);
        let s = sample_patch(&facets, grid).unwrap();
        assert_eq!((s.columns, s.rows), (24, 16));
        // row 0 is the top: y = 4 − 0.25
        assert!(
            (s.z[0] - (0.1 * -5.75 - 0.2 * 3.75 + 3.0)).abs() < 1e-9,
            "{}",
            s.z[0]
        );
        assert!(s.z.iter().all(|z| z.is_finite()));
    }

    #[test]
    fn overhangs_holes_and_short_patches_are_refused_with_their_place() {
        let grid = PatchGrid::over(10.0, 10.0, 0.5);
        let mut folded = patch(4, 20.0, |_, _| 0.0);
        folded.push([
            DVec3::new(-1.0, -1.0, 2.0),
            DVec3::new(1.0, -1.0, 2.0),
            DVec3::new(0.0, 1.0, 2.0),
        ]);
        let e = sample_patch(&folded, grid).unwrap_err();
        assert!(
            matches!(e, PatchError::Overhang { low, high, .. } if low == 0.0 && high == 2.0),
            "{e}"
        );
        let mut holed = patch(8, 20.0, |_, _| 0.0);
        holed.retain(|f| !f.iter().all(|p| p.x.abs() <= 2.6 && p.y.abs() <= 2.6));
        assert!(
            matches!(sample_patch(&holed, grid).unwrap_err(), PatchError::Gap { x, y } if x.abs() < 2.6 && y.abs() < 2.6)
        );
        let short = patch(4, 8.0, |_, _| 0.0);
        assert!(matches!(
            sample_patch(&short, grid).unwrap_err(),
            PatchError::Gap { .. }
        ));
        let mut nan = patch(2, 20.0, |_, _| 0.0);
        nan[0][1].z = f64::NAN;
        assert_eq!(sample_patch(&nan, grid).unwrap_err(), PatchError::NotFinite);
    }
}
