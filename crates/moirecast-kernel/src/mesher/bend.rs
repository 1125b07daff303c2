//! Rows added where the planned rows miss the tolerance. The plan spaces
//! rows by curvature surveyed over cells of half a period or more; a
//! surface that bends within a cell is seen only in part
//! (found-769a4dace557b1fe: a formula's bump of σ = 1.6 mm under lenses
//! 6.9 mm wide on a layout 678 mm long missed the tolerance by 26 %).
//! These measure, on the rows that were placed, what the `surface-to-mesh`
//! check samples between two rows, and split the strips that miss.

use super::revealer::RevealerRow;
use crate::design::Design;
use crate::measure::closest_on_segment;
use crate::model::LensRef;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// Share of the tolerance by which a column's chord between two rows may
/// miss the exact surface at its middle before the strip is split: the
/// survey aims at [`super::plan::ALONG_SHARE`] (0.4, and crowding may add
/// 11 %), and the across share (0.45) must still fit beside it.
const COLUMN_SHARE: f64 = 0.5;

/// Share of the tolerance by which a diagonal may miss the exact surface
/// at its middle: there the across and along errors add (0.85 of the
/// tolerance by the plan's shares) with the twist, and the check allows
/// the whole tolerance.
const DIAGONAL_SHARE: f64 = 0.9;

/// Strips this thin (mm of station or height) are never split: a chord
/// this short cannot miss a smooth surface by a share of any tolerance.
pub(super) const MIN_SPLIT: f64 = 1e-4;

/// Times the rows are measured and split: each split quarters a strip's
/// chordal error.
pub(super) const MAX_BEND_PASSES: usize = 6;

/// A vertex of a strip between two rows: its lens parameters (t, v) and
/// its position.
#[derive(Clone, Copy)]
pub(super) struct Corner {
    pub params: DVec2,
    pub p: DVec3,
}

/// Whether the chord between column vertices `a` and `b` (the same t, on
/// neighbouring rows) misses `m`, the exact point at its middle's
/// parameters, by more than [`COLUMN_SHARE`] of the tolerance: measured as
/// the check does, from that point to the edge. `m` is None off the device.
pub(super) fn column_misses(d: &Design, m: Option<DVec3>, a: Corner, b: Corner) -> bool {
    m.is_some_and(|m| off_edge(m, a, b) > COLUMN_SHARE * d.tolerance.mm())
}

/// Whether either diagonal of the quad of columns `a0, a1` on one row and
/// `b0, b1` (the same t) on the next misses `m`, the exact point at the
/// quad's centre, by more than [`DIAGONAL_SHARE`] of the tolerance (the
/// zip may take either diagonal; their middles have the centre's
/// parameters up to the rows' spread in v).
pub(super) fn centre_misses(d: &Design, m: Option<DVec3>, [a0, a1, b0, b1]: [Corner; 4]) -> bool {
    m.is_some_and(|m| {
        off_edge(m, a0, b1).max(off_edge(m, a1, b0)) > DIAGONAL_SHARE * d.tolerance.mm()
    })
}

/// Distance from `m` to the edge between `a` and `b`.
fn off_edge(m: DVec3, a: Corner, b: Corner) -> f64 {
    m.distance(closest_on_segment(m, a.p, b.p))
}

/// `p`, if it lies on the device (inside the outline).
pub(super) fn on_device(d: &Design, p: DVec3) -> Option<DVec3> {
    let (xl, xr) = d.outline_x;
    (p.is_finite() && p.x >= xl && p.x <= xr && p.y.abs() <= d.half_height).then_some(p)
}

/// Stations of revealer rows to add (sorted): the middle of every strip
/// with a bent quad.
pub(super) fn revealer_rows(
    d: &Design,
    (stations, columns): (&[f64], &[usize]),
    rows: &[RevealerRow],
) -> Vec<f64> {
    let corner = |row: &RevealerRow, at: usize, lens: LensRef| {
        let (p, o) = row[at];
        o.params_on(lens).map(|params| Corner { params, p })
    };
    (0..rows.len() - 1)
        .into_par_iter()
        .filter_map(|r| {
            let (a, b) = (&rows[r], &rows[r + 1]);
            let (va, vb) = (stations[r], stations[r + 1]);
            if vb - va <= MIN_SPLIT {
                return None;
            }
            let mut first = 0;
            let bent = columns.iter().enumerate().any(|(i, &cols)| {
                let lens = LensRef::Revealer(i as i64);
                let exact = |q: DVec2| on_device(d, d.revealer_point(i as i64, q.x, q.y));
                let middle = |x: Corner, y: Corner| exact(0.5 * (x.params + y.params));
                let start = first;
                first += cols;
                (start..start + cols).any(|j| {
                    let quad = [(a, j), (a, j + 1), (b, j), (b, j + 1)]
                        .map(|(row, at)| corner(row, at, lens));
                    let [Some(a0), Some(a1), Some(b0), Some(b1)] = quad else {
                        return false;
                    };
                    let centre = 0.25 * (a0.params + a1.params + b0.params + b1.params);
                    column_misses(d, middle(a0, b0), a0, b0)
                        || (j + 1 == start + cols && column_misses(d, middle(a1, b1), a1, b1))
                        || centre_misses(d, exact(centre), [a0, a1, b0, b1])
                })
            });
            bent.then_some(0.5 * (va + vb))
        })
        .collect()
}
