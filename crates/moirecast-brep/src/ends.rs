//! Lens surfaces that end in the walls across them.
//!
//! **Why.** A wall across the lenses (the device's front and back) is a
//! plane, and on a curved surface it is no station plane: it cuts a lens
//! along a curve that bends in the lens's parameters. OpenCascade's mesher
//! (BRepMesh, as FreeCAD and PrusaSlicer use it) then takes an *ear* (a
//! triangle of three consecutive nodes of the edge) on a narrow cut lens,
//! where the wall's plane takes the same ear, and the joined mesh uses an
//! edge four times (docs/decisions.md, B-rep).
//!
//! **What.** Every surface of a family is cut at one station v_c, the
//! nearest to the layout that any of its wall vertices reaches, and the
//! end column of control points is moved, each along its own row's end
//! leg, into the wall's plane. The end iso-curve v = v_c then lies in the
//! plane: a rational quadratic, and the edge between the lens and the
//! wall. A lens is a swept arc, so moving its end section along the sweep
//! leaves it on the lens to second order (for a cylinder, the arc
//! projected along the axis *is* the oblique section). Rows shared by two
//! lenses (a crease) move alike, so the neighbours still share it bit for
//! bit. Only the last knot span changes.
//!
//! **Guarantee.** Only the last knot span moves. It is sampled
//! (thirds of the span, five parameters across) against the surface before
//! the move; an ending is kept only where every sample lies within
//! [`END_SHARE`] × tolerance of it, and the family's measured deviation
//! grows by the farthest. Elsewhere the family keeps its surfaces and the
//! walls trim them as before. The end moves off the lens by about
//! δ²κ/2 (δ the move, up to 0.1 mm where the wall meets lenses at
//! different stations; κ the lens's curvature along its axis), and inside
//! the span by the move times the turn of the lens over it: 0.115 µm on
//! the reference's base lenses, 0.043 µm on its revealer.
//! (A knot 0.1 mm from the end would confine the move, but OpenCascade's
//! default volume integration then missed 1.8 mm³ of the reference's
//! 6787 mm³ over such short spans.)

use crate::lenses::LensFamily;
use crate::patch::LensPatch;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::BTreeMap;
use truck_modeling::{
    BoundedCurve, BoundedSurface, Curve, Cut, NurbsCurve, NurbsSurface, ParametricCurve, Vector4,
};

/// Which end of a lens surface's stations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum End {
    First,
    Last,
}

/// The stations at which a family's surfaces end in a wall, where they do.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WallEnds {
    pub first: Option<f64>,
    pub last: Option<f64>,
    /// The farthest (mm) a sample of an ended span lies from the surface
    /// it was cut from.
    pub departure: f64,
}

impl WallEnds {
    /// The end in a wall that a boundary run from station `a` to station
    /// `b` lies on: both at or beyond the end's station (a wall vertex is
    /// never nearer the layout than the end, which is the nearest of them).
    pub fn end_of(&self, a: f64, b: f64) -> Option<End> {
        match (self.first, self.last) {
            (_, Some(v)) if a >= v && b >= v => Some(End::Last),
            (Some(v), _) if a <= v && b <= v => Some(End::First),
            _ => None,
        }
    }

    fn set(&mut self, end: End, station: f64) {
        match end {
            End::First => self.first = Some(station),
            End::Last => self.last = Some(station),
        }
    }
}

/// A plane: a point of it and its unit normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallPlane {
    pub origin: DVec3,
    pub normal: DVec3,
}

impl WallPlane {
    fn signed_distance(&self, p: DVec3) -> f64 {
        (p - self.origin).dot(self.normal)
    }
}

/// Where a family's surfaces are to end: which end, at which station, in
/// which plane.
#[derive(Clone, Copy, Debug)]
pub struct WallCut {
    pub end: End,
    pub station: f64,
    pub plane: WallPlane,
}

/// The least sine between a row's end leg and the wall's plane: a lens
/// runs into its wall at a steep angle; a leg along the wall cannot reach it.
const LEG_SINE: f64 = 0.1;
/// The shortest end leg (mm) whose direction is taken.
const MIN_LEG_MM: f64 = 1e-9;
/// Parameters across, and shares of the moved span, that are sampled.
const SAMPLE_T: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];
const SAMPLE_SPAN: [f64; 3] = [1.0 / 3.0, 2.0 / 3.0, 1.0];

