//! The device posed in the mold frame, its mid-wall curve, and the parting
//! surface (METHOD §6): the device inside the outline, a skirt carried
//! horizontally outward from the mid-wall curve outside it.

use crate::error::{MoldError, Result};
use glam::{DAffine3, DMat3, DVec2, DVec3};
use moirecast_kernel::check::{triangle_altitude, MIN_ALTITUDE_MM};
use moirecast_kernel::mesher::{Patch, Side};
use moirecast_kernel::model::LensRef;
use moirecast_kernel::{Design, DeviceMesh, Mesh};
use std::collections::HashMap;

/// A side of the outline rectangle, in the mold frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Wall {
    XMin,
    XMax,
    YMin,
    YMax,
}

impl Wall {
    pub const ALL: [Wall; 4] = [Wall::YMin, Wall::XMax, Wall::YMax, Wall::XMin];

    pub fn name(self) -> &'static str {
        match self {
            Wall::XMin => "x-min",
            Wall::XMax => "x-max",
            Wall::YMin => "y-min",
            Wall::YMax => "y-max",
        }
    }

    /// Unit outward normal in xy.
    pub fn outward(self) -> DVec2 {
        match self {
            Wall::XMin => DVec2::NEG_X,
            Wall::XMax => DVec2::X,
            Wall::YMin => DVec2::NEG_Y,
            Wall::YMax => DVec2::Y,
        }
    }

    /// The coordinate that runs along the wall.
    pub fn along(self, p: DVec3) -> f64 {
        match self {
            Wall::XMin | Wall::XMax => p.y,
            Wall::YMin | Wall::YMax => p.x,
        }
    }

    /// The point of this wall of `rect` at along-coordinate `t`, height `z`.
    pub fn point(self, rect: &Rect, t: f64, z: f64) -> DVec3 {
        match self {
            Wall::XMin => DVec3::new(rect.x0, t, z),
            Wall::XMax => DVec3::new(rect.x1, t, z),
            Wall::YMin => DVec3::new(t, rect.y0, z),
            Wall::YMax => DVec3::new(t, rect.y1, z),
        }
    }

    /// The along-coordinate range of this wall of `rect`.
    pub fn span(self, rect: &Rect) -> (f64, f64) {
        match self {
            Wall::XMin | Wall::XMax => (rect.y0, rect.y1),
            Wall::YMin | Wall::YMax => (rect.x0, rect.x1),
        }
    }
}

/// An axis-aligned rectangle in xy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    pub x0: f64,
    pub x1: f64,
    pub y0: f64,
    pub y1: f64,
}

impl Rect {
    /// Whether `p` is strictly inside.
    pub fn contains(&self, p: DVec2) -> bool {
        p.x > self.x0 && p.x < self.x1 && p.y > self.y0 && p.y < self.y1
    }

    pub fn grown(&self, by: f64) -> Rect {
        Rect {
            x0: self.x0 - by,
            x1: self.x1 + by,
            y0: self.y0 - by,
            y1: self.y1 + by,
        }
    }
    pub fn centre(&self) -> DVec2 {
        DVec2::new(0.5 * (self.x0 + self.x1), 0.5 * (self.y0 + self.y1))
    }
    /// Signed distance from `p` to the rectangle's boundary: negative inside.
    pub fn signed_distance(&self, p: DVec2) -> f64 {
        let c = self.centre();
        let half = DVec2::new(0.5 * (self.x1 - self.x0), 0.5 * (self.y1 - self.y0));
        let q = (p - c).abs() - half;
        q.max(DVec2::ZERO).length() + q.x.max(q.y).min(0.0)
    }
}

/// Which face of the cavity a device triangle is, in the mold frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Face {
    /// A lens face under the top half (drawn along +z).
    Upper,
    /// A lens face over the bottom half (drawn along −z).
    Lower,
    Wall(Wall),
}

/// Where a vertex of the posed device lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// On a face under the top half (its lenses or the walls' top edges).
    Upper,
    /// On a face over the bottom half.
    Lower,
    /// Halfway up a wall: the parting line, where the skirt starts.
    Mid,
}

/// The device in the mold frame: rotated 180° about x if flipped, scaled by
/// the shrink factor about its outline's centre, its walls split at
/// mid-height (the parting line), so that each half's cavity is a set of
/// the device's own triangles.
pub struct PosedDevice {
    pub mesh: Mesh,
    pub faces: Vec<Face>,
    /// Per triangle, the device mesher's face it is part of.
    pub patches: Vec<Patch>,
    /// Per vertex.
    pub levels: Vec<Level>,
    /// The outline: the xy bounds of the posed device.
    pub outline: Rect,
    /// How the device was posed in the mold frame.
    pub pose: Pose,
}

impl PosedDevice {
    pub fn new(design: &Design, device: &DeviceMesh, flip: bool, scale: f64) -> Result<Self> {
        let (ox0, ox1) = design.outline_x;
        let hh = design.half_height;
        let posed = Pose::of(design, flip, scale);
        let positions: Vec<DVec3> = device
            .mesh
            .positions
            .iter()
            .map(|&p| crate::boolean::f32_exact(posed.apply(p)))
            .collect();
        let mut mesh = Mesh {
            positions,
            triangles: device.mesh.triangles.clone(),
        };
        let mut faces = device
            .patches
            .iter()
            .map(|patch| match patch {
                Patch::Lens(LensRef::Revealer(_)) if !flip => Face::Upper,
                Patch::Lens(LensRef::Base(_)) if flip => Face::Upper,
                Patch::Lens(_) => Face::Lower,
                // From the mesher's side, not the normal: a thin wall
                // triangle's f32 normal can point anywhere (a random
                // cylinder design put an x-max triangle on x-min).
                // Flipping turns the device about x: y-sides swap.
                Patch::Wall(side) => Face::Wall(match (side, flip) {
                    (Side::Left, _) => Wall::XMin,
                    (Side::Right, _) => Wall::XMax,
                    (Side::Front, false) | (Side::Back, true) => Wall::YMin,
                    (Side::Front, true) | (Side::Back, false) => Wall::YMax,
                }),
            })
            .collect();
        let mut patches = device.patches.clone();
        let smoothing = PARTING_SMOOTHING_PERIODS * design.params.period * scale;
        let levels = split_walls(&mut mesh, (&mut faces, &mut patches), smoothing)?;
        // The exact outline, posed (vertices lie on it to the wall snap).
        let (a, b) = (
            posed.apply(DVec3::new(ox0, -hh, 0.0)),
            posed.apply(DVec3::new(ox1, hh, 0.0)),
        );
        let (lo, hi) = (
            crate::boolean::f32_exact(a.min(b)),
            crate::boolean::f32_exact(a.max(b)),
        );
        let outline = Rect {
            x0: lo.x,
            x1: hi.x,
            y0: lo.y,
            y1: hi.y,
        };
        Ok(PosedDevice {
            mesh,
            faces,
            patches,
            levels,
            outline,
            pose: posed,
        })
    }

    /// A point of the design frame in the mold frame.
    pub fn pose(&self, p: DVec3) -> DVec3 {
        self.pose.apply(p)
    }
}

/// The width (σ, in lens periods) of the Gaussian that smooths the
/// parting line along each wall.
const PARTING_SMOOTHING_PERIODS: f64 = 2.0;
/// Where on a rung the parting line may cross it, at the most: a rung's
/// share from either end (where the smooth height leaves the wall).
const RUNG_SHARE: (f64, f64) = (0.2, 0.8);

/// Splits every wall triangle where the parting line crosses its two rungs
/// (its edges from the wall's top edge to its bottom edge): three
/// triangles, wound as the one they replace. Neighbours share a rung, so
/// the split conforms, and the crossings, in order along a wall, are the
/// mid-wall curve. The parting line is smooth: on each wall, the rungs'
/// midpoints' heights averaged along the wall by a Gaussian of σ =
/// `smoothing` (mm). The midpoints themselves zigzag from rung to rung
/// (0.025 mm on `plane-rings`), and a skirt through such a line has a knee
/// at every rung, which OpenCascade's mesher refines without end (holes in
/// the STEP halves at 0.005-0.01 mm). `faces` and `patches` (per
/// triangle) follow. Returns each vertex's level.
fn split_walls(
    mesh: &mut Mesh,
    (faces, patches): (&mut Vec<Face>, &mut Vec<Patch>),
    smoothing: f64,
) -> Result<Vec<Level>> {
    let mut levels = vertex_levels(mesh, faces)?;
    let rungs = wall_rungs(mesh, faces, &levels)?;
    let heights = parting_heights(mesh, faces, &rungs, smoothing);
    let crossings = rung_crossings(mesh, faces, &rungs, &heights);
    let mut mid_of: HashMap<(u32, u32), u32> = HashMap::new();
    let mut mid = |mesh: &mut Mesh, levels: &mut Vec<Level>, a: u32, b: u32| -> u32 {
        let key = (a.min(b), a.max(b));
        *mid_of.entry(key).or_insert_with(|| {
            mesh.positions.push(crossings[&key]);
            levels.push(Level::Mid);
            (mesh.positions.len() - 1) as u32
        })
    };
    let (old_tris, old_faces) = (std::mem::take(&mut mesh.triangles), std::mem::take(faces));
    let old_patches = std::mem::take(patches);
    for (((t, face), patch), rung) in old_tris
        .into_iter()
        .zip(old_faces)
        .zip(old_patches)
        .zip(rungs)
    {
        let (Face::Wall(_), Some((p, q, x))) = (face, rung) else {
            mesh.triangles.push(t);
            faces.push(face);
            patches.push(patch);
            continue;
        };
        let (mp, mq) = (mid(mesh, &mut levels, p, x), mid(mesh, &mut levels, q, x));
        for tri in [[p, q, mq], [p, mq, mp], [mp, mq, x]] {
            mesh.triangles.push(tri);
            faces.push(face);
            patches.push(patch);
        }
    }
    Ok(levels)
}

