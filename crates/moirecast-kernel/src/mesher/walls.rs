//! The four vertical side walls (METHOD §5.3): planar strips zipped
//! between the device's top and bottom boundary polylines, which are the
//! revealer's and the base's own boundary vertices.

use super::base::BaseRow;
use super::zip::{zip, Strip};
use crate::check::{triangle_altitude, MIN_ALTITUDE_MM};
use crate::device_mesh::{DeviceMesh, Patch, Side};
use crate::model::LensRef;
use glam::DVec3;

/// The walls' triangles, in the order left, right, front, back.
pub(super) fn strips(dm: &DeviceMesh, base_rows: &[BaseRow], base_offsets: &[u32]) -> Strip {
    let (mut tris, mut patches) = (Vec::new(), Vec::new());
    let pos = &dm.mesh.positions;
    let key_x = |v: u32| pos[v as usize].x;
    let key_y = |v: u32| pos[v as usize].y;
    let last_row = dm.revealer_rows.len() - 1;
    let n = dm.revealer_columns.len();
    let row_len = dm.revealer_row_len();
    let left_top: Vec<u32> = (0..=last_row)
        .map(|r| dm.revealer_vertex(r, 0, 0))
        .collect();
    let right_top: Vec<u32> = (0..=last_row)
        .map(|r| dm.revealer_vertex(r, n - 1, dm.revealer_columns[n - 1]))
        .collect();
    let left_bottom: Vec<u32> = base_rows
        .iter()
        .zip(base_offsets)
        .map(|(row, o)| row.ends.0 + o)
        .collect();
    let right_bottom: Vec<u32> = base_rows
        .iter()
        .zip(base_offsets)
        .map(|(row, o)| row.ends.1 + o)
        .collect();
    let front_top: Vec<u32> = (0..row_len as u32).collect();
    let back_top: Vec<u32> = (0..row_len as u32)
        .map(|c| c + (last_row * row_len) as u32)
        .collect();
    let row_span = |r: usize| {
        let row = &base_rows[r];
        (row.ends.0..=row.ends.1)
            .map(|i| i + base_offsets[r])
            .collect::<Vec<u32>>()
    };
    let front_bottom = row_span(0);
    let back_bottom = row_span(base_rows.len() - 1);
    for (bottom, top, key, flip, side, outward) in [
        (
            &left_bottom,
            &left_top,
            &key_y as &dyn Fn(u32) -> f64,
            true,
            Side::Left,
            DVec3::NEG_X,
        ),
        (
            &right_bottom,
            &right_top,
            &key_y,
            false,
            Side::Right,
            DVec3::X,
        ),
        (
            &front_bottom,
            &front_top,
            &key_x,
            false,
            Side::Front,
            DVec3::NEG_Y,
        ),
        (&back_bottom, &back_top, &key_x, true, Side::Back, DVec3::Y),
    ] {
        zip(
            bottom,
            top,
            key,
            flip,
            Patch::Wall(side),
            Some((pos, outward)),
            (&mut tris, &mut patches),
        );
    }
    (tris, patches)
}

/// The wall triangles that fold or are slivers: each one's side, with
/// its corners split into those on the revealer (top) and on the base.
/// A triangle folds when its normal points into the device, and is a
/// sliver when it is thinner than the degenerate-triangle check allows.
fn defects<'a>(
    dm: &'a DeviceMesh,
    (tris, patches): &'a Strip,
) -> impl Iterator<Item = (Side, Vec<DVec3>, Vec<DVec3>)> + 'a {
    let pos = &dm.mesh.positions;
    tris.iter().zip(patches).filter_map(move |(t, patch)| {
        let Patch::Wall(side) = *patch else {
            return None;
        };
        let outward = match side {
            Side::Left => DVec3::NEG_X,
            Side::Right => DVec3::X,
            Side::Front => DVec3::NEG_Y,
            Side::Back => DVec3::Y,
        };
        let corners = t.map(|v| pos[v as usize]);
        let [a, b, c] = corners;
        let faces_out = (b - a).cross(c - a).dot(outward) > 0.0;
        if faces_out && triangle_altitude(corners) >= MIN_ALTITUDE_MM {
            return None;
        }
        let (top, bottom): (Vec<u32>, Vec<u32>) = t
            .iter()
            .partition(|&&v| dm.origins[v as usize].is_revealer());
        let at = |vs: Vec<u32>| vs.into_iter().map(|v| pos[v as usize]).collect();
        Some((side, at(top), at(bottom)))
    })
}

