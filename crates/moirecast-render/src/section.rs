//! The preview tracer: a dual-lens device's exact cross-sections.
//!
//! A view tilted along the lenses as well is traced through the same
//! sections by [`Drift`], which slides each ray along the axis of the lens
//! it meets; what follows describes a ray in a section's plane.
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
//! crease, as the mesh's x-walls are planes. Where the surface slopes along
//! v, a revealer lens leans out of the plane, and the plane cuts it, swept
//! along its axis (the surface's v direction), in an ellipse: its sag grows
//! as 1/cos of the slope (3 % at the dome's edge, slope 0.25). A base arc is
//! its lens projected along y (swept instead along its creases, which
//! follow the profile, it agrees less with the mesh: the saddle's frame
//! 0.9865 → 0.9862, against the path tracer 0.9844 → 0.9833). What it
//! leaves out, and why a preview may: the normal's component along v,
//! which bends a refracted ray out of the plane by about the slope times
//! the lens's own tilt. The mesh tracer traces what is printed;
//! tests/render_agreement.rs holds the two to the same picture (the dome's
//! frames agreed 0.9798 with circles in the plane, 0.9819 so).

use crate::scene::Side;
use crate::trace::{Meeting, Surfaces};
use glam::{DMat2, DVec2, DVec3};
use moirecast_kernel::lens::{ArcRule, LensArc};
use moirecast_kernel::{BaseKind, Design, KernelError};
use std::sync::OnceLock;

/// A point's coordinates in the section's plane: (x, z).
fn in_plane(p: DVec3) -> DVec2 {
    DVec2::new(p.x, p.z)
}

/// One lens arc in the section's plane: where the lens, swept along its
/// axis, crosses the plane. A lens leaning along v (where the surface
/// slopes along v) crosses it in an ellipse, the affine image of its
/// circle, p(θ) = centre + R (cos θ · bulge + sin θ · chord), θ within
/// ± its half angle of the middle.
#[derive(Clone, Copy, Debug)]
struct Arc2 {
    centre: DVec2,
    /// Maps p − centre to the unit circle's (sin θ, cos θ).
    to_unit: DMat2,
    /// A point of the ellipse is on the arc iff its cos θ ≥ this.
    on_arc: f64,
    x: (f64, f64),
    z: (f64, f64),
    /// The lens's axis, which its surface runs along, scaled to a y of 1
    /// (the step a point slides along it per mm of y; y alone where the
    /// axis turns towards x): a revealer lens's is the surface's v
    /// direction, a base lens's its creases'. Its normal is square to it
    /// ([`Drift`]).
    axis: DVec3,
}

impl Arc2 {
    /// The arc of `lens` (whose creases share their y) where the lens,
    /// swept along `axis`, crosses the plane of its creases; its axis is
    /// `axis`.
    fn new(lens: &LensArc, axis: DVec3) -> Arc2 {
        let (p0, p1) = (in_plane(lens.p0), in_plane(lens.p1));
        let cos_half = lens.half_angle.cos();
        let centre3 = 0.5 * (lens.p0 + lens.p1) - lens.radius * cos_half * lens.bulge;
        // a point of the circle slides along the axis into the plane
        let y = lens.p0.y;
        let into_plane = |p: DVec3| {
            let along = if axis.y.abs() > 1e-3 {
                (y - p.y) / axis.y
            } else {
                0.0
            };
            in_plane(p + along * axis)
        };
        let centre = into_plane(centre3);
        let bulge = into_plane(centre3 + lens.bulge) - centre;
        let chord = into_plane(centre3 + lens.chord_dir) - centre;
        let to_unit = DMat2::from_cols(lens.radius * chord, lens.radius * bulge).inverse();
        // the ellipse's extreme point in a direction counts if on the arc
        let extent = |axis: DVec2| {
            let along = |p: DVec2| p.dot(axis);
            let (mut lo, mut hi) = (along(p0).min(along(p1)), along(p0).max(along(p1)));
            let (m, c) = (bulge.dot(axis), chord.dot(axis));
            let reach = m.hypot(c);
            for sign in [-1.0, 1.0] {
                if sign * m >= cos_half * reach {
                    let e = along(centre) + sign * lens.radius * reach;
                    (lo, hi) = (lo.min(e), hi.max(e));
                }
            }
            (lo, hi)
        };
        Arc2 {
            centre,
            to_unit,
            // a relative slack of 1e-12: neighbouring arcs share their
            // crease, and no ray slips between them through round-off
            on_arc: cos_half - 1e-12,
            x: extent(DVec2::X),
            z: extent(DVec2::Y),
            axis: per_unit_y(axis),
        }
    }

    /// A point's (sin θ, cos θ) on the unit circle the arc is an image of.
    fn unit(&self, p: DVec2) -> DVec2 {
        self.to_unit * (p - self.centre)
    }

    /// The z of the arc's point at x, if the arc reaches x.
    fn z_at(&self, x: f64) -> Option<f64> {
        // the vertical line at x: unit(x, z) = q0 + z · qz
        let q0 = self.unit(DVec2::new(x, 0.0));
        let qz = self.to_unit * DVec2::Y;
        let (a, b, c) = (qz.dot(qz), q0.dot(qz), q0.dot(q0) - 1.0);
        let h = (b * b - a * c).sqrt();
        [(-b - h) / a, (-b + h) / a]
            .into_iter()
            .find(|&z| (q0 + z * qz).y >= self.on_arc)
    }

    /// The nearest t > `t_min` at which `o + t·d` meets the arc from
    /// `side` (entering from outside, leaving from inside), and the
    /// outward normal there.
    ///
    /// The body a lens bounds lies inside its circle near the arc (every
    /// lens bulges away from its body), so a ray entering from outside
    /// meets the arc at the circle's nearer root and one leaving from
    /// inside at its farther root: only that root is solved.
    fn meet(&self, o: DVec2, d: DVec2, t_min: f64, side: Side) -> Option<(f64, DVec2)> {
        // on the unit circle: t is the same
        let (oc, d) = (self.unit(o), self.to_unit * d);
        let b = oc.dot(d);
        // entering, the ray meets the circle before its nearest approach
        // to the centre, which is behind it: every ray leaving a lens
        if side == Side::Outside && b > 0.0 {
            return None;
        }
        let (a, c) = (d.dot(d), oc.dot(oc) - 1.0);
        let disc = b * b - a * c;
        if disc < 0.0 || a == 0.0 {
            return None;
        }
        let root = disc.sqrt();
        // the root wanted, without cancellation: q/a is the nearer root
        // where q < 0 and the farther where q > 0, c/q the other
        let q = if b.is_sign_negative() {
            root - b
        } else {
            -(b + root)
        };
        let t = if q == 0.0 {
            0.0
        } else if (side == Side::Outside) == (q < 0.0) {
            q / a
        } else {
            c / q
        };
        if t <= t_min {
            return None;
        }
        let radial = oc + t * d;
        let facing = match side {
            Side::Outside => d.dot(radial) < 0.0,
            Side::Inside => d.dot(radial) > 0.0,
        };
        // the outward normal: the gradient of |unit(p)|²
        (facing && radial.y >= self.on_arc)
            .then(|| (t, (self.to_unit.transpose() * radial).normalize()))
    }
}