/// Each vertex's level: on an upper or a lower lens face (the walls' top
/// and bottom edges are both), never both.
fn vertex_levels(mesh: &Mesh, faces: &[Face]) -> Result<Vec<Level>> {
    let n = mesh.positions.len();
    let (mut on_upper, mut on_lower) = (vec![false; n], vec![false; n]);
    for (t, face) in mesh.triangles.iter().zip(faces.iter()) {
        let flags = match face {
            Face::Upper => &mut on_upper,
            Face::Lower => &mut on_lower,
            Face::Wall(_) => continue,
        };
        for &v in t {
            flags[v as usize] = true;
        }
    }
    (0..n)
        .map(|v| match (on_upper[v], on_lower[v]) {
            (true, false) => Ok(Level::Upper),
            (false, true) => Ok(Level::Lower),
            _ => Err(MoldError::NotSolid {
                what: "device walls",
                detail: format!(
                    "vertex {v} at {} is on {} lens faces",
                    mesh.positions[v],
                    if on_upper[v] { "both" } else { "no" }
                ),
            }),
        })
        .collect()
}

/// Per triangle, for a wall triangle, (p, q, x) in its winding: p and q on
/// one edge of the wall, x on the other; (p, x) and (q, x) are its rungs.
type Rungs = Vec<Option<(u32, u32, u32)>>;

fn wall_rungs(mesh: &Mesh, faces: &[Face], levels: &[Level]) -> Result<Rungs> {
    mesh.triangles
        .iter()
        .zip(faces)
        .map(|(t, face)| {
            if !matches!(face, Face::Wall(_)) {
                return Ok(None);
            }
            let level = |k: usize| levels[t[k] as usize];
            let k = (0..3)
                .find(|&k| {
                    level((k + 1) % 3) == level((k + 2) % 3) && level(k) != level((k + 1) % 3)
                })
                .ok_or_else(|| MoldError::NotSolid {
                    what: "device walls",
                    detail: format!(
                        "wall triangle {t:?} does not span from the top edge to the bottom edge"
                    ),
                })?;
            Ok(Some((t[(k + 1) % 3], t[(k + 2) % 3], t[k])))
        })
        .collect()
}

/// Each wall's parting height along it: its rungs' midpoints (along, z),
/// sorted; their polyline smoothed by a Gaussian of σ, tabulated; and the
/// corrections at the wall's two ends (along, added height) that meet its
/// neighbours' at the corners.
struct PartingHeights {
    samples: Vec<(f64, f64)>,
    sigma: f64,
    smooth: Tabulated,
    ends: [(f64, f64); 2],
}

/// A function of the along-coordinate at nodes `start + i·step`, read
/// between them linearly.
struct Tabulated {
    start: f64,
    step: f64,
    values: Vec<f64>,
}

/// Nodes per σ of the tabulated smooth height: its chords stray from the
/// smooth curve by h''·(σ/32)²/8, far below a micrometre.
const NODES_PER_SIGMA: f64 = 32.0;
/// Most nodes of one wall's table (a 20,000-lens wall at 0.05 mm periods
/// still fits).
const MAX_NODES: usize = 1 << 20;

impl PartingHeights {
    /// `samples` sorted by along-coordinate, at least one.
    fn new(samples: Vec<(f64, f64)>, sigma: f64) -> PartingHeights {
        let smooth = Tabulated::smoothed(&samples, sigma);
        PartingHeights {
            samples,
            sigma,
            smooth,
            ends: [(0.0, 0.0); 2],
        }
    }

    /// The smoothed height at along-coordinate `t`, plus each end's
    /// correction under a Gaussian of the same σ.
    fn at(&self, t: f64) -> f64 {
        let bell = |a: f64| (-0.5 * ((a - t) / self.sigma).powi(2)).exp();
        let corrections: f64 = self.ends.iter().map(|&(a, dz)| dz * bell(a)).sum();
        self.smoothed(t) + corrections
    }

    fn smoothed(&self, t: f64) -> f64 {
        self.smooth.at(t)
    }

    /// The wall's first and last along-coordinates (its corners' rungs).
    fn span(&self) -> (f64, f64) {
        (self.samples[0].0, self.samples[self.samples.len() - 1].0)
    }

    /// Sets the end corrections so that the height at the wall's two ends
    /// is `target` exactly: two Gaussians whose tails reach the other end
    /// (a wall a few σ long), solved together.
    fn meet(&mut self, target: (f64, f64)) {
        let (t0, t1) = self.span();
        let r = (target.0 - self.smoothed(t0), target.1 - self.smoothed(t1));
        let g = (-0.5 * ((t1 - t0) / self.sigma).powi(2)).exp();
        let det = 1.0 - g * g;
        self.ends = [(t0, (r.0 - g * r.1) / det), (t1, (r.1 - g * r.0) / det)];
    }
}

impl Tabulated {
    /// The samples' polyline (along, z), smoothed by a Gaussian of σ over
    /// the wall's span: at each node the Gaussian-weighted mean of the
    /// polyline's values at the nodes within 3σ (one-sided at the ends).
    fn smoothed(samples: &[(f64, f64)], sigma: f64) -> Tabulated {
        let (t0, t1) = (samples[0].0, samples[samples.len() - 1].0);
        let nodes = (((t1 - t0) / sigma * NODES_PER_SIGMA).ceil() as usize + 1).clamp(2, MAX_NODES);
        let step = (t1 - t0) / (nodes - 1) as f64;
        let raw: Vec<f64> = (0..nodes)
            .map(|i| polyline_at(samples, t0 + i as f64 * step))
            .collect();
        if step == 0.0 {
            return Tabulated {
                start: t0,
                step: 1.0,
                values: raw,
            };
        }
        let reach = (3.0 * sigma / step).ceil() as isize;
        let weights: Vec<f64> = (-reach..=reach)
            .map(|k| (-0.5 * (k as f64 * step / sigma).powi(2)).exp())
            .collect();
        let values = (0..nodes as isize)
            .map(|i| {
                let (mut sum, mut weight) = (0.0, 0.0);
                for (k, w) in (-reach..=reach).zip(&weights) {
                    if let Some(z) = raw.get((i + k) as usize).filter(|_| i + k >= 0) {
                        sum += w * z;
                        weight += w;
                    }
                }
                sum / weight
            })
            .collect();
        Tabulated {
            start: t0,
            step,
            values,
        }
    }

    fn at(&self, t: f64) -> f64 {
        let x = ((t - self.start) / self.step).clamp(0.0, (self.values.len() - 1) as f64);
        let i = (x as usize).min(self.values.len() - 2);
        let f = x - i as f64;
        self.values[i] + f * (self.values[i + 1] - self.values[i])
    }
}

/// The polyline through `samples` (sorted by along) at `t`, clamped at its
/// ends; where two samples share an along-coordinate (a vertical rung
/// pair), the later one.
fn polyline_at(samples: &[(f64, f64)], t: f64) -> f64 {
    let j = samples.partition_point(|s| s.0 <= t);
    if j == 0 {
        return samples[0].1;
    }
    if j == samples.len() {
        return samples[j - 1].1;
    }
    let ((a0, z0), (a1, z1)) = (samples[j - 1], samples[j]);
    z0 + (z1 - z0) * (t - a0) / (a1 - a0)
}

/// The walls meeting at each corner, and which of their ends (false: the
/// first along the wall) is there: as [`wall_curves`] checks them.
const CORNERS: [((Wall, bool), (Wall, bool)); 4] = [
    ((Wall::YMin, false), (Wall::XMin, false)),
    ((Wall::YMin, true), (Wall::XMax, false)),
    ((Wall::YMax, true), (Wall::XMax, true)),
    ((Wall::YMax, false), (Wall::XMin, true)),
];

/// Makes the walls' smoothed heights meet at the corners: each corner at
/// the mean of its two walls' (a corner's rung is both walls', and a
/// mismatch there made the parting line drop 0.02 mm within 2.4e-5 mm
/// along, found-84f9858ee9297332, where the block's side cannot zip).
fn meet_at_corners(heights: &mut HashMap<Wall, PartingHeights>) {
    let end_height = |h: &PartingHeights, last: bool| {
        let (t0, t1) = h.span();
        h.smoothed(if last { t1 } else { t0 })
    };
    let mut targets: HashMap<(Wall, bool), f64> = HashMap::new();
    for (a, b) in CORNERS {
        let (Some(ha), Some(hb)) = (heights.get(&a.0), heights.get(&b.0)) else {
            continue;
        };
        let corner = 0.5 * (end_height(ha, a.1) + end_height(hb, b.1));
        targets.insert(a, corner);
        targets.insert(b, corner);
    }
    for (&wall, h) in heights.iter_mut() {
        let own = |last: bool| targets.get(&(wall, last)).copied();
        let first = own(false).unwrap_or_else(|| end_height(h, false));
        let last = own(true).unwrap_or_else(|| end_height(h, true));
        h.meet((first, last));
    }
}