/// Where the x-walls fold or fan into slivers: for every triangle of the
/// left or right wall whose normal points into the device, or that is
/// thinner than the degenerate-triangle check allows, the height y of its
/// edge on the base. A revealer row there gives the sparse top edge a
/// vertex near the wavy bottom one, so the zip can take only triangles
/// that face out, and fan two bottom vertices a few tens of nanometres
/// apart (a crease grazing the wall) from a vertex above them rather than
/// from one millimetres away (found-9e054658bb6abd84: 8.7 nm).
pub(super) fn folds(dm: &DeviceMesh, strip: &Strip) -> Vec<f64> {
    defects(dm, strip)
        .filter(|(side, ..)| matches!(side, Side::Left | Side::Right))
        .map(|(_, _, bottom)| bottom.iter().map(|p| p.y).sum::<f64>() / bottom.len().max(1) as f64)
        .collect()
}

/// The mirror of [`folds`] for the front and back walls, whose *bottom*
/// edge can be the sparse one: a printed base's flat band, or a base lens
/// stretched where the profile's slope nearly cancels the period, leaves
/// the wall's base row without a vertex for tens of millimetres, and the
/// zip fans the revealer's wavy edge from its far end, folded
/// (found-9b9a24a46a9dbb23: 13 lenses fanned from a corner 32 mm away). For
/// every such triangle, its side and the x where the base edge needs a
/// vertex: under its revealer edge, or between its two base vertices.
pub(super) fn sparse_bottoms(dm: &DeviceMesh, strip: &Strip) -> Vec<(Side, f64)> {
    defects(dm, strip)
        .filter(|(side, ..)| matches!(side, Side::Front | Side::Back))
        .map(|(side, top, bottom)| {
            let edge = if top.len() == 2 { top } else { bottom };
            (
                side,
                edge.iter().map(|p| p.x).sum::<f64>() / edge.len() as f64,
            )
        })
        .collect()
}

/// A base vertex nearer than this (mm) to the x of a revealer crease
/// stands for the vertex under it. Fanned from a base vertex s off the
/// crease, the steep arc beside it (slope up to about 2 at the widest
/// AFOV) drops 2s below the crease, and the wall there is at least the
/// printed base's depth (about 10 µm) high: 1 µm keeps every such
/// triangle facing out, and a base edge 1 µm long fans into triangles
/// hundreds of times thicker than [`MIN_ALTITUDE_MM`].
const UNDER_CREASE_MM: f64 = 1e-3;

/// Lens parameters to add to the base's wall rows where the front or back
/// wall folds or fans into slivers (`sparse`, from [`sparse_bottoms`]):
/// on that wall, one base vertex under every revealer crease of its top
/// edge that has none within [`UNDER_CREASE_MM`]. Below a crease, every
/// triangle fanned over the convex lens arcs on either side faces out.
/// Every crease, not only those near a defect: where the wall is a few
/// µm high and the surface slopes, a lens span with no base vertex under
/// it sends the zip out of step for millimetres, and its folds show far
/// from their cause (found-ec8e1532e484370a: 2.5 mm, 0.83 nm slivers).
/// Returned as (base row, base lens k, parameter t), t interpolated along
/// the base edge's segment under the crease; the vertex is then solved
/// onto the lens at that t, exactly.
pub(super) fn base_vertices_under_creases(
    dm: &DeviceMesh,
    (base_rows, base_offsets): (&[BaseRow], &[u32]),
    sparse: &[(Side, f64)],
) -> Vec<(usize, i64, f64)> {
    let pos = &dm.mesh.positions;
    let last_row = dm.revealer_rows.len() - 1;
    let mut added = Vec::new();
    for side in [Side::Front, Side::Back] {
        if !sparse.iter().any(|&(s, _)| s == side) {
            continue;
        }
        let (r, top_row) = match side {
            Side::Front => (0, 0),
            _ => (base_rows.len() - 1, last_row),
        };
        let row = &base_rows[r];
        let at = |i: u32| (i + base_offsets[r]) as usize;
        for lens_i in 0..dm.revealer_columns.len() {
            let xc = pos[dm.revealer_vertex(top_row, lens_i, 0) as usize].x;
            let segment = row.lenses.iter().find_map(|(&k, poly)| {
                poly.windows(2).find_map(|w| {
                    let (xa, xb) = (pos[at(w[0])].x, pos[at(w[1])].x);
                    (xa <= xc && xc <= xb).then_some((k, w[0], w[1], xa, xb))
                })
            });
            let Some((k, ia, ib, xa, xb)) = segment else {
                continue;
            };
            if xc <= xa + UNDER_CREASE_MM || xc >= xb - UNDER_CREASE_MM {
                continue;
            }
            let lens = LensRef::Base(k);
            let t = |i: u32| dm.origins[at(i)].params_on(lens).map(|p| p.x);
            if let (Some(ta), Some(tb)) = (t(ia), t(ib)) {
                added.push((r, k, ta + (xc - xa) / (xb - xa) * (tb - ta)));
            }
        }
    }
    added.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)).then(a.2.total_cmp(&b.2)));
    added.dedup_by(|a, b| (a.0, a.1) == (b.0, b.1) && (a.2 - b.2).abs() < 1e-12);
    added
}
