//! A half's region, split for its boolean. Manifold's cost grows with every
//! triangle of an operand, and a half's channels come near only a few of the
//! device's faces. The device faces no channel comes near (the far patch)
//! therefore stay out of the boolean: the rest of the region is closed by an
//! interface (vertical curtains over the patch's rims and a flat lid over
//! them), manifold cuts the channels into that, and the patch takes the
//! interface's place again. The patch and the interface bound a solid the
//! channels miss, so the result is the region minus the channels, face for
//! face.
//!
//! Every assumption is checked, and where one fails the caller cuts the
//! whole region instead: the patch must be one piece (one outer rim, holes
//! where channels come down inside it, no vertex on two rims or on one
//! twice) of faces seen from the half's side only, the lid must clear the
//! patch and the region's cap and cover the rims once, every new triangle
//! must be well shaped, and the cut must come back with the interface whole.

use crate::boolean::{f32_exact, Traced};
use crate::parting::{Face, PosedDevice, Rect, Region};
use glam::{DVec2, DVec3};
use manifold_rust::linalg::Vec2;
use moirecast_kernel::Mesh;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Clearance (mm) in xy between the far patch and the channels' bounding
/// boxes, and between the patch and the outline (the walls).
const CLEARANCE_MM: f64 = 0.5;
/// Height (mm) of the lid over the patch's highest point (lowest, below).
const LID_RISE_MM: f64 = 1.0;
/// Thinnest altitude (mm) of a curtain or lid triangle.
const MIN_ALTITUDE_MM: f64 = 1e-4;
/// The patch must hold at least this share of the region's device faces to
/// be worth splitting off.
const MIN_FAR_SHARE: f64 = 0.5;

/// A region without its far patch, closed by the interface.
pub struct Split {
    /// The region's device faces that are not in the patch, its own faces,
    /// then the interface's; with only the vertices they use.
    pub near: Mesh,
    /// The device face each of `near`'s first triangles is.
    pub near_device_faces: Vec<u32>,
    /// How many of `near`'s triangles (the last) are the interface.
    pub interface: usize,
    /// The patch: region triangles and the device faces they are.
    far: Vec<[u32; 3]>,
    far_device_faces: Vec<u32>,
    /// The region vertices on the patch's boundary.
    rim: Vec<u32>,
}

/// Splits the region on `side` (+1 above the parting surface, −1 below)
/// whose device faces of `kind` are the cavity's. `clear` are the xy boxes
/// (min, max) of everything that will be cut from it; `cap_z` its cap's
/// height. `None` where the patch is not one piece (an outer rim and holes) or a
/// check fails.
pub fn split(
    region: &Region,
    posed: &PosedDevice,
    kind: Face,
    side: f64,
    clear: &[(DVec2, DVec2)],
    cap_z: f64,
) -> Option<Split> {
    let k = region.device_faces.len();
    let pos = &region.mesh.positions;
    let is_far = far_faces(region, posed, (kind, side), clear);
    let far_count = is_far.iter().filter(|&&f| f).count();
    if (far_count as f64) < MIN_FAR_SHARE * k as f64 {
        return None;
    }
    // The patch's rim lies on faces outside it: only edges between
    // vertices those faces use can be on it.
    let mut by_near = vec![false; pos.len()];
    for (t, _) in region.mesh.triangles[..k]
        .iter()
        .zip(&is_far)
        .filter(|(_, &far)| !far)
    {
        for &v in t {
            by_near[v as usize] = true;
        }
    }
    let rims = boundary_loops(&region.mesh.triangles[..k], &is_far, |v| {
        by_near[v as usize]
    })?;
    let n: usize = rims.iter().map(Vec::len).sum();
    // The lid: clear of the patch by LID_RISE_MM, and of the cap.
    let extreme = (0..k)
        .into_par_iter()
        .filter(|&i| is_far[i])
        .flat_map_iter(|i| region.mesh.triangles[i].map(|v| side * pos[v as usize].z))
        .reduce(|| f64::NEG_INFINITY, f64::max);
    let lid_z = f32_exact(DVec3::new(0.0, 0.0, side * (extreme + LID_RISE_MM))).z;
    if side * (cap_z - lid_z) < LID_RISE_MM / 2.0 {
        return None;
    }
    let mut near = Mesh {
        positions: pos.clone(),
        triangles: Vec::with_capacity(region.mesh.triangles.len() - far_count + 4 * n),
    };
    let mut near_device_faces = Vec::with_capacity(k - far_count);
    let (mut far, mut far_device_faces) =
        (Vec::with_capacity(far_count), Vec::with_capacity(far_count));
    for ((&t, &face), &is_far) in region
        .mesh
        .triangles
        .iter()
        .zip(&region.device_faces)
        .zip(&is_far)
    {
        if is_far {
            far.push(t);
            far_device_faces.push(face);
        } else {
            near.triangles.push(t);
            near_device_faces.push(face);
        }
    }
    near.triangles
        .extend_from_slice(&region.mesh.triangles[k..]);
    let first_interface = near.triangles.len();
    let lid_of = curtains(&mut near, &rims, lid_z);
    add_lid(&mut near, &rims, &lid_of)?;
    let interface = near.triangles.len() - first_interface;
    let thinnest = near.triangles[first_interface..]
        .iter()
        .map(|t| altitude(t.map(|v| near.positions[v as usize])))
        .fold(f64::INFINITY, f64::min);
    if thinnest < MIN_ALTITUDE_MM {
        return None;
    }
    Some(Split {
        near: compacted(near),
        near_device_faces,
        interface,
        far,
        far_device_faces,
        rim: rims.concat(),
    })
}

