//! A mesh ready for ray queries: an 8-wide BVH with f32 child boxes finds
//! candidates, and every candidate is intersected exactly in f64 with a
//! watertight test (Woop, Benthin and Wald, JCGT 2013), so rays do not leak
//! between the triangles of a closed lens surface.
//!
//! obvhs builds the tree (a compressed wide BVH, CWBVH); we decode each
//! node's quantised child boxes to plain f32 once, padded outwards, and
//! traverse that ourselves: the nearest child first, every child box tested
//! in two SSE halves. The quantised boxes cost obvhs's own traversal about
//! as much to decode at every visit as the box tests themselves.
//!
//! A path through a closed mesh knows which side of it it is on, and from
//! outside it can first meet only a face it enters through (from inside,
//! one it leaves through). Each slot also bounds the z of its triangles'
//! normals, which skips the slots whose triangles all face the other way:
//! near a ray's origin, that is the surface it just crossed.

use glam::{DMat3, DVec3};
use moirecast_kernel::Mesh;
use obvhs::cwbvh::{builder::build_cwbvh_from_tris, CwBvh};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use std::mem::MaybeUninit;

/// Entries of the traversal stack. A visit pops one entry and pushes at most
/// eight, so a tree of depth d needs at most 7·d + 1.
const STACK: usize = 512;
/// Deepest tree the stack holds.
const MAX_BVH_DEPTH: u32 = ((STACK - 1) / 7) as u32;
/// A tree from obvhs's medium build this deep is rebuilt with its slow build.
const REBUILD_DEPTH: u32 = 30;
/// A child slot holds no child.
const EMPTY: u32 = u32::MAX;
/// A child slot is a leaf: bits 28–30 count its triangles (1–3), bits 0–27
/// index the first in leaf order.
const LEAF: u32 = 1 << 31;
const LEAF_FIRST_BITS: u32 = 28;

/// Levels of inner nodes below the root (the root is level 1).
fn depth(bvh: &CwBvh) -> u32 {
    if bvh.nodes.is_empty() {
        return 0;
    }
    let (mut stack, mut deepest) = (vec![(0u32, 1u32)], 0);
    while let Some((n, d)) = stack.pop() {
        deepest = deepest.max(d);
        let node = &bvh.nodes[n as usize];
        for ch in 0..8 {
            if !node.is_child_empty(ch) && !node.is_leaf(ch) {
                stack.push((node.child_node_index(ch), d + 1));
            }
        }
    }
    deepest
}

/// One inner node: the boxes of its eight child slots, structure of arrays
/// ([min x, min y, min z, max x, max y, max z] × slot), and what each slot
/// holds (an inner node's index, a [`LEAF`], or [`EMPTY`], whose box is
/// inverted so that no ray enters it).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct WideNode {
    bounds: [[f32; 8]; 6],
    /// [lowest, highest] z component of the unit normals under each slot.
    normal_z: [[f32; 8]; 2],
    child: [u32; 8],
}

impl WideNode {
    /// Decodes a CWBVH node; `pad` widens every box on every side.
    fn decode(node: &obvhs::cwbvh::node::CwBvhNode, pad: f32, normal_z: [[f32; 8]; 2]) -> Self {
        let mut out = WideNode {
            normal_z,
            bounds: [
                [f32::INFINITY; 8],
                [f32::INFINITY; 8],
                [f32::INFINITY; 8],
                [f32::NEG_INFINITY; 8],
                [f32::NEG_INFINITY; 8],
                [f32::NEG_INFINITY; 8],
            ],
            child: [EMPTY; 8],
        };
        for slot in 0..8 {
            if node.is_child_empty(slot) {
                continue;
            }
            let b = node.child_aabb(slot);
            for axis in 0..3 {
                out.bounds[axis][slot] = b.min[axis] - pad;
                out.bounds[axis + 3][slot] = b.max[axis] + pad;
            }
            out.child[slot] = if node.is_leaf(slot) {
                let (first, count) = node.child_primitives(slot);
                assert!(first < 1 << LEAF_FIRST_BITS && (1..=3).contains(&count));
                LEAF | count << LEAF_FIRST_BITS | first
            } else {
                node.child_node_index(slot)
            };
        }
        out
    }
}

