//! Triangulating the strip between two polylines: lens strips between
//! neighbouring rows, and the planar walls between the device's top and
//! bottom edges.

use crate::check::{triangle_altitude, MIN_ALTITUDE_MM};
use crate::device_mesh::Patch;
use glam::DVec3;

/// A wall triangle thinner than this (mm) is avoided where the zip has a
/// thicker choice: four times [`MIN_ALTITUDE_MM`], as the mold halves the
/// wall's rungs at mid-height and fans to those points at an angle (the
/// same margin as [`crate::tolerance::WALL_SNAP_MM`]).
const WALL_SLIVER_MM: f64 = 4.0 * MIN_ALTITUDE_MM;

/// Triangles and the face each belongs to, in order.
pub(super) type Strip = (Vec<[u32; 3]>, Vec<Patch>);

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
pub(super) fn zip(
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
            // the preferred triangle's short edge, fanned instead from the
            // next vertex of the other side: deferring it only helps if that
            // cures the sliver. A deferral that is merely a little thicker
            // repeats to the strip's far end and fans the edge from there
            // (found-986991dc2071040e), folded over the whole strip when the
            // edge slants (found-a83422ce812e1630: each vertex further along
            // 1 % thicker, up to the edge's own 37 nm)
            let deferred = if nearer {
                [a[i], a[i + 1], b[j + 1]]
            } else {
                [a[i + 1], b[j + 1], b[j]]
            };
            // below the check's own limit, any deferral that clears it
            // helps: where the wavy edge ends 25 nm from the strip's end,
            // both are slivers (found-2450659d01e6e5a6: 9.985 nm preferred,
            // the corner's 25 nm deferred)
            let cures = |floor: f64| thin < floor && thickness(deferred) >= floor;
            let sliver =
                thickness(other) > thin && (cures(WALL_SLIVER_MM) || cures(MIN_ALTITUDE_MM));
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