/// A wall's rung midpoints (along, z), keyed by the rung's two vertices so
/// that a rung shared by two triangles counts once.
type RungMidpoints = HashMap<(u32, u32), (f64, f64)>;

fn parting_heights(
    mesh: &Mesh,
    faces: &[Face],
    rungs: &Rungs,
    sigma: f64,
) -> HashMap<Wall, PartingHeights> {
    let mut samples: HashMap<Wall, RungMidpoints> = HashMap::new();
    for (rung, face) in rungs.iter().zip(faces) {
        let (Some((p, q, x)), Face::Wall(wall)) = (*rung, *face) else {
            continue;
        };
        for a in [p, q] {
            let m = 0.5 * (mesh.positions[a as usize] + mesh.positions[x as usize]);
            samples
                .entry(wall)
                .or_default()
                .insert((a.min(x), a.max(x)), (wall.along(m), m.z));
        }
    }
    let mut heights: HashMap<Wall, PartingHeights> = samples
        .into_iter()
        .map(|(wall, by_rung)| {
            let mut samples: Vec<(f64, f64)> = by_rung.into_values().collect();
            samples.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
            (wall, PartingHeights::new(samples, sigma))
        })
        .collect();
    meet_at_corners(&mut heights);
    heights
}

/// Where the parting line crosses each wall rung (keyed by its two
/// vertices, in f32): at the wall's smoothed height ([`rung_share`]), in
/// the rungs' order along the wall. Where two neighbours' crossings would
/// swap or meet along the wall (a rung that runs along as far as it rises,
/// on a low wall), both move halfway back to their midpoints, whose order
/// is the rungs' own, until none do (after [`ORDER_ROUNDS`], the whole
/// wall takes its midpoints). A rung at a corner belongs to two
/// walls and stands vertical: the first wall in [`Wall::ALL`] places it.
fn rung_crossings(
    mesh: &Mesh,
    faces: &[Face],
    rungs: &Rungs,
    heights: &HashMap<Wall, PartingHeights>,
) -> HashMap<(u32, u32), DVec3> {
    let mut per_wall: HashMap<Wall, Vec<(u32, u32)>> = HashMap::new();
    for (rung, face) in rungs.iter().zip(faces) {
        if let (Some((p, q, x)), Face::Wall(wall)) = (*rung, *face) {
            let list = per_wall.entry(wall).or_default();
            list.extend([(p.min(x), p.max(x)), (q.min(x), q.max(x))]);
        }
    }
    let at = |v: u32| mesh.positions[v as usize];
    let mut crossings = HashMap::new();
    for wall in Wall::ALL {
        let Some(mut keys) = per_wall.remove(&wall) else {
            continue;
        };
        let mid_along = |k: &(u32, u32)| wall.along(0.5 * (at(k.0) + at(k.1)));
        keys.sort_by(|a, b| mid_along(a).total_cmp(&mid_along(b)).then(a.cmp(b)));
        keys.dedup();
        keys.retain(|k| !crossings.contains_key(k));
        let ends: Vec<(DVec3, DVec3)> = keys.iter().map(|k| (at(k.0), at(k.1))).collect();
        let mut shares: Vec<f64> = ends
            .iter()
            .map(|&(a, b)| rung_share(&heights[&wall], a, b, wall))
            .collect();
        let point = |i: usize, s: f64| {
            let (a, b) = ends[i];
            crate::boolean::f32_exact(a + s * (b - a))
        };
        for round in 0..=ORDER_ROUNDS {
            let swapped: Vec<usize> = (1..keys.len())
                .filter(|&i| {
                    wall.along(point(i, shares[i])) <= wall.along(point(i - 1, shares[i - 1]))
                })
                .collect();
            if swapped.is_empty() {
                break;
            }
            if round == ORDER_ROUNDS {
                // the midpoints' own order, which the rungs have
                shares.iter_mut().for_each(|s| *s = 0.5);
                break;
            }
            for i in swapped {
                for j in [i - 1, i] {
                    shares[j] = 0.5 * (shares[j] + 0.5);
                }
            }
        }
        for (i, key) in keys.into_iter().enumerate() {
            crossings.insert(key, point(i, shares[i]));
        }
    }
    crossings
}

/// Rounds that move swapped crossings halfway back to their midpoints
/// before the whole wall is put on them.
const ORDER_ROUNDS: usize = 8;

/// Where the parting line crosses the rung from `a` to `b` of `wall`, as
/// a share of the rung from `a`, within [`RUNG_SHARE`]: where the rung
/// meets the wall's smoothed height (bisection), or, where it does not
/// within those shares (a low wall, or a rung that runs along as steeply
/// as the line does, on a sloping surface), the share of the smoothed
/// height at the rung's middle, clamped.
fn rung_share(heights: &PartingHeights, a: DVec3, b: DVec3, wall: Wall) -> f64 {
    let rise = b.z - a.z;
    if rise == 0.0 {
        return 0.5;
    }
    let gap = |s: f64| {
        let p = a + s * (b - a);
        p.z - heights.at(wall.along(p))
    };
    let (mut lo, mut hi) = RUNG_SHARE;
    let (g_lo, g_hi) = (gap(lo), gap(hi));
    if g_lo * g_hi > 0.0 {
        let middle = 0.5 * (a + b);
        let s = (heights.at(wall.along(middle)) - a.z) / rise;
        return s.clamp(RUNG_SHARE.0, RUNG_SHARE.1);
    }
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (lo + hi);
        if (gap(mid) > 0.0) == (g_lo > 0.0) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Halvings of a rung's share range (0.6 / 2²⁴: 4e-8 of the rung).
const BISECTION_STEPS: usize = 24;

/// The map from the design frame to the mold frame: a turn of 180° about
/// the x axis through `centre` if `flip`, then a scale by `scale` about
/// `centre` (the outline's centre at z = 0). A proper similarity: it keeps
/// every solid's orientation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub centre: DVec3,
    pub flip: bool,
    pub scale: f64,
}

impl Pose {
    /// The pose of `design` in its mold.
    pub fn of(design: &Design, flip: bool, scale: f64) -> Pose {
        let (ox0, ox1) = design.outline_x;
        Pose {
            centre: DVec3::new(0.5 * (ox0 + ox1), 0.0, 0.0),
            flip,
            scale,
        }
    }

    /// A point of the design frame in the mold frame. A proper rotation
    /// (det +1) keeps the triangles' orientation.
    pub fn apply(&self, p: DVec3) -> DVec3 {
        let q = p - self.centre;
        let q = if self.flip {
            DVec3::new(q.x, -q.y, -q.z)
        } else {
            q
        };
        self.centre + self.scale * q
    }

    /// The same map as an affine transform (for exact geometry: NURBS
    /// control points map as points).
    pub fn affine(&self) -> DAffine3 {
        let turn = if self.flip {
            DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0))
        } else {
            DMat3::IDENTITY
        };
        let linear = turn * self.scale;
        DAffine3::from_mat3_translation(linear, self.centre - linear * self.centre)
    }
}

/// A piecewise-linear function z(t) with strictly increasing t.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Polyline {
    pub t: Vec<f64>,
    pub z: Vec<f64>,
}

impl Polyline {
    /// Linear interpolation, clamped at the ends.
    pub fn eval(&self, t: f64) -> f64 {
        let i = self.t.partition_point(|&x| x <= t);
        if i == 0 {
            return self.z[0];
        }
        if i >= self.t.len() {
            return *self.z.last().expect("non-empty polyline");
        }
        let (t0, t1) = (self.t[i - 1], self.t[i]);
        let s = (t - t0) / (t1 - t0);
        self.z[i - 1] + s * (self.z[i] - self.z[i - 1])
    }

    /// Smallest and largest z over [a, b] (breakpoints and ends).
    pub fn range(&self, a: f64, b: f64) -> (f64, f64) {
        let mut lo = self.eval(a).min(self.eval(b));
        let mut hi = self.eval(a).max(self.eval(b));
        for (t, z) in self.t.iter().zip(&self.z) {
            if *t > a && *t < b {
                lo = lo.min(*z);
                hi = hi.max(*z);
            }
        }
        (lo, hi)
    }
}

/// The top and bottom edges of one wall and the mid-wall curve between them.
#[derive(Clone, Debug)]
pub struct WallCurves {
    pub wall: Wall,
    pub upper: Polyline,
    pub lower: Polyline,
    /// Halfway up the meshed wall: through the midpoints of its rungs (its
    /// edges from the top edge to the bottom edge), which are vertices of
    /// the split wall.
    pub mid: Polyline,
    /// Those vertices' positions, in order along the wall, ends included.
    pub mid_points: Vec<DVec3>,
}