/// Share of the mesh tolerance an ended span may move off the surface it
/// was cut from; with [`crate::lenses::FIT_SHARE`], the lens faces stay
/// within 0.2 × tolerance of the exact lenses.
pub const END_SHARE: f64 = 0.1;

/// Ends every surface of `family` in the wall of `cut`, if every one can
/// and its moved span stays within `allowance` (mm) of the surface it was
/// cut from; the family's deviation grows by the farthest sample. Returns
/// whether it did.
pub fn end_in_wall(family: &mut LensFamily, cut: &WallCut, allowance: f64) -> bool {
    if !family.surfaces.values().all(LensPatch::fits) {
        return false; // band spans of several pieces across
    }
    let budget = allowance;
    let ended: Option<Vec<(i64, NurbsSurface<Vector4>, f64)>> = family
        .surfaces
        .par_iter()
        .map(|(&k, surface)| {
            let ended = ended(surface, cut)?;
            let departure = departure(surface, &ended, cut.end);
            (departure <= budget).then_some((k, ended, departure))
        })
        .collect();
    let Some(ended) = ended else {
        return false;
    };
    // the ends lie apart: the family's deviation grows by the farthest
    let worst = ended
        .iter()
        .map(|e| e.2)
        .fold(family.ends.departure, f64::max);
    family.deviation.0 += worst - family.ends.departure;
    family.ends.departure = worst;
    family.surfaces = ended
        .into_iter()
        .map(|(k, s, _)| (k, s))
        .collect::<BTreeMap<_, _>>();
    family.ends.set(cut.end, cut.station);
    true
}

/// `surface` cut at the station of `cut` and ended in its plane, or none
/// where the station is not inside the surface's or a leg cannot reach.
fn ended(surface: &NurbsSurface<Vector4>, cut: &WallCut) -> Option<NurbsSurface<Vector4>> {
    let (_, (v0, v1)) = surface.range_tuple();
    if !(cut.station > v0 && cut.station < v1) {
        return None;
    }
    let mut kept = surface.clone();
    let kept = match cut.end {
        End::Last => {
            let _beyond = kept.vcut(cut.station);
            kept
        }
        End::First => kept.vcut(cut.station),
    };
    into_plane(kept, cut.end, cut.plane)
}

/// `surface` with its `end` column of control points moved into `plane`,
/// each along its row's end leg (the direction of the row's curve at its
/// end), weights kept; none where a leg is too short or along the plane.
pub(crate) fn into_plane(
    mut surface: NurbsSurface<Vector4>,
    end: End,
    plane: WallPlane,
) -> Option<NurbsSurface<Vector4>> {
    let columns = surface.control_points()[0].len();
    if columns < 2 {
        return None;
    }
    let (column, inner) = match end {
        End::First => (0, 1),
        End::Last => (columns - 1, columns - 2),
    };
    let cartesian = |h: &Vector4| DVec3::new(h.x / h.w, h.y / h.w, h.z / h.w);
    for row in 0..surface.control_points().len() {
        let h = *surface.control_point(row, column);
        let p = cartesian(&h);
        let leg = p - cartesian(surface.control_point(row, inner));
        let across = leg.dot(plane.normal);
        if leg.length() < MIN_LEG_MM || across.abs() < LEG_SINE * leg.length() {
            return None;
        }
        let moved = p - leg * (plane.signed_distance(p) / across);
        *surface.control_point_mut(row, column) =
            Vector4::new(moved.x * h.w, moved.y * h.w, moved.z * h.w, h.w);
    }
    Some(surface)
}

