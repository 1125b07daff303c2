//! The preview tracer: a dual-lens device's exact cross-sections.
//!
//! Every lens of the device is a circular arc across and runs along the
//! layout's v (METHOD §2, §5.1). Seen with its lens axes square to the view
//! (an orthographic camera tilted about the lens axis only), a ray stays in
//! the plane y = v it starts in, up to the surface's slope along v, and
//! there the device is a row of revealer arcs over a row of base arcs. A
//! [`Section`] is that row at one station, built from the exact model
//! (`Design::revealer_arc`, `Design::base_arc_between`), and a ray meets it
//! in closed form: a quadratic per arc, a handful of arcs per ray, against a
//! BVH walk over half a million triangles for the mesh.
//!
//! The walls are vertical segments from the base to the revealer's end
//! crease, as the mesh's x-walls are planes. What it leaves out, and why a
//! preview may: the surface's slope along v (an arc's bulge is projected
//! into the plane; on the reference saddle the slope is at most 0.15, which
//! changes a sag by about 1 %). The mesh tracer traces what is printed;
//! tests/render_agreement.rs holds the two to the same picture.

use crate::scene::Side;
use crate::trace::{Meeting, Surfaces};
use glam::{DVec2, DVec3};
use moirecast_kernel::lens::{ArcRule, LensArc};
use moirecast_kernel::{BaseKind, Design, KernelError};
use std::sync::OnceLock;

/// A point's coordinates in the section's plane: (x, z).
fn in_plane(p: DVec3) -> DVec2 {
    DVec2::new(p.x, p.z)
}

/// One lens arc in the section's plane.
#[derive(Clone, Copy, Debug)]
struct Arc2 {
    centre: DVec2,
    radius: f64,
    /// Unit direction from the centre to the arc's middle: outward, since
    /// every lens of the device bulges away from its body.
    middle: DVec2,
    /// A point p of the circle is on the arc iff (p − centre)·middle ≥ this.
    on_arc: f64,
    x: (f64, f64),
    z: (f64, f64),
}

impl Arc2 {
    /// The arc of `lens` in the plane of its two creases (which share their
    /// y), with its bulge projected into that plane.
    fn new(lens: &LensArc) -> Arc2 {
        let (p0, p1) = (in_plane(lens.p0), in_plane(lens.p1));
        let chord = (p1 - p0).normalize();
        let bulge = DVec2::new(lens.bulge.x, lens.bulge.z);
        let middle = (bulge - bulge.dot(chord) * chord).normalize();
        let cos_half = lens.half_angle.cos();
        let centre = 0.5 * (p0 + p1) - lens.radius * cos_half * middle;
        // a circle's extreme point in a direction counts if it is on the arc
        let extent = |axis: DVec2| {
            let along = |p: DVec2| p.dot(axis);
            let (mut lo, mut hi) = (along(p0).min(along(p1)), along(p0).max(along(p1)));
            for sign in [-1.0, 1.0] {
                if (sign * axis).dot(middle) >= cos_half {
                    let e = along(centre) + sign * lens.radius;
                    (lo, hi) = (lo.min(e), hi.max(e));
                }
            }
            (lo, hi)
        };
        Arc2 {
            centre,
            radius: lens.radius,
            middle,
            // a relative slack of 1e-12: neighbouring arcs share their
            // crease, and no ray slips between them through round-off
            on_arc: lens.radius * (cos_half - 1e-12),
            x: extent(DVec2::X),
            z: extent(DVec2::Y),
        }
    }

    /// The z of the arc's point at x, if the arc reaches x.
    fn z_at(&self, x: f64) -> Option<f64> {
        let dx = x - self.centre.x;
        let h = (self.radius * self.radius - dx * dx).sqrt();
        [self.centre.y - h, self.centre.y + h]
            .into_iter()
            .find(|&z| (DVec2::new(x, z) - self.centre).dot(self.middle) >= self.on_arc)
    }

