//! The mold's channels and keys' sockets as exact surfaces, and the curves
//! where they meet the other faces of a half.
//!
//! A channel primitive stands for a cylinder or a frustum of revolution
//! ([`ChannelShape`]); its side is a line revolved about its axis, its
//! ends are planes. Where a side meets a plane across its axis the edge is
//! an exact circle (rational quadratic arcs). Elsewhere (a lens, the
//! skirt, another channel) the edge is the C² cubic through points solved
//! exactly onto both surfaces, one at each mesh vertex of the edge, at the
//! angle about the axis that vertex has; the cubic breaks (C⁰) where the
//! other surface has a crease, as the skirt has along its rulings.
//!
//! **Guarantee.** Every solved point lies on both exact surfaces to 1e-10
//! mm; between them the cubic is within O(h⁴) of the exact curve, h the
//! spacing of the mesh vertices (at most a 48th of a turn).

use crate::error::BrepError;
use crate::solid::{cubic_through, point3};
use crate::spline::chord_lengths;
use glam::{DMat3, DVec3};
use moirecast_mold::{ChannelAxis, ChannelShape};
use truck_modeling::{
    BSplineCurve, Curve, KnotVec, Line, NurbsCurve, NurbsSurface, ParametricCurve,
    ParametricSurface, ParametricSurface3D, Point3, RevolutedCurve, Vector3, Vector4,
};

/// A channel's frame: a point of its axis (position 0), the axis's unit
/// direction, and the two unit directions angles are measured from and
/// towards ([`ChannelShape::angle`]).
pub(crate) struct ChannelFrame {
    pub origin: DVec3,
    pub axis: DVec3,
    pub e1: DVec3,
    pub e2: DVec3,
}

pub(crate) fn frame(c: &ChannelShape) -> ChannelFrame {
    match c.axis {
        ChannelAxis::Vertical(at) => ChannelFrame {
            origin: at.extend(0.0),
            axis: DVec3::Z,
            e1: DVec3::X,
            e2: DVec3::Y,
        },
        ChannelAxis::Horizontal { from, dir } => ChannelFrame {
            origin: from,
            axis: dir.extend(0.0),
            e1: DVec3::new(-dir.y, dir.x, 0.0),
            e2: DVec3::Z,
        },
    }
}

impl ChannelFrame {
    /// Where `p` lies along the axis.
    pub fn along(&self, p: DVec3) -> f64 {
        (p - self.origin).dot(self.axis)
    }

    /// The unit direction at `angle` across the axis.
    pub fn radial(&self, angle: f64) -> DVec3 {
        angle.cos() * self.e1 + angle.sin() * self.e2
    }

    /// How far `p` lies from the axis.
    pub fn distance(&self, p: DVec3) -> f64 {
        let d = p - self.origin;
        (d - d.dot(self.axis) * self.axis).length()
    }
}

/// The radius of `c` at position `h` along its axis (linear over its span).
pub(crate) fn radius_at(c: &ChannelShape, h: f64) -> f64 {
    let (h0, h1) = c.span;
    let (r0, r1) = c.radii;
    r0 + (r1 - r0) * (h - h0) / (h1 - h0)
}

/// How far `p` lies off `c`'s side (outside positive).
pub(crate) fn off_side(c: &ChannelShape, f: &ChannelFrame, p: DVec3) -> f64 {
    f.distance(p) - radius_at(c, f.along(p))
}

/// Where the crease at across parameter `near.x` of `lens` crosses the
/// side of one of `shapes`, near along parameter `near.y` (a mesh
/// vertex's, within `within` mm of the side): the along parameter solved by secant steps to
/// [`SOLVED_MM`]. `None` where no side passes that near, or the steps do
/// not settle. A channel's vertex on a crease goes there, so that its edges
/// along the crease and along the side meet on both surfaces (found: a vent
/// on the lenses whose corner lay 3.6 µm off the vent, and OpenCascade's
/// mesher left the lens face beside it untriangulated).
pub(crate) fn crease_crossing(
    shapes: &[ChannelShape],
    lens: &NurbsSurface<Vector4>,
    near: glam::DVec2,
    within: f64,
) -> Option<f64> {
    let (t, v) = (near.x, near.y);
    let at = |v: f64| {
        let q = lens.subs(t, v);
        DVec3::new(q.x, q.y, q.z)
    };
    let (shape, f) = shapes.iter().map(|c| (c, frame(c))).min_by(|a, b| {
        let off = |(c, f): &(&ChannelShape, ChannelFrame)| off_side(c, f, at(v)).abs();
        off(a).total_cmp(&off(b))
    })?;
    let g = |v: f64| off_side(shape, &f, at(v));
    if g(v).abs() > within {
        return None;
    }
    secant_root(v, g)
}