/// The farthest (mm) a sample of `ended`'s moved span lies from `surface`
/// (before the move): each sample slides back along the lens (by its
/// offset along the surface's v-tangent), and its offset along the normal
/// there is its distance to the surface, but for the rest of its offset
/// along the surface squared times the curvature (the slide leaves only
/// the drift across the lens, far below the fit).
fn departure(surface: &NurbsSurface<Vector4>, ended: &NurbsSurface<Vector4>, end: End) -> f64 {
    let (_, (v0, v1)) = ended.range_tuple();
    let knots = ended.vknot_vec();
    let (from, to) = match end {
        End::Last => (inner_knot(knots, v1, End::Last), v1),
        End::First => (inner_knot(knots, v0, End::First), v0),
    };
    let (before, after) = (LensPatch::of(surface), LensPatch::of(ended));
    let mut farthest = 0.0_f64;
    for share in SAMPLE_SPAN {
        let v = from + share * (to - from);
        for t in SAMPLE_T {
            let q = after.at(t, v).point;
            let at = before.at(t, v);
            let slid = v + (q - at.point).dot(at.along) / at.along.length_squared();
            let there = before.at(t, slid);
            let normal = there.across.cross(there.along).normalize();
            farthest = farthest.max((q - there.point).dot(normal).abs());
        }
    }
    farthest
}

/// The knot nearest `end_knot` on the inside: where the moved span begins.
fn inner_knot(knots: &truck_modeling::KnotVec, end_knot: f64, end: End) -> f64 {
    let inside = knots.iter().copied().filter(|&k| k != end_knot);
    match end {
        End::Last => inside.fold(f64::NEG_INFINITY, f64::max),
        End::First => inside.fold(f64::INFINITY, f64::min),
    }
}

/// Where a lens–wall edge starts and ends: each end's parameter across
/// the lens, and its mesh point.
pub(crate) struct RunEnds {
    pub t: [f64; 2],
    pub at: [DVec3; 2],
}

/// The end iso-curve of an ended `surface` at `end`, across from
/// `ends.t[0]` to `ends.t[1]`: a crease's end (t = 0 or 1) as it is, any
/// other end moved to where the iso-curve crosses the nearest of `sides`
/// (the walls along the lenses) to its mesh point, if one lies within
/// `within` (mm). Its ends place its vertices.
pub(crate) fn iso_edge(
    surface: &NurbsSurface<Vector4>,
    end: End,
    ends: RunEnds,
    sides: &[WallPlane],
    within: f64,
) -> Curve {
    let RunEnds { t, at } = ends;
    let columns = surface.control_points()[0].len();
    let column = match end {
        End::First => 0,
        End::Last => columns - 1,
    };
    let iso = surface.row_curve(column);
    let onto_side = |t: f64, at: DVec3| -> f64 {
        if t == 0.0 || t == 1.0 {
            return t;
        }
        sides
            .iter()
            .filter(|plane| plane.signed_distance(at).abs() <= within)
            .min_by(|a, b| {
                let d = |p: &WallPlane| p.signed_distance(at).abs();
                d(a).total_cmp(&d(b))
            })
            .and_then(|plane| crossing(&iso, plane, t))
            .unwrap_or(t)
    };
    let (ta, tb) = (onto_side(t[0], at[0]), onto_side(t[1], at[1]));
    let (lo, hi) = (ta.min(tb), ta.max(tb));
    let mut piece = iso;
    if lo > 0.0 {
        piece = piece.cut(lo);
    }
    if hi < 1.0 {
        let _after = piece.cut(hi);
    }
    if ta > tb {
        piece.invert();
    }
    Curve::NurbsCurve(piece)
}

/// Bisection steps of [`crossing`]: to round-off over [0, 1].
const CROSSING_STEPS: usize = 60;
/// How far from its guess [`crossing`] brackets a crossing, at first.
const CROSSING_BRACKET: f64 = 0.01;