/// A lens in a section's plane: its arc and the arc's ends (its creases).
#[derive(Clone, Copy, Debug)]
struct Lens2 {
    arc: Arc2,
    ends: [DVec2; 2],
}

impl Lens2 {
    /// `lens`'s arc swept along `axis` ([`Arc2::new`]), with its ends.
    fn new(lens: &LensArc, axis: DVec3) -> Lens2 {
        Lens2 {
            arc: Arc2::new(lens, axis),
            ends: [in_plane(lens.p0), in_plane(lens.p1)],
        }
    }
}

/// How far (mm) beyond a wall's z extent a ray's line, found without
/// dividing, must pass for the wall to be skipped: far more than that
/// line's rounding, so the skip never drops a meeting.
const WALL_SLACK: f64 = 1e-6;

/// Base creases a section adds beyond the layout's edge, at most, to reach
/// a wall (a base that ends this many periods inside its wall would fold).
const MAX_EXTRA_CREASES: usize = 64;

/// A ray in a section's plane, and its slope dz/dx (shared by the rows
/// it is tested against).
#[derive(Clone, Copy, Debug)]
struct Ray2 {
    o: DVec2,
    d: DVec2,
    slope: f64,
}

impl Ray2 {
    fn new(o: DVec2, d: DVec2) -> Ray2 {
        Ray2 {
            o,
            d,
            slope: d.y / d.x,
        }
    }

    /// The z of the ray's line at x.
    fn z_at(&self, x: f64) -> f64 {
        self.o.y + (x - self.o.x) * self.slope
    }

    /// The z extent of the ray's line over an x extent.
    fn z_over(&self, x: (f64, f64)) -> (f64, f64) {
        let (a, b) = (self.z_at(x.0), self.z_at(x.1));
        if a < b {
            (a, b)
        } else {
            (b, a)
        }
    }

    /// Whether the ray is too close to vertical for its z over an x extent
    /// to be told from its slope: an x one rounding off would move the z
    /// by more than about 1e-9 mm.
    fn steep(&self) -> bool {
        self.d.x.abs() < 1e-6 * self.d.y.abs() || !self.slope.is_finite()
    }
}

/// The union of two extents.
fn union(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (a.0.min(b.0), a.1.max(b.1))
}

const EMPTY: (f64, f64) = (f64::INFINITY, f64::NEG_INFINITY);

/// Whether two extents do not overlap.
fn apart(a: (f64, f64), b: (f64, f64)) -> bool {
    a.1 < b.0 || a.0 > b.1
}

/// Where a ray meets a section: how far along it, the outward unit normal
/// in the section's plane (x, z), the axis of the surface met, and which
/// arc it is (none for a wall).
#[derive(Clone, Copy, Debug)]
struct Hit2 {
    t: f64,
    normal: DVec2,
    axis: DVec3,
    arc: Option<ArcAt>,
}

/// One arc of a section: of its base row or its revealer row, and which.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ArcAt {
    base: bool,
    index: usize,
}

/// Arcs ordered along x (their x extents increase), as the lenses of a
/// row, with the z extent of the arcs on either side of each: a ray walks
/// the arcs from where it starts in the direction it travels, and stops
/// where it has passed above or below every arc left. No division but
/// where a ray starts outside the row's z extent.
#[derive(Clone, Debug, Default)]
struct ArcRow {
    arcs: Vec<Arc2>,
    /// Each arc's ends in the plane (its creases): what [`Drift`] compares
    /// between neighbouring sections to bound the swept lens's error.
    ends: Vec<[DVec2; 2]>,
    /// `after[k]`: the z extent of arcs k.. (EMPTY past the last);
    /// `before[k]`: of arcs ..k (EMPTY at 0).
    after: Vec<(f64, f64)>,
    before: Vec<(f64, f64)>,
    /// The first arc's x and arcs per mm across the row: where to start
    /// looking for the arc at an x (the arcs are about equally wide).
    x_first: f64,
    arcs_per_mm: f64,
}

impl ArcRow {
    fn new(lenses: Vec<Lens2>) -> ArcRow {
        let (arcs, ends): (Vec<Arc2>, Vec<[DVec2; 2]>) =
            lenses.into_iter().map(|l| (l.arc, l.ends)).unzip();
        let n = arcs.len();
        let mut after = vec![EMPTY; n + 1];
        let mut before = vec![EMPTY; n + 1];
        for k in (0..n).rev() {
            after[k] = union(after[k + 1], arcs[k].z);
        }
        for k in 0..n {
            before[k + 1] = union(before[k], arcs[k].z);
        }
        let (x_first, arcs_per_mm) = match (arcs.first(), arcs.last()) {
            (Some(a), Some(b)) if b.x.1 > a.x.0 => (a.x.0, n as f64 / (b.x.1 - a.x.0)),
            _ => (0.0, 0.0),
        };
        ArcRow {
            arcs,
            ends,
            after,
            before,
            x_first,
            arcs_per_mm,
        }
    }

    /// The row's z extent: a ray outside it meets nothing.
    fn z(&self) -> (f64, f64) {
        self.after[0]
    }

    /// The nearest meeting in (`t_min`, `t_max`] within `walls` (x):
    /// the arcs walked from where the ray is in the row's z extent, in the
    /// direction it travels, up to the nearest meeting found, the walls,
    /// or where the ray is above or below every arc left. (A meeting
    /// beyond the walls is the caller's to drop.)
    #[inline(always)]
    fn meet(
        &self,
        ray: Ray2,
        (t_min, t_max): (f64, f64),
        side: Side,
        walls: (f64, f64),
    ) -> Option<Hit2> {
        let (o, d) = (ray.o, ray.d);
        // where the search starts: at t_min, or where the ray enters the
        // row's z extent if it starts outside it, heading in
        let (z_min, z) = (o.y + t_min * d.y, self.z());
        let t_start = if z_min > z.1 {
            if d.y >= 0.0 {
                return None;
            }
            (z.1 - o.y) / d.y
        } else if z_min < z.0 {
            if d.y <= 0.0 {
                return None;
            }
            (z.0 - o.y) / d.y
        } else {
            t_min
        };
        if t_start > t_max {
            return None;
        }
        let forward = d.x >= 0.0;
        // beyond `x_stop`, in the direction of travel, nothing is nearer:
        // the far wall, t_max, and then the nearest meeting found
        // (plain comparisons: no NaN reaches here, and f64::min is slower)
        let nearer = |x: f64, y: f64| if (x < y) == forward { x } else { y };
        let mut x_stop = if forward { walls.1 } else { walls.0 };
        if t_max.is_finite() {
            x_stop = nearer(x_stop, o.x + t_max * d.x);
        }
        let x_start = o.x + t_start * d.x;
        let x_start = match forward {
            true if x_start < walls.0 => walls.0,
            false if x_start > walls.1 => walls.1,
            _ => x_start,
        };
        if (forward && x_start > x_stop) || (!forward && x_start < x_stop) {
            return None;
        }
        let (steep, arcs) = (ray.steep(), &self.arcs);
        let mut best: Option<Hit2> = None;
        // forward, k is the next arc; backward, one past it
        let mut k = if forward {
            self.first_reaching(x_start)
        } else {
            self.first_beyond(x_start)
        };
        loop {
            let arc = match (forward, k) {
                (true, k) if k < arcs.len() => &arcs[k],
                (false, k) if k > 0 => &arcs[k - 1],
                _ => break,
            };
            if (forward && arc.x.0 > x_stop) || (!forward && arc.x.1 < x_stop) {
                break;
            }
            if steep || !apart(ray.z_over(arc.x), arc.z) {
                if let Some((t, normal)) = arc.meet(o, d, t_min, side) {
                    if t <= t_max && best.is_none_or(|b| t < b.t) {
                        best = Some(Hit2 {
                            t,
                            normal,
                            axis: arc.axis,
                            arc: Some(ArcAt {
                                base: false,
                                index: if forward { k } else { k - 1 },
                            }),
                        });
                        x_stop = nearer(x_stop, o.x + t * d.x);
                    }
                }
            }
            // past this arc, the ray is above or below every arc left
            if !steep {
                let (z_end, left) = if forward {
                    (ray.z_at(arc.x.1), self.after[k + 1])
                } else {
                    (ray.z_at(arc.x.0), self.before[k - 1])
                };
                let rising = (ray.slope > 0.0) == forward;
                if (rising && z_end > left.1) || (!rising && z_end < left.0) {
                    break;
                }
            }
            k = if forward { k + 1 } else { k - 1 };
        }
        best
    }