/// The four walls' edge curves, read off the posed mesh.
pub fn wall_curves(device: &PosedDevice) -> Result<Vec<WallCurves>> {
    let n = device.mesh.positions.len();
    let rect = device.outline;
    let mut curves: Vec<WallCurves> = Vec::new();
    for wall in Wall::ALL {
        let mut seen = vec![false; n];
        let (mut upper, mut lower, mut mid) = (Vec::new(), Vec::new(), Vec::new());
        let mut mid_points: Vec<DVec3> = Vec::new();
        for (t, face) in device.mesh.triangles.iter().zip(&device.faces) {
            if *face != Face::Wall(wall) {
                continue;
            }
            for &v in t {
                let v = v as usize;
                if std::mem::replace(&mut seen[v], true) {
                    continue;
                }
                let p = device.mesh.positions[v];
                match device.levels[v] {
                    Level::Upper => upper.push((wall.along(p), p.z)),
                    Level::Lower => lower.push((wall.along(p), p.z)),
                    Level::Mid => mid.push((wall.along(p), p.z)),
                }
                if device.levels[v] == Level::Mid {
                    mid_points.push(p);
                }
            }
        }
        let span = wall.span(&rect);
        mid_points.sort_by(|a, b| wall.along(*a).total_cmp(&wall.along(*b)));
        curves.push(WallCurves {
            wall,
            upper: polyline(wall, upper, span)?,
            lower: polyline(wall, lower, span)?,
            mid: polyline(wall, mid, span)?,
            mid_points,
        });
    }
    // The corners: both walls meeting there share the corner's vertical
    // edge and so its midpoint; check they agree.
    for (a, b, a_end, b_end) in [
        (0usize, 3usize, false, false), // y-min start, x-min start: (x0, y0)
        (0, 1, true, false),            // y-min end, x-max start: (x1, y0)
        (2, 1, true, true),             // y-max end, x-max end: (x1, y1)
        (2, 3, false, true),            // y-max start, x-min end: (x0, y1)
    ] {
        let end_z = |c: usize, end: bool| {
            let z = &curves[c].mid.z;
            if end {
                z[z.len() - 1]
            } else {
                z[0]
            }
        };
        let end_p = |c: usize, end: bool| {
            let m = &curves[c].mid_points;
            if end {
                m[m.len() - 1]
            } else {
                m[0]
            }
        };
        let (za, zb) = (end_z(a, a_end), end_z(b, b_end));
        if za != zb || end_p(a, a_end) != end_p(b, b_end) {
            return Err(MoldError::NotSolid {
                what: "device walls",
                detail: format!("mid-wall heights {za} and {zb} disagree at a corner"),
            });
        }
    }
    Ok(curves)
}

/// How far a wall edge's ends may sit from the outline's corners: the
/// mesher snaps crease-wall crossings by up to `WALL_SNAP_MM`.
const EDGE_SPAN_SLACK_MM: f64 = 1e-4;

/// Sorts wall-edge samples into a polyline spanning exactly `span`.
fn polyline(wall: Wall, mut pts: Vec<(f64, f64)>, span: (f64, f64)) -> Result<Polyline> {
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts.dedup_by(|a, b| a.0 == b.0 && a.1 == b.1);
    let bad = |detail: String| MoldError::NotSolid {
        what: "device walls",
        detail: format!("{} wall: {detail}", wall.name()),
    };
    if pts.len() < 2 {
        return Err(bad("fewer than two edge vertices".into()));
    }
    if let Some(w) = pts.windows(2).find(|w| w[0].0 == w[1].0) {
        return Err(bad(format!(
            "an edge is not a graph along the wall: two points at {} (heights {} and {})",
            w[0].0, w[0].1, w[1].1
        )));
    }
    let (first, last) = (pts[0].0, pts[pts.len() - 1].0);
    if (first - span.0).abs() > EDGE_SPAN_SLACK_MM || (last - span.1).abs() > EDGE_SPAN_SLACK_MM {
        return Err(bad(format!(
            "edge spans [{first}, {last}], the outline [{}, {}]",
            span.0, span.1
        )));
    }
    let n = pts.len();
    pts[0].0 = span.0;
    pts[n - 1].0 = span.1;
    Ok(Polyline {
        t: pts.iter().map(|p| p.0).collect(),
        z: pts.iter().map(|p| p.1).collect(),
    })
}

/// Vertical ray casts into a set of triangles that form a graph over xy:
/// a uniform bucket grid over their xy bounds.
pub struct HeightQuery<'a> {
    mesh: &'a Mesh,
    tris: Vec<u32>,
    cells: Vec<(u32, u32)>,
    lo: DVec2,
    cell: DVec2,
    n: (usize, usize),
}

impl<'a> HeightQuery<'a> {
    pub fn new(mesh: &'a Mesh, selected: impl Iterator<Item = usize>) -> Self {
        let selected: Vec<usize> = selected.collect();
        let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for &t in &selected {
            for v in mesh.triangles[t] {
                let p = mesh.positions[v as usize].truncate();
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        let side = ((selected.len() as f64).sqrt() / 2.0).ceil().max(1.0) as usize;
        let n = (side, side);
        let cell = (hi - lo).max(DVec2::splat(1e-9)) / DVec2::new(n.0 as f64, n.1 as f64);
        let bucket = |p: DVec2| {
            let q = ((p - lo) / cell).floor();
            (
                (q.x.max(0.0) as usize).min(n.0 - 1),
                (q.y.max(0.0) as usize).min(n.1 - 1),
            )
        };
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); n.0 * n.1];
        for &t in &selected {
            let ps = mesh.triangles[t].map(|v| mesh.positions[v as usize].truncate());
            let (a, b) = (
                bucket(ps[0].min(ps[1]).min(ps[2])),
                bucket(ps[0].max(ps[1]).max(ps[2])),
            );
            for j in a.1..=b.1 {
                for i in a.0..=b.0 {
                    lists[j * n.0 + i].push(t as u32);
                }
            }
        }
        let mut tris = Vec::new();
        let mut cells = Vec::with_capacity(lists.len());
        for l in lists {
            cells.push((tris.len() as u32, l.len() as u32));
            tris.extend(l);
        }
        HeightQuery {
            mesh,
            tris,
            cells,
            lo,
            cell,
            n,
        }
    }

    /// The height of the surface above (x, y), if a triangle covers it.
    pub fn height(&self, p: DVec2) -> Option<f64> {
        let q = ((p - self.lo) / self.cell).floor();
        if q.x < -1.0 || q.y < -1.0 {
            return None;
        }
        let (i, j) = (
            (q.x.max(0.0) as usize).min(self.n.0 - 1),
            (q.y.max(0.0) as usize).min(self.n.1 - 1),
        );
        let (start, len) = self.cells[j * self.n.0 + i];
        for &t in &self.tris[start as usize..(start + len) as usize] {
            let [a, b, c] =
                self.mesh.triangles[t as usize].map(|v| self.mesh.positions[v as usize]);
            let d = (b - a).truncate().perp_dot((c - a).truncate());
            if d == 0.0 {
                continue;
            }
            let l1 = (p - a.truncate()).perp_dot((c - a).truncate()) / d;
            let l2 = (b - a).truncate().perp_dot(p - a.truncate()) / d;
            let l0 = 1.0 - l1 - l2;
            const EPS: f64 = -1e-12;
            if l0 >= EPS && l1 >= EPS && l2 >= EPS {
                return Some(l0 * a.z + l1 * b.z + l2 * c.z);
            }
        }
        None
    }
}

/// Builds a closed mesh from triangles given with the outward direction they
/// must face; identical positions share one vertex. Every triangle is
/// labelled with `surface`, the surface it is being built on.
#[derive(Default)]
pub struct SolidBuilder {
    pub mesh: Mesh,
    index: rustc_hash::FxHashMap<[u64; 3], u32>,
    /// The surface the triangles added next lie on.
    pub surface: RegionSurface,
    /// Per triangle, the surface it lies on.
    pub surfaces: Vec<RegionSurface>,
}

/// The surface a parting region's triangle lies on: what an exact B-rep of
/// the region makes its faces of.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum RegionSurface {
    /// One of the device's faces (the region's `device_faces` says which).
    Device,
    /// A wall's skirt: its mid curve carried horizontally outward.
    Skirt(Wall),
    /// The flat square at a corner of the skirt, counter-clockwise from
    /// (x min, y min), as `Skirt::corners`.
    Corner(usize),
    /// The side of a registration key's bump standing on corner square k:
    /// its first half of facets (0) or its second (1), so that an exact
    /// B-rep's cone and the circles it meets have seams to start from.
    BumpSide(usize, usize),
    /// The top of that bump.
    BumpTop(usize),
    /// The floor through the device's interior ([`Floor::Grid`]).
    Grid,
    /// A side of the block, beyond this wall.
    Side(Wall),
    /// The block's top or bottom face.
    #[default]
    Cap,
}

impl SolidBuilder {
    pub fn vertex(&mut self, p: DVec3) -> u32 {
        let p = crate::boolean::f32_exact(p);
        let key = p.to_array().map(|c| (c + 0.0).to_bits());
        *self.index.entry(key).or_insert_with(|| {
            self.mesh.positions.push(p);
            (self.mesh.positions.len() - 1) as u32
        })
    }

    /// Adds triangle (a, b, c), wound so its normal faces `outward`.
    pub fn triangle(&mut self, a: DVec3, b: DVec3, c: DVec3, outward: DVec3) {
        let n = (b - a).cross(c - a);
        let (ia, ib, ic) = (self.vertex(a), self.vertex(b), self.vertex(c));
        if n.dot(outward) >= 0.0 {
            self.mesh.triangles.push([ia, ib, ic]);
        } else {
            self.mesh.triangles.push([ia, ic, ib]);
        }
        self.surfaces.push(self.surface);
    }

    /// A vertex no other call will share: one the caller indexes itself.
    pub fn unshared_vertex(&mut self, p: DVec3) -> u32 {
        self.mesh.positions.push(crate::boolean::f32_exact(p));
        (self.mesh.positions.len() - 1) as u32
    }

    pub fn quad(&mut self, a: DVec3, b: DVec3, c: DVec3, d: DVec3, outward: DVec3) {
        self.triangle(a, b, c, outward);
        self.triangle(a, c, d, outward);
    }
}