/// Which of the region's device faces (its first triangles) are far: of
/// the cavity's `kind`, facing out of the region through the parting
/// surface on `side`, inside the outline by the clearance, and clear of
/// every box in `clear`.
fn far_faces(
    region: &Region,
    posed: &PosedDevice,
    (kind, side): (Face, f64),
    clear: &[(DVec2, DVec2)],
) -> Vec<bool> {
    let k = region.device_faces.len();
    let pos = &region.mesh.positions;
    let inside = shrunk(&posed.outline, CLEARANCE_MM);
    (0..k)
        .into_par_iter()
        .map(|i| {
            if posed.faces[region.device_faces[i] as usize] != kind {
                return false;
            }
            let [a, b, c] = region.mesh.triangles[i].map(|v| pos[v as usize]);
            // Facing out of the region through the parting surface.
            if (b - a).cross(c - a).z * side >= 0.0 {
                return false;
            }
            let lo = a.min(b).min(c).truncate();
            let hi = a.max(b).max(c).truncate();
            let within =
                lo.x > inside.x0 && hi.x < inside.x1 && lo.y > inside.y0 && hi.y < inside.y1;
            within
                && clear.iter().all(|&(cl, ch)| {
                    lo.x > ch.x + CLEARANCE_MM
                        || hi.x < cl.x - CLEARANCE_MM
                        || lo.y > ch.y + CLEARANCE_MM
                        || hi.y < cl.y - CLEARANCE_MM
                })
        })
        .collect()
}

/// Curtains from every rim up to the lid height: over rim edge a→b of the
/// patch, the near side holds a→b; the lid then holds a'→b' (the lid
/// vertex over a to that over b). Returns each rim's first lid vertex.
fn curtains(near: &mut Mesh, rims: &[Vec<u32>], lid_z: f64) -> Vec<u32> {
    let mut lid_of = Vec::with_capacity(rims.len());
    for rim in rims {
        let first = near.positions.len() as u32;
        let m = rim.len() as u32;
        for &v in rim {
            let p = near.positions[v as usize];
            near.positions.push(DVec3::new(p.x, p.y, lid_z));
        }
        for (j, &a) in rim.iter().enumerate() {
            let j = j as u32;
            let b = rim[((j + 1) % m) as usize];
            let (a2, b2) = (first + j, first + (j + 1) % m);
            near.triangles.push([a, b, b2]);
            near.triangles.push([a, b2, a2]);
        }
        lid_of.push(first);
    }
    lid_of
}