    /// The index of an arc near x: the arcs are about equally wide.
    fn guess(&self, x: f64) -> usize {
        let (g, last) = ((x - self.x_first) * self.arcs_per_mm, self.arcs.len());
        if g > 0.0 && g < last as f64 {
            g as usize
        } else if g > 0.0 {
            last.saturating_sub(1)
        } else {
            0
        }
    }

    /// The axis of the arc at x (the last arc's beyond it; y without arcs).
    fn axis_at(&self, x: f64) -> DVec3 {
        let k = self
            .first_reaching(x)
            .min(self.arcs.len().saturating_sub(1));
        self.arcs.get(k).map_or(DVec3::Y, |arc| arc.axis)
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
    body: Body,
    /// The base crease (k) base arc 0 starts at: arc i lies between
    /// creases k + i and k + i + 1 in every section.
    base_first: i64,
    /// The base creases, `base_first` first: where [`Drift`] starts to
    /// solve a base lens's creases at a ray's own station.
    creases: Vec<Crease>,
    /// The rule its base arcs follow.
    rule: ArcRule,
}

/// Between the walls, a z that lies inside the device's body at each x
/// (below every revealer arc there and above every base arc), in bins
/// of equal width; NaN where the arcs' extents overlap in z.
///
/// Outside the body and between the walls, a ray is above the revealer
/// or below the base. From above, it can meet the base only after the
/// revealer (the base lies under the revealer at every x between the
/// walls, and a line cannot leave that stretch of x and come back), and
/// a wall never (it faces away): only the revealer is searched. From
/// below, only the base. That halves the search of half the rays (every
/// branch that leaves the device).
#[derive(Clone, Debug)]
struct Body {
    x0: f64,
    bins_per_mm: f64,
    z: Vec<f64>,
}

impl Body {
    /// Bins half a revealer lens wide between `walls`.
    fn new(top: &ArcRow, base: &ArcRow, walls: (f64, f64)) -> Body {
        let bins = 2 * top.arcs.len().max(1);
        let width = (walls.1 - walls.0) / bins as f64;
        let z = (0..bins)
            .map(|b| {
                let x = (walls.0 + b as f64 * width, walls.0 + (b + 1) as f64 * width);
                let over = |row: &ArcRow| {
                    row.arcs
                        .iter()
                        .filter(|a| !apart(a.x, x))
                        .fold(EMPTY, |z, a| union(z, a.z))
                };
                let (top, base) = (over(top), over(base));
                if top.0 > base.1 && top.0.is_finite() && base.1.is_finite() {
                    0.5 * (top.0 + base.1)
                } else {
                    f64::NAN
                }
            })
            .collect();
        Body {
            x0: walls.0,
            bins_per_mm: 1.0 / width,
            z,
        }
    }

    /// The body's z at x, if x is strictly between the walls and known.
    fn z_at(&self, x: f64) -> Option<f64> {
        let b = (x - self.x0) * self.bins_per_mm;
        if !(b > 0.0 && b < self.z.len() as f64) {
            return None;
        }
        let z = self.z[b as usize];
        (!z.is_nan()).then_some(z)
    }
}

impl Section {
    /// The section of `design` (dual-lens) at station `v`, from the exact
    /// revealer arcs and the base arcs between the base creases solved
    /// there.
    pub fn new(design: &Design, v: f64) -> Result<Section, KernelError> {
        let hw = design.params.width / 2.0;
        let top = (0..design.lenses as i64)
            .map(|i| revealer_lens(design, i, v))
            .collect();
        let x_of = |u: f64| design.surface().point(u, v).x;
        let walls = (x_of(-hw), x_of(hw));
        let (base_first, creases) = base_creases(design, v, walls)?;
        let rule = base_rule(design, v);
        let base = creases
            .windows(2)
            .map(|w| base_lens(design, rule, w[0], w[1]))
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
            body: Body::new(&top, &base, walls),
            top,
            base,
            base_first,
            creases,
            rule,
        })
    }
}

/// Revealer lens `i`'s arc in the plane y = `v`, swept along the
/// surface's v direction at its middle.
fn revealer_lens(design: &Design, i: i64, v: f64) -> Lens2 {
    let mid_u = design.crease_u(i) + 0.5 * design.params.period;
    let axis = design.surface().jet(mid_u, v).dv.normalize();
    Lens2::new(&design.revealer_arc(i, v), axis)
}

/// The rule every base arc of station `v` follows (constant AFOV: the
/// half angle of the layout's first base lens there).
fn base_rule(design: &Design, v: f64) -> ArcRule {
    let (hw, period) = (design.params.width / 2.0, design.params.period);
    ArcRule::ConstantAfov {
        half_angle: design.base_arc_between(-hw, -hw + period, v).half_angle,
    }
}

/// A base crease, (u, station), as a section holds it: crease k at the
/// station that puts it in the section's plane.
type Crease = (f64, f64);

/// Base crease `k` in the plane y = `v`, solved from `near` (a nearby
/// crease's u, if known, and a station to start from).
///
/// The base lies below f along its normal, which leans along v where the
/// surface slopes along v: the base crease of station v is not in the
/// plane y = v (0.2 mm off at the reference saddle's edge, where the level
/// lines move with v). Each crease is taken at the station that puts it in
/// the plane.
fn solve_crease(
    design: &Design,
    k: i64,
    near: (Option<f64>, f64),
    v: f64,
) -> Result<Crease, KernelError> {
    let (mut u, mut station) = near;
    for _ in 0..3 {
        let solved = design.base_crease_u_near(k, station, u)?;
        station -= design.base_surface(solved, station).y - v;
        u = Some(solved);
    }
    Ok((design.base_crease_u_near(k, station, u)?, station))
}

