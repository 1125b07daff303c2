//! Light through one closed dielectric mesh in air, two ways.
//!
//! - [`trace_branches`], the default: at every interface the ray splits
//!   into its reflected part (Fresnel R, unpolarised) and its refracted part
//!   (1 − R; total internal reflection takes the whole weight), and both
//!   are followed with their weights, so a pixel's colour is the exact
//!   expectation over the branches: no noise. Branches lighter than a
//!   stated weight, or deeper than a stated depth, are dropped and counted.
//! - [`trace_path`], the Monte Carlo reference: one branch chosen at random
//!   with the Fresnel probability (SplitMix64, seeded by the caller). A path
//!   records where it ends, not a colour; the lighting is applied afterwards.

use crate::optics::split;
use crate::scene::{Scene, Side};
use glam::DVec3;

/// SplitMix64 (Steele, Lea and Flood 2014): small, fast, reproducible.
#[derive(Clone, Debug)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// What a ray meets first: how far along it, the surface's outward unit
/// normal there, and whether the surface absorbs (a printed device's bands).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Meeting {
    pub t: f64,
    pub normal: DVec3,
    pub absorbs: bool,
}

/// The surfaces light is traced through: the device's mesh ([`Scene`]), or
/// its exact cross-sections ([`crate::section::Section`]).
pub trait Surfaces {
    /// The nearest surface past `t_min` along `origin + t·dir` (dir unit)
    /// that a ray on `side` can meet: from outside one it enters through,
    /// from inside one it leaves through.
    fn meet(&self, side: Side, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Meeting>;
}

impl Surfaces for Scene<'_> {
    fn meet(&self, side: Side, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Meeting> {
        self.intersect_from(side, origin, dir, t_min)
            .map(|hit| Meeting {
                t: hit.t,
                normal: hit.normal,
                absorbs: self.absorbs(hit.triangle),
            })
    }
}

/// Interfaces a path may cross before it is dropped (it then carries no light).
pub const MAX_BOUNCES: usize = 32;
/// How far (mm) a new segment starts past the surface it leaves.
const EPSILON_MM: f64 = 1e-7;

/// Where a path from the camera goes: the first surface point it meets,
/// and how it ends. Light is linear in the path, so one path serves any
/// lighting (see [`crate::frame::Lighting`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathEnd {
    /// The first point of the mesh the path meets and the outward normal
    /// there; `None` if it misses the mesh.
    pub first: Option<(DVec3, DVec3)>,
    /// The direction the path leaves the mesh in for good (towards the
    /// environment); `None` where it meets an absorbing face or is dropped
    /// after [`MAX_BOUNCES`] interfaces: it then carries no light.
    pub leaves: Option<DVec3>,
}

/// What a ray meets at the device's surface: its reflection, its
/// refraction (none under total internal reflection), the unpolarised
/// Fresnel reflectance, and the side a refracted ray goes on to.
struct Interface {
    reflected: DVec3,
    refracted: Option<DVec3>,
    reflectance: f64,
    through: Side,
}

impl Interface {
    /// The ray `dir` meeting a surface of outward normal `normal` between
    /// air and a medium of `index`, from either side.
    fn meet(dir: DVec3, normal: DVec3, index: f64) -> Interface {
        let leaving = dir.dot(normal) > 0.0;
        let (normal, n1, n2) = if leaving {
            (-normal, index, 1.0)
        } else {
            (normal, 1.0, index)
        };
        let split = split(dir, normal, n1, n2);
        Interface {
            reflected: split.reflected,
            refracted: split.refracted,
            reflectance: split.reflectance,
            through: if leaving { Side::Outside } else { Side::Inside },
        }
    }
}

/// Follows a path from `origin` along `dir` (unit) through the mesh of
/// refractive `index` in air: at every interface it reflects with the
/// Fresnel probability and refracts otherwise.
pub fn trace_path(
    scene: &(impl Surfaces + ?Sized),
    index: f64,
    mut origin: DVec3,
    mut dir: DVec3,
    rng: &mut SplitMix64,
) -> PathEnd {
    let mut first = None;
    // the path starts outside, and crosses the surface where it refracts
    let mut side = Side::Outside;
    for _ in 0..MAX_BOUNCES {
        let Some(hit) = scene.meet(side, origin, dir, EPSILON_MM) else {
            return PathEnd {
                first,
                leaves: Some(dir),
            };
        };
        let point = origin + hit.t * dir;
        first.get_or_insert((point, hit.normal));
        if hit.absorbs {
            break;
        }
        let at = Interface::meet(dir, hit.normal, index);
        dir = match at.refracted {
            Some(t) if rng.next_f64() >= at.reflectance => {
                side = at.through;
                t
            }
            _ => at.reflected,
        };
        origin = point;
    }
    PathEnd {
        first,
        leaves: None,
    }
}

