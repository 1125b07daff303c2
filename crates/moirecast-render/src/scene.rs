//! A mesh ready for ray queries: obvhs's compressed wide BVH (f32 bounds)
//! finds candidates, and every candidate is intersected exactly in f64 with
//! a watertight test (Woop, Benthin and Wald, JCGT 2013), so rays do not
//! leak between the triangles of a closed lens surface.

use glam::{DMat3, DVec3, Vec3A};
use moirecast_kernel::Mesh;
use obvhs::cwbvh::{builder::build_cwbvh_from_tris, CwBvh};
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

/// Deepest BVH that obvhs's 32-entry traversal stack holds with room to spare.
const MAX_BVH_DEPTH: u32 = 30;

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
    bvh: CwBvh,
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
                let [a, b, c] = t.map(|i| mesh.positions[i as usize].to_vec3a());
                Triangle {
                    v0: a,
                    v1: b,
                    v2: c,
                }
            })
            .collect();
        let build = |params| build_cwbvh_from_tris(&tris, params, &mut Default::default());
        let mut bvh = build(BvhBuildParams::medium_build());
        // obvhs traverses with a fixed stack of 32 entries that silently
        // overwrites its top when full, which would lose hits. The medium
        // build can go that deep on many long, thin, stacked triangles (a
        // printed device's layers: depth ≥ 32 where the slow build gives 22).
        if depth(&bvh) >= MAX_BVH_DEPTH {
            bvh = build(BvhBuildParams::slow_build());
            let d = depth(&bvh);
            assert!(
                d < MAX_BVH_DEPTH,
                "the BVH is {d} levels deep; obvhs traverses at most {MAX_BVH_DEPTH}"
            );
        }
        let corners = bvh
            .primitive_indices
            .iter()
            .map(|&t| mesh.triangles[t as usize].map(|i| mesh.positions[i as usize]))
            .collect();
        Scene {
            mesh,
            bvh,
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

    /// The nearest hit along `origin + t·dir` with `t > t_min` (dir unit).
    pub fn intersect(&self, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Hit> {
        // the f32 BVH only culls; widen its interval so no f64 hit is lost
        // −0.0 components are made +0.0: obvhs takes the octant from sign
        // bits and the slab inverses from signum, which disagree on −0.0
        // (a ray straight down −z missed every triangle).
        let ray = Ray::new(
            origin.to_vec3a(),
            dir.to_vec3a() + Vec3A::ZERO,
            0.0,
            f32::INFINITY,
        );
        let mut hit = RayHit::none();
        let mut best = (f64::INFINITY, u32::MAX);
        let sheared = ShearedRay::new(origin, dir);
        self.bvh.ray_traverse(ray, &mut hit, |_, id| {
            match sheared.intersect(&self.corners[id]) {
                Some(t) if t > t_min => {
                    let tri = self.bvh.primitive_indices[id];
                    if t < best.0 || (t == best.0 && tri < best.1) {
                        best = (t, tri);
                    }
                    // keep traversing boxes that may hold nearer hits
                    (t as f32).max(0.0) * (1.0 + 1e-6) + 1e-6
                }
                _ => f32::INFINITY,
            }
        });
        (best.1 != u32::MAX).then(|| {
            let [a, b, c] =
                self.mesh.triangles[best.1 as usize].map(|i| self.mesh.positions[i as usize]);
            Hit {
                t: best.0,
                triangle: best.1,
                normal: (b - a).cross(c - a).normalize(),
            }
        })
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

trait ToVec3A {
    fn to_vec3a(self) -> Vec3A;
}

impl ToVec3A for DVec3 {
    fn to_vec3a(self) -> Vec3A {
        Vec3A::new(self.x as f32, self.y as f32, self.z as f32)
    }
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
}