/// The base creases of the plane y = `v`, in order across, and the number
/// of the first. They reach each wall: the walls are vertical over the
/// layout's edge, and the base, below f along the normal, may end inside
/// them (where the surface slopes down towards a wall), so the base arcs
/// go on until they reach each wall, as the mesh's base does before the
/// walls trim it.
fn base_creases(
    design: &Design,
    v: f64,
    walls: (f64, f64),
) -> Result<(i64, Vec<Crease>), KernelError> {
    let (hw, period) = (design.params.width / 2.0, design.params.period);
    let first = design.base_phase(-hw, v).floor() as i64;
    let last = design.base_phase(hw, v).ceil() as i64;
    let mut creases: Vec<Crease> = Vec::with_capacity((last - first + 1).max(0) as usize);
    for k in first..=last {
        let near = creases
            .last()
            .map_or((None, v), |&(u, s)| (Some(u + period), s));
        creases.push(solve_crease(design, k, near, v)?);
    }
    let base_x = |(u, station): Crease| design.base_surface(u, station).x;
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
            creases.insert(0, solve_crease(design, k0, (Some(a.0 - period), a.1), v)?);
        }
        if right {
            k1 += 1;
            creases.push(solve_crease(design, k1, (Some(b.0 + period), b.1), v)?);
        }
    }
    Ok((k0, creases))
}

/// The base arc between two creases, swept along their mean direction.
/// (Projected along y instead of swept along their creases, which follow
/// the profile, they agree less with the mesh; the creases' direction is
/// the lens's axis all the same.)
fn base_lens(design: &Design, rule: ArcRule, (u0, v0): Crease, (u1, v1): Crease) -> Lens2 {
    let toward = -design.base_normal(0.5 * (u0 + u1), 0.5 * (v0 + v1));
    let (p0, p1) = (design.base_surface(u0, v0), design.base_surface(u1, v1));
    let lens = Lens2::new(&LensArc::new(p0, p1, toward, rule), DVec3::Y);
    let axis = per_unit_y(crease_direction(design, u0, v0) + crease_direction(design, u1, v1));
    Lens2 {
        arc: Arc2 { axis, ..lens.arc },
        ..lens
    }
}

/// The unit direction of the base crease through layout point (u, v):
/// along it the base phase is constant, u − E(u, v) + C(u, v) fixed, so
/// du/dv = ∂shift/∂v / (1 − ∂shift/∂u).
fn crease_direction(design: &Design, u: f64, v: f64) -> DVec3 {
    let (_, grad) = design.shift_and_gradient(u, v);
    let du_dv = grad.y / (1.0 - grad.x);
    let h = CREASE_STEP_MM;
    (design.base_surface(u + du_dv * h, v + h) - design.base_surface(u - du_dv * h, v - h))
        .normalize()
}

/// The step (mm along v) of [`crease_direction`]'s central difference.
const CREASE_STEP_MM: f64 = 1e-3;

impl Surfaces for Section {
    fn meet(&self, side: Side, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Meeting> {
        self.meet_hit(side, origin, dir, t_min).map(|hit| Meeting {
            t: hit.t,
            normal: DVec3::new(hit.normal.x, 0.0, hit.normal.y),
            absorbs: false,
        })
    }
}

impl Section {
    /// The axis of the lens a ray from `origin` along `dir` heads for
    /// first, about: the base's under it going down inside (or coming from
    /// below), else the revealer's, at the ray's x.
    fn axis_ahead(&self, side: Side, origin: DVec3, dir: DVec3) -> DVec3 {
        let from_below =
            side == Side::Outside && self.body.z_at(origin.x).is_some_and(|body| origin.z < body);
        let row = if (side == Side::Inside && dir.z < 0.0) || from_below {
            &self.base
        } else {
            &self.top
        };
        row.axis_at(origin.x)
    }

    /// About how far along `dir` a ray from `origin` meets the section:
    /// going down inside, the base lies as far below the body's middle as
    /// the revealer above it (going up, the revealer); from outside, where
    /// it reaches the row it heads for. 0 where unknown.
    fn reach_guess(&self, side: Side, origin: DVec3, dir: DVec3) -> f64 {
        let t = match (side, self.body.z_at(origin.x)) {
            (Side::Inside, Some(middle)) => 2.0 * (middle - origin.z) / dir.z,
            // from above or below, to the revealer's or the base's top
            (Side::Outside, _) if dir.z < 0.0 => (self.top.z().1 - origin.z) / dir.z,
            (Side::Outside, _) => (self.base.z().0 - origin.z) / dir.z,
            _ => 0.0,
        };
        if t.is_finite() {
            t.max(0.0)
        } else {
            0.0
        }
    }

    /// The arc `at`.
    fn arc(&self, at: ArcAt) -> &Arc2 {
        let row = if at.base { &self.base } else { &self.top };
        &row.arcs[at.index]
    }

    /// The ends (creases) of arc `at` in the plane.
    fn lens_ends(&self, at: ArcAt) -> [DVec2; 2] {
        let row = if at.base { &self.base } else { &self.top };
        row.ends[at.index]
    }

    /// `hit`, an arc of `row`'s, said to be of that row.
    fn of_row(&self, hit: Hit2, row: &ArcRow) -> Hit2 {
        let base = std::ptr::eq(row, &self.base);
        Hit2 {
            arc: hit.arc.map(|at| ArcAt { base, ..at }),
            ..hit
        }
    }

    /// The arc of this section that is `at` of `other`'s: the same lens,
    /// the same base crease pair. `None` if this section has no such arc.
    fn same_arc(&self, at: ArcAt, other: &Section) -> Option<ArcAt> {
        let index = if at.base {
            usize::try_from(other.base_first + at.index as i64 - self.base_first).ok()?
        } else {
            at.index
        };
        let row = if at.base { &self.base } else { &self.top };
        (index < row.arcs.len()).then_some(ArcAt { index, ..at })
    }

    /// Where a ray meets one arc alone, from `side`, between the walls.
    fn meet_arc(
        &self,
        at: ArcAt,
        side: Side,
        origin: DVec3,
        dir: DVec3,
        t_min: f64,
    ) -> Option<Hit2> {
        let row = if at.base { &self.base } else { &self.top };
        let arc = &row.arcs[at.index];
        let (o, d) = (in_plane(origin), DVec2::new(dir.x, dir.z));
        let (t, normal) = arc.meet(o, d, t_min, side)?;
        let x = o.x + t * d.x;
        (x >= self.walls.0 && x <= self.walls.1).then_some(Hit2 {
            t,
            normal,
            axis: arc.axis,
            arc: Some(at),
        })
    }

    /// Where a ray meets arc `at` alone, if it does, else the whole
    /// section ([`Section::meet_hit`]).
    fn meet_lens_first(
        &self,
        at: Option<ArcAt>,
        side: Side,
        origin: DVec3,
        dir: DVec3,
        t_min: f64,
    ) -> Option<Hit2> {
        at.and_then(|at| self.meet_arc(at, side, origin, dir, t_min))
            .or_else(|| self.meet_hit(side, origin, dir, t_min))
    }