    /// The nearest t > `t_min` at which `o + t·d` meets the arc from
    /// `side` (entering from outside, leaving from inside), and the
    /// outward normal there.
    fn meet(&self, o: DVec2, d: DVec2, t_min: f64, side: Side) -> Option<(f64, DVec2)> {
        let oc = o - self.centre;
        let (a, b, c) = (d.dot(d), oc.dot(d), oc.dot(oc) - self.radius * self.radius);
        let disc = b * b - a * c;
        if disc < 0.0 || a == 0.0 {
            return None;
        }
        let root = disc.sqrt();
        // the two roots, nearer first, without cancellation
        let q = -(b + b.signum() * root);
        let (t0, t1) = if q == 0.0 {
            (0.0, 0.0)
        } else {
            let (x, y) = (q / a, c / q);
            (x.min(y), x.max(y))
        };
        [t0, t1].into_iter().find_map(|t| {
            if t <= t_min {
                return None;
            }
            let radial = oc + t * d;
            let normal = radial / self.radius;
            let facing = match side {
                Side::Outside => d.dot(normal) < 0.0,
                Side::Inside => d.dot(normal) > 0.0,
            };
            (facing && radial.dot(self.middle) >= self.on_arc).then_some((t, normal))
        })
    }
}

/// Base creases a section adds beyond the layout's edge, at most, to reach
/// a wall (a base that ends this many periods inside its wall would fold).
const MAX_EXTRA_CREASES: usize = 64;

/// Arcs per block of an [`ArcRow`].
const BLOCK: usize = 8;

/// An x and a z extent.
type Extent = ((f64, f64), (f64, f64));

/// Arcs ordered along x (their x extents increase), as the lenses of a row,
/// in blocks of [`BLOCK`] with the x and z extent of each: a ray skips the
/// blocks it passes above or below.
#[derive(Clone, Debug, Default)]
struct ArcRow {
    arcs: Vec<Arc2>,
    blocks: Vec<Extent>,
    /// The row's z extent: a ray outside it meets nothing.
    z: (f64, f64),
}

/// The union of two extents.
fn union(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0.min(b.0), a.1.max(b.1))
}

const EMPTY: (f64, f64) = (f64::INFINITY, f64::NEG_INFINITY);

impl ArcRow {
    fn new(arcs: Vec<Arc2>) -> ArcRow {
        let blocks: Vec<Extent> = arcs
            .chunks(BLOCK)
            .map(|c| {
                c.iter()
                    .fold((EMPTY, EMPTY), |(x, z), a| (union(x, a.x), union(z, a.z)))
            })
            .collect();
        let z = blocks.iter().fold(EMPTY, |z, b| union(z, b.1));
        ArcRow { arcs, blocks, z }
    }

    /// The nearest meeting in (`t_min`, `t_max`] within `walls` (x), among
    /// the arcs the ray passes inside the row's z extent: walked from the
    /// ray's start in the direction it travels, stopping past the nearest
    /// meeting found. (A meeting beyond the walls is the caller's to drop.)
    fn meet(
        &self,
        (o, d): (DVec2, DVec2),
        (t_min, t_max): (f64, f64),
        side: Side,
        walls: (f64, f64),
    ) -> Option<(f64, DVec2)> {
        // the stretch of the ray inside the row's z extent, and its x range
        let (t0, t1) = if d.y == 0.0 {
            if o.y < self.z.0 || o.y > self.z.1 {
                return None;
            }
            (f64::NEG_INFINITY, f64::INFINITY)
        } else {
            let (a, b) = ((self.z.0 - o.y) / d.y, (self.z.1 - o.y) / d.y);
            (a.min(b), a.max(b))
        };
        let (t0, t1) = (t0.max(t_min), t1.min(t_max));
        if t0 > t1 {
            return None;
        }
        let x_at = |t: f64| {
            if t.is_finite() {
                o.x + t * d.x
            } else if (d.x >= 0.0) == (t > 0.0) {
                f64::INFINITY
            } else {
                f64::NEG_INFINITY
            }
        };
        let (xa, xb) = (x_at(t0), x_at(t1));
        let (x0, x1) = (xa.min(xb).max(walls.0), xa.max(xb).min(walls.1));
        if x0 > x1 {
            return None;
        }
        let forward = d.x >= 0.0;
        // the ray's z over an x extent must overlap the z extent
        let slope = d.y / d.x;
        let misses = |(x, z): Extent| {
            if !slope.is_finite() {
                return false;
            }
            let (za, zb) = (o.y + (x.0 - o.x) * slope, o.y + (x.1 - o.x) * slope);
            za.max(zb) < z.0 || za.min(zb) > z.1
        };
        // an extent wholly beyond [x0, x1] or the nearest meeting so far,
        // in the direction of travel: nothing after it is nearer
        let past = |x: (f64, f64), best: &Option<(f64, DVec2)>| {
            let far = best.map_or(if forward { x1 } else { x0 }, |(t, _)| o.x + t * d.x);
            if forward {
                x.0 > far.min(x1)
            } else {
                x.1 < far.max(x0)
            }
        };
        let mut best: Option<(f64, DVec2)> = None;
        let arcs = &self.arcs;
        // arcs in the order the ray passes them, from the first it can
        // meet; a block the ray passes above or below is skipped whole
        let n = arcs.len();
        let (mut j, stop) = if forward {
            (self.first_reaching(x0), n)
        } else {
            (n - self.first_beyond(x1), n)
        };
        // j counts arcs passed; the arc is `at(j)`
        let at = |j: usize| if forward { j } else { n - 1 - j };
        while j < stop {
            let i = at(j);
            let entering_block = if forward {
                i % BLOCK == 0
            } else {
                i % BLOCK == BLOCK - 1 || i == n - 1
            };
            if entering_block && misses(self.blocks[i / BLOCK]) {
                // to the first arc of the next block in the direction of travel
                j += if forward { BLOCK } else { i % BLOCK + 1 };
                continue;
            }
            let arc = &arcs[i];
            if past(arc.x, &best) {
                break;
            }
            if !misses((arc.x, arc.z)) {
                if let Some(hit) = arc.meet(o, d, t_min, side) {
                    if best.is_none_or(|b| hit.0 < b.0) {
                        best = Some(hit);
                    }
                }
            }
            j += 1;
        }
        best
    }