/// Per node, per slot: the lowest and highest z of the unit normals of the
/// triangles under it, rounded outwards to f32 (empty slots: an empty
/// range, +∞ to −∞).
fn normal_z_ranges(bvh: &CwBvh, mesh: &Mesh) -> Vec<[[f32; 8]; 2]> {
    let normal_z = |t: u32| {
        let [a, b, c] = mesh.triangles[t as usize].map(|i| mesh.positions[i as usize]);
        (b - a).cross(c - a).normalize_or_zero().z
    };
    let mut out = vec![[[f32::INFINITY; 8], [f32::NEG_INFINITY; 8]]; bvh.nodes.len()];
    // parents before children, breadth first; filled in reverse
    let mut order = vec![0u32];
    let mut i = 0;
    while i < order.len() {
        let node = &bvh.nodes[order[i] as usize];
        for slot in 0..8 {
            if !node.is_child_empty(slot) && !node.is_leaf(slot) {
                order.push(node.child_node_index(slot));
            }
        }
        i += 1;
    }
    for &n in order.iter().rev() {
        let node = &bvh.nodes[n as usize];
        for slot in 0..8 {
            if node.is_child_empty(slot) {
                continue;
            }
            let (lo, hi) = if node.is_leaf(slot) {
                let (first, count) = node.child_primitives(slot);
                (first..first + count)
                    .map(|id| normal_z(bvh.primitive_indices[id as usize]))
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
                        (lo.min(z), hi.max(z))
                    })
            } else {
                let [lo, hi] = out[node.child_node_index(slot) as usize];
                let lo = lo.iter().fold(f32::INFINITY, |m, &z| m.min(z));
                let hi = hi.iter().fold(f32::NEG_INFINITY, |m, &z| m.max(z));
                (lo as f64, hi as f64)
            };
            // outwards by more than the rounding to f32 and the normals' error
            out[n as usize][0][slot] = (lo - 1e-6) as f32;
            out[n as usize][1][slot] = (hi + 1e-6) as f32;
        }
    }
    out
}

/// Which side of the mesh a ray starts on, and so which triangles it can
/// meet first: from outside a closed, outward-oriented mesh, one it enters
/// through; from inside, one it leaves through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Outside,
    Inside,
}

/// The nearest intersection of a ray with the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f64,
    pub triangle: u32,
    /// Unit normal of the triangle, outward (the mesh is oriented).
    pub normal: DVec3,
}

pub struct Scene<'m> {
    mesh: &'m Mesh,
    nodes: Vec<WideNode>,
    /// The mesh triangle of each BVH primitive, in leaf order.
    primitive_indices: Vec<u32>,
    /// The corners of each BVH primitive, in the BVH's leaf order: a leaf's
    /// triangles are read from one stretch of memory, not gathered.
    corners: Vec<[DVec3; 3]>,
    /// Per triangle: it absorbs every ray that reaches it (a printed
    /// device's black bands). Empty: every face is a dielectric interface.
    absorbing: Vec<bool>,
    /// The mesh's bounding box, (lowest, highest) corner.
    bounds: (DVec3, DVec3),
}

impl<'m> Scene<'m> {
    /// A scene of `mesh` whose faces are `absorbing` (true) or dielectric.
    pub fn with_absorbing(mesh: &'m Mesh, absorbing: Vec<bool>) -> Self {
        assert_eq!(
            absorbing.len(),
            mesh.triangles.len(),
            "one flag per triangle"
        );
        Scene {
            absorbing,
            ..Self::new(mesh)
        }
    }

    /// Whether triangle `tri` absorbs the rays that reach it.
    pub fn absorbs(&self, tri: u32) -> bool {
        self.absorbing.get(tri as usize).copied().unwrap_or(false)
    }