/// The point of `c`'s exact side at `angle` and position `h`.
pub(crate) fn on_side(c: &ChannelShape, f: &ChannelFrame, angle: f64, h: f64) -> DVec3 {
    f.origin + h * f.axis + radius_at(c, h) * f.radial(angle)
}

/// `c`'s side as a truck surface: its generator at the seam, a tenth
/// longer than its span at both ends, revolved about its axis.
pub(crate) fn side_surface(c: &ChannelShape) -> RevolutedCurve<Curve> {
    let f = frame(c);
    let (h0, h1) = c.span;
    let pad = 0.1 * (h1 - h0);
    let (a, b) = (
        on_side(c, &f, c.seam, h0 - pad),
        on_side(c, &f, c.seam, h1 + pad),
    );
    let axis = Vector3::new(f.axis.x, f.axis.y, f.axis.z);
    RevolutedCurve::by_revolution(
        Curve::Line(Line(point3(a), point3(b))),
        point3(f.origin),
        axis,
    )
}

/// Whether `surface` (a revolved side of axis `f`) faces away from its
/// axis along its natural normal, as `outward` (a mesh triangle's normal
/// at `at`) faces: both point off the axis, or both onto it.
pub(crate) fn natural_is_outward(
    surface: &RevolutedCurve<Curve>,
    f: &ChannelFrame,
    outward: DVec3,
    at: DVec3,
) -> bool {
    let off_axis = |n: DVec3, p: DVec3| {
        let d = p - f.origin;
        (d - d.dot(f.axis) * f.axis).dot(n)
    };
    let nat = surface.normal(0.5, 0.0);
    let p = surface.subs(0.5, 0.0);
    off_axis(DVec3::new(nat.x, nat.y, nat.z), DVec3::new(p.x, p.y, p.z)) * off_axis(outward, at)
        > 0.0
}

/// The arc of the circle about `centre` of radius `r` in the plane of the
/// unit directions `e1` and `e2` through `pts` (in order, near that
/// circle), from the first point's angle to the last's: rational quadratic
/// pieces of at most a quarter turn.
pub(crate) fn circle_arc(
    centre: DVec3,
    (e1, e2): (DVec3, DVec3),
    r: f64,
    pts: &[DVec3],
) -> NurbsCurve<Vector4> {
    let angle = |p: DVec3| (p - centre).dot(e2).atan2((p - centre).dot(e1));
    // unwrapped: each step between neighbours is the short way round
    let start = angle(pts[0]);
    let mut sweep = 0.0;
    for w in pts.windows(2) {
        let mut d = angle(w[1]) - angle(w[0]);
        d -= std::f64::consts::TAU * (d / std::f64::consts::TAU).round();
        sweep += d;
    }
    let pieces = (sweep.abs() / std::f64::consts::FRAC_PI_2).ceil().max(1.0) as usize;
    let step = sweep / pieces as f64;
    let w_mid = (0.5 * step).cos();
    let on_circle = |t: f64, radius: f64, w: f64| {
        let p = centre + radius * (t.cos() * e1 + t.sin() * e2);
        Vector4::new(p.x * w, p.y * w, p.z * w, w)
    };
    let mut ctrl = vec![on_circle(start, r, 1.0)];
    let mut knots = vec![0.0; 3];
    for i in 0..pieces {
        let t0 = start + step * i as f64;
        ctrl.push(on_circle(t0 + 0.5 * step, r / w_mid, w_mid));
        ctrl.push(on_circle(t0 + step, r, 1.0));
        let k = (i + 1) as f64 / pieces as f64;
        knots.extend(if i + 1 == pieces {
            [k; 3].to_vec()
        } else {
            vec![k, k]
        });
    }
    NurbsCurve::new(BSplineCurve::new(KnotVec::from(knots), ctrl))
}

/// `arc` (in a horizontal plane) lifted onto the plane z = `z`(x, y), an
/// affine function: x and y stay, so the image is exact, and an affine map
/// of a rational curve is the rational curve of its mapped control points
/// with their weights.
pub(crate) fn lifted_arc(
    arc: NurbsCurve<Vector4>,
    z: impl Fn(DVec3) -> f64,
) -> NurbsCurve<Vector4> {
    let curve = arc.into_non_rationalized();
    let ctrl = curve
        .control_points()
        .iter()
        .map(|c| {
            let p = DVec3::new(c.x / c.w, c.y / c.w, 0.0);
            Vector4::new(c.x, c.y, z(p) * c.w, c.w)
        })
        .collect();
    NurbsCurve::new(BSplineCurve::new(curve.knot_vec().clone(), ctrl))
}