/// When [`trace_branches`] stops following a branch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pruning {
    /// Branches of less weight than this are dropped.
    pub min_weight: f64,
    /// Branches that crossed this many interfaces are dropped.
    pub max_depth: usize,
}

impl Pruning {
    /// 1e-3 of a ray's weight, 16 interfaces: the branches dropped carry
    /// a few thousandths of the light on the shipped designs.
    pub const DEFAULT: Pruning = Pruning {
        min_weight: 1e-3,
        max_depth: 16,
    };
    /// Nothing dropped short of [`MAX_BOUNCES`] (for tests of conservation).
    pub const NONE: Pruning = Pruning {
        min_weight: 0.0,
        max_depth: MAX_BOUNCES,
    };
}

/// What the branches of one camera ray found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Branches {
    /// The first point of the mesh the ray meets and the outward normal there.
    pub first: Option<(DVec3, DVec3)>,
    /// Σ weight × the colour each branch leaving the mesh sees.
    pub colour: DVec3,
    /// Weight that left the mesh (in any direction, lit or not).
    pub left: f64,
    /// Weight absorbed by absorbing faces (a printed device's bands).
    pub absorbed: f64,
    /// Weight dropped by the pruning.
    pub dropped: f64,
    /// The heaviest branch that left the mesh: its direction and weight
    /// (its colour is part of `colour`).
    pub main: Option<(DVec3, f64)>,
}