    /// [`Surfaces::meet`], with the axis of the surface met.
    fn meet_hit(&self, side: Side, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Hit2> {
        let (o, d) = (in_plane(origin), DVec2::new(dir.x, dir.z));
        let ray = Ray2::new(o, d);
        let within = |hit: &Hit2| {
            let x = o.x + hit.t * d.x;
            x >= self.walls.0 && x <= self.walls.1
        };
        // outside the body between the walls: one row to search
        if side == Side::Outside {
            if let Some(body) = self.body.z_at(o.x) {
                let row = if o.y > body { &self.top } else { &self.base };
                return row
                    .meet(ray, (t_min, f64::INFINITY), side, self.walls)
                    .filter(within)
                    .map(|hit| self.of_row(hit, row));
            }
        }
        // the walls: entered from outside, left from inside; a ray moving
        // towards +x enters through the −x wall and leaves through the +x
        // one (a ray along z meets neither)
        let towards_plus = d.x > 0.0;
        let wall = (d.x != 0.0)
            .then(|| {
                let plus = towards_plus == (side == Side::Inside);
                let (x, outward, (z0, z1)) = if plus {
                    (self.walls.1, 1.0, self.wall_z[1])
                } else {
                    (self.walls.0, -1.0, self.wall_z[0])
                };
                // most rays pass far above or below a wall: said first
                // without dividing
                let z = ray.z_at(x);
                if !ray.steep() && (z < z0 - WALL_SLACK || z > z1 + WALL_SLACK) {
                    return None;
                }
                let t = (x - o.x) / d.x;
                let z = o.y + t * d.y;
                (t > t_min && z >= z0 && z <= z1).then_some(Hit2 {
                    t,
                    normal: DVec2::new(outward, 0.0),
                    axis: DVec3::Y,
                    arc: None,
                })
            })
            .flatten();
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
            let t_max = nearest.map_or(f64::INFINITY, |h| h.t);
            if let Some(hit) = row
                .meet(ray, (t_min, t_max), side, self.walls)
                .filter(within)
                .map(|hit| self.of_row(hit, row))
            {
                if nearest.is_none_or(|n| hit.t < n.t) {
                    nearest = Some(hit);
                }
            }
        }
        nearest
    }
}

/// The sections as a ray tilted along the lenses meets them: a view
/// tilted about x, whose rays leave the plane of the section they start in.
///
/// Every lens is a cylinder along its axis: a revealer lens along the
/// surface's v direction, a base lens along its creases, which follow the
/// profile (and slant by du/dv = ∂shift/∂v / (1 − ∂shift/∂u)). A ray
/// slid along a lens's axis into a section's plane, `p − (p.y − v)·a` for
/// the axis `a` scaled to a y of 1, is a straight line in that plane with
/// the ray's own t, and it meets the lens's arc there exactly where the ray
/// meets the lens: the effective-index method for cylindrical lenses (the
/// ray's momentum along the axis is conserved, and its projection refracts
/// in the plane). The normal met is square to the axis, and
/// [`crate::trace`] refracts the 3D direction about it.
///
/// What the cylinder leaves out grows with the distance d from the
/// section along v: linearly where the lens widens or its axis turns, as
/// the square where its creases curve (a crease on a ring of radius R
/// leaves its tangent by d²/2R: 11 µm at d = 0.47 mm, R = 10 mm). So each
/// segment meets the section of a row within about one row's spacing of
/// where it ends: guessed from where it starts and the body's thickness,
/// and met again in the nearest row when the guess was farther (on the
/// same lens there first: base arcs are matched between sections by their
/// creases' numbers). A ray slid along a neighbouring lens's axis (the
/// guess) is slid again along the lens it met, on that lens alone, unless
/// the difference moves the meeting by less than 0.25 µm.
///
/// Every meeting is then held to the design's mesh tolerance, the mesh's
/// own promise, in three tiers (`LensAround` gives the bounds, from the
/// lens's ends in the neighbouring sections):
/// - kept, where its distance from the row lies within the lens's reach
///   ([`Sections`] keeps each lens's, the distance at which the swept
///   lens's bound reaches the tolerance): 94.8–99.7 % of the meetings on
///   lenses of the shipped dual-lens specs at 5°–20° along;
/// - else met on the lens interpolated between the two sections around
///   its station, where that bound is within the tolerance;
/// - else met on the lens built at its station (its creases solved
///   there): 0.08–0.36 % of them, at about 35 000 instructions each.
///
/// Meetings beyond the layout's end faces, which the sections leave out,
/// are kept as they are. Rays within 40° of straight up or down from
/// inside a saddle, a dome and a plane with 3 mm rings met their lens
/// within 1.5 µm of the lens built at their station (tolerance 2 µm;
/// 51 µm swept alone): `a_drifting_ray_meets_its_lens_within_the_mesh_tolerance`.
///
/// Against the mesh tracer (tests/render_agreement.rs, 128 px, 5°, 10° and
/// 20° along): 0.984–0.999 on every shipped dual-lens spec. With each ray
/// projected along y instead, the lens-period means of plane-rings at 10°
/// correlated 0.82 with the mesh's (0.98 slid): the base creases' slant
/// moved the lens a ray meets by up to half a lens.
pub struct Drift<'s, 'd> {
    sections: &'s Sections<'d>,
    /// The row a camera ray starts in: the station of the point it is
    /// aimed at (the cell's).
    home: usize,
    /// The device's z extent (the frame's bounds): a segment starting
    /// outside it is a camera ray's, which starts in `home`.
    z: (f64, f64),
    /// How far (mm) a meeting's bound from its lens's ends may reach: the
    /// [`ENDS_SHARE`] of the design's mesh tolerance, which the mesh the
    /// sections preview keeps.
    tolerance: f64,
}

/// How many meetings [`Drift`] tries for one segment before it keeps the
/// last (a segment ending near the middle between two rows may alternate).
const DRIFT_ROWS: usize = 4;

/// A lens axis whose y component is below this is not slid along (a crease
/// that turns towards x: the base folds before it gets there).
const MIN_AXIS_Y: f64 = 0.1;

/// How far (mm) a meeting [`Drift`] keeps may lie off the one its lens's
/// own axis gives, where it slid the ray along a neighbouring lens's axis:
/// a quarter of the finest mesh tolerance a spec may ask for (1 µm).
const SLIDE_TOLERANCE_MM: f64 = 2.5e-4;

impl<'s, 'd> Drift<'s, 'd> {
    /// Rays of the cell at row `home`.
    pub fn new(sections: &'s Sections<'d>, home: usize, z: (f64, f64)) -> Self {
        Drift {
            sections,
            home,
            z,
            tolerance: ENDS_SHARE * sections.design.tolerance.mm(),
        }
    }

