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
    child: [u32; 8],
}

impl WideNode {
    /// Decodes a CWBVH node; `pad` widens every box on every side.
    fn decode(node: &obvhs::cwbvh::node::CwBvhNode, pad: f32) -> Self {
        let mut out = WideNode {
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
        if depth(&bvh) >= 30 {
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
        let (lo, hi) = mesh.bounds();
        let pad = (lo.abs().max(hi.abs()).max_element() as f32).max(1.0) * 2f32.powi(-16);
        let nodes = bvh.nodes.iter().map(|n| WideNode::decode(n, pad)).collect();
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
            bounds: mesh.bounds(),
        }
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
        if self.nodes.is_empty() {
            return None;
        }
        let slabs = Slabs::new(origin, dir);
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
                    if let Some(t) = sheared.intersect(&self.corners[id]) {
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
}

impl Slabs {
    fn new(origin: DVec3, dir: DVec3) -> Self {
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
                mask |= ((t0 <= t1) as u32) << slot;
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
                mask |= (_mm_movemask_ps(_mm_cmple_ps(t0, t1)) as u32) << (4 * half);
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
        Some((u * az + v * bz + w * cz) * self.sz / det)
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

    /// The BVH finds exactly the nearest hit a brute-force scan of every
    /// triangle finds, on a device mesh, for random rays and for rays along
    /// the axes (with −0.0 components).
    #[test]
    fn bvh_hits_are_the_brute_force_hits() {
        let mut p =
            DesignParams::with_defaults(PitchSurface::Saddle { radius: 40.0 }, 4.0, 3.0, 0.5);
        p.profile = Profile::Bump { sigma: 1.0 };
        let design = Design::new(p).unwrap();
        let dm = mesh_device(&design, &Silent).unwrap();
        let scene = Scene::new(&dm.mesh);
        let brute = |o: DVec3, d: DVec3| {
            (0..dm.mesh.triangles.len() as u32)
                .filter_map(|t| {
                    watertight(
                        &dm.mesh.triangles[t as usize].map(|i| dm.mesh.positions[i as usize]),
                        o,
                        d,
                    )
                    .filter(|&x| x > 1e-9)
                    .map(|x| (x, t))
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
        let mut hits = 0;
        for (o, d) in rays {
            let got = scene.intersect(o, d, 1e-9).map(|h| (h.t, h.triangle));
            let want = brute(o, d);
            match (got, want) {
                (Some(g), Some(w)) => {
                    hits += 1;
                    assert!((g.0 - w.0).abs() <= 1e-12 * w.0.max(1.0), "{g:?} vs {w:?}");
                }
                (None, None) => {}
                _ => panic!("ray {o} {d}: BVH {got:?}, brute force {want:?}"),
            }
        }
        assert!(hits > 500, "{hits} rays hit");
    }

    /// Rays straight down onto a 40 mm plane device, where coordinates are
    /// large against f32's rounding: the f32 boxes must keep every triangle
    /// the exact test hits. The first ray went through the lens surface
    /// under obvhs's own traversal (unpadded boxes), 1 ray in 600,000.
    #[test]
    fn no_ray_slips_between_the_f32_boxes() {
        let mut p = DesignParams::with_defaults(PitchSurface::Plane, 40.0, 40.0, 0.5);
        p.profile = Profile::Rings { wavelength: 10.0 };
        let design = Design::new(p).unwrap();
        let dm = mesh_device(&design, &Silent).unwrap();
        let scene = Scene::new(&dm.mesh);
        let corners = |t: u32| dm.mesh.triangles[t as usize].map(|i| dm.mesh.positions[i as usize]);
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
            let want = (0..dm.mesh.triangles.len() as u32)
                .filter_map(|t| watertight(&corners(t), o, d).map(|x| (x, t)))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let got = scene.intersect(o, d, 0.0).map(|h| (h.t, h.triangle));
            assert_eq!(got, want, "ray down from {o}");
        }
    }
}