/// Follows every branch of the ray from `origin` along `dir` (unit) through
/// the mesh of refractive `index` in air, weighting each by the Fresnel
/// reflectance and transmittance, and sums what each branch leaving the
/// mesh sees in direction `d`, `colour_of(d)`. Before pruning, `left +
/// absorbed = 1` up to round-off: the weights are conserved.
pub fn trace_branches(
    scene: &(impl Surfaces + ?Sized),
    index: f64,
    origin: DVec3,
    dir: DVec3,
    colour_of: &dyn Fn(DVec3) -> DVec3,
    pruning: Pruning,
) -> Branches {
    let mut out = Branches {
        first: None,
        colour: DVec3::ZERO,
        left: 0.0,
        absorbed: 0.0,
        dropped: 0.0,
        main: None,
    };
    // (origin, direction, side, weight, interfaces crossed)
    // (depth first: it never holds more than one branch per interface
    // crossed, and one more)
    let mut stack = Vec::with_capacity(pruning.max_depth.min(MAX_BOUNCES) + 2);
    stack.push((origin, dir, Side::Outside, 1.0f64, 0usize));
    while let Some((origin, dir, side, weight, depth)) = stack.pop() {
        let Some(hit) = scene.meet(side, origin, dir, EPSILON_MM) else {
            out.colour += weight * colour_of(dir);
            out.left += weight;
            if out.main.is_none_or(|(_, w)| weight > w) {
                out.main = Some((dir, weight));
            }
            continue;
        };
        let point = origin + hit.t * dir;
        out.first.get_or_insert((point, hit.normal));
        if hit.absorbs {
            out.absorbed += weight;
            continue;
        }
        if depth >= pruning.max_depth {
            out.dropped += weight;
            continue;
        }
        let at = Interface::meet(dir, hit.normal, index);
        let mut branch = |d: DVec3, side: Side, w: f64| {
            if w < pruning.min_weight {
                out.dropped += w;
            } else {
                stack.push((point, d, side, w, depth + 1));
            }
        };
        match at.refracted {
            Some(t) => {
                branch(at.reflected, side, weight * at.reflectance);
                branch(t, at.through, weight * (1.0 - at.reflectance));
            }
            None => branch(at.reflected, side, weight),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::{fresnel, refract};
    use moirecast_kernel::Mesh;

    /// An axis-aligned box from `lo` to `hi`, outward triangles.
    pub(crate) fn cuboid(lo: DVec3, hi: DVec3) -> Mesh {
        let positions = (0..8)
            .map(|i| {
                DVec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                )
            })
            .collect();
        #[rustfmt::skip]
        let triangles = vec![
            [0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
            [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5],
        ];
        Mesh {
            positions,
            triangles,
        }
    }

    /// A wide slab lit from above only, seen from above at normal
    /// incidence: the light returned is the slab's reflectance with
    /// incoherent multiple reflections, 2R / (1 + R) for one face's R.
    #[test]
    fn a_slab_reflects_as_fresnel_and_multiple_reflections_say() {
        let slab = cuboid(DVec3::new(-1e3, -1e3, -1.0), DVec3::new(1e3, 1e3, 0.0));
        let scene = Scene::new(&slab);
        let r = fresnel(1.0, 1.0, 1.41);
        let expected = 2.0 * r / (1.0 + r);
        let n = 200_000;
        let up = |d: DVec3| if d.z > 0.0 { 1.0 } else { 0.0 };
        let total = |seed: u64| -> f64 {
            let mut rng = SplitMix64(seed);
            (0..n)
                .map(|_| {
                    let end =
                        trace_path(&scene, 1.41, DVec3::new(0.1, 0.2, 5.0), -DVec3::Z, &mut rng);
                    end.leaves.map_or(0.0, up)
                })
                .sum()
        };
        let sum = total(7);
        let mean = sum / n as f64;
        let sigma = (expected * (1.0 - expected) / n as f64).sqrt();
        assert!(
            (mean - expected).abs() < 4.0 * sigma,
            "{mean} vs {expected} ± {sigma}"
        );
        // and deterministic for a seed
        let again = total(7);
        assert_eq!(sum, again);
    }

    /// The branches conserve the ray's weight: on a slab, what leaves up
    /// and down and what is dropped add up to 1, and what leaves upwards is
    /// the slab's reflectance with incoherent multiple reflections, 2R / (1 + R).
    #[test]
    fn branches_conserve_weight_on_a_slab() {
        let slab = cuboid(DVec3::new(-1e3, -1e3, -1.0), DVec3::new(1e3, 1e3, 0.0));
        let scene = Scene::new(&slab);
        for angle in [0.0f64, 30.0, 60.0] {
            let a = angle.to_radians();
            let dir = DVec3::new(a.sin(), 0.0, -a.cos());
            let up = |d: DVec3| DVec3::new(if d.z > 0.0 { 1.0 } else { 0.0 }, 0.0, 0.0);
            let b = trace_branches(
                &scene,
                1.41,
                DVec3::new(0.0, 0.0, 5.0),
                dir,
                &up,
                Pruning::NONE,
            );
            assert!(
                (b.left + b.absorbed + b.dropped - 1.0).abs() < 1e-12,
                "{b:?}"
            );
            assert!(b.dropped < 1e-9, "{angle}°: dropped {}", b.dropped);
            assert!((b.left - 1.0).abs() < 1e-9, "{angle}°: {b:?}");
            let r = fresnel(a.cos(), 1.0, 1.41);
            assert!(
                (b.colour.x - 2.0 * r / (1.0 + r)).abs() < 1e-9,
                "{angle}°: {} vs {}",
                b.colour.x,
                2.0 * r / (1.0 + r)
            );
            let pruned = trace_branches(
                &scene,
                1.41,
                DVec3::new(0.0, 0.0, 5.0),
                dir,
                &up,
                Pruning::DEFAULT,
            );
            assert!((pruned.left + pruned.absorbed + pruned.dropped - 1.0).abs() < 1e-12);
            assert!(pruned.dropped < 1e-3);
        }
    }

    /// An oblique ray through the slab, always transmitted (index 1: no
    /// reflection), leaves parallel to itself; with index 1.41 and no
    /// reflection forced, the exit is displaced as Snell's law says.
    #[test]
    fn a_transmitted_ray_leaves_parallel_and_displaced() {
        let slab = cuboid(DVec3::new(-1e3, -1e3, -1.0), DVec3::new(1e3, 1e3, 0.0));
        let scene = Scene::new(&slab);
        let theta: f64 = 40f64.to_radians();
        let d = DVec3::new(theta.sin(), 0.0, -theta.cos());
        let o = DVec3::new(0.0, 0.0, 1.0) - d * (1.0 / theta.cos());
        // follow the transmitted path by hand with the scene's hits
        let h1 = scene.intersect(o, d, 0.0).unwrap();
        let p1 = o + h1.t * d;
        let t = refract(d, h1.normal, 1.0, 1.41).unwrap();
        let h2 = scene.intersect(p1, t, 1e-9).unwrap();
        let p2 = p1 + h2.t * t;
        let out = refract(t, -h2.normal, 1.41, 1.0).unwrap();
        assert!((out - d).length() < 1e-14);
        assert!(p1.z.abs() < 1e-12 && (p2.z + 1.0).abs() < 1e-12);
        let theta_t = (theta.sin() / 1.41).asin();
        assert!((p2.x - p1.x - theta_t.tan()).abs() < 1e-12);
    }
}