    /// The row nearest station (y) `y`, clamped to the layout.
    fn nearest(&self, y: f64) -> usize {
        // truncation of a positive number is its floor (no libm call)
        let s = (y - self.sections.v0) / self.sections.step + 0.5;
        let row = if s > 0.0 { s as usize } else { 0 };
        row.min(self.sections.rows.len() - 1)
    }
}

impl Surfaces for Drift<'_, '_> {
    fn meet(&self, side: Side, origin: DVec3, dir: DVec3, t_min: f64) -> Option<Meeting> {
        if dir.y == 0.0 {
            return self
                .sections
                .section(self.home)?
                .meet(side, origin, dir, t_min);
        }
        let ray = Probe {
            side,
            origin,
            dir,
            t_min,
        };
        self.meet_drifting(ray)
            .map(|(row, hit)| oblique(self.within_tolerance(row, ray, hit)))
    }
}

impl Drift<'_, '_> {
    /// Where a ray out of the sections' planes meets the lens swept from
    /// the nearest row it reaches, and that row.
    fn meet_drifting(&self, ray: Probe) -> Option<(usize, Hit2)> {
        let Probe {
            side,
            origin,
            dir,
            t_min,
        } = ray;
        // the row and lens the ray likely meets: a camera ray's cell's row,
        // else the row about where it reaches the other side of the body
        let outside_z = origin.z < self.z.0 || origin.z > self.z.1;
        let start = if outside_z {
            self.home
        } else {
            self.nearest(origin.y)
        };
        let reach = self.sections.section(start)?.reach_guess(side, origin, dir);
        let mut row = if outside_z {
            start
        } else {
            self.nearest(origin.y + reach * dir.y)
        };
        let mut section = self.sections.section(row)?;
        let mut axis = section.axis_ahead(side, origin + reach * dir, dir);
        let mut hit = section.meet_hit(
            side,
            self.slid(row, axis, origin),
            dir - dir.y * axis,
            t_min,
        );
        for _ in 1..DRIFT_ROWS {
            let Some(h) = hit else { break };
            let end = origin.y + h.t * dir.y;
            let offset = (end - self.sections.station(row)).abs();
            if offset > self.sections.step {
                // a row nearer the meeting, and the lens's own axis: the
                // same lens there, unless the ray now passes it by
                let met_in = section;
                (row, axis) = (self.nearest(end), h.axis);
                section = self.sections.section(row)?;
                let (o, d) = (self.slid(row, axis, origin), dir - dir.y * axis);
                let same = h.arc.and_then(|at| section.same_arc(at, met_in));
                hit = section.meet_lens_first(same, side, o, d, t_min);
                continue;
            }
            // a row a step away still holds the lens swept along its axis
            // (what it leaves out grows as the square of the offset); a
            // slide along another lens's axis is off by the offset times
            // the change of axis
            if offset * (h.axis - axis).length() <= SLIDE_TOLERANCE_MM {
                break;
            }
            // slid along the lens's own axis: that lens alone, unless the
            // ray now passes it by
            axis = h.axis;
            let (o, d) = (self.slid(row, axis, origin), dir - dir.y * axis);
            hit = section.meet_lens_first(h.arc, side, o, d, t_min);
        }
        hit.map(|h| (row, h))
    }
}

/// One lens in four neighbouring sections, rows c − 1 to c + 2: its arcs
/// and their ends, and what they tell of the lens near row c.
///
/// At row c, the ends' first difference less the slide along the axis,
/// e1, is what a sweep along the axis misses linearly (the lens's width
/// changing, its axis turning), and their second difference, e2, the
/// curvature of its creases. Over s spacings from row c, its lens swept
/// along its axis is off by |e1|·|s| + |e2|·s²/2 at most, to the second
/// order. Between rows c and c + 1, a fraction σ of the way, the lens
/// interpolated between them is off by f''·σ(1 − σ)/2, with f'' at most
/// the larger second difference of the two rows plus the third
/// difference (how much it changes between them).
struct LensAround {
    arcs: [Arc2; 4],
    ends: [[DVec2; 2]; 4],
    /// Row c's station, and the spacing of the rows.
    station: f64,
    step: f64,
    /// The walls of the section the ray met it in.
    walls: (f64, f64),
}

/// A lens interpolated between two sections, and a bound (mm) on how far
/// it lies off the lens at its station.
struct Between {
    arc: Arc2,
    error: f64,
}

impl LensAround {
    /// The largest length over the two ends of `f(ends)`.
    fn at_worse_end(&self, f: impl Fn([DVec2; 4]) -> DVec2) -> f64 {
        (0..2)
            .map(|j| f(self.ends.map(|e| e[j])).length())
            .fold(0.0, f64::max)
    }

    /// e1 and e2 at row c (mm per spacing, and per spacing squared), at
    /// the worse end.
    fn differences(&self) -> (f64, f64) {
        let axis = self.arcs[1].axis;
        let slide = self.step * DVec2::new(axis.x, axis.z);
        (
            self.at_worse_end(|[m, _, p, _]| 0.5 * (p - m) - slide),
            self.at_worse_end(|[m, c, p, _]| p + m - 2.0 * c),
        )
    }

    /// How far the lens swept along its axis by `d` (mm along y) from row
    /// c lies off it, at most.
    fn swept_error(&self, d: f64) -> f64 {
        let (e1, e2) = self.differences();
        let s = d / self.step;
        e1 * s.abs() + 0.5 * e2 * s * s
    }

    /// The first-order part of [`LensAround::swept_error`].
    fn linear_error(&self, d: f64) -> f64 {
        self.differences().0 * (d / self.step).abs()
    }

    /// The lens at station `y`, interpolated between rows c and c + 1;
    /// `None` outside them.
    fn between(&self, y: f64) -> Option<Between> {
        let sigma = (y - self.station) / self.step;
        if !(0.0..=1.0).contains(&sigma) {
            return None;
        }
        let (a, b) = (&self.arcs[1], &self.arcs[2]);
        let lerp =
            |x: (f64, f64), y: (f64, f64)| (x.0 + sigma * (y.0 - x.0), x.1 + sigma * (y.1 - x.1));
        let arc = Arc2 {
            centre: a.centre.lerp(b.centre, sigma),
            // the map from the unit circle is linear in the lens's ends
            // (its inverse is not): interpolated, then inverted
            to_unit: (a.to_unit.inverse() * (1.0 - sigma) + b.to_unit.inverse() * sigma).inverse(),
            on_arc: a.on_arc + sigma * (b.on_arc - a.on_arc),
            x: lerp(a.x, b.x),
            z: lerp(a.z, b.z),
            axis: a.axis.lerp(b.axis, sigma),
        };
        let second = self
            .at_worse_end(|[m, c, p, _]| p + m - 2.0 * c)
            .max(self.at_worse_end(|[_, c, p, q]| q + c - 2.0 * p));
        let third = self.at_worse_end(|[m, c, p, q]| q - 3.0 * p + 3.0 * c - m);
        let error = 0.5 * (second + third) * sigma * (1.0 - sigma);
        Some(Between { arc, error })
    }
}

/// Where `ray`, slid along `arc`'s axis into the plane y, meets `arc` (a
/// lens at station y) between `walls`; the meeting keeps the lens's axis
/// (and leaves which arc it is to the caller).
fn meet_slid(arc: &Arc2, ray: Probe, y: f64, walls: (f64, f64)) -> Option<Hit2> {
    let o = ray.origin - (ray.origin.y - y) * arc.axis;
    let d = ray.dir - ray.dir.y * arc.axis;
    let (o, d) = (in_plane(o), DVec2::new(d.x, d.z));
    let (t, normal) = arc.meet(o, d, ray.t_min, ray.side)?;
    let x = o.x + t * d.x;
    (x >= walls.0 && x <= walls.1).then_some(Hit2 {
        t,
        normal,
        axis: arc.axis,
        arc: None,
    })
}

/// A ray as [`Surfaces::meet`] asks for its meeting.
#[derive(Clone, Copy, Debug)]
struct Probe {
    side: Side,
    origin: DVec3,
    dir: DVec3,
    t_min: f64,
}

/// The share of the design's mesh tolerance a meeting's bound from its
/// lens's ends ([`LensAround`]) may use: the rest is left to what the ends
/// do not see, the bulge turning with the normal between them, and the
/// third order of the sweep (measured on a saddle's revealer: 1.5 % over
/// the ends' bound; `a_drifting_ray_meets_its_lens_within_the_mesh_tolerance`).
const ENDS_SHARE: f64 = 0.75;

/// How many times [`Drift`] meets a lens at a ray's own station, at most,
/// before it keeps the meeting (each moves the station by the change of t
/// times the ray's slope along v, and the error with it).
const EXACT_PASSES: usize = 3;

impl Drift<'_, '_> {
    /// `hit`, a meeting in row `row`, kept within the design's mesh
    /// tolerance of the lens it met, in three tiers: as it is, where the
    /// lens swept from the row is within the tolerance at the meeting's
    /// station; else on the lens interpolated between the sections around
    /// that station, where that is; else on the lens built at the
    /// station itself. Where neither can be had, `hit`.
    fn within_tolerance(&self, row: usize, ray: Probe, hit: Hit2) -> Hit2 {
        let Some(at) = hit.arc else {
            return hit; // a wall: a plane, as in the mesh
        };
        let y = ray.origin.y + hit.t * ray.dir.y;
        if y.abs() > self.sections.design.half_height {
            // beyond the layout's end faces, which the sections leave out:
            // there is no lens there to be nearer to
            return hit;
        }
        let d = y - self.sections.station(row);
        if d.abs() <= self.sections.reach(row, at) {
            return hit;
        }
        // the lens around the station the ray met it at (a ray may meet a
        // lens rows away from the row it was slid into)
        let below = self.sections.row_below(y).map_or(row, |(r, _)| r);
        if let Some(between) = self
            .around(below, at, row)
            .and_then(|lens| self.meet_between(&lens, ray, y))
        {
            return Hit2 {
                arc: Some(at),
                ..between
            };
        }
        self.meet_built(row, at, ray, hit)
    }