/// Rational pieces of one degree, each ending where the next starts,
/// joined C⁰ into one curve ([`join_end_to_end`]).
pub(crate) fn join_arcs(arcs: Vec<NurbsCurve<Vector4>>) -> Curve {
    let degree = arcs[0].degree();
    let (knots, ctrl) = join_end_to_end(
        arcs.into_iter().map(|a| {
            let b = a.into_non_rationalized();
            (b.knot_vec().to_vec(), b.control_points().clone())
        }),
        degree,
    );
    Curve::NurbsCurve(NurbsCurve::new(BSplineCurve::new(knots, ctrl)))
}

/// Clamped pieces of one `degree` (knots, control points), each starting
/// at the last one's end point, as one B-spline's knots and control points,
/// C⁰ at the joins: each piece's knots shifted to start where the last
/// ended, its first control point (the shared end) and one of its join
/// knot's copies dropped.
fn join_end_to_end<P: Copy>(
    pieces: impl IntoIterator<Item = (Vec<f64>, Vec<P>)>,
    degree: usize,
) -> (KnotVec, Vec<P>) {
    let (mut ctrl, mut knots) = (Vec::new(), Vec::new());
    let mut offset = 0.0;
    for (i, (k, c)) in pieces.into_iter().enumerate() {
        let k: Vec<f64> = k.iter().map(|t| t - k[0] + offset).collect();
        if i == 0 {
            ctrl.extend(c);
            knots.extend(&k[..k.len() - 1]);
        } else {
            ctrl.extend(c.into_iter().skip(1));
            knots.extend(&k[degree + 1..k.len() - 1]);
        }
        offset = k[k.len() - 1];
    }
    knots.push(offset);
    (KnotVec::from(knots), ctrl)
}

/// The circle where `c`'s side crosses the plane across its axis at
/// position `h`, as an arc through `pts`.
pub(crate) fn section_arc(c: &ChannelShape, h: f64, pts: &[DVec3]) -> Curve {
    let f = frame(c);
    Curve::NurbsCurve(circle_arc(
        f.origin + h * f.axis,
        (f.e1, f.e2),
        radius_at(c, h),
        pts,
    ))
}