/// Closest spacing (mm) of the points along a region's top edge. The
/// floor's border may hold points a few 1e-5 mm apart (a crease just
/// outside the wall snap, its rung then split at mid-wall), and the cap's
/// fan from the footprint's centre meets such a pair at a shallow angle: a
/// sliver. Each side instead zips the whole border to a top edge thinned to
/// this spacing; its triangles stand nearly upright, the cap being at least
/// a wall's thickness (1 mm) above the border.
const TOP_EDGE_SPACING_MM: f64 = 0.1;

/// The points of `border` (increasing `along`, ends at the footprint's
/// corners) kept on the top edge at `top_z`: both ends, and between them
/// each point [`TOP_EDGE_SPACING_MM`] past the last one kept and short of
/// the far end by as much.
fn top_edge(border: &[DVec3], along: impl Fn(DVec3) -> f64, top_z: f64) -> Vec<DVec3> {
    let (first, last) = (border[0], border[border.len() - 1]);
    let mut kept = vec![first];
    for &p in &border[1..border.len() - 1] {
        let since = along(p) - along(kept[kept.len() - 1]);
        if since >= TOP_EDGE_SPACING_MM && along(last) - along(p) >= TOP_EDGE_SPACING_MM {
            kept.push(p);
        }
    }
    kept.push(last);
    kept.into_iter()
        .map(|p| DVec3::new(p.x, p.y, top_z))
        .collect()
}

/// The smallest altitude of `triangles` (infinite for none).
fn thinnest(triangles: &[[DVec3; 3]]) -> f64 {
    triangles
        .iter()
        .map(|&t| triangle_altitude(t))
        .fold(f64::INFINITY, f64::min)
}

/// How far into the ring, as a share of the distance from a wall's mid
/// curve to the grid's first row, [`ring_strip`]'s middle chain lies; its
/// points are as far apart. Towards a corner, where the ring narrows to a
/// wedge, both shrink with the wedge's width.
const RING_MIDDLE_SHARE: f64 = 0.25;

/// The ring between a wall's mid curve `outer` and the grid's row or
/// column `inner` next to it, zipped. Where two mid points lie a few
/// 1e-5 mm apart (a base crease 6e-5 mm inside the outline, its rungs
/// split at mid-wall), a grid node a cell away meets them at a shallow
/// angle: a sliver (found-78b8f12bc8bf0892: 7.4e-6 mm, from a node 3 mm
/// along the wall). There the ring takes a middle chain, the mid curve
/// thinned and moved in by [`RING_MIDDLE_SHARE`] of the ring's local
/// width: it meets the mid points nearly square and the grid as sparsely
/// as the grid is. The plain zip stays wherever the middle chain is no
/// thicker, so a ring without slivers is unchanged.
fn ring_strip(
    b: &mut SolidBuilder,
    outer: &[DVec3],
    inner: &[DVec3],
    along: impl Fn(DVec3) -> f64,
    down: DVec3,
) {
    let mut triangles = zipped(outer, inner, &along, true);
    if thinnest(&triangles) < CORNER_SLIVER_MM {
        let middle = middle_chain(outer, inner, &along);
        if middle.len() > 2 {
            // the middle chain shares its ends with the mid curve: between
            // them the mid curve zips to its inner points
            let mut t = zipped(outer, &middle[1..middle.len() - 1], &along, false);
            t.extend(zipped(&middle, inner, &along, false));
            let faces = |t: &[DVec3; 3]| (t[1] - t[0]).cross(t[2] - t[0]).dot(down) > 0.0;
            let upright = faces(&triangles[0]);
            if thinnest(&t) > thinnest(&triangles) && t.iter().all(|t| faces(t) == upright) {
                triangles = t;
            }
        }
    }
    for [p, q, r] in triangles {
        b.triangle(p, q, r, down);
    }
}

/// [`ring_strip`]'s middle chain: the ends of `outer`, and between them its
/// points thinned to the local depth and moved that far towards `inner`
/// (heights on the way to the inner chain's). The depth is
/// [`RING_MIDDLE_SHARE`] of the ring's width, narrowing towards the ends
/// in proportion to the corner wedge between the wall and the line from
/// the mid curve's end to the inner chain's.
fn middle_chain(outer: &[DVec3], inner: &[DVec3], along: &impl Fn(DVec3) -> f64) -> Vec<DVec3> {
    let (o0, o1) = (outer[0], outer[outer.len() - 1]);
    let (n0, n1) = (inner[0], inner[inner.len() - 1]);
    let wall = (o1 - o0).truncate().normalize();
    let across = (n0 - o0).truncate();
    let inward = across - across.dot(wall) * wall;
    let width = inward.length();
    let inward = inward / width;
    let depth = |a: f64| {
        let wedge = ((a - along(o0)) / (along(n0) - along(o0)))
            .min((along(o1) - a) / (along(o1) - along(n1)))
            .min(1.0);
        RING_MIDDLE_SHARE * width * wedge
    };
    // the inner chain is a straight row of the grid: its height at `at`
    let inner_z = |at: f64| {
        let k = inner
            .partition_point(|&p| along(p) < at)
            .clamp(1, inner.len() - 1);
        let (p, q) = (inner[k - 1], inner[k]);
        let s = ((at - along(p)) / (along(q) - along(p))).clamp(0.0, 1.0);
        p.z + s * (q.z - p.z)
    };
    let mut middle = vec![o0];
    let mut last_kept = along(o0);
    for &p in &outer[1..outer.len() - 1] {
        let a = along(p);
        let d = depth(a);
        if d > 0.0 && a - last_kept >= d && along(o1) - a >= d {
            last_kept = a;
            let moved = p.truncate() + d * inward;
            middle.push(moved.extend(p.z + d / width * (inner_z(a) - p.z)));
        }
    }
    middle.push(o1);
    middle
}

/// Zips two polylines that run side by side (a strip between two parallel
/// segments) into triangles, advancing whichever is behind.
fn zip_strip(
    b: &mut SolidBuilder,
    outer: &[DVec3],
    inner: &[DVec3],
    along: impl Fn(DVec3) -> f64,
    outward: DVec3,
) {
    for [p, q, r] in zipped(outer, inner, &along, true) {
        b.triangle(p, q, r, outward);
    }
}

/// [`zip_strip`]'s triangles, in order. With `normalized`, each chain's
/// along-coordinate runs from 0 to 1 over it (chains of different lengths
/// side by side); else both advance by the coordinate itself.
fn zipped(
    outer: &[DVec3],
    inner: &[DVec3],
    along: &impl Fn(DVec3) -> f64,
    normalized: bool,
) -> Vec<[DVec3; 3]> {
    let norm = |pts: &[DVec3], k: usize| {
        if !normalized {
            return along(pts[k]);
        }
        let (s, e) = (along(pts[0]), along(pts[pts.len() - 1]));
        (along(pts[k]) - s) / (e - s)
    };
    let mut triangles = Vec::with_capacity(outer.len() + inner.len());
    let (mut i, mut j) = (0, 0);
    while i + 1 < outer.len() || j + 1 < inner.len() {
        let advance_outer = if i + 1 == outer.len() {
            false
        } else if j + 1 == inner.len() {
            true
        } else {
            norm(outer, i + 1) <= norm(inner, j + 1)
        };
        if advance_outer {
            triangles.push([outer[i], outer[i + 1], inner[j]]);
            i += 1;
        } else {
            triangles.push([outer[i], inner[j + 1], inner[j]]);
            j += 1;
        }
    }
    triangles
}

/// Which side of the parting surface a region lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PartSide {
    Above,
    Below,
}

/// What a parting region's floor is inside the outline.
pub enum Floor<'a> {
    /// Through the device's interior: the mid height between the device's
    /// faces at the nodes of a grid of `cells`, zipped to the mid-wall
    /// curves. Cut away with the device, this region gives the half
    /// before its channels, as METHOD §6 states it: another tool rebuilds
    /// the halves from it.
    Grid {
        interior_mid: &'a dyn Fn(DVec2) -> f64,
        cells: (usize, usize),
    },
    /// The device's own faces on this side of the parting line, reversed:
    /// the region is then the half before its channels, with no boolean.
    Device(&'a PosedDevice),
}

/// A registration key's bump, built into the bottom half's region (which
/// saves a boolean pass over the whole half): the part of its frustum above
/// the corner square's plane. `bottom` and `top` are the frustum's rings,
/// vertex k of one over vertex k of the other, counter-clockwise seen from
/// above.
pub struct Bump {
    pub centre: DVec2,
    pub bottom: Vec<DVec3>,
    pub top: Vec<DVec3>,
}

impl Bump {
    /// Where the frustum's side edges cross the plane `z`.
    fn foot(&self, z: f64) -> Vec<DVec3> {
        self.bottom
            .iter()
            .zip(&self.top)
            .map(|(&a, &b)| {
                let s = (z - a.z) / (b.z - a.z);
                (a + s * (b - a)).truncate().extend(z)
            })
            .collect()
    }

    /// Whether the bump stands in the axis-aligned square with corners `a`, `b`.
    fn in_square(&self, a: DVec3, b: DVec3) -> bool {
        let (lo, hi) = (
            a.truncate().min(b.truncate()),
            a.truncate().max(b.truncate()),
        );
        self.centre.cmpgt(lo).all() && self.centre.cmplt(hi).all()
    }
}