    /// The index of an arc near x: the arcs are about equally wide.
    fn guess(&self, x: f64) -> usize {
        let (first, last) = match (self.arcs.first(), self.arcs.last()) {
            (Some(a), Some(b)) if b.x.1 > a.x.0 => (a.x.0, b.x.1),
            _ => return 0,
        };
        let n = self.arcs.len();
        (((x - first) / (last - first) * n as f64).max(0.0) as usize).min(n - 1)
    }

    /// The first arc whose x extent reaches x (ends at or past it), or n.
    fn first_reaching(&self, x: f64) -> usize {
        let arcs = &self.arcs;
        let mut i = self.guess(x);
        while i > 0 && arcs[i - 1].x.1 >= x {
            i -= 1;
        }
        while i < arcs.len() && arcs[i].x.1 < x {
            i += 1;
        }
        i
    }

    /// The first arc that starts beyond x, or n.
    fn first_beyond(&self, x: f64) -> usize {
        let arcs = &self.arcs;
        let mut i = self.guess(x);
        while i > 0 && arcs[i - 1].x.0 > x {
            i -= 1;
        }
        while i < arcs.len() && arcs[i].x.0 <= x {
            i += 1;
        }
        i
    }
}

/// The cross-section of a dual-lens device at one station v: its revealer
/// arcs over its base arcs, between its walls.
#[derive(Clone, Debug)]
pub struct Section {
    top: ArcRow,
    base: ArcRow,
    /// x of the walls: a meeting beyond them is not on the device.
    walls: (f64, f64),
    /// Each wall's z extent, from the base to the revealer's crease there:
    /// the wall itself, a vertical segment (the mesh's x-walls are planes).
    wall_z: [(f64, f64); 2],
}