/// The lid over the curtains: one polygon per rim, wound as the rims run
/// (the outer one against the holes), ear-clipped. `None` where the rims
/// do not nest as an outer one and holes, or the lid would not cover the
/// area between them exactly once.
fn add_lid(near: &mut Mesh, rims: &[Vec<u32>], lid_of: &[u32]) -> Option<()> {
    let n: usize = rims.iter().map(Vec::len).sum();
    let rings: Vec<Vec<Vec2>> = rims
        .iter()
        .map(|rim| {
            rim.iter()
                .map(|&v| Vec2::new(near.positions[v as usize].x, near.positions[v as usize].y))
                .collect()
        })
        .collect();
    let twice_areas: Vec<f64> = rings.iter().map(|r| twice_signed_area(r)).collect();
    let outer = (0..rings.len())
        .max_by(|&i, &j| twice_areas[i].abs().total_cmp(&twice_areas[j].abs()))
        .expect("a rim");
    let twice_area: f64 = twice_areas.iter().sum();
    let ccw = twice_areas[outer] > 0.0;
    if (0..rings.len()).any(|i| i != outer && (twice_areas[i] > 0.0) == ccw) {
        return None;
    }
    // The ear clipper's vertices, flattened, and the lid vertex each is.
    let mut lid_vertex = Vec::with_capacity(n);
    let polygons: Vec<Vec<Vec2>> = rings
        .iter()
        .zip(lid_of)
        .map(|(ring, &first)| {
            let m = ring.len() as u32;
            if ccw {
                lid_vertex.extend(first..first + m);
                ring.clone()
            } else {
                lid_vertex.extend((first..first + m).rev());
                ring.iter().rev().copied().collect()
            }
        })
        .collect();
    let lid = manifold_rust::polygon::triangulate(&polygons, 1e-12, false);
    if lid.len() + 2 != n + 2 * (rings.len() - 1) {
        return None;
    }
    // Every triangle turns the rims' way and together they have the area
    // between the rims: the lid covers it once.
    let at = |v: u32| {
        let p = near.positions[v as usize];
        Vec2::new(p.x, p.y)
    };
    let mut lid_twice_area = 0.0;
    for t in lid {
        let mut tri = [t.x, t.y, t.z].map(|i| lid_vertex[i as usize]);
        if !ccw {
            tri.swap(1, 2);
        }
        let [a, b, c] = tri.map(at);
        let turn = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
        if turn * twice_area <= 0.0 {
            return None;
        }
        lid_twice_area += turn;
        near.triangles.push(tri);
    }
    if (lid_twice_area - twice_area).abs() > 1e-9 * twice_area.abs() {
        return None;
    }
    Some(())
}

impl Split {
    /// The region minus the cut: `cut` (the near part minus the cut, traced)
    /// without the interface (original ID `interface_id`), and the patch in
    /// its place, traced to the device faces under `device_id`. `None` if
    /// the interface did not come back whole.
    pub fn join(
        &self,
        region: &Region,
        cut: Traced,
        interface_id: u32,
        device_id: u32,
    ) -> Option<Traced> {
        let Traced {
            mut mesh,
            mut source,
        } = cut;
        let key = |p: DVec3| p.to_array().map(|c| (c + 0.0).to_bits());
        let rim_at: rustc_hash::FxHashMap<[u64; 3], u32> = self
            .rim
            .iter()
            .map(|&v| (key(region.mesh.positions[v as usize]), v))
            .collect();
        let mut to_out = vec![u32::MAX; region.mesh.positions.len()];
        let mut found = 0;
        for (i, &p) in mesh.positions.iter().enumerate() {
            if let Some(&v) = rim_at.get(&key(p)) {
                if to_out[v as usize] == u32::MAX {
                    found += 1;
                }
                to_out[v as usize] = i as u32;
            }
        }
        if found != self.rim.len() {
            return None;
        }
        let before = mesh.triangles.len();
        let mut kept = 0;
        for t in 0..before {
            if source[t].0 != interface_id {
                mesh.triangles[kept] = mesh.triangles[t];
                source[kept] = source[t];
                kept += 1;
            }
        }
        if before - kept != self.interface {
            return None;
        }
        mesh.triangles.truncate(kept);
        source.truncate(kept);
        for (t, &face) in self.far.iter().zip(&self.far_device_faces) {
            let tri = t.map(|v| {
                let v = v as usize;
                if to_out[v] == u32::MAX {
                    to_out[v] = mesh.positions.len() as u32;
                    mesh.positions.push(region.mesh.positions[v]);
                }
                to_out[v]
            });
            mesh.triangles.push(tri);
            source.push((device_id, u64::from(face)));
        }
        // without the lid's vertices, which nothing uses now
        Some(Traced {
            mesh: compacted(mesh),
            source,
        })
    }
}

/// `m` with only the vertices its triangles use, in their first use's
/// order (the patch's own vertices would cost manifold time for nothing).
fn compacted(m: Mesh) -> Mesh {
    let mut new_index = vec![u32::MAX; m.positions.len()];
    let mut positions = Vec::new();
    let triangles = m
        .triangles
        .iter()
        .map(|t| {
            t.map(|v| {
                let v = v as usize;
                if new_index[v] == u32::MAX {
                    new_index[v] = positions.len() as u32;
                    positions.push(m.positions[v]);
                }
                new_index[v]
            })
        })
        .collect();
    Mesh {
        positions,
        triangles,
    }
}