    pub fn new(mesh: &'m Mesh) -> Self {
        let tris: Vec<Triangle> = mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| mesh.positions[i as usize].as_vec3a());
                Triangle {
                    v0: a,
                    v1: b,
                    v2: c,
                }
            })
            .collect();
        let build = |params| build_cwbvh_from_tris(&tris, params, &mut Default::default());
        let mut bvh = build(BvhBuildParams::medium_build());
        // The medium build can go deep on many long, thin, stacked
        // triangles (a printed device's layers: depth ≥ 32 where the slow
        // build gives 22); a deep tree is a slow one.
        if depth(&bvh) >= REBUILD_DEPTH {
            bvh = build(BvhBuildParams::slow_build());
        }
        let d = depth(&bvh);
        assert!(
            d <= MAX_BVH_DEPTH,
            "the BVH is {d} levels deep; the traversal stack holds {MAX_BVH_DEPTH}"
        );
        // The f32 boxes only cull, and must never cull a triangle the exact
        // f64 test would hit: the corners and the ray's origin are rounded to
        // f32 (relative error 2⁻²⁴), the quantised boxes are decoded with one
        // more rounding and the slab test adds a few more. Padding every box
        // by 2⁻¹⁶ of the scene's largest coordinate (1.5 µm at 100 mm) covers
        // them all with room to spare.
        let bounds = mesh.bounds();
        let (lo, hi) = bounds;
        let pad = (lo.abs().max(hi.abs()).max_element() as f32).max(1.0) * 2f32.powi(-16);
        let ranges = normal_z_ranges(&bvh, mesh);
        let nodes = bvh
            .nodes
            .iter()
            .zip(ranges)
            .map(|(n, r)| WideNode::decode(n, pad, r))
            .collect();
        let corners = bvh
            .primitive_indices
            .iter()
            .map(|&t| mesh.triangles[t as usize].map(|i| mesh.positions[i as usize]))
            .collect();
        Scene {
            mesh,
            nodes,
            primitive_indices: bvh.primitive_indices,
            corners,
            absorbing: Vec::new(),
            bounds,
        }
    }

    /// A scene with nothing in it that frames `bounds`: for frames traced
    /// wholly through [`crate::section::Sections`], whose rays never need
    /// the mesh.
    pub fn framing(bounds: (DVec3, DVec3)) -> Scene<'static> {
        static NOTHING: Mesh = Mesh {
            positions: Vec::new(),
            triangles: Vec::new(),
        };
        Scene {
            mesh: &NOTHING,
            nodes: Vec::new(),
            primitive_indices: Vec::new(),
            corners: Vec::new(),
            absorbing: Vec::new(),
            bounds,
        }
    }

    /// Whether the scene holds no triangles (see [`Scene::framing`]).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The mesh's bounding box, (lowest, highest) corner.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.bounds
    }

    /// The mesh the scene was built over.
    pub fn mesh(&self) -> &'m Mesh {
        self.mesh
    }

    /// The nearest hit along `origin + t·dir` with `t > t_min` (dir unit);
    /// of hits at equal t, the lowest triangle index.
    pub fn intersect(&self, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Hit> {
        self.nearest(origin, dir, t_min, None)
    }

    /// [`Scene::intersect`] for a ray that starts on `side` of the mesh:
    /// the nearest hit among the triangles facing that side (dot(dir, n) < 0
    /// from outside, > 0 from inside). On a closed mesh that is the nearest
    /// hit; boxes whose triangles all face the other way are skipped.
    pub fn intersect_from(&self, side: Side, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Hit> {
        self.nearest(origin, dir, t_min, Some(side))
    }

    fn nearest(&self, origin: DVec3, dir: DVec3, t_min: f64, side: Option<Side>) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let slabs = Slabs::new(origin, dir, side);
        let sheared = ShearedRay::new(origin, dir);
        // (t, triangle, its place in leaf order)
        let mut best = (f64::INFINITY, u32::MAX, 0);
        // The f32 cut-off for boxes: beyond the best hit, widened so that
        // rounding keeps every box that may hold an equally near hit.
        let mut t_far = f32::INFINITY;
        // Uninitialised: zeroing 4 kB would cost every ray more than a node.
        let mut stack = [MaybeUninit::<(u32, f32)>::uninit(); STACK];
        stack[0].write((0, 0.0));
        let mut top = 1;
        while top > 0 {
            top -= 1;
            // SAFETY: every entry below `top` was written before `top` passed it.
            let (entry, t_near) = unsafe { stack[top].assume_init() };
            if t_near > t_far {
                continue;
            }
            if entry & LEAF != 0 {
                let first = (entry & ((1 << LEAF_FIRST_BITS) - 1)) as usize;
                let count = ((entry & !LEAF) >> LEAF_FIRST_BITS) as usize;
                for id in first..first + count {
                    if let Some((t, entering)) = sheared.intersect_facing(&self.corners[id]) {
                        if side.is_some_and(|s| (s == Side::Outside) != entering) {
                            continue;
                        }
                        let tri = self.primitive_indices[id];
                        if t > t_min && (t < best.0 || (t == best.0 && tri < best.1)) {
                            best = (t, tri, id);
                            t_far = (t as f32).max(0.0) * (1.0 + 1e-6) + 1e-6;
                        }
                    }
                }
                continue;
            }
            let node = &self.nodes[entry as usize];
            let (mut mask, near) = slabs.enter(node, t_far);
            // push the children farthest first, so the nearest is popped next
            let mut order = [(0f32, 0u32); 8];
            let mut n = 0;
            while mask != 0 {
                let slot = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let item = (near[slot], node.child[slot]);
                let mut i = n;
                while i > 0 && order[i - 1].0 < item.0 {
                    order[i] = order[i - 1];
                    i -= 1;
                }
                order[i] = item;
                n += 1;
            }
            for &(t, child) in &order[..n] {
                stack[top].write((child, t));
                top += 1;
            }
        }
        (best.1 != u32::MAX).then(|| {
            // the corners just tested, still in cache (the mesh's are not)
            let [a, b, c] = self.corners[best.2];
            Hit {
                t: best.0,
                triangle: best.1,
                normal: (b - a).cross(c - a).normalize(),
            }
        })
    }
}