/// The parameter where `iso` crosses `plane`, nearest `guess`; none where
/// no sign change lies in [0, 1].
fn crossing(iso: &NurbsCurve<Vector4>, plane: &WallPlane, guess: f64) -> Option<f64> {
    let f = |t: f64| {
        let p = iso.subs(t);
        plane.signed_distance(DVec3::new(p.x, p.y, p.z))
    };
    let (t0, t1) = iso.range_tuple();
    let mut reach = CROSSING_BRACKET;
    let (mut lo, mut hi) = loop {
        let (lo, hi) = ((guess - reach).max(t0), (guess + reach).min(t1));
        if f(lo) * f(hi) <= 0.0 {
            break (lo, hi);
        }
        if lo == t0 && hi == t1 {
            return None;
        }
        reach *= 4.0;
    };
    let f_lo = f(lo);
    for _ in 0..CROSSING_STEPS {
        let mid = 0.5 * (lo + hi);
        if f(mid) * f_lo > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

#[cfg(test)]
mod tests {
    use crate::lenses::{LensFamily, FIT_SHARE};
    use crate::solid::build_brep;
    use moirecast_kernel::mesher::mesh_device;
    use moirecast_kernel::progress::Silent;
    use moirecast_kernel::{Design, DesignParams, PitchSurface};

    /// A saddle: its front and back walls cut every lens obliquely.
    fn small_saddle() -> Design {
        let mut params =
            DesignParams::with_defaults(PitchSurface::Saddle { radius: 30.0 }, 10.0, 8.0, 0.5);
        params.tolerance = 0.01;
        Design::new(params).unwrap()
    }

    fn end_points(family: &LensFamily, last: bool) -> Vec<Vec<[f64; 3]>> {
        family
            .surfaces
            .values()
            .map(|s| {
                s.control_points()
                    .iter()
                    .map(|row| {
                        let h = if last { row[row.len() - 1] } else { row[0] };
                        [h.x / h.w, h.y / h.w, h.z / h.w]
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn lenses_end_in_the_front_and_back_walls_and_keep_their_creases_shared() {
        let design = small_saddle();
        let dm = mesh_device(&design, &Silent).unwrap();
        let brep = build_brep(&design, &dm).unwrap();
        let tolerance = design.tolerance.mm();
        let h = design.half_height;
        for family in [&brep.revealer, &brep.base] {
            let ends = family.ends;
            assert!(ends.first.is_some() && ends.last.is_some(), "{ends:?}");
            assert!(ends.departure > 0.0 && ends.departure <= super::END_SHARE * tolerance);
            assert!(family.deviation.0 <= (FIT_SHARE + super::END_SHARE) * tolerance);
            // every end column lies in its wall's plane (its iso-curve, a
            // combination of those points, with it)
            for (last, wall_y) in [(false, -h), (true, h)] {
                for column in end_points(family, last) {
                    for p in column {
                        assert!((p[1] - wall_y).abs() < 1e-12, "{p:?} off y = {wall_y}");
                    }
                }
            }
            // neighbours share their crease rows to the bit
            let surfaces: Vec<_> = family.surfaces.iter().collect();
            for pair in surfaces.windows(2) {
                let ((&k, a), (&j, b)) = (pair[0], pair[1]);
                if j == k + 1 {
                    let rows = a.control_points();
                    assert_eq!(
                        rows[rows.len() - 1],
                        b.control_points()[0],
                        "lenses {k}, {j}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_lens_patch_reads_as_truck_evaluates() {
        use truck_modeling::BoundedSurface;
        let design = small_saddle();
        let dm = mesh_device(&design, &Silent).unwrap();
        let brep = build_brep(&design, &dm).unwrap();
        for surface in brep.base.surfaces.values().take(3) {
            let patch = crate::patch::LensPatch::of(surface);
            let (_, (v0, v1)) = surface.range_tuple();
            for i in 0..=20 {
                let v = v0 + (v1 - v0) * i as f64 / 20.0;
                for t in [0.0, 0.3, 0.5, 1.0] {
                    let at = patch.at(t, v);
                    let p = surface.subs(t, v);
                    let (du, dv) = (surface.uder(t, v), surface.vder(t, v));
                    let close = |a: glam::DVec3, b: [f64; 3]| (a - glam::DVec3::from(b)).length();
                    assert!(
                        close(at.point, [p.x, p.y, p.z]) < 1e-12,
                        "point at {t}, {v}"
                    );
                    assert!(
                        close(at.across, [du.x, du.y, du.z]) < 1e-9,
                        "across at {t}, {v}"
                    );
                    assert!(
                        close(at.along, [dv.x, dv.y, dv.z]) < 1e-9,
                        "along at {t}, {v}"
                    );
                }
            }
        }
    }
}