fn shrunk(r: &Rect, by: f64) -> Rect {
    r.grown(-by)
}

/// The smallest altitude of a triangle.
fn altitude([a, b, c]: [DVec3; 3]) -> f64 {
    let twice_area = (b - a).cross(c - a).length();
    let longest = a.distance(b).max(b.distance(c)).max(c.distance(a));
    twice_area / longest
}

/// Twice the signed area of a closed polygon (positive counter-clockwise).
fn twice_signed_area(ring: &[Vec2]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|j| {
            let (p, q) = (ring[j], ring[(j + 1) % n]);
            p.x * q.y - q.x * p.y
        })
        .sum()
}

/// The boundary of the triangles marked `inside`, as loops of vertices in
/// the triangles' winding; `None` where a vertex is on it twice (two
/// loops touch, or one pinches). Every boundary vertex must be
/// `maybe_on_rim` (the others are passed over unseen).
fn boundary_loops(
    triangles: &[[u32; 3]],
    inside: &[bool],
    maybe_on_rim: impl Fn(u32) -> bool + Sync,
) -> Option<Vec<Vec<u32>>> {
    // The marked triangles' directed edges that may be on the boundary,
    // keyed by their undirected pair: an edge seen once is on it.
    let mut edges: Vec<(u64, u32, u32)> = triangles
        .par_iter()
        .zip(inside)
        .filter(|(_, &m)| m)
        .flat_map_iter(|(t, _)| {
            (0..3).filter_map(|j| {
                let (a, b) = (t[j], t[(j + 1) % 3]);
                (maybe_on_rim(a) && maybe_on_rim(b))
                    .then(|| ((u64::from(a.min(b)) << 32) | u64::from(a.max(b)), a, b))
            })
        })
        .collect();
    edges.par_sort_unstable_by_key(|e| e.0);
    let mut next: BTreeMap<u32, u32> = BTreeMap::new();
    let mut i = 0;
    while i < edges.len() {
        let mut j = i + 1;
        while j < edges.len() && edges[j].0 == edges[i].0 {
            j += 1;
        }
        match j - i {
            1 => {
                if next.insert(edges[i].1, edges[i].2).is_some() {
                    return None;
                }
            }
            2 if edges[i].1 == edges[i + 1].2 => {}
            _ => return None,
        }
        i = j;
    }
    // Each loop from its least vertex, in order: deterministic.
    let mut loops = Vec::new();
    while let Some((&start, _)) = next.first_key_value() {
        let mut ring = vec![start];
        let mut v = next.remove(&start)?;
        while v != start {
            ring.push(v);
            v = next.remove(&v)?;
        }
        loops.push(ring);
    }
    (!loops.is_empty()).then_some(loops)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3 × 3 grid of squares (two triangles each): its boundary is one
    /// loop of 12 vertices; without the middle square, two loops, the hole
    /// wound against the outer one; two squares meeting at a corner only
    /// pinch a vertex (refused).
    #[test]
    fn the_boundary_is_simple_loops_or_nothing() {
        let id = |i: u32, j: u32| j * 4 + i;
        let mut triangles = Vec::new();
        for j in 0..3 {
            for i in 0..3 {
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let at = |v: u32| Vec2::new(f64::from(v % 4), f64::from(v / 4));
        let area = |ring: &Vec<u32>| {
            twice_signed_area(&ring.iter().map(|&v| at(v)).collect::<Vec<_>>()) / 2.0
        };
        let all = vec![true; 18];
        let rims = boundary_loops(&triangles, &all, |_| true).unwrap();
        assert_eq!(rims.len(), 1);
        assert_eq!(rims[0].len(), 12);
        assert_eq!(area(&rims[0]), 9.0);
        let mut holed = all.clone();
        holed[8] = false;
        holed[9] = false;
        let rims = boundary_loops(&triangles, &holed, |_| true).unwrap();
        let mut areas: Vec<f64> = rims.iter().map(area).collect();
        areas.sort_by(f64::total_cmp);
        assert_eq!(areas, [-1.0, 9.0]);
        let mut pinched = vec![false; 18];
        for t in [0, 1, 8, 9] {
            pinched[t] = true;
        }
        assert!(boundary_loops(&triangles, &pinched, |_| true).is_none());
    }
}