/// A ray set up for f32 slab tests against a node's eight child boxes.
struct Slabs {
    origin: [f32; 3],
    inverse: [f32; 3],
    /// Per axis, the bounds row the ray enters a box through (the min row if
    /// it travels up the axis, else the max row) and the row it leaves by.
    enter_row: [usize; 3],
    leave_row: [usize; 3],
    /// A slot is kept only if its normals' z range reaches up to
    /// `normal_z_floor` and down to `normal_z_ceiling`: outside those, all
    /// its triangles face away from the ray's side.
    normal_z_floor: f32,
    normal_z_ceiling: f32,
}

impl Slabs {
    fn new(origin: DVec3, dir: DVec3, side: Option<Side>) -> Self {
        // With ψ the angle between the ray and the pole (±z) it heads to
        // and sin ψ = |dir_xy|, a normal within 90° − ψ of that pole faces
        // along the ray (dot > 0), one within 90° − ψ of the other pole
        // against it (dot < 0). Outside, a ray heading down can meet no
        // slot whose normals all have z < −sin ψ; inside, none whose
        // normals all have z > sin ψ; heading up, the other way round.
        let sin_psi = (dir.x * dir.x + dir.y * dir.y).sqrt().min(1.0) as f32 * (1.0 + 1e-6) + 1e-6;
        let down = dir.z <= 0.0;
        let (floor, ceiling) = match side {
            None => (f32::NEG_INFINITY, f32::INFINITY),
            Some(s) if (s == Side::Outside) == down => (-sin_psi, f32::INFINITY),
            Some(_) => (f32::NEG_INFINITY, sin_psi),
        };
        // no zero components: a tiny one keeps every product finite and
        // every comparison ordered (±0 would make 0·∞ = NaN)
        let d = dir.to_array().map(|c| {
            let c = c as f32;
            if c.abs() < 1e-30 {
                1e-30
            } else {
                c
            }
        });
        let up = d.map(|c| c > 0.0);
        Slabs {
            origin: origin.to_array().map(|c| c as f32),
            inverse: d.map(|c| 1.0 / c),
            enter_row: [0, 1, 2].map(|a| if up[a] { a } else { a + 3 }),
            leave_row: [0, 1, 2].map(|a| if up[a] { a + 3 } else { a }),
            normal_z_floor: floor,
            normal_z_ceiling: ceiling,
        }
    }