impl Section {
    /// The section of `design` (dual-lens) at station `v`, from the exact
    /// revealer arcs and the base arcs between the base creases solved
    /// there.
    pub fn new(design: &Design, v: f64) -> Result<Section, KernelError> {
        let (hw, period) = (design.params.width / 2.0, design.params.period);
        let top = (0..design.lenses as i64)
            .map(|i| Arc2::new(&design.revealer_arc(i, v)))
            .collect();
        let first = design.base_phase(-hw, v).floor() as i64;
        let last = design.base_phase(hw, v).ceil() as i64;
        // The base lies below f along its normal, which leans along v where
        // the surface slopes along v: the base crease of station v is not
        // in the plane y = v (0.2 mm off at the reference saddle's edge,
        // where the level lines move with v). Each crease is taken at the
        // station that puts it in the plane.
        let crease =
            |k: i64, (u, mut station): (Option<f64>, f64)| -> Result<(f64, f64), KernelError> {
                let mut u = u;
                for _ in 0..3 {
                    let solved = design.base_crease_u_near(k, station, u)?;
                    station -= design.base_surface(solved, station).y - v;
                    u = Some(solved);
                }
                Ok((design.base_crease_u_near(k, station, u)?, station))
            };
        let mut creases: Vec<(f64, f64)> = Vec::with_capacity((last - first + 1).max(0) as usize);
        for k in first..=last {
            let near = creases
                .last()
                .map_or((None, v), |&(u, s)| (Some(u + period), s));
            creases.push(crease(k, near)?);
        }
        // The walls are vertical over the layout's edge, and the base,
        // below f along the normal, may end inside them (where the surface
        // slopes down towards a wall): the base arcs go on until they reach
        // each wall, as the mesh's base does before the walls trim it.
        let base_x = |(u, station): (f64, f64)| design.base_surface(u, station).x;
        let x_of = |u: f64| design.surface().point(u, v).x;
        let walls = (x_of(-hw), x_of(hw));
        let (mut k0, mut k1) = (first, last);
        for _ in 0..MAX_EXTRA_CREASES {
            let (Some(&a), Some(&b)) = (creases.first(), creases.last()) else {
                break;
            };
            let (left, right) = (base_x(a) > walls.0, base_x(b) < walls.1);
            if !(left || right) {
                break;
            }
            if left {
                k0 -= 1;
                creases.insert(0, crease(k0, (Some(a.0 - period), a.1))?);
            }
            if right {
                k1 += 1;
                creases.push(crease(k1, (Some(b.0 + period), b.1))?);
            }
        }
        let rule = ArcRule::ConstantAfov {
            half_angle: design.base_arc_between(-hw, -hw + period, v).half_angle,
        };
        let base = creases
            .windows(2)
            .map(|w| {
                let [(u0, v0), (u1, v1)] = [w[0], w[1]];
                let toward = -design.base_normal(0.5 * (u0 + u1), 0.5 * (v0 + v1));
                let (p0, p1) = (design.base_surface(u0, v0), design.base_surface(u1, v1));
                Arc2::new(&LensArc::new(p0, p1, toward, rule))
            })
            .collect();
        let (top, base) = (ArcRow::new(top), ArcRow::new(base));
        // a wall runs from the base arc under it up to the revealer's crease
        let wall_z = |u: f64| {
            let (x, top_z) = (x_of(u), design.surface().point(u, v).z);
            let bottom = base
                .arcs
                .iter()
                .find_map(|a| a.z_at(x))
                .unwrap_or_else(|| design.base_surface(u, v).z);
            (bottom.min(top_z), bottom.max(top_z))
        };
        Ok(Section {
            walls,
            wall_z: [wall_z(-hw), wall_z(hw)],
            top,
            base,
        })
    }
}