    /// Lens `at` of row `of` in rows c − 1 to c + 2 for c = `row` (at
    /// the layout's edges, the nearest c that has them), if each has it.
    fn around(&self, row: usize, at: ArcAt, of: usize) -> Option<LensAround> {
        let sections = self.sections;
        if sections.rows.len() < 4 {
            return None;
        }
        let c = row.clamp(1, sections.rows.len() - 3);
        let here = sections.section(of)?;
        let lens = |r: usize| {
            let there = sections.section(r)?;
            let at = if r == of {
                Some(at)
            } else {
                there.same_arc(at, here)
            }?;
            Some((*there.arc(at), there.lens_ends(at)))
        };
        let [m, a, p, q] = [lens(c - 1)?, lens(c)?, lens(c + 1)?, lens(c + 2)?];
        Some(LensAround {
            arcs: [m.0, a.0, p.0, q.0],
            ends: [m.1, a.1, p.1, q.1],
            station: sections.station(c),
            step: sections.step,
            walls: here.walls,
        })
    }

    /// Where the ray meets the lens interpolated between the sections
    /// around station y, if it does and the interpolation is within the
    /// tolerance there; the station follows the meeting (a pass or two).
    fn meet_between(&self, lens: &LensAround, ray: Probe, y: f64) -> Option<Hit2> {
        let mut y = y;
        let mut best = None;
        for _ in 0..EXACT_PASSES {
            let arc = lens.between(y).filter(|b| b.error <= self.tolerance)?.arc;
            let hit = meet_slid(&arc, ray, y, lens.walls)?;
            let moved = ray.origin.y + hit.t * ray.dir.y - y;
            best = Some(hit);
            // the lens swept over the move is off by its first order
            if lens.linear_error(moved) <= 0.25 * self.tolerance {
                break;
            }
            y += moved;
        }
        best
    }

    /// `hit`, or the meeting of its lens built at the ray's own station
    /// where the one swept from row `row` strays beyond the tolerance (a
    /// pass or two: each moves the station by the change of t times the
    /// ray's slope along v).
    fn meet_built(&self, row: usize, at: ArcAt, ray: Probe, hit: Hit2) -> Hit2 {
        let mut best = hit;
        let mut station = self.sections.station(row);
        let around = self.around(row, at, row);
        for _ in 0..EXACT_PASSES {
            let y = ray.origin.y + best.t * ray.dir.y;
            let off = around
                .as_ref()
                .map_or(f64::INFINITY, |l| l.swept_error(y - station));
            if station != self.sections.station(row) && off <= self.tolerance {
                break;
            }
            match self.meet_at_station(row, at, ray, y) {
                Some(exact) => (best, station) = (exact, y),
                None => break,
            }
        }
        best
    }

    /// Where the ray meets lens `at` (of row `row`'s numbering) built at
    /// station `y`, if it does: slid along that lens's own axis into the
    /// plane y, as [`Drift`] slides it into a row's.
    fn meet_at_station(&self, row: usize, at: ArcAt, ray: Probe, y: f64) -> Option<Hit2> {
        let section = self.sections.section(row)?;
        let design = self.sections.design;
        let arc = if at.base {
            let k = section.base_first + at.index as i64;
            let shift = y - self.sections.station(row);
            let near = |c: Crease| (Some(c.0), c.1 + shift);
            let c0 = solve_crease(design, k, near(section.creases[at.index]), y).ok()?;
            let c1 = solve_crease(design, k + 1, near(section.creases[at.index + 1]), y).ok()?;
            base_lens(design, section.rule, c0, c1).arc
        } else {
            revealer_lens(design, at.index as i64, y).arc
        };
        meet_slid(&arc, ray, y, section.walls).map(|hit| Hit2 {
            arc: Some(at),
            ..hit
        })
    }

    /// A point slid along `axis` (y = 1) into the plane of row `row`; a
    /// ray's direction slides to `dir − dir.y · axis`, and the slid ray
    /// keeps the ray's t.
    fn slid(&self, row: usize, axis: DVec3, p: DVec3) -> DVec3 {
        p - (p.y - self.sections.station(row)) * axis
    }
}

/// An axis scaled to a y of 1: how far a point slides along it per mm of
/// y. Y where the axis turns towards x (a crease that does so folds the
/// base before it gets there).
fn per_unit_y(axis: DVec3) -> DVec3 {
    let unit = axis.normalize();
    if unit.y.abs() > MIN_AXIS_Y {
        unit / unit.y
    } else {
        DVec3::Y
    }
}

/// The meeting of a ray out of the section's plane: the surface's normal
/// square to both its curve in the plane and its axis.
fn oblique(hit: Hit2) -> Meeting {
    let in_plane = DVec3::new(hit.normal.x, 0.0, hit.normal.y);
    let tangent = DVec3::new(-in_plane.z, 0.0, in_plane.x);
    let normal = tangent.cross(hit.axis).normalize();
    Meeting {
        t: hit.t,
        normal: if normal.dot(in_plane) < 0.0 {
            -normal
        } else {
            normal
        },
        absorbs: false,
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
    /// Each row's [`Reach`], computed the first time a ray needs it.
    reaches: Vec<OnceLock<Reach>>,
}

/// How far (mm along y) each lens of a section may be swept along its
/// axis and stay within the design's mesh tolerance of the lens there, by
/// [`LensAround::swept_error`]: 0 where a neighbouring section lacks it.
struct Reach {
    top: Vec<f64>,
    base: Vec<f64>,
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
            reaches: (0..rows).map(|_| OnceLock::new()).collect(),
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
            let z = union(s.top.z(), s.base.z());
            (lo.z, hi.z) = (lo.z.min(z.0), hi.z.max(z.1));
        }
        Some((lo, hi))
    }