    /// The slots whose boxes the ray meets between 0 and `t_far` (a bit
    /// mask), and the ray parameter where it enters each.
    #[inline(always)]
    fn enter(&self, node: &WideNode, t_far: f32) -> (u32, [f32; 8]) {
        #[cfg(target_arch = "x86_64")]
        {
            self.enter_sse(node, t_far)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let mut near = [0f32; 8];
            let mut mask = 0;
            for slot in 0..8 {
                let (mut t0, mut t1) = (0f32, t_far);
                for a in 0..3 {
                    let e =
                        (node.bounds[self.enter_row[a]][slot] - self.origin[a]) * self.inverse[a];
                    let l =
                        (node.bounds[self.leave_row[a]][slot] - self.origin[a]) * self.inverse[a];
                    t0 = if e > t0 { e } else { t0 };
                    t1 = if l < t1 { l } else { t1 };
                }
                near[slot] = t0;
                let facing = node.normal_z[1][slot] >= self.normal_z_floor
                    && node.normal_z[0][slot] <= self.normal_z_ceiling;
                mask |= ((t0 <= t1 && facing) as u32) << slot;
            }
            (mask, near)
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn enter_sse(&self, node: &WideNode, t_far: f32) -> (u32, [f32; 8]) {
        use std::arch::x86_64::*;
        let mut near = [0f32; 8];
        let mut mask = 0;
        // SAFETY: SSE is part of x86_64; every load reads 4 of a row's 8
        // f32s, inside the node.
        unsafe {
            for half in 0..2 {
                let mut t0 = _mm_setzero_ps();
                let mut t1 = _mm_set1_ps(t_far);
                for a in 0..3 {
                    let o = _mm_set1_ps(self.origin[a]);
                    let inv = _mm_set1_ps(self.inverse[a]);
                    let e = _mm_loadu_ps(node.bounds[self.enter_row[a]].as_ptr().add(4 * half));
                    let l = _mm_loadu_ps(node.bounds[self.leave_row[a]].as_ptr().add(4 * half));
                    t0 = _mm_max_ps(t0, _mm_mul_ps(_mm_sub_ps(e, o), inv));
                    t1 = _mm_min_ps(t1, _mm_mul_ps(_mm_sub_ps(l, o), inv));
                }
                _mm_storeu_ps(near.as_mut_ptr().add(4 * half), t0);
                let lo = _mm_loadu_ps(node.normal_z[0].as_ptr().add(4 * half));
                let hi = _mm_loadu_ps(node.normal_z[1].as_ptr().add(4 * half));
                let facing = _mm_and_ps(
                    _mm_cmpge_ps(hi, _mm_set1_ps(self.normal_z_floor)),
                    _mm_cmple_ps(lo, _mm_set1_ps(self.normal_z_ceiling)),
                );
                let keep = _mm_and_ps(_mm_cmple_ps(t0, t1), facing);
                mask |= (_mm_movemask_ps(keep) as u32) << (4 * half);
            }
        }
        (mask, near)
    }
}

/// A ray set up for the watertight test (Woop, Benthin and Wald 2013):
/// the axis permutation and shear that make its direction +z, computed
/// once per ray rather than once per triangle, as one matrix.
#[derive(Clone, Copy, Debug)]
pub struct ShearedRay {
    origin: DVec3,
    /// Rows: e_kx − sx·e_kz, e_ky − sy·e_kz, e_kz, where kz is the
    /// direction's dominant axis (kx, ky swapped if it points down it).
    shear: DMat3,
    sz: f64,
}

impl ShearedRay {
    pub fn new(origin: DVec3, dir: DVec3) -> Self {
        let kz = dir.abs().max_position();
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let e = |k: usize| DVec3::AXES[k];
        let (sx, sy) = (dir[kx] / dir[kz], dir[ky] / dir[kz]);
        ShearedRay {
            origin,
            shear: DMat3::from_cols(e(kx) - sx * e(kz), e(ky) - sy * e(kz), e(kz)).transpose(),
            sz: 1.0 / dir[kz],
        }
    }

    /// The ray parameter t of its intersection with the triangle
    /// `corners`, if any. Watertight: edges shared by two triangles are
    /// decided consistently, so a ray through a shared edge hits exactly one
    /// of them... or both, at the same t.
    #[inline]
    pub fn intersect(&self, corners: &[DVec3; 3]) -> Option<f64> {
        self.intersect_facing(corners).map(|(t, _)| t)
    }

    /// [`ShearedRay::intersect`], and whether the ray enters through the
    /// triangle's front (dot(dir, n) < 0, n by the corners' winding):
    /// decided by the same determinant, so consistently with the hit.
    #[inline]
    pub fn intersect_facing(&self, corners: &[DVec3; 3]) -> Option<(f64, bool)> {
        let DVec3 {
            x: ax,
            y: ay,
            z: az,
        } = self.shear * (corners[0] - self.origin);
        let DVec3 {
            x: bx,
            y: by,
            z: bz,
        } = self.shear * (corners[1] - self.origin);
        let DVec3 {
            x: cx,
            y: cy,
            z: cz,
        } = self.shear * (corners[2] - self.origin);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        Some(((u * az + v * bz + w * cz) * self.sz / det, det > 0.0))
    }
}

/// [`ShearedRay::intersect`] for one ray and one triangle.
pub fn watertight(corners: &[DVec3; 3], origin: DVec3, dir: DVec3) -> Option<f64> {
    ShearedRay::new(origin, dir).intersect(corners)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::SplitMix64;
    use moirecast_kernel::mesher::mesh_device;
    use moirecast_kernel::progress::Silent;
    use moirecast_kernel::{Design, DesignParams, PitchSurface, Profile};

    /// The mesh of a device `width` × `height` mm (period 0.5 mm).
    fn device_mesh(surface: PitchSurface, width: f64, height: f64, profile: Profile) -> Mesh {
        let mut p = DesignParams::with_defaults(surface, width, height, 0.5);
        p.profile = profile;
        mesh_device(&Design::new(p).unwrap(), &Silent).unwrap().mesh
    }

    /// A saddle device (radius 40 mm) with a bump profile of `sigma` mm.
    fn saddle_with_bump(width: f64, height: f64, sigma: f64) -> Mesh {
        let saddle = PitchSurface::Saddle { radius: 40.0 };
        device_mesh(saddle, width, height, Profile::Bump { sigma })
    }

    /// The BVH finds exactly the nearest hit a brute-force scan of every
    /// triangle finds, on a device mesh, for random rays and for rays along
    /// the axes (with −0.0 components); from either side too, among the
    /// triangles facing it.
    #[test]
    fn bvh_hits_are_the_brute_force_hits() {
        let mesh = saddle_with_bump(4.0, 3.0, 1.0);
        let scene = Scene::new(&mesh);
        let brute = |o: DVec3, d: DVec3, side: Option<Side>| {
            let ray = ShearedRay::new(o, d);
            (0..mesh.triangles.len() as u32)
                .filter_map(|t| {
                    ray.intersect_facing(
                        &mesh.triangles[t as usize].map(|i| mesh.positions[i as usize]),
                    )
                    .filter(|&(x, entering)| {
                        x > 1e-9 && side.is_none_or(|s| (s == Side::Outside) == entering)
                    })
                    .map(|(x, _)| (x, t))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        };
        let mut rng = SplitMix64(3);
        let mut rays: Vec<(DVec3, DVec3)> = (0..2000)
            .map(|_| {
                let mut r = || 2.0 * rng.next_f64() - 1.0;
                let o = DVec3::new(2.5 * r(), 2.0 * r(), 2.0 * r());
                let d = DVec3::new(r(), r(), r()).normalize();
                (o, d)
            })
            .collect();
        for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
            for s in [1.0, -1.0] {
                rays.push((DVec3::new(0.3, -0.2, 0.0) - 3.0 * s * axis, s * axis));
            }
        }
        let mut hits = [0; 3];
        for (o, d) in rays {
            for (k, side) in [None, Some(Side::Outside), Some(Side::Inside)]
                .into_iter()
                .enumerate()
            {
                let got = match side {
                    None => scene.intersect(o, d, 1e-9),
                    Some(s) => scene.intersect_from(s, o, d, 1e-9),
                };
                let got = got.map(|h| (h.t, h.triangle));
                let want = brute(o, d, side);
                match (got, want) {
                    (Some(g), Some(w)) => {
                        hits[k] += 1;
                        assert!((g.0 - w.0).abs() <= 1e-12 * w.0.max(1.0), "{g:?} vs {w:?}");
                    }
                    (None, None) => {}
                    _ => panic!("ray {o} {d} {side:?}: BVH {got:?}, brute force {want:?}"),
                }
            }
        }
        assert!(hits.iter().all(|&h| h > 300), "{hits:?} rays hit");
    }

    /// The watertight test's determinant says which way the ray crosses:
    /// into the triangle's front exactly where dot(dir, n) < 0.
    #[test]
    fn the_determinant_says_which_way_a_triangle_faces() {
        let mut rng = SplitMix64(9);
        let mut r = || 2.0 * rng.next_f64() - 1.0;
        let mut hits = 0;
        for _ in 0..20_000 {
            let corners = [(); 3].map(|_| DVec3::new(r(), r(), r()));
            let d = DVec3::new(r(), r(), r()).normalize();
            let o = -2.0 * d + 0.3 * DVec3::new(r(), r(), r());
            let n = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
            if let Some((_, entering)) = ShearedRay::new(o, d).intersect_facing(&corners) {
                hits += 1;
                assert_eq!(entering, d.dot(n) < 0.0, "{corners:?} {o} {d}");
            }
        }
        assert!(hits > 1000, "{hits} hits");
    }

    /// On a closed device mesh, a path's side predicts what it meets: the
    /// nearest hit of all is the nearest facing the side the path is on,
    /// over paths refracted and reflected through the device.
    #[test]
    fn a_path_meets_only_faces_turned_to_its_side() {
        let mesh = saddle_with_bump(6.0, 5.0, 1.5);
        let scene = Scene::new(&mesh);
        let mut rng = SplitMix64(13);
        let (mut segments, mut inside) = (0, 0);
        for _ in 0..2000 {
            let tilt = 0.6 * (rng.next_f64() - 0.5);
            let mut d = DVec3::new(tilt.sin(), 0.2 * tilt, -tilt.cos()).normalize();
            let mut o = DVec3::new(6.0 * rng.next_f64() - 3.0, 5.0 * rng.next_f64() - 2.5, 5.0);
            let mut side = Side::Outside;
            for _ in 0..8 {
                let all = scene.intersect(o, d, 1e-7);
                assert_eq!(
                    all,
                    scene.intersect_from(side, o, d, 1e-7),
                    "{o} {d} {side:?}"
                );
                segments += 1;
                inside += (side == Side::Inside) as usize;
                let Some(hit) = all else { break };
                let leaving = d.dot(hit.normal) > 0.0;
                assert_eq!(leaving, side == Side::Inside);
                let (n, n1, n2) = if leaving {
                    (-hit.normal, 1.5, 1.0)
                } else {
                    (hit.normal, 1.0, 1.5)
                };
                o += hit.t * d;
                let r = crate::optics::fresnel(-d.dot(n), n1, n2);
                d = match crate::optics::refract(d, n, n1, n2) {
                    // refract more often than Fresnel says: more crossings
                    Some(t) if rng.next_f64() >= r.max(0.3) => {
                        side = if leaving { Side::Outside } else { Side::Inside };
                        t
                    }
                    _ => crate::optics::reflect(d, n),
                };
            }
        }
        assert!(
            segments > 5000 && inside > 1500,
            "{segments} segments, {inside} inside"
        );
    }

    /// Rays straight down onto a 40 mm plane device, where coordinates are
    /// large against f32's rounding: the f32 boxes must keep every triangle
    /// the exact test hits. The first ray went through the lens surface
    /// under obvhs's own traversal (unpadded boxes), 1 ray in 600,000.
    #[test]
    fn no_ray_slips_between_the_f32_boxes() {
        let mesh = device_mesh(
            PitchSurface::Plane,
            40.0,
            40.0,
            Profile::Rings { wavelength: 10.0 },
        );
        let scene = Scene::new(&mesh);
        let corners = |t: u32| mesh.triangles[t as usize].map(|i| mesh.positions[i as usize]);
        let mut rng = SplitMix64(7);
        let mut rays = vec![DVec3::new(10.720926675211928, 1.1977738528647492, 10.0)];
        rays.extend((0..40).map(|_| {
            DVec3::new(
                40.0 * rng.next_f64() - 20.0,
                40.0 * rng.next_f64() - 20.0,
                10.0,
            )
        }));
        for o in rays {
            let d = DVec3::NEG_Z;
            let want = (0..mesh.triangles.len() as u32)
                .filter_map(|t| watertight(&corners(t), o, d).map(|x| (x, t)))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let got = scene.intersect(o, d, 0.0).map(|h| (h.t, h.triangle));
            assert_eq!(got, want, "ray down from {o}");
        }
    }
}