impl Surfaces for Section {
    fn meet(&self, side: Side, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Meeting> {
        let (o, d) = (in_plane(origin), DVec2::new(dir.x, dir.z));
        // the walls: entered from outside, left from inside
        let wall = [(self.walls.0, -1.0), (self.walls.1, 1.0)]
            .into_iter()
            .zip(self.wall_z)
            .filter_map(|((x, outward), (z0, z1))| {
                let t = (x - o.x) / d.x;
                let z = o.y + t * d.y;
                let facing = match side {
                    Side::Outside => d.x * outward < 0.0,
                    Side::Inside => d.x * outward > 0.0,
                };
                (t > t_min && facing && z >= z0 && z <= z1).then_some((t, DVec2::new(outward, 0.0)))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let within = |hit: &(f64, DVec2)| {
            let x = o.x + hit.0 * d.x;
            x >= self.walls.0 && x <= self.walls.1
        };
        // The row the ray more likely meets first is searched first, and
        // the other only before that meeting: a ray going down inside
        // meets the base, any other the revealer (from above, or from
        // inside going up), and a ray that meets the revealer first passes
        // the base's z extent only after it, so that search is empty.
        let (first, second) = if side == Side::Inside && d.y < 0.0 {
            (&self.base, &self.top)
        } else {
            (&self.top, &self.base)
        };
        let mut nearest = wall;
        for row in [first, second] {
            let t_max = nearest.map_or(f64::INFINITY, |(t, _)| t);
            if let Some(hit) = row
                .meet((o, d), (t_min, t_max), side, self.walls)
                .filter(within)
            {
                if nearest.is_none_or(|n| hit.0 < n.0) {
                    nearest = Some(hit);
                }
            }
        }
        nearest.map(|(t, n)| Meeting {
            t,
            normal: DVec3::new(n.x, 0.0, n.y),
            absorbs: false,
        })
    }
}

/// A dual-lens design's sections at evenly spaced stations across its
/// layout, each built the first time a ray needs it and kept.
pub struct Sections<'d> {
    design: &'d Design,
    /// Station of row 0 and the spacing of rows (mm).
    v0: f64,
    step: f64,
    rows: Vec<OnceLock<Option<Section>>>,
}

impl<'d> Sections<'d> {
    /// Sections of `design` at `rows` stations from one edge of the layout
    /// to the other; `None` for a printed design, whose base is not a row
    /// of lenses.
    pub fn new(design: &'d Design, rows: usize) -> Option<Self> {
        if !matches!(design.params.base.kind, BaseKind::DualLens) {
            return None;
        }
        let rows = rows.max(2);
        let h = design.half_height;
        Some(Sections {
            design,
            v0: -h,
            step: 2.0 * h / (rows - 1) as f64,
            rows: (0..rows).map(|_| OnceLock::new()).collect(),
        })
    }

    /// The sections a frame of `size` × `size` pixels of `design` traces:
    /// a station every lens period or every two pixels, whichever is
    /// finer, but no finer than a pixel. Pixels interpolate between
    /// stations as they do between lens centres, so a frame resolves the
    /// layout's v as finely as its u, which the lenses sample once a
    /// period (and at least every two pixels at large sizes). `None` for a
    /// printed design.
    pub fn for_frame(design: &'d Design, size: usize) -> Option<Self> {
        let p = &design.params;
        let pixel = p.width.max(p.height) / size.max(1) as f64;
        let step = p.period.min(2.0 * pixel).max(pixel);
        let rows = (2.0 * design.half_height / step).ceil() as usize + 1;
        Self::new(design, rows)
    }

    /// The design the sections cut.
    pub fn design(&self) -> &'d Design {
        self.design
    }

    /// The row at or below station `v` and how far `v` is towards the next
    /// row (0 to 1), if `v` is on the layout.
    pub fn row_below(&self, v: f64) -> Option<(usize, f64)> {
        let s = (v - self.v0) / self.step;
        let last = self.rows.len() - 1;
        if !(s >= 0.0 && s <= last as f64) {
            return None;
        }
        let r = (s.floor() as usize).min(last - 1);
        Some((r, s - r as f64))
    }

    /// How many rows.
    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    /// The station of row `r`.
    pub fn station(&self, r: usize) -> f64 {
        self.v0 + r as f64 * self.step
    }

    /// The box around every section (all rows built), from wall to wall,
    /// lowest base to highest revealer, edge to edge of the layout: the
    /// device's bounding box up to the slope along v. `None` if a row
    /// could not be built.
    pub fn bounds(&self) -> Option<(DVec3, DVec3)> {
        let h = self.design.half_height;
        let (mut lo, mut hi) = (
            DVec3::new(f64::INFINITY, -h, f64::INFINITY),
            DVec3::new(f64::NEG_INFINITY, h, f64::NEG_INFINITY),
        );
        for r in 0..self.rows.len() {
            let s = self.section(r)?;
            (lo.x, hi.x) = (lo.x.min(s.walls.0), hi.x.max(s.walls.1));
            let z = union(s.top.z, s.base.z);
            (lo.z, hi.z) = (lo.z.min(z.0), hi.z.max(z.1));
        }
        Some((lo, hi))
    }

    /// Row `r`'s section; `None` where its base creases could not be
    /// solved (the caller traces the mesh there).
    pub fn section(&self, r: usize) -> Option<&Section> {
        self.rows[r]
            .get_or_init(|| Section::new(self.design, self.station(r)).ok())
            .as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::{trace_branches, Pruning};
    use moirecast_kernel::{DesignParams, PitchSurface, Profile};

    fn flat_design() -> Design {
        let mut p = DesignParams::with_defaults(PitchSurface::Plane, 6.0, 4.0, 0.5);
        p.profile = Profile::Rings { wavelength: 2.0 };
        Design::new(p).unwrap()
    }

    /// A vertical ray meets the revealer's apex first, entering, with the
    /// normal straight up, and from inside it meets the base lens below,
    /// leaving; the arcs' ends are the model's creases.
    #[test]
    fn a_section_meets_rays_on_the_exact_arcs() {
        let d = flat_design();
        let s = Section::new(&d, 0.3).unwrap();
        let apex = d.revealer_arc(2, 0.3).point(0.5);
        let down = DVec3::NEG_Z;
        let from = DVec3::new(apex.x, 0.3, 10.0);
        let hit = s.meet(Side::Outside, from, down, 0.0).unwrap();
        assert!((from.z - hit.t - apex.z).abs() < 1e-12, "{hit:?} vs {apex}");
        assert!((hit.normal - DVec3::Z).length() < 1e-9);
        let inside = from + hit.t * down;
        let out = s.meet(Side::Inside, inside, down, 1e-9).unwrap();
        assert!(out.normal.z < 0.0 && out.t > 0.0);
        // from outside, a ray going up from below meets the base
        let below = DVec3::new(apex.x, 0.3, -10.0);
        let up = s.meet(Side::Outside, below, DVec3::Z, 0.0).unwrap();
        assert!((below.z + up.t - (inside.z - out.t)).abs() < 1e-9);
        // and beyond the walls there is nothing to meet
        let beside = DVec3::new(d.params.width, 0.3, 10.0);
        assert!(s.meet(Side::Outside, beside, down, 0.0).is_none());
        // a ray inside, across the device, leaves through the wall
        let across = DVec3::new(0.1, 0.3, inside.z - 0.5 * out.t);
        let wall = s.meet(Side::Inside, across, DVec3::NEG_X, 0.0).unwrap();
        assert!((across.x - wall.t + d.params.width / 2.0).abs() < 1e-12);
        assert_eq!(wall.normal, DVec3::NEG_X);
        // and from outside it enters through it
        let from = DVec3::new(-d.params.width, 0.3, across.z);
        let enters = s.meet(Side::Outside, from, DVec3::X, 0.0).unwrap();
        assert!((enters.t - d.params.width / 2.0).abs() < 1e-12);
    }

    /// Where the surface slopes down towards a wall, the base (below f
    /// along the normal) ends inside the wall at the layout's edge; the
    /// section's base goes on to each wall, as the mesh's does, so a ray
    /// down beside the wall meets the base and does not fall through.
    #[test]
    fn the_base_reaches_both_walls_where_the_surface_slopes_away() {
        let mut p =
            DesignParams::with_defaults(PitchSurface::Cylinder { radius: 50.0 }, 50.0, 4.0, 0.5);
        p.profile = Profile::Rings { wavelength: 10.0 };
        let d = Design::new(p).unwrap();
        let s = Section::new(&d, 0.0).unwrap();
        let hw = d.params.width / 2.0;
        // the base at the layout's edge is well inside the wall
        assert!(d.base_surface(-hw, 0.0).x > s.walls.0 + d.params.period);
        assert!(d.base_surface(hw, 0.0).x < s.walls.1 - d.params.period);
        let (first, last) = (s.base.arcs[0], *s.base.arcs.last().unwrap());
        assert!(first.x.0 <= s.walls.0 && last.x.1 >= s.walls.1);
        for x in [s.walls.0 + 1e-3, s.walls.1 - 1e-3] {
            let top = s.top.arcs.iter().find_map(|a| a.z_at(x)).unwrap();
            let from = DVec3::new(x, 0.0, top - 1e-3);
            let hit = s.meet(Side::Inside, from, DVec3::NEG_Z, 0.0).unwrap();
            assert!(hit.normal.z < 0.0, "{x}: {hit:?}");
        }
    }

    /// Through a section, as through the mesh, the branches conserve the
    /// ray's weight.
    #[test]
    fn branches_through_a_section_conserve_weight() {
        let d = flat_design();
        let s = Section::new(&d, -0.7).unwrap();
        for (x, angle) in [(0.1, 0.0f64), (0.37, 10.0), (-1.2, 25.0)] {
            let a = angle.to_radians();
            let dir = DVec3::new(a.sin(), 0.0, -a.cos());
            let b = trace_branches(
                &s,
                1.41,
                DVec3::new(x, -0.7, 5.0) - 5.0 * dir,
                dir,
                &|d| DVec3::splat(d.z.min(0.0).abs()),
                Pruning::NONE,
            );
            assert!(
                (b.left + b.absorbed + b.dropped - 1.0).abs() < 1e-12,
                "{b:?}"
            );
            assert!(b.first.is_some());
        }
    }
}