    /// How far (mm along y) lens `at` of row `r` may be swept ([`Reach`]).
    fn reach(&self, r: usize, at: ArcAt) -> f64 {
        let reach = self.reaches[r].get_or_init(|| self.reach_of(r));
        let lenses = if at.base { &reach.base } else { &reach.top };
        lenses.get(at.index).copied().unwrap_or(0.0)
    }

    /// Row `r`'s [`Reach`]: for each lens, the |d| at which
    /// e1·|s| + e2·s²/2 (s = d / spacing) reaches the tolerance.
    fn reach_of(&self, r: usize) -> Reach {
        let tolerance = ENDS_SHARE * self.design.tolerance.mm();
        let drift = Drift::new(self, r, (f64::NEG_INFINITY, f64::INFINITY));
        let Some(section) = self.section(r) else {
            return Reach {
                top: Vec::new(),
                base: Vec::new(),
            };
        };
        let of_row = |base: bool, n: usize| -> Vec<f64> {
            (0..n)
                .map(|index| {
                    let at = ArcAt { base, index };
                    drift.around(r, at, r).map_or(0.0, |lens| {
                        let (e1, e2) = lens.differences();
                        let s = if e2 > 0.0 {
                            (2.0 * e2 * tolerance + e1 * e1).sqrt() - e1
                        } else {
                            tolerance
                        } / if e2 > 0.0 { e2 } else { e1 };
                        s * self.step
                    })
                })
                .collect()
        };
        Reach {
            top: of_row(false, section.top.arcs.len()),
            base: of_row(true, section.base.arcs.len()),
        }
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

    /// Where the surface slopes along v, the revealer lens leans out of
    /// the section's plane; the plane cuts it in the ellipse of its circle
    /// slid along the lens's axis, not in the circle itself: at 20 mm
    /// from a dome's centre (slope 0.2) the section's arc lies within
    /// 1e-5 mm of the exact lens's points in the plane (8.6e-7 mm; a
    /// circle in the plane, its bulge projected, is 2.6e-3 mm off, 4 % of
    /// the lens's 0.067 mm sag).
    #[test]
    fn a_leaning_lens_crosses_its_section_in_an_ellipse() {
        use moirecast_kernel::model::LensRef;
        let mut p = DesignParams::with_defaults(
            PitchSurface::Paraboloid { radius: -100.0 },
            50.0,
            50.0,
            0.5,
        );
        p.profile = Profile::Rings { wavelength: 10.0 };
        let d = Design::new(p).unwrap();
        let v = 20.0;
        let s = Section::new(&d, v).unwrap();
        let (i, mut worst, mut sag) = (50i64, 0.0f64, 0.0f64);
        for t in [0.2, 0.35, 0.5, 0.65, 0.8] {
            // the exact lens's point at t in the plane y = v
            let station = d
                .solve_station_for_y(LensRef::Revealer(i), t, v, v)
                .unwrap();
            let exact = d.revealer_point(i, t, station);
            let z = s.top.arcs[i as usize].z_at(exact.x).unwrap();
            worst = worst.max((z - exact.z).abs());
            let arc = d.revealer_arc(i, v);
            sag = sag.max((arc.point(0.5) - 0.5 * (arc.p0 + arc.p1)).length());
        }
        assert!(
            worst < 1e-5 && sag > 0.05,
            "section off the lens by {worst} mm (sag {sag})"
        );
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

    /// A ray tilted along the lenses meets, through [`Drift`], a point
    /// within the design's mesh tolerance of the lens it met as built at
    /// the ray's own station: on a saddle, a dome and a plane with tight
    /// rings, whose base creases curve enough that many meetings lie
    /// beyond their lens's reach and need the interpolated or the built
    /// lens.
    #[test]
    fn a_drifting_ray_meets_its_lens_within_the_mesh_tolerance() {
        for surface in [
            PitchSurface::Saddle { radius: 40.0 },
            PitchSurface::Paraboloid { radius: -60.0 },
            PitchSurface::Plane,
        ] {
            let mut p = DesignParams::with_defaults(surface.clone(), 24.0, 16.0, 0.5);
            p.profile = Profile::Rings { wavelength: 3.0 };
            let d = Design::new(p).unwrap();
            let (checked, beyond_reach, worst) = drifting_rays_off_their_lenses(&d, 3000);
            let tolerance = d.tolerance.mm();
            eprintln!(
                "{surface:?}: {checked} meetings, {beyond_reach} beyond reach, worst {worst:.2e} mm"
            );
            assert!(
                checked > 1000 && beyond_reach > 50,
                "{surface:?}: {checked} meetings, {beyond_reach} beyond their lens's reach"
            );
            assert!(
                worst <= tolerance,
                "{surface:?}: a meeting {worst:.2e} mm off its lens (tolerance {tolerance} mm)"
            );
        }
    }

    /// Rays from `n` random points inside `design`'s body, within 40° of
    /// straight up or down, met through [`Drift`] and against the lens
    /// built at the meeting's station (followed until the station holds
    /// still): how many were compared, how many lay beyond their lens's
    /// reach, and the largest distance (mm) along the normal between the
    /// two meetings.
    fn drifting_rays_off_their_lenses(design: &Design, n: usize) -> (usize, usize, f64) {
        let sections = Sections::for_frame(design, 96).unwrap();
        let (lo, hi) = sections.bounds().unwrap();
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (w, h) = (design.params.width, design.params.height);
        let (mut checked, mut beyond_reach, mut worst) = (0, 0, 0.0f64);
        for _ in 0..n {
            let (x, y) = ((next() - 0.5) * 0.8 * w, (next() - 0.5) * 0.8 * h);
            let row = sections.row_below(y).unwrap().0;
            let Some(z) = sections.section(row).unwrap().body.z_at(x) else {
                continue;
            };
            let (polar, azimuth) = (0.7 * next(), std::f64::consts::TAU * next());
            let up = if next() < 0.5 { 1.0 } else { -1.0 };
            let dir = DVec3::new(
                polar.sin() * azimuth.cos(),
                polar.sin() * azimuth.sin(),
                up * polar.cos(),
            );
            let drift = Drift::new(&sections, row, (lo.z, hi.z));
            let ray = Probe {
                side: Side::Inside,
                origin: DVec3::new(x, y, z),
                dir,
                t_min: 1e-9,
            };
            let Some((met_row, hit)) = drift.meet_drifting(ray) else {
                continue;
            };
            let (Some(at), y_met) = (hit.arc, y + hit.t * dir.y) else {
                continue;
            };
            if y_met.abs() > design.half_height {
                continue; // beyond the end faces, which sections leave out
            }
            let far = (y_met - sections.station(met_row)).abs() > sections.reach(met_row, at);
            let kept = drift.within_tolerance(met_row, ray, hit);
            let Some(mut exact) = drift.meet_at_station(met_row, at, ray, y_met) else {
                continue;
            };
            for _ in 0..8 {
                let station = y + exact.t * dir.y;
                exact = drift
                    .meet_at_station(met_row, at, ray, station)
                    .unwrap_or(exact);
            }
            let off = ((kept.t - exact.t) * dir.dot(oblique(exact).normal)).abs();
            worst = worst.max(off);
            checked += 1;
            beyond_reach += usize::from(far);
        }
        (checked, beyond_reach, worst)
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
