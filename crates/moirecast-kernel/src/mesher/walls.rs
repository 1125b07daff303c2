//! The four vertical side walls (METHOD §5.3): planar strips zipped
//! between the device's top and bottom boundary polylines, which are the
//! revealer's and the base's own boundary vertices.

use super::base::BaseRow;
use super::zip::{zip, Strip};
use crate::check::{triangle_altitude, MIN_ALTITUDE_MM};
use crate::device_mesh::{DeviceMesh, Patch, Side};
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

/// Where the x-walls fold or fan into slivers: for every triangle of the
/// left or right wall whose normal points into the device, or that is
/// thinner than the degenerate-triangle check allows, the height y of its
/// edge on the base. A revealer row there gives the sparse top edge a
/// vertex near the wavy bottom one, so the zip can take only triangles
/// that face out, and fan two bottom vertices a few tens of nanometres
/// apart (a crease grazing the wall) from a vertex above them rather than
/// from one millimetres away (found-9e054658bb6abd84: 8.7 nm).
pub(super) fn folds(dm: &DeviceMesh, (tris, patches): &Strip) -> Vec<f64> {
    let pos = &dm.mesh.positions;
    let top = |v: u32| dm.origins[v as usize].is_revealer();
    let mut ys = Vec::new();
    for (t, patch) in tris.iter().zip(patches) {
        let outward = match patch {
            Patch::Wall(Side::Left) => DVec3::NEG_X,
            Patch::Wall(Side::Right) => DVec3::X,
            _ => continue,
        };
        let corners = t.map(|v| pos[v as usize]);
        let [a, b, c] = corners;
        let faces_out = (b - a).cross(c - a).dot(outward) > 0.0;
        if faces_out && triangle_altitude(corners) >= MIN_ALTITUDE_MM {
            continue;
        }
        let bottom: Vec<f64> = t
            .iter()
            .filter(|&&v| !top(v))
            .map(|&v| pos[v as usize].y)
            .collect();
        ys.push(bottom.iter().sum::<f64>() / bottom.len().max(1) as f64);
    }
    ys
}
