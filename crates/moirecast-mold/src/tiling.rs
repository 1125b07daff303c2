//! The exact no-overlap certificate of the halves before their channels
//! (METHOD §7.5): closed, oriented parts whose faces cancel in pairs (each
//! face of one part is a face of another, reversed) but for faces that
//! cover the block's boundary once, facing out, tile the block. The sum of
//! their boundaries is the block's boundary, so the sum of their winding
//! numbers is the block's; each is 0 or 1 for a solid, so no point is inside
//! two parts. This needs no boolean, and it is exact: faces are compared by
//! their vertices' bits.

use glam::DVec3;
use moirecast_kernel::check::CheckResult;
use moirecast_kernel::Mesh;
use rayon::prelude::*;

/// Area (relative to the block's surface) the uncovered or doubly covered
/// boundary may have: the sum of many triangles' areas rounds.
const AREA_REL: f64 = 1e-9;

/// Whether `parts` tile the box `block` (lowest, highest corner).
pub fn tiles_block(parts: &[&Mesh], block: (DVec3, DVec3)) -> CheckResult {
    // One index per distinct position across all parts: sort them all.
    let mut keyed: Vec<([u64; 3], u32, u32)> = parts
        .iter()
        .enumerate()
        .flat_map(|(k, m)| {
            m.positions.iter().enumerate().map(move |(i, p)| {
                (
                    p.to_array().map(|c| (c + 0.0).to_bits()),
                    k as u32,
                    i as u32,
                )
            })
        })
        .collect();
    keyed.par_sort_unstable();
    let mut ids: Vec<Vec<u32>> = parts.iter().map(|m| vec![0; m.positions.len()]).collect();
    let mut positions: Vec<DVec3> = Vec::new();
    for (k, &(key, part, local)) in keyed.iter().enumerate() {
        if k == 0 || keyed[k - 1].0 != key {
            positions.push(DVec3::from_array(key.map(f64::from_bits)));
        }
        ids[part as usize][local as usize] = (positions.len() - 1) as u32;
    }
    let mut faces: Vec<([u32; 3], i32)> = Vec::new();
    for (mesh, ids) in parts.iter().zip(&ids) {
        faces.par_extend(mesh.triangles.par_iter().map(|t| {
            // (m, x, y) from the smallest vertex; (m, y, x) is its reverse
            let t = t.map(|v| ids[v as usize]);
            let k = (0..3).min_by_key(|&k| t[k]).expect("three vertices");
            let (m, x, y) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            if x < y {
                ([m, x, y], 1)
            } else {
                ([m, y, x], -1)
            }
        }));
    }
    faces.par_sort_unstable();
    // Faces left after cancelling pairs, as (m, x, y) in their orientation.
    let mut left: Vec<[u32; 3]> = Vec::new();
    let mut bad_multiplicity = 0usize;
    let mut k = 0;
    while k < faces.len() {
        let key = faces[k].0;
        let mut sum = 0;
        while k < faces.len() && faces[k].0 == key {
            sum += faces[k].1;
            k += 1;
        }
        match sum {
            0 => {}
            1 => left.push(key),
            -1 => left.push([key[0], key[2], key[1]]),
            _ => bad_multiplicity += 1,
        }
    }
    let (lo, hi) = (
        crate::boolean::f32_exact(block.0),
        crate::boolean::f32_exact(block.1),
    );
    // Per box face (x−, x+, y−, y+, z−, z+): the area left facing out of it.
    let mut covered = [0.0f64; 6];
    let mut stray_area = 0.0;
    for t in &left {
        let [a, b, c] = t.map(|v| positions[v as usize]);
        let n = (b - a).cross(c - a);
        let on = (0..6).find(|&f| {
            let (axis, value, sign) = (
                f / 2,
                if f % 2 == 0 { lo } else { hi },
                if f % 2 == 0 { -1.0 } else { 1.0 },
            );
            [a, b, c].iter().all(|p| p[axis] == value[axis]) && n[axis] * sign > 0.0
        });
        match on {
            Some(f) => covered[f] += 0.5 * n.length(),
            None => stray_area += 0.5 * n.length(),
        }
    }
    let d = hi - lo;
    let face_area = [
        d.y * d.z,
        d.y * d.z,
        d.x * d.z,
        d.x * d.z,
        d.x * d.y,
        d.x * d.y,
    ];
    let total: f64 = face_area.iter().sum();
    let miscovered: f64 = covered
        .iter()
        .zip(&face_area)
        .map(|(c, a)| (c - a).abs())
        .sum();
    let value = (stray_area + miscovered) / total + bad_multiplicity as f64;
    CheckResult::at_most(
        "mold-parts-tile-block",
        value,
        AREA_REL,
        "of the block's surface",
        format!(
            "{} faces of {} parts: all but {} cancel in pairs; those cover the block's boundary facing out to {:.3e} mm² (of {total:.3} mm²), {stray_area:.3e} mm² lie elsewhere, {bad_multiplicity} faces repeat",
            faces.len(),
            parts.len(),
            left.len(),
            miscovered,
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::boolean::{cuboid, to_mesh};

    fn slab(lo: DVec3, hi: DVec3) -> Mesh {
        to_mesh(&cuboid(lo, hi).unwrap()).mesh
    }

    /// Two boxes sharing a face tile their union only when the shared face is
    /// triangulated alike on both sides; overlapping or separated boxes,
    /// and a box counted twice, never do.
    #[test]
    fn tiling_is_exact() {
        let (lo, hi) = (DVec3::new(0.0, 0.0, 0.0), DVec3::new(4.0, 2.0, 3.0));
        let lower = slab(lo, DVec3::new(4.0, 2.0, 1.0));
        let upper = slab(DVec3::new(0.0, 0.0, 1.0), hi);
        let whole = slab(lo, hi);
        let c = tiles_block(&[&lower, &upper], (lo, hi));
        assert!(c.passed && c.value == 0.0, "{c:?}");
        assert!(tiles_block(&[&whole], (lo, hi)).passed);
        // overlapping by 0.5 mm: the inner faces do not cancel
        let high = slab(DVec3::new(0.0, 0.0, 0.5), hi);
        assert!(!tiles_block(&[&lower, &high], (lo, hi)).passed);
        // a gap
        let higher = slab(DVec3::new(0.0, 0.0, 1.5), hi);
        assert!(!tiles_block(&[&lower, &higher], (lo, hi)).passed);
        // the whole block twice: every boundary face twice over
        assert!(!tiles_block(&[&whole, &whole], (lo, hi)).passed);
        // a part missing
        assert!(!tiles_block(&[&lower], (lo, hi)).passed);
    }
}