/// The corner square `square` with the foot of `bump` cut out of it, and
/// the bump's side and top. The square is fanned from each corner to the
/// stretch of the foot ring facing it, and closed along each side by a
/// triangle to the ring vertex facing that side's middle; the foot lies
/// within the square's inscribed circle (the keys' placement checks that),
/// so every corner sees its stretch of the ring.
fn square_with_bump(
    b: &mut SolidBuilder,
    (k, square): (usize, [DVec3; 4]),
    bump: &Bump,
    down: DVec3,
) {
    let c = bump.centre;
    let angle = |p: DVec3| (p.y - c.y).atan2(p.x - c.x);
    let mut sq = square;
    sq.sort_by(|p, q| angle(*p).total_cmp(&angle(*q)));
    let ring = bump.foot(square[0].z);
    let n = ring.len();
    // per side of the square, the ring vertex facing its middle
    let facing: Vec<usize> = (0..4)
        .map(|i| {
            let mid = 0.5 * (sq[i] + sq[(i + 1) % 4]).truncate() - c;
            (0..n)
                .max_by(|&j, &k| {
                    let d = |v: usize| (ring[v].truncate() - c).normalize().dot(mid.normalize());
                    d(j).total_cmp(&d(k))
                })
                .expect("a ring")
        })
        .collect();
    b.surface = RegionSurface::Corner(k);
    for i in 0..4 {
        let (corner, next) = (sq[(i + 1) % 4], facing[(i + 1) % 4]);
        b.triangle(sq[i], corner, ring[facing[i]], down);
        let mut r = facing[i];
        while r != next {
            b.triangle(corner, ring[r], ring[(r + 1) % n], down);
            r = (r + 1) % n;
        }
    }
    let up = DVec3::Z;
    for j in 0..n {
        let (p, q) = (ring[j], ring[(j + 1) % n]);
        let (pt, qt) = (bump.top[j], bump.top[(j + 1) % n]);
        let out = (0.5 * (p + q).truncate() - c).extend(0.0);
        b.surface = RegionSurface::BumpSide(k, 2 * j / n);
        b.quad(p, q, qt, pt, out);
        b.surface = RegionSurface::BumpTop(k);
        b.triangle(c.extend(pt.z), pt, qt, up);
    }
}

/// A parting region: a closed solid, and which of its triangles are the
/// device's (the first `device_faces.len()`, in that order).
pub struct Region {
    pub mesh: Mesh,
    /// The device triangle each of the region's first triangles is, reversed.
    pub device_faces: Vec<u32>,
    /// Per triangle, the surface it lies on.
    pub surfaces: Vec<RegionSurface>,
    /// Per vertex of a device face, the posed device's vertex it is (the
    /// others: `u32::MAX`).
    pub device_vertices: Vec<u32>,
}

/// The block's part on one side of the parting surface, as a closed solid
/// over `footprint` (the block's), from the parting surface to `cap_z` (the
/// block's top or bottom face). Regions on the two sides share the parting
/// surface's vertices exactly; the device's faces, the two regions with a
/// device floor and the device tile the block.
///
/// Outside the outline its floor is the skirt: each wall's mid curve carried
/// horizontally outward, flat over the corners. Inside, it is `floor`.
/// Each of `bumps` stands on the corner square it is in (the bottom half's
/// registration keys); the tiling holds only without them.
pub fn parting_region(
    walls: &[WallCurves],
    floor: Floor,
    footprint: &Rect,
    cap_z: f64,
    side: PartSide,
    bumps: &[Bump],
) -> Region {
    // Outward from the region: through the parting surface, and through the cap.
    let (down, cap_out) = match side {
        PartSide::Above => (DVec3::NEG_Z, DVec3::Z),
        PartSide::Below => (DVec3::Z, DVec3::NEG_Z),
    };
    let mut b = SolidBuilder::default();
    let skirt = Skirt { walls, footprint };
    // The device's faces first, so that they keep their indices.
    let (device_faces, device_vertices) = match &floor {
        Floor::Device(device) => device_floor(&mut b, device, side),
        Floor::Grid { .. } => (Vec::new(), Vec::new()),
    };
    // Skirt strips.
    for w in Wall::ALL {
        b.surface = RegionSurface::Skirt(w);
        let pts = skirt.on_wall(w);
        for k in 0..pts.len() - 1 {
            let (p, q) = (pts[k], pts[k + 1]);
            b.quad(p, q, skirt.carried_out(w, q), skirt.carried_out(w, p), down);
        }
    }
    let corners = skirt.corners();
    // A fan around a point off the square's centre: the keys stand in the
    // middle of these squares, and a diagonal would run through two of a
    // key's polygon vertices, leaving slivers in the booleans.
    for (k, &(c, fx, fy)) in corners.iter().enumerate() {
        let square = [
            c,
            DVec3::new(fx, c.y, c.z),
            DVec3::new(fx, fy, c.z),
            DVec3::new(c.x, fy, c.z),
        ];
        if let Some(bump) = bumps.iter().find(|k| k.in_square(square[0], square[2])) {
            square_with_bump(&mut b, (k, square), bump, down);
            continue;
        }
        b.surface = RegionSurface::Corner(k);
        let hub = DVec3::new(c.x + 0.75 * (fx - c.x), 0.5 * (c.y + fy), c.z);
        for k in 0..4 {
            b.triangle(hub, square[k], square[(k + 1) % 4], down);
        }
    }
    if let Floor::Grid {
        interior_mid,
        cells,
    } = floor
    {
        b.surface = RegionSurface::Grid;
        grid_floor(
            &mut b,
            &skirt,
            (corners[0].0, corners[2].0),
            (interior_mid, cells),
            down,
        );
    }
    sides_and_cap(&mut b, &skirt, &corners, cap_z, cap_out);
    debug_assert_eq!(b.surfaces.len(), b.mesh.triangles.len());
    let (mesh, surfaces) = (b.mesh, b.surfaces);
    Region {
        mesh,
        device_faces,
        surfaces,
        device_vertices,
    }
}

/// The skirt: each wall's mid curve carried horizontally out to the block.
struct Skirt<'a> {
    walls: &'a [WallCurves],
    footprint: &'a Rect,
}

impl Skirt<'_> {
    fn on_wall(&self, w: Wall) -> &[DVec3] {
        &self
            .walls
            .iter()
            .find(|c| c.wall == w)
            .expect("four walls")
            .mid_points
    }

    fn carried_out(&self, w: Wall, p: DVec3) -> DVec3 {
        let footprint = self.footprint;
        match w {
            Wall::XMin => DVec3::new(footprint.x0, p.y, p.z),
            Wall::XMax => DVec3::new(footprint.x1, p.y, p.z),
            Wall::YMin => DVec3::new(p.x, footprint.y0, p.z),
            Wall::YMax => DVec3::new(p.x, footprint.y1, p.z),
        }
    }

    /// The corner squares, flat at the height of the corner's mid point:
    /// (that point, the block corner's x and y), counter-clockwise from
    /// (x min, y min).
    fn corners(&self) -> [(DVec3, f64, f64); 4] {
        let footprint = self.footprint;
        let corner = |w: Wall, end: bool| {
            let m = self.on_wall(w);
            if end {
                m[m.len() - 1]
            } else {
                m[0]
            }
        };
        [
            (corner(Wall::YMin, false), footprint.x0, footprint.y0),
            (corner(Wall::YMin, true), footprint.x1, footprint.y0),
            (corner(Wall::YMax, true), footprint.x1, footprint.y1),
            (corner(Wall::YMax, false), footprint.x0, footprint.y1),
        ]
    }
}

/// The device's faces on `side` of the parting line, reversed; returns the
/// device triangle each added triangle is, and per vertex added the posed
/// device's vertex it is.
fn device_floor(
    b: &mut SolidBuilder,
    device: &PosedDevice,
    side: PartSide,
) -> (Vec<u32>, Vec<u32>) {
    let mut device_faces = Vec::new();
    let level = match side {
        PartSide::Above => Level::Upper,
        PartSide::Below => Level::Lower,
    };
    // Device vertices map by index; only the mid-wall ones, which the
    // skirt shares, go through the builder's position index.
    let mut index = vec![u32::MAX; device.mesh.positions.len()];
    for (k, t) in device.mesh.triangles.iter().enumerate() {
        if !t.iter().any(|&v| device.levels[v as usize] == level) {
            continue;
        }
        let [p, q, r] = t.map(|v| {
            let v = v as usize;
            if index[v] == u32::MAX {
                let at = device.mesh.positions[v];
                index[v] = match device.levels[v] {
                    Level::Mid => b.vertex(at),
                    _ => b.unshared_vertex(at),
                };
            }
            index[v]
        });
        b.mesh.triangles.push([p, r, q]);
        b.surfaces.push(RegionSurface::Device);
        device_faces.push(k as u32);
    }
    let mut device_vertices = vec![u32::MAX; b.mesh.positions.len()];
    for (v, &i) in index.iter().enumerate() {
        if i != u32::MAX {
            device_vertices[i as usize] = v as u32;
        }
    }
    (device_faces, device_vertices)
}