/// A surface a channel's edge is solved onto.
pub(crate) enum Other<'a> {
    /// Where this function (of roughly unit gradient) is 0.
    Implicit(&'a dyn Fn(DVec3) -> f64),
    /// A NURBS lens surface, and how far (mm) the edge's mesh points
    /// may lie from it: the tolerance.
    Lens(&'a NurbsSurface<Vector4>, f64),
}

/// Where `g` is zero near `x0`: secant steps from `x0` and `x0 + 1e-4`,
/// at most [`SOLVE_STEPS`], until |g| < [`SOLVED_MM`]; `None` if they do
/// not get there.
fn secant_root(x0: f64, g: impl Fn(f64) -> f64) -> Option<f64> {
    let (mut a, mut b) = (x0, x0 + 1e-4);
    let (mut ga, mut gb) = (g(a), g(b));
    for _ in 0..SOLVE_STEPS {
        if gb.abs() < SOLVED_MM {
            return Some(b);
        }
        if gb == ga {
            break;
        }
        let next = b - gb * (b - a) / (gb - ga);
        (a, ga) = (b, gb);
        b = next;
        gb = g(b);
    }
    (gb.abs() < SOLVED_MM).then_some(b)
}

/// How many Newton or secant steps a solve takes at most.
const SOLVE_STEPS: usize = 40;
/// When a solved point counts as on both surfaces (mm).
const SOLVED_MM: f64 = 1e-10;

/// The point where `c`'s side at the angle of `p` meets `other`, near `p`.
pub(crate) fn solve_on_side(
    c: &ChannelShape,
    f: &ChannelFrame,
    other: &Other,
    p: DVec3,
) -> Result<DVec3, BrepError> {
    let angle = c.angle(p);
    let h0 = f.along(p);
    let at = |h: f64| on_side(c, f, angle, h);
    let fail = || {
        BrepError::Topology(format!(
            "a channel's edge point near {p} does not solve onto the surface it meets"
        ))
    };
    match other {
        Other::Implicit(g) => {
            // secant steps from the mesh point's position
            secant_root(h0, |h| g(at(h))).map(at).ok_or_else(fail)
        }
        Other::Lens(s, within) => {
            let (mut u, mut v) = crate::solid::lens_params(s, p, *within);
            let mut h = h0;
            let d3 = |v: Vector3| DVec3::new(v.x, v.y, v.z);
            for _ in 0..SOLVE_STEPS {
                let q = s.subs(u, v);
                let x = at(h);
                let r = DVec3::new(q.x, q.y, q.z) - x;
                if r.length() < SOLVED_MM {
                    return Ok(x);
                }
                let dx = (at(h + 1e-6) - at(h - 1e-6)) / 2e-6;
                let jac = DMat3::from_cols(d3(s.uder(u, v)), d3(s.vder(u, v)), -dx);
                if jac.determinant().abs() < 1e-300 {
                    break;
                }
                let step = jac.inverse() * r;
                u -= step.x;
                v -= step.y;
                h -= step.z;
            }
            Err(fail())
        }
    }
}

/// The indices where pieces of `len` points broken at `breaks` start and
/// end: 0, the breaks strictly inside (sorted, once each), and the last.
pub(crate) fn piece_bounds(len: usize, breaks: &[usize]) -> Vec<usize> {
    let mut bounds: Vec<usize> = breaks
        .iter()
        .copied()
        .filter(|&i| i > 0 && i + 1 < len)
        .collect();
    bounds.sort_unstable();
    bounds.dedup();
    bounds.insert(0, 0);
    bounds.push(len - 1);
    bounds
}

/// How far a channel's edge may lie from the exact crossing of its two
/// surfaces, as a share of the tolerance. OpenCascade's mesher leaves a face
/// untriangulated where an edge lies microns off it (a vent on the lenses,
/// `tests/python/specs/vent-on-lens-mold.toml`: 5.9 µm), so the edge is held
/// far below the tolerance.
pub const EDGE_SHARE: f64 = 1e-4;
/// How many times an edge's points may be doubled where it is off.
const REFINE_ROUNDS: usize = 8;

/// The edge through the exact points `pts` (in order), C² between breaks
/// and C⁰ at the indices in `breaks`: cubic pieces, each through its
/// points, joined end to end in one B-spline.
pub(crate) fn piecewise_cubic(pts: &[DVec3], breaks: &[usize]) -> Curve {
    let bounds = piece_bounds(pts.len(), breaks);
    let (knots, ctrl) = join_end_to_end(
        bounds.windows(2).map(|w| {
            let piece = cubic_through(&pts[w[0]..=w[1]], |p| p);
            (piece.knot_vec().to_vec(), piece.control_points().clone())
        }),
        3,
    );
    Curve::BSplineCurve(BSplineCurve::new(knots, ctrl))
}

/// The C² cubic through the exact points `pts` (in order), with more
/// exact points from `solve` (a point near the crossing to the crossing)
/// in each span whose middle lies farther than `within` from its solved
/// point, for at most [`REFINE_ROUNDS`] rounds: what the middles of the
/// spans guarantee, checked there.
pub(crate) fn refined_cubic(
    pts: Vec<DVec3>,
    solve: impl Fn(DVec3) -> Result<DVec3, BrepError>,
    within: f64,
) -> Result<Curve, BrepError> {
    Ok(Curve::BSplineCurve(refined(pts, &solve, within)?))
}

/// The cubic through `pts`, with a solved point added in each span whose
/// middle lies farther than `within` from the crossing.
fn refined(
    mut pts: Vec<DVec3>,
    solve: &impl Fn(DVec3) -> Result<DVec3, BrepError>,
    within: f64,
) -> Result<BSplineCurve<Point3>, BrepError> {
    for round in 0.. {
        let cubic = cubic_through(&pts, |p| p);
        if round == REFINE_ROUNDS {
            return Ok(cubic);
        }
        let s = chord_lengths(&pts);
        let mut more = Vec::with_capacity(2 * pts.len());
        for (i, &p) in pts.iter().enumerate().take(pts.len() - 1) {
            more.push(p);
            let m = cubic.subs(0.5 * (s[i] + s[i + 1]));
            let mid = DVec3::new(m.x, m.y, m.z);
            let on = solve(mid)?;
            if on.distance(mid) > within {
                more.push(on);
            }
        }
        more.push(pts[pts.len() - 1]);
        if more.len() == pts.len() {
            return Ok(cubic);
        }
        pts = more;
    }
    unreachable!("the rounds end at REFINE_ROUNDS")
}