/// The interior grid (nodes strictly inside the corners `c0` and `c2`)
/// at the height `interior_mid` gives, and the ring zipped between its
/// border and the walls' mid curves.
fn grid_floor(
    b: &mut SolidBuilder,
    skirt: &Skirt,
    (c0, c2): (DVec3, DVec3),
    (interior_mid, cells): (&dyn Fn(DVec2) -> f64, (usize, usize)),
    down: DVec3,
) {
    let (nx, ny) = (cells.0.max(2), cells.1.max(2));
    let gx: Vec<f64> = (1..nx)
        .map(|i| c0.x + (c2.x - c0.x) * i as f64 / nx as f64)
        .collect();
    let gy: Vec<f64> = (1..ny)
        .map(|j| c0.y + (c2.y - c0.y) * j as f64 / ny as f64)
        .collect();
    let node: Vec<Vec<DVec3>> = gy
        .iter()
        .map(|&y| {
            gx.iter()
                .map(|&x| DVec3::new(x, y, interior_mid(DVec2::new(x, y))))
                .collect()
        })
        .collect();
    for j in 0..gy.len() - 1 {
        for i in 0..gx.len() - 1 {
            b.quad(
                node[j][i],
                node[j][i + 1],
                node[j + 1][i + 1],
                node[j + 1][i],
                down,
            );
        }
    }
    let (last_i, last_j) = (gx.len() - 1, gy.len() - 1);
    let inner = |w: Wall| -> Vec<DVec3> {
        match w {
            Wall::YMin => node[0].clone(),
            Wall::YMax => node[last_j].clone(),
            Wall::XMin => node.iter().map(|r| r[0]).collect(),
            Wall::XMax => node.iter().map(|r| r[last_i]).collect(),
        }
    };
    let mut outer: Vec<Vec<DVec3>> = Wall::ALL
        .iter()
        .map(|&w| skirt.on_wall(w).to_vec())
        .collect();
    // Wall::ALL's order: y-min, x-max, y-max, x-min. Each corner: the walls
    // meeting there (index, whether at its end) and the inner node nearest.
    let corners = [
        ((0, true), (1, false), node[0][last_i]),
        ((1, true), (2, true), node[last_j][last_i]),
        ((2, false), (3, true), node[last_j][0]),
        ((3, false), (0, false), node[0][0]),
    ];
    for ((wa, end_a), (wb, end_b), n) in corners {
        corner_fan(b, &mut outer, (wa, end_a), (wb, end_b), n, down);
    }
    for (w, outer) in Wall::ALL.into_iter().zip(&outer) {
        ring_strip(b, outer, &inner(w), |p| w.along(p), down);
    }
}

/// A mid-wall point closer to a corner than this (as the altitude of its
/// triangle with the corner and the inner node, mm) is fanned to the
/// corner's other neighbour instead: four times the degenerate-triangle
/// check's limit, as the walls' zip.
const CORNER_SLIVER_MM: f64 = 4.0 * MIN_ALTITUDE_MM;

/// Where a wall's mid curve has a point right next to a corner (a base
/// crease snapped a few hundredths of a micrometre from the side wall),
/// the ring's triangle from that short edge to the inner node, a cell
/// away at an angle, is a sliver (found-b5c3fdfbaa3b00af: 7.9e-6 mm). Then
/// the corner is fanned from its two neighbours, at right angles, and
/// leaves both walls' chains, which the ring zips from those neighbours.
fn corner_fan(
    b: &mut SolidBuilder,
    outer: &mut [Vec<DVec3>],
    (wa, end_a): (usize, bool),
    (wb, end_b): (usize, bool),
    n: DVec3,
    down: DVec3,
) {
    let near = |chain: &[DVec3], end: bool| {
        if end {
            [chain[chain.len() - 1], chain[chain.len() - 2]]
        } else {
            [chain[0], chain[1]]
        }
    };
    let ([c, p], [_, q]) = (near(&outer[wa], end_a), near(&outer[wb], end_b));
    let zipped = thinnest(&[[p, c, n], [q, c, n]]);
    if zipped >= CORNER_SLIVER_MM
        || outer[wa].len() < 3
        || outer[wb].len() < 3
        || thinnest(&[[p, c, q], [p, q, n]]) <= zipped
    {
        return;
    }
    b.triangle(p, c, q, down);
    b.triangle(p, q, n, down);
    for (w, end) in [(wa, end_a), (wb, end_b)] {
        if end {
            outer[w].pop();
        } else {
            outer[w].remove(0);
        }
    }
}

/// The region's sides, from the floor's border up to `top_z`, and its cap.
fn sides_and_cap(
    b: &mut SolidBuilder,
    skirt: &Skirt,
    corners: &[(DVec3, f64, f64); 4],
    top_z: f64,
    cap_out: DVec3,
) {
    let footprint = skirt.footprint;
    let border = |w: Wall| -> Vec<DVec3> {
        // The floor's border on the footprint side beyond wall `w`, in
        // increasing along-coordinate, corners included.
        let (c0, c1) = match w {
            Wall::YMin => (corners[0], corners[1]),
            Wall::XMax => (corners[1], corners[2]),
            Wall::YMax => (corners[3], corners[2]),
            Wall::XMin => (corners[0], corners[3]),
        };
        let mut pts = vec![DVec3::new(c0.1, c0.2, c0.0.z)];
        pts.extend(skirt.on_wall(w).iter().map(|&p| skirt.carried_out(w, p)));
        pts.push(DVec3::new(c1.1, c1.2, c1.0.z));
        pts
    };
    let mut top_ring: Vec<DVec3> = Vec::new();
    for w in Wall::ALL {
        let pts = border(w);
        let top = top_edge(&pts, |p| w.along(p), top_z);
        // Counter-clockwise seen from above: y-min and x-max forward,
        // y-max and x-min backward.
        let ring_part: Vec<DVec3> = match w {
            Wall::YMin | Wall::XMax => top.clone(),
            Wall::YMax | Wall::XMin => top.iter().rev().copied().collect(),
        };
        for q in ring_part {
            if top_ring.last() != Some(&q) {
                top_ring.push(q);
            }
        }
        b.surface = RegionSurface::Side(w);
        zip_strip(b, &pts, &top, |p| w.along(p), w.outward().extend(0.0));
    }
    if top_ring.first() == top_ring.last() {
        top_ring.pop();
    }
    let c = footprint.centre().extend(top_z);
    b.surface = RegionSurface::Cap;
    for k in 0..top_ring.len() {
        let (p, q) = (top_ring[k], top_ring[(k + 1) % top_ring.len()]);
        b.triangle(c, p, q, cap_out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The largest knee of a polyline of points along `wall`: how far a
    /// point lies from the chord of its two neighbours, in z.
    fn largest_knee(wall: Wall, pts: &[DVec3]) -> f64 {
        pts.windows(3)
            .map(|w| {
                let (a, b, c) = (wall.along(w[0]), wall.along(w[1]), wall.along(w[2]));
                let chord = w[0].z + (w[2].z - w[0].z) * (b - a) / (c - a);
                (w[1].z - chord).abs()
            })
            .fold(0.0, f64::max)
    }

    /// On a plane device with a rings profile (the shipped `plane-rings`
    /// in small), the walls' rung midpoints zigzag, and the parting line
    /// through the crossings does not: across the lenses its knees stay
    /// under 1 % of the midpoints', each crossing on its rung within
    /// [`RUNG_SHARE`], and the walls meet at the corners (`wall_curves`
    /// checks that, and that the line runs strictly along each wall).
    #[test]
    fn the_parting_line_is_smooth_where_the_midpoints_zigzag() {
        use moirecast_kernel::{mesher::mesh_device, progress::Silent};
        use moirecast_kernel::{profile::Profile, DesignParams, PitchSurface};
        let mut params = DesignParams::with_defaults(PitchSurface::Plane, 12.0, 10.0, 0.5);
        params.profile = Profile::Rings { wavelength: 4.0 };
        params.base.a = 0.5;
        params.tolerance = 0.01;
        let design = Design::new(params).unwrap();
        let dm = mesh_device(&design, &Silent).unwrap();
        let posed = PosedDevice::new(&design, &dm, false, 1.0).unwrap();
        let walls = wall_curves(&posed).unwrap();
        for w in &walls {
            // each crossing's rung: the two neighbours, one on each edge,
            // whose segment it lies on; the rung's midpoint
            let at = |v: u32| posed.mesh.positions[v as usize];
            let mut neighbours: HashMap<u32, Vec<u32>> = HashMap::new();
            for (t, f) in posed.mesh.triangles.iter().zip(&posed.faces) {
                if *f != Face::Wall(w.wall) {
                    continue;
                }
                for k in 0..3 {
                    let (m, n) = (t[k], t[(k + 1) % 3]);
                    for (m, n) in [(m, n), (n, m)] {
                        if posed.levels[m as usize] == Level::Mid
                            && posed.levels[n as usize] != Level::Mid
                        {
                            neighbours.entry(m).or_default().push(n);
                        }
                    }
                }
            }
            let midpoints: Vec<DVec3> = neighbours
                .iter()
                .map(|(&m, ns)| {
                    let (a, b) = ns
                        .iter()
                        .flat_map(|&a| ns.iter().map(move |&b| (a, b)))
                        .filter(|&(a, b)| {
                            posed.levels[a as usize] == Level::Upper
                                && posed.levels[b as usize] == Level::Lower
                        })
                        .min_by(|x, y| {
                            let off = |(a, b): (u32, u32)| {
                                (at(m) - at(a)).cross(at(b) - at(a)).length()
                                    / (at(b) - at(a)).length_squared()
                            };
                            off(*x).total_cmp(&off(*y))
                        })
                        .expect("a crossing between the two edges");
                    let share = (at(m) - at(a)).length() / (at(b) - at(a)).length();
                    assert!(
                        (RUNG_SHARE.0 - 1e-6..=RUNG_SHARE.1 + 1e-6).contains(&share)
                            || (RUNG_SHARE.0 - 1e-6..=RUNG_SHARE.1 + 1e-6).contains(&(1.0 - share)),
                        "{} wall: a crossing at {share} of its rung",
                        w.wall.name()
                    );
                    0.5 * (at(a) + at(b))
                })
                .collect();
            let mut midpoints = midpoints;
            midpoints.sort_by(|a, b| w.wall.along(*a).total_cmp(&w.wall.along(*b)));
            midpoints.dedup();
            let (zigzag, knee) = (
                largest_knee(w.wall, &midpoints),
                largest_knee(w.wall, &w.mid_points),
            );
            // across the lenses the midpoints zigzag by 0.026 mm and the
            // line bends by 3e-5; along a lens (x walls) both follow the
            // rings (5e-3 and 1e-3: the line's own curve between sparse
            // vertices)
            let share = match w.wall {
                Wall::YMin | Wall::YMax => 0.01,
                Wall::XMin | Wall::XMax => 0.3,
            };
            assert!(
                knee <= share * zigzag,
                "{} wall: knees of {knee} mm against the midpoints' {zigzag}",
                w.wall.name()
            );
        }
    }

    /// The affine form of a pose maps points as the pose does, flipped or
    /// not.
    #[test]
    fn a_pose_and_its_affine_map_agree() {
        for flip in [false, true] {
            let pose = Pose {
                centre: DVec3::new(1.5, 0.0, 0.0),
                flip,
                scale: 1.02,
            };
            for p in [
                DVec3::ZERO,
                DVec3::new(-3.0, 2.0, 0.7),
                DVec3::new(9.0, -4.0, -1.0),
            ] {
                let (a, b) = (pose.apply(p), pose.affine().transform_point3(p));
                assert!(a.distance(b) < 1e-12, "{flip}: {a} against {b}");
            }
            assert!(pose.affine().matrix3.determinant() > 0.0);
        }
    }

    /// Points crowding a corner (a crease just outside the wall snap, its
    /// rung split at mid-wall) never reach the top edge closer than the
    /// spacing, which keeps both corners.
    #[test]
    fn the_top_edge_keeps_its_corners_and_its_spacing() {
        let xs = [
            -9.0, -5.0, -4.99998, -4.9999, -4.89, -4.0, 4.95, 4.99998, 5.0, 9.0,
        ];
        let border: Vec<DVec3> = xs.iter().map(|&x| DVec3::new(x, 2.0, 0.1 * x)).collect();
        let top = top_edge(&border, |p| p.x, 7.0);
        assert_eq!(top.first().unwrap().x, -9.0);
        assert_eq!(top.last().unwrap().x, 9.0);
        assert!(top.iter().all(|p| p.z == 7.0 && p.y == 2.0));
        for pair in top.windows(2) {
            assert!(pair[1].x - pair[0].x >= TOP_EDGE_SPACING_MM, "{pair:?}");
        }
        let kept: Vec<f64> = top.iter().map(|p| p.x).collect();
        assert_eq!(kept, [-9.0, -5.0, -4.89, -4.0, 4.95, 9.0]);
    }

    /// A ring whose mid curve has two points 3e-5 mm apart near a corner
    /// (found-78b8f12bc8bf0892): the plain zip fans them from a node far
    /// along the wall, a sliver; the ring's middle chain meets them square.
    /// Either way the ring is one strip: its open edges are exactly the two
    /// chains and the two ends, each once.
    #[test]
    fn a_ring_with_close_mid_points_takes_a_middle_chain() {
        let mut xs: Vec<f64> = (0..=50).map(|k| -10.2 + 0.4 * k as f64).collect();
        xs.extend([10.16159, 10.16162, 10.1995]);
        xs.sort_by(f64::total_cmp);
        xs.dedup();
        let outer: Vec<DVec3> = xs
            .iter()
            .map(|&x| DVec3::new(x, -1.0, -2.5 + 0.01 * (3.0 * x).sin()))
            .collect();
        let inner: Vec<DVec3> = (0..=11)
            .map(|k| DVec3::new(-8.6 + 1.6 * k as f64, -0.46, -2.55))
            .collect();
        let along = |p: DVec3| p.x;
        assert!(thinnest(&zipped(&outer, &inner, &along, true)) < MIN_ALTITUDE_MM);
        let mut b = SolidBuilder::default();
        ring_strip(&mut b, &outer, &inner, along, DVec3::NEG_Z);
        let triangles: Vec<[DVec3; 3]> = b
            .mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| b.mesh.positions[v as usize]))
            .collect();
        // the short edge is 3.05e-5 mm: no triangle on it can be thicker
        let shortest = outer
            .windows(2)
            .map(|w| w[0].distance(w[1]))
            .fold(f64::INFINITY, f64::min);
        assert!(
            thinnest(&triangles) >= 0.9 * shortest,
            "{} against an edge of {shortest}",
            thinnest(&triangles)
        );
        assert!(triangles
            .iter()
            .all(|t| (t[1] - t[0]).cross(t[2] - t[0]).z < 0.0));
        let mut open: HashMap<(u32, u32), i32> = HashMap::new();
        for t in &b.mesh.triangles {
            for k in 0..3 {
                let (p, q) = (t[k], t[(k + 1) % 3]);
                *open.entry((p.min(q), p.max(q))).or_default() += 1;
            }
        }
        let open: Vec<(u32, u32)> = open
            .into_iter()
            .filter(|&(_, n)| n == 1)
            .map(|(e, _)| e)
            .collect();
        assert_eq!(open.len(), outer.len() - 1 + inner.len() - 1 + 2);
        let index = |p: DVec3| {
            let p = crate::boolean::f32_exact(p);
            b.mesh.positions.iter().position(|&q| q == p).unwrap() as u32
        };
        for chain in [&outer, &inner] {
            for pair in chain.windows(2) {
                let (p, q) = (index(pair[0]), index(pair[1]));
                assert!(open.contains(&(p.min(q), p.max(q))), "{pair:?}");
            }
        }
    }

    /// A ring without slivers is the plain zip, triangle for triangle.
    #[test]
    fn a_ring_without_slivers_is_the_plain_zip() {
        let outer: Vec<DVec3> = (0..=51)
            .map(|k| DVec3::new(-10.2 + 0.4 * k as f64, -1.0, -2.5))
            .collect();
        let inner: Vec<DVec3> = (0..=11)
            .map(|k| DVec3::new(-8.6 + 1.6 * k as f64, -0.46, -2.55))
            .collect();
        let (mut ring, mut plain) = (SolidBuilder::default(), SolidBuilder::default());
        ring_strip(&mut ring, &outer, &inner, |p| p.x, DVec3::NEG_Z);
        zip_strip(&mut plain, &outer, &inner, |p| p.x, DVec3::NEG_Z);
        assert_eq!(ring.mesh.triangles, plain.mesh.triangles);
        assert_eq!(ring.mesh.positions, plain.mesh.positions);
    }

    /// A key bump on a corner square, closed below by a 1 mm box: a closed
    /// solid of genus 0 whose volume is the box's plus the frustum's part
    /// above the square (the frustum of two similar polygons:
    /// h/3·(A₀ + A₁ + √(A₀A₁))).
    #[test]
    fn a_bump_stands_on_its_corner_square_as_a_closed_solid() {
        let (n, centre) = (48, DVec2::new(10.0, 20.0));
        let ring = |r: f64, z: f64| -> Vec<DVec3> {
            (0..n)
                .map(|k| {
                    let a = (k as f64 + 0.5) * std::f64::consts::TAU / n as f64;
                    (centre + r * DVec2::new(a.cos(), a.sin())).extend(z)
                })
                .collect()
        };
        let bump = Bump {
            centre,
            bottom: ring(2.0, -1.0),
            top: ring(1.5, 2.0),
        };
        let (lo, hi) = (centre - 3.0, centre + 3.0);
        let at = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
        let square = [
            at(lo.x, lo.y, 0.0),
            at(hi.x, lo.y, 0.0),
            at(hi.x, hi.y, 0.0),
            at(lo.x, hi.y, 0.0),
        ];
        let mut b = SolidBuilder::default();
        square_with_bump(&mut b, (0, square), &bump, DVec3::Z);
        let below = square.map(|p| p - DVec3::Z);
        for k in 0..4 {
            let (p, q) = (square[k], square[(k + 1) % 4]);
            let out = (0.5 * (p + q).truncate() - centre).extend(0.0);
            b.quad(p, q, below[(k + 1) % 4], below[k], out);
        }
        b.quad(below[0], below[1], below[2], below[3], DVec3::NEG_Z);
        for c in moirecast_kernel::check::solid_checks_for(
            &b.mesh,
            moirecast_kernel::check::SolidSpec::boolean_result(0),
        ) {
            assert!(c.passed, "{}: {} ({})", c.name, c.value, c.detail);
        }
        let polygon = |r: f64| 0.5 * n as f64 * r * r * (std::f64::consts::TAU / n as f64).sin();
        // radius at the square's plane, a third of the way up the frustum
        let (a0, a1) = (polygon(2.0 - 0.5 / 3.0 * 1.0), polygon(1.5));
        let frustum = 2.0 / 3.0 * (a0 + a1 + (a0 * a1).sqrt());
        let want = 36.0 + frustum;
        let got = b.mesh.volume();
        assert!((got - want).abs() < 1e-5 * want, "{got} vs {want}");
    }
}
