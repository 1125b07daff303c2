//! The device as a closed truck `Solid` (METHOD §5.1, §5.3).
//!
//! Faces: one NURBS face per connected piece of a lens (a base lens cut in
//! two by a wall gives two), and one planar face per wall. Edges:
//! - crease edges: the boundary curve that two neighbouring lens surfaces
//!   share exactly, cut to the run's stations;
//! - the outermost revealer creases, which lie in the x-walls: the same;
//! - where the front or back wall cuts a lens: the lens surface's end
//!   iso-curve, which lies in the wall's plane ([`crate::ends`]);
//! - other trims, where a wall cuts a lens: the C² cubic through the exact
//!   intersection points the mesher solved, flattened into the wall plane;
//! - wall corners: vertical lines.
//!
//! Every edge is one truck `Edge`, used by its two faces in opposite
//! directions, so the shell is closed by construction; `ShellCondition`
//! measures that.

use crate::ends::{end_in_wall, iso_edge, End, RunEnds, WallCut, WallEnds, WallPlane, END_SHARE};
use crate::error::BrepError;
pub use crate::lenses::FIT_SHARE;
use crate::lenses::{worst_deviation, Array, LensFamily};
use crate::patch::LensPatch;
use crate::spline::{chord_lengths, clamped_knots, interpolate};
use crate::topology::{pieces, Piece, Run};
use glam::DVec3;
use moirecast_kernel::mesher::{DeviceMesh, Patch, Side};
use moirecast_kernel::model::LensRef;
use moirecast_kernel::{Design, Tolerance};
use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};
use truck_modeling::{
    BSplineCurve, BoundedSurface, Curve, Cut, Edge, Face, KnotVec, Line, MetricSpace, NurbsSurface,
    ParametricSurface3D, Plane, Point3, SearchNearestParameter, Shell, ShellCondition, Solid,
    Surface, Vector4, Vertex, Wire,
};

/// Layout margin (mm) of the lens surfaces beyond the stations they are
/// trimmed at, in lens periods: the trims stay clear of the surface edges.
const MARGIN_PERIODS: f64 = 2.0;

/// Counts and measurements of one B-rep (in `report.json` as `brep`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct BrepStats {
    pub faces: usize,
    pub revealer_faces: usize,
    pub base_faces: usize,
    /// Base lenses that have a face (a lens cut in two has two faces).
    pub base_lenses: usize,
    pub wall_faces: usize,
    pub edges: usize,
    pub vertices: usize,
    pub revealer_stations: usize,
    pub base_stations: usize,
    /// Worst sampled distance (mm) of a lens surface from its exact lens,
    /// with the lens and the parameters (t across, v along) where it is.
    pub max_surface_deviation_mm: f64,
    pub worst_surface: String,
    /// Limit for that distance: `FIT_SHARE` × tolerance.
    pub surface_fit_mm: f64,
}

/// The device as a closed B-rep solid.
pub struct DeviceBrep {
    pub solid: Solid,
    pub stats: BrepStats,
    /// The lens surfaces the faces lie on.
    pub revealer: LensFamily,
    pub base: LensFamily,
}

pub(crate) fn point3(p: DVec3) -> Point3 {
    Point3::new(p.x, p.y, p.z)
}

/// The parameters of the point of a lens `surface` nearest `p`, a point
/// `within` (mm) of it. truck's Newton search from its own 50 × 50
/// presearch is taken where it ends within that distance (a point past a
/// crease ends a hair outside the domain, on the surface's extension,
/// which is as good). Where it does not, the answer is the nearest of
/// that search and, clamped into the domain, the same search started
/// from the nearest point of a grid with [`SAMPLES_PER_SPAN`] samples in
/// every knot span, and that grid point. Along a profile of short
/// wavelength a base lens waves across its stations faster than 50
/// samples see: the presearch starts a wave away, and Newton either
/// diverges or leaves the domain, where the surface extrapolates
/// (found-00f7846f67596c21: rings 0.41 mm apart, 50 samples 0.8 mm
/// apart, and a "nearest" point at u = 324 on a lens whose u runs over
/// [0, 1], 4.8 mm away).
pub(crate) fn lens_params(surface: &NurbsSurface<Vector4>, p: DVec3, within: f64) -> (f64, f64) {
    let target = point3(p);
    let distance = |(u, v): (f64, f64)| surface.subs(u, v).distance(target);
    // truck's own search, its presearch read off the lens directly (a
    // tenth of the time: each grid column's section once)
    let first = if LensPatch::fits(surface) {
        let hint = LensPatch::of(surface).presearch(p, surface.range_tuple(), PRESEARCH_DIVISION);
        surface.search_nearest_parameter(target, Some(hint), 100)
    } else {
        surface.search_nearest_parameter(target, None, 100)
    };
    if let Some(uv) = first.filter(|&uv| distance(uv) <= within) {
        return uv;
    }
    let ((u0, u1), (v0, v1)) = surface.range_tuple();
    let clamp = |(u, v): (f64, f64)| (u.clamp(u0, u1), v.clamp(v0, v1));
    let samples = |knots: &KnotVec| {
        let mut ts: Vec<f64> = knots
            .windows(2)
            .filter(|w| w[1] > w[0])
            .flat_map(|w| {
                (0..SAMPLES_PER_SPAN)
                    .map(move |i| w[0] + (w[1] - w[0]) * i as f64 / SAMPLES_PER_SPAN as f64)
            })
            .collect();
        ts.extend(knots.last());
        ts
    };
    let (us, vs) = surface.knot_vecs();
    let (us, vs) = (samples(us), samples(vs));
    let nearest = |a: &(f64, f64), b: &(f64, f64)| distance(*a).total_cmp(&distance(*b));
    let grid = vs
        .iter()
        .flat_map(|&v| us.iter().map(move |&u| (u, v)))
        .min_by(nearest)
        .unwrap_or((u0, v0));
    let refined = surface
        .search_nearest_parameter(target, Some(grid), 100)
        .map(clamp);
    [first.map(clamp), refined, Some(grid)]
        .into_iter()
        .flatten()
        .min_by(nearest)
        .unwrap_or(grid)
}

/// truck's presearch grid: 50 divisions of each parameter.
const PRESEARCH_DIVISION: usize = 50;

/// Samples in every knot span of the grid [`lens_params`] starts from
/// where truck's own presearch is too coarse.
const SAMPLES_PER_SPAN: usize = 8;

/// The plane a wall lies in, and its outward normal.
fn wall_plane(design: &Design, side: Side) -> (DVec3, DVec3) {
    let (xl, xr) = design.outline_x;
    let h = design.half_height;
    match side {
        Side::Left => (DVec3::new(xl, 0.0, 0.0), DVec3::NEG_X),
        Side::Right => (DVec3::new(xr, 0.0, 0.0), DVec3::X),
        Side::Front => (DVec3::new(0.0, -h, 0.0), DVec3::NEG_Y),
        Side::Back => (DVec3::new(0.0, h, 0.0), DVec3::Y),
    }
}

/// Puts `p` exactly into the wall's plane.
fn onto_wall(design: &Design, side: Side, p: DVec3) -> DVec3 {
    let (o, n) = wall_plane(design, side);
    if n.x != 0.0 {
        DVec3::new(o.x, p.y, p.z)
    } else {
        DVec3::new(p.x, o.y, p.z)
    }
}

fn lens_of(patch: Patch) -> Option<LensRef> {
    match patch {
        Patch::Lens(l) => Some(l),
        Patch::Wall(_) => None,
    }
}

fn family_key(lens: LensRef) -> (Array, i64) {
    match lens {
        LensRef::Revealer(i) => (Array::Revealer, i),
        LensRef::Base(k) => (Array::Base, k),
    }
}

/// Builds the B-rep of the device from the exact model, with the topology
/// of the mesher's face partition. Every lens surface is within
/// `FIT_SHARE × tolerance` of its exact lens at every sampled point, or this
/// fails with [`BrepError::SurfaceFit`].
pub fn build_brep(design: &Design, dm: &DeviceMesh) -> Result<DeviceBrep, BrepError> {
    // the faces' topology and the lens surfaces are independent
    let (pieces, families) = rayon::join(
        || pieces(&dm.mesh, &dm.patches),
        || lens_families(design, dm),
    );
    let (pieces, (mut revealer, mut base)) = (pieces?, families?);
    for (array, cut) in wall_cuts(design, dm, &pieces) {
        let family = match array {
            Array::Revealer => &mut revealer,
            Array::Base => &mut base,
        };
        end_in_wall(family, &cut, END_SHARE * design.tolerance.mm());
    }
    let surface_of = |lens: LensRef| match lens {
        LensRef::Revealer(i) => &revealer.surfaces[&i],
        LensRef::Base(k) => &base.surfaces[&k],
    };
    let ends_of = |lens: LensRef| match lens {
        LensRef::Revealer(_) => revealer.ends,
        LensRef::Base(_) => base.ends,
    };
    let lenses = Lenses {
        surface_of: &surface_of,
        ends_of: &ends_of,
    };

    let assembled = assemble(
        &pieces,
        &dm.mesh.positions,
        |piece| lens_of(piece.patch).is_none(),
        |piece, other, run| edge_curve(design, dm, Between { piece, other, run }, &lenses),
        |piece, wires| make_face(design, dm, piece, wires, &surface_of),
    )?;
    let (edge_count, vertex_count) = (assembled.edges, assembled.vertices);
    let solid = closed_solid(assembled.faces, ("shell", "solid"))?;

    let count = |f: &dyn Fn(&Piece) -> bool| pieces.iter().filter(|p| f(p)).count();
    let base_lenses = base.surfaces.len();
    let (deviation, worst) = worst_deviation(&[(&revealer, "revealer lens"), (&base, "base lens")]);
    let stats = BrepStats {
        faces: pieces.len(),
        revealer_faces: count(&|p| matches!(p.patch, Patch::Lens(LensRef::Revealer(_)))),
        base_faces: count(&|p| matches!(p.patch, Patch::Lens(LensRef::Base(_)))),
        base_lenses,
        wall_faces: count(&|p| matches!(p.patch, Patch::Wall(_))),
        edges: edge_count,
        vertices: vertex_count,
        revealer_stations: revealer.stations.len(),
        base_stations: base.stations.len(),
        max_surface_deviation_mm: deviation,
        worst_surface: worst,
        surface_fit_mm: FIT_SHARE * design.tolerance.mm(),
    };
    Ok(DeviceBrep {
        solid,
        stats,
        revealer,
        base,
    })
}

/// The lens surfaces of both arrays (for a printed design, the base's are
/// its band spans of s), over the stations the lenses' faces on the device
/// mesh `dm` span, each within `FIT_SHARE × tolerance` of the exact
/// sections at every sampled point, or [`BrepError::SurfaceFit`].
pub fn lens_families(
    design: &Design,
    dm: &DeviceMesh,
) -> Result<(LensFamily, LensFamily), BrepError> {
    let tolerance: Tolerance = design.tolerance;
    // lenses with faces, and the station range their triangles span (a
    // face's extreme stations are on its boundary; every vertex of a lens
    // triangle is on the lens, so no topology is needed)
    type Ranges = BTreeMap<(u8, i64), (f64, f64)>;
    let add =
        |mut ranges: Ranges, (tri, patch): (&[u32; 3], &Patch)| -> Result<Ranges, BrepError> {
            let Some(lens) = lens_of(*patch) else {
                return Ok(ranges);
            };
            let (array, k) = family_key(lens);
            let entry = ranges
                .entry((array as u8, k))
                .or_insert((f64::INFINITY, f64::NEG_INFINITY));
            for &v in tri {
                let pv = dm.origins[v as usize].params_on(lens).ok_or_else(|| {
                    BrepError::Topology(format!(
                        "vertex {v} of a triangle of {lens:?} has no parameters on it"
                    ))
                })?;
                entry.0 = entry.0.min(pv.y);
                entry.1 = entry.1.max(pv.y);
            }
            Ok(ranges)
        };
    let ranges: Ranges = dm
        .mesh
        .triangles
        .par_iter()
        .zip(&dm.patches)
        .try_fold(Ranges::new, add)
        .try_reduce(Ranges::new, |mut a, b| {
            for (key, (lo, hi)) in b {
                let entry = a.entry(key).or_insert((f64::INFINITY, f64::NEG_INFINITY));
                entry.0 = entry.0.min(lo);
                entry.1 = entry.1.max(hi);
            }
            Ok(a)
        })?;
    let margin = MARGIN_PERIODS * design.params.period;
    let fit = FIT_SHARE * tolerance.mm();
    let family = |array: Array| -> Result<LensFamily, BrepError> {
        // the array's lenses and the station range they span
        let (lenses, stations): (Vec<i64>, Vec<(f64, f64)>) = ranges
            .iter()
            .filter(|(k, _)| k.0 == array as u8)
            .map(|(k, r)| (k.1, *r))
            .unzip();
        let lo = stations.iter().map(|r| r.0).fold(f64::INFINITY, f64::min) - margin;
        let hi = stations
            .iter()
            .map(|r| r.1)
            .fold(f64::NEG_INFINITY, f64::max)
            + margin;
        LensFamily::build(design, array, &lenses, (lo, hi), fit)
    };
    let (revealer, base) = rayon::join(|| family(Array::Revealer), || family(Array::Base));
    Ok((revealer?, base?))
}

/// One solid of `faces`, which must make a closed shell; `what` names the
/// shell and the solid in the error.
pub(crate) fn closed_solid(
    faces: Vec<Face>,
    (shell_what, solid_what): (&'static str, &'static str),
) -> Result<Solid, BrepError> {
    let shell: Shell = faces.into();
    let condition = shell.shell_condition();
    if condition != ShellCondition::Closed {
        return Err(BrepError::Truck {
            what: shell_what,
            detail: format!("shell condition is {condition:?}, not Closed"),
        });
    }
    Solid::try_new(vec![shell]).map_err(|e| BrepError::Truck {
        what: solid_what,
        detail: e.to_string(),
    })
}

/// The faces of a B-rep with one truck `Edge` per boundary run, used by its
/// two faces in opposite directions, and the counts of edges and vertices.
pub(crate) struct Assembled {
    /// One face per piece, in the pieces' order.
    pub faces: Vec<Face>,
    pub edges: usize,
    pub vertices: usize,
}

/// An edge's curve, and how far its ends say where its vertices go.
pub(crate) struct EdgeCurve {
    pub curve: Curve,
    pub ends: Ends,
}

/// Where an edge's vertices go, in the order the ends' kinds place them.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug)]
pub(crate) enum Ends {
    /// A lens surface's crease or end: it ends where that surface does,
    /// places its vertices, and is never moved.
    Fixed,
    /// A curve through points solved exactly onto both its faces (a
    /// channel's side across a lens): the ends it `places` place the
    /// vertices no fixed curve placed, and it is moved onto the others.
    Solved { places: [bool; 2] },
    /// A curve fitted through mesh points (a trim, a line): moved onto the
    /// vertices at its ends.
    Fitted,
}

impl EdgeCurve {
    /// A curve whose ends place its vertices (a lens surface's crease).
    pub(crate) fn fixed(curve: Curve) -> EdgeCurve {
        EdgeCurve {
            curve,
            ends: Ends::Fixed,
        }
    }

    /// A curve whose ends lie exactly on both its faces ([`Ends::Solved`]);
    /// those it `places` place their vertices.
    pub(crate) fn solved(curve: Curve, places: [bool; 2]) -> EdgeCurve {
        EdgeCurve {
            curve,
            ends: Ends::Solved { places },
        }
    }
}

impl From<Curve> for EdgeCurve {
    fn from(curve: Curve) -> EdgeCurve {
        EdgeCurve {
            curve,
            ends: Ends::Fitted,
        }
    }
}

/// A curve's first and last points.
fn ends(curve: &Curve) -> Option<(DVec3, DVec3)> {
    use truck_modeling::BoundedCurve;
    let p = |q: Point3| DVec3::new(q.x, q.y, q.z);
    match curve {
        Curve::Line(Line(a, b)) => Some((p(*a), p(*b))),
        Curve::BSplineCurve(c) => Some((p(c.front()), p(c.back()))),
        Curve::NurbsCurve(c) => Some((p(c.front()), p(c.back()))),
        _ => None,
    }
}

/// `curve` with its ends moved onto `front` and `back` (a line's ends, a
/// clamped B-spline's first and last control points); other curves as
/// they are.
fn with_ends(curve: Curve, front: DVec3, back: DVec3) -> Curve {
    match curve {
        Curve::Line(_) => Curve::Line(Line(point3(front), point3(back))),
        Curve::BSplineCurve(mut c) => {
            let last = c.control_points().len() - 1;
            *c.control_point_mut(0) = point3(front);
            *c.control_point_mut(last) = point3(back);
            Curve::BSplineCurve(c)
        }
        other => other,
    }
}

/// Assembles the faces of `pieces` (vertices at `positions`): every run's
/// edge is made once, by `curve` (from the run's first vertex to its last),
/// when the first piece that meets it is assembled; pieces for which `later`
/// holds come last, so that their neighbours make their shared curves.
///
/// Where a crease ends ([`EdgeCurve::fixed`]), its vertex goes to the
/// crease's end, and every fitted curve at that vertex ends there too: a
/// trim through the exact wall crossing ended up to 0.04 µm from the
/// crease's NURBS, and a reader that projects both onto the lens surface
/// found a gap there and filled it with a degenerated edge, which its
/// mesher turned into slivers (213 on the reference). Where no crease
/// ends, a solved curve's end ([`Ends::Solved`]) places the vertex: a
/// channel's vertex left at its mesh position lay 1.8 µm off the lens.
pub(crate) fn assemble<P>(
    pieces: &[Piece<P>],
    positions: &[DVec3],
    later: impl Fn(&Piece<P>) -> bool,
    mut curve: impl FnMut(&Piece<P>, &Piece<P>, &Run) -> Result<EdgeCurve, BrepError>,
    mut face: impl FnMut(&Piece<P>, Vec<Wire>) -> Result<Face, BrepError>,
) -> Result<Assembled, BrepError> {
    let mut order: Vec<usize> = (0..pieces.len()).collect();
    order.sort_by_key(|&p| (later(&pieces[p]), p));
    // every run's curve, in the order the pieces meet them
    let mut made: Vec<((u32, u32), u32, u32, EdgeCurve)> = Vec::new();
    let mut seen: std::collections::HashSet<(u32, u32)> = std::collections::HashSet::new();
    for &p in &order {
        for run in pieces[p].loops.iter().flatten() {
            if seen.insert(run.key()) {
                let last = *run.vertices.last().expect("a run has two or more vertices");
                let c = curve(&pieces[p], &pieces[run.neighbour], run)?;
                made.push((run.key(), run.vertices[0], last, c));
            }
        }
    }
    let placed = vertex_places(&made);
    let at = |v: u32| placed.get(&v).copied().unwrap_or(positions[v as usize]);
    let mut vertices: HashMap<u32, Vertex> = HashMap::new();
    let mut vertex = |v: u32| -> Vertex {
        vertices
            .entry(v)
            .or_insert_with(|| Vertex::new(point3(at(v))))
            .clone()
    };
    let mut edges: HashMap<(u32, u32), Edge> = HashMap::new();
    for (key, first, last, c) in made {
        let c = match c.ends {
            Ends::Fixed => c.curve,
            Ends::Solved { .. } | Ends::Fitted => with_ends(c.curve, at(first), at(last)),
        };
        let e = Edge::try_new(&vertex(first), &vertex(last), c).map_err(|e| BrepError::Truck {
            what: "edge",
            detail: e.to_string(),
        })?;
        edges.insert(key, e);
    }
    // the first piece to meet a run made its edge in its direction; the
    // second goes the other way
    let mut used: std::collections::HashSet<(u32, u32)> = std::collections::HashSet::new();
    let mut faces: Vec<Option<Face>> = vec![None; pieces.len()];
    for &p in &order {
        let piece = &pieces[p];
        let mut wires = Vec::new();
        for runs in &piece.loops {
            let mut wire = Wire::new();
            for run in runs {
                let last = *run.vertices.last().expect("a run has two or more vertices");
                let e = &edges[&run.key()];
                wire.push_back(if used.insert(run.key()) {
                    e.clone()
                } else if e.front().id() == vertex(last).id() {
                    e.inverse()
                } else {
                    return Err(BrepError::Topology(format!(
                        "edge {:?} is used twice in the same direction",
                        run.key()
                    )));
                });
            }
            wires.push(wire);
        }
        faces[p] = Some(face(piece, wires)?);
    }
    let faces: Vec<Face> = faces
        .into_iter()
        .map(|f| f.expect("every piece has a face"))
        .collect();
    Ok(Assembled {
        faces,
        edges: edges.len(),
        vertices: vertices.len(),
    })
}

/// Where the vertices at creases' ends go: each crease's end (the first
/// crease to reach a vertex places it), then each solved curve's end.
fn vertex_places(made: &[((u32, u32), u32, u32, EdgeCurve)]) -> HashMap<u32, DVec3> {
    let mut placed = HashMap::new();
    let fixed = |c: &EdgeCurve| matches!(c.ends, Ends::Fixed).then_some([true; 2]);
    let solved = |c: &EdgeCurve| match c.ends {
        Ends::Solved { places } => Some(places),
        _ => None,
    };
    for places_of in [&fixed as &dyn Fn(&EdgeCurve) -> Option<[bool; 2]>, &solved] {
        for (_, first, last, c) in made {
            let (Some(places), Some((front, back))) = (places_of(c), ends(&c.curve)) else {
                continue;
            };
            if places[0] {
                placed.entry(*first).or_insert(front);
            }
            if places[1] {
                placed.entry(*last).or_insert(back);
            }
        }
    }
    placed
}

/// The lens surfaces a device's edges lie on, and where they end in walls.
struct Lenses<'s> {
    surface_of: &'s dyn Fn(LensRef) -> &'s NurbsSurface<Vector4>,
    ends_of: &'s dyn Fn(LensRef) -> WallEnds,
}

/// A boundary run and the two pieces it lies between.
struct Between<'a> {
    piece: &'a Piece,
    other: &'a Piece,
    run: &'a Run,
}

/// The curve of the edge along `between.run` (from its first vertex to its
/// last), seen from `between.piece`; `between.other` is the piece across it.
fn edge_curve(
    design: &Design,
    dm: &DeviceMesh,
    between: Between,
    lenses: &Lenses,
) -> Result<EdgeCurve, BrepError> {
    let Between { piece, other, run } = between;
    let at = |v: u32| dm.mesh.positions[v as usize];
    let (Some(lens), other_patch) = (lens_of(piece.patch), other.patch) else {
        // wall against wall: a vertical corner line
        let (a, b) = (at(run.vertices[0]), at(*run.vertices.last().unwrap()));
        if run.vertices.len() != 2 {
            return Err(BrepError::Topology(format!(
                "wall corner from {a} to {b} has {} mesh vertices, expected 2",
                run.vertices.len()
            )));
        }
        return Ok(Curve::Line(Line(point3(a), point3(b))).into());
    };
    // On a crease of this lens (t = 0 or t = 1 at every vertex)?
    let params: Vec<_> = run
        .vertices
        .iter()
        .map(|&v| dm.origins[v as usize].params_on(lens))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| BrepError::Topology(format!("run of {lens:?} leaves the lens")))?;
    let (first, last) = (params[0], *params.last().unwrap());
    let on_crease = [0.0, 1.0]
        .into_iter()
        .find(|&t| params.iter().all(|p| p.x == t));
    if let Some(t) = on_crease {
        return Ok(EdgeCurve::fixed(Curve::BSplineCurve(crease_curve(
            (lenses.surface_of)(lens),
            t,
            first.y,
            last.y,
        )?)));
    }
    let Patch::Wall(side) = other_patch else {
        return Err(BrepError::Topology(format!(
            "{lens:?} meets {:?} away from a crease",
            other_patch
        )));
    };
    let ends = (lenses.ends_of)(lens);
    if let (Side::Front | Side::Back, Some(end)) = (side, ends.end_of(first.y, last.y)) {
        let sides = [Side::Left, Side::Right].map(|s| {
            let (origin, normal) = wall_plane(design, s);
            WallPlane { origin, normal }
        });
        let ends_at = [at(run.vertices[0]), at(*run.vertices.last().unwrap())];
        return Ok(EdgeCurve::fixed(iso_edge(
            (lenses.surface_of)(lens),
            end,
            RunEnds {
                t: [first.x, last.x],
                at: ends_at,
            },
            &sides,
            design.tolerance.mm(),
        )));
    }
    let pts: Vec<DVec3> = run.vertices.iter().map(|&v| at(v)).collect();
    Ok(trim_curve(design, side, &pts).into())
}

/// Where the families' surfaces are to end in the front and back walls
/// ([`crate::ends`]): for each array and wall, the station of its wall
/// vertices nearest the layout. A wall is left out where a boundary run of
/// that array ends beyond that station off the wall (a base crease meeting
/// a side wall in the corner), whose vertex the ending would move.
fn wall_cuts(design: &Design, dm: &DeviceMesh, pieces: &[Piece]) -> Vec<(Array, WallCut)> {
    type Key = (u8, u8);
    let mut on_wall: HashMap<Key, (Vec<f64>, std::collections::HashSet<u32>)> = HashMap::new();
    let mut run_ends: HashMap<u8, Vec<(u32, f64)>> = HashMap::new();
    for piece in pieces {
        let Some(lens) = lens_of(piece.patch) else {
            continue;
        };
        let array = family_key(lens).0 as u8;
        let station = |v: u32| dm.origins[v as usize].params_on(lens).map(|p| p.y);
        for run in piece.loops.iter().flatten() {
            if let Patch::Wall(side @ (Side::Front | Side::Back)) = pieces[run.neighbour].patch {
                let entry = on_wall.entry((array, side as u8)).or_default();
                for &v in &run.vertices {
                    entry.0.extend(station(v));
                    entry.1.insert(v);
                }
            }
            for v in [run.vertices[0], *run.vertices.last().unwrap()] {
                run_ends
                    .entry(array)
                    .or_default()
                    .extend(station(v).map(|s| (v, s)));
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let mut cuts = Vec::new();
    // a printed base's band spans are no lenses: its walls trim them
    let arrays = match design.params.base.kind {
        moirecast_kernel::BaseKind::DualLens => &[Array::Revealer, Array::Base][..],
        _ => &[Array::Revealer][..],
    };
    for &array in arrays {
        let key = |side: Side| (array as u8, side as u8);
        let (Some(front), Some(back)) = (
            on_wall.get(&key(Side::Front)),
            on_wall.get(&key(Side::Back)),
        ) else {
            continue;
        };
        let back_is_last = mean(&back.0) > mean(&front.0);
        for (side, (stations, vertices)) in [(Side::Front, front), (Side::Back, back)] {
            let end = if (side == Side::Back) == back_is_last {
                End::Last
            } else {
                End::First
            };
            let station = match end {
                End::Last => stations.iter().copied().fold(f64::INFINITY, f64::min),
                End::First => stations.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            };
            let beyond = |s: f64| match end {
                End::Last => s > station,
                End::First => s < station,
            };
            let clear = run_ends[&(array as u8)]
                .iter()
                .all(|&(v, s)| !beyond(s) || vertices.contains(&v));
            if clear && station.is_finite() {
                let (origin, normal) = wall_plane(design, side);
                let plane = WallPlane { origin, normal };
                cuts.push((
                    array,
                    WallCut {
                        end,
                        station,
                        plane,
                    },
                ));
            }
        }
    }
    cuts
}

/// The crease curve of `surface` at t = 0 (its first row of control
/// points) or t = 1 (its last), between stations v0 and v1 (in that
/// direction).
pub(crate) fn crease_curve(
    surface: &truck_modeling::NurbsSurface<truck_modeling::Vector4>,
    t: f64,
    v0: f64,
    v1: f64,
) -> Result<BSplineCurve<Point3>, BrepError> {
    let row = if t == 0.0 {
        0
    } else {
        surface.control_points().len() - 1
    };
    let points: Vec<Point3> = surface.control_points()[row]
        .iter()
        .map(|h| Point3::new(h.x / h.w, h.y / h.w, h.z / h.w))
        .collect();
    let mut whole = BSplineCurve::new(surface.vknot_vec().clone(), points);
    // a surface ended in a wall ends where the wall's vertices are, or
    // nearer the layout (crate::ends): a station beyond its end is its end
    let (first, last) = truck_modeling::BoundedCurve::range_tuple(&whole);
    let (lo, hi) = (v0.min(v1).max(first), v0.max(v1).min(last));
    if lo >= hi {
        return Err(BrepError::Topology(format!(
            "a crease from {v0} to {v1} has no length on its surface's span {first}..{last}"
        )));
    }
    let mut piece_curve = if lo > first { whole.cut(lo) } else { whole };
    if hi < last {
        let _after = piece_curve.cut(hi);
    }
    if v0 > v1 {
        piece_curve.invert();
    }
    Ok(piece_curve)
}

/// The C² cubic through `pts` (in order, at chord-length parameters from
/// 0), its points and control points put through `flatten` (into a plane
/// the curve must lie in, or left as they are).
pub(crate) fn cubic_through(
    pts: &[DVec3],
    flatten: impl Fn(DVec3) -> DVec3,
) -> BSplineCurve<Point3> {
    let pts: Vec<DVec3> = pts.iter().map(|&p| flatten(p)).collect();
    let s = chord_lengths(&pts);
    let data: Vec<[f64; 3]> = pts.iter().map(|p| p.to_array()).collect();
    let ctrl: Vec<Point3> = interpolate(&s, &data)
        .into_iter()
        .map(|c| point3(flatten(DVec3::from_array(c))))
        .collect();
    BSplineCurve::new(clamped_knots(&s), ctrl)
}

/// A trim, where a wall cuts a surface: the C² cubic through the exact
/// intersection points `pts` (in order), flattened into the wall's plane.
pub(crate) fn trim_curve(design: &Design, side: Side, pts: &[DVec3]) -> Curve {
    Curve::BSplineCurve(cubic_through(pts, |p| onto_wall(design, side, p)))
}

/// The planar face of a wall, outward.
pub(crate) fn wall_face(
    design: &Design,
    side: Side,
    wires: Vec<Wire>,
) -> Result<Face, truck_topology::errors::Error> {
    let (o, n) = wall_plane(design, side);
    // in-plane axes a, b with a × b = outward normal
    let a = if n.x != 0.0 { DVec3::Z } else { DVec3::X };
    let b = n.cross(a);
    debug_assert!((a.cross(b) - n).length() < 1e-15);
    let plane = Plane::new(point3(o), point3(o + a), point3(o + b));
    Face::try_new(wires, Surface::Plane(plane))
}

/// A face on `surface`, oriented like `outward` (a mesh triangle's normal)
/// at the surface's parameters `at`.
pub(crate) fn surface_face(
    surface: truck_modeling::NurbsSurface<truck_modeling::Vector4>,
    outward: DVec3,
    at: glam::DVec2,
    wires: Vec<Wire>,
) -> Result<Face, truck_topology::errors::Error> {
    let nat = surface.normal(at.x, at.y);
    let natural_is_outward = outward.dot(DVec3::new(nat.x, nat.y, nat.z)) > 0.0;
    face_facing(Surface::NurbsSurface(surface), natural_is_outward, wires)
}

/// The span of the along-lens parameter v over `piece`'s boundary, each
/// vertex's parameters given by `params`.
pub(crate) fn boundary_span<P>(
    piece: &Piece<P>,
    params: impl Fn(u32) -> Result<glam::DVec2, BrepError>,
) -> Result<(f64, f64), BrepError> {
    let mut span = (f64::INFINITY, f64::NEG_INFINITY);
    for run in piece.loops.iter().flatten() {
        for &v in &run.vertices {
            let along = params(v)?.y;
            span = (span.0.min(along), span.1.max(along));
        }
    }
    Ok(span)
}

/// `surface` cut down along v to the knot spans that `span` touches and
/// one more on each side, for a face whose boundary spans that: a face
/// keeps only the part of a long lens or band surface it lies on. Where
/// the walls clip a printed band into thousands of pieces, each holding
/// the whole band's surface took over 22 GB (found-ee2e521bd310a47e:
/// 6,941 faces of 3 × 4,130 control points). Its edges follow mesh runs
/// between its boundary vertices, so they stay inside the spare span. The
/// cut is knot insertion, exact but for round-off; a face that spans the
/// surface to within a span of its ends keeps it whole.
pub(crate) fn cut_to_span(
    surface: &truck_modeling::NurbsSurface<truck_modeling::Vector4>,
    (v0, v1): (f64, f64),
) -> truck_modeling::NurbsSurface<truck_modeling::Vector4> {
    let (knots, _) = surface.vknot_vec().to_single_multi();
    let (first, last) = (knots[0], knots[knots.len() - 1]);
    let lo = knots[knots.partition_point(|&k| k <= v0).saturating_sub(2)];
    let hi = knots[(knots.partition_point(|&k| k < v1) + 1).min(knots.len() - 1)];
    let mut part = surface.clone();
    if lo > first {
        part = part.vcut(lo);
    }
    if hi < last {
        let _above = part.vcut(hi);
    }
    part
}

/// A face on `surface` bounded by `wires` (counter-clockwise seen from
/// outside), outward along the surface's natural normal or against it.
pub(crate) fn face_facing(
    surface: Surface,
    natural_is_outward: bool,
    wires: Vec<Wire>,
) -> Result<Face, truck_topology::errors::Error> {
    if natural_is_outward {
        Face::try_new(wires, surface)
    } else {
        let reversed: Vec<Wire> = wires.iter().map(|w| w.inverse()).collect();
        let mut face = Face::try_new(reversed, surface)?;
        face.invert();
        Ok(face)
    }
}

fn make_face<'s>(
    design: &Design,
    dm: &DeviceMesh,
    piece: &Piece,
    wires: Vec<Wire>,
    surface_of: &dyn Fn(LensRef) -> &'s truck_modeling::NurbsSurface<truck_modeling::Vector4>,
) -> Result<Face, BrepError> {
    let refuse = |e: truck_topology::errors::Error| BrepError::Truck {
        what: "face",
        detail: format!("{:?}: {e}", piece.patch),
    };
    match piece.patch {
        Patch::Wall(side) => wall_face(design, side, wires).map_err(refuse),
        Patch::Lens(lens) => {
            // orientation: the surface's own normal against the triangle's
            let tri = dm.mesh.triangles[piece.triangle as usize];
            let [p0, p1, p2] = tri.map(|v| dm.mesh.positions[v as usize]);
            let pv = tri.map(|v| dm.origins[v as usize].params_on(lens).expect("checked"));
            let at = (pv[0] + pv[1] + pv[2]) / 3.0;
            let span = boundary_span(piece, |v| {
                dm.origins[v as usize].params_on(lens).ok_or_else(|| {
                    BrepError::Topology(format!("boundary vertex {v} is not on {lens:?}"))
                })
            })?;
            let surface = cut_to_span(surface_of(lens), span);
            surface_face(surface, (p1 - p0).cross(p2 - p0), at, wires).map_err(refuse)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use truck_modeling::{BSplineSurface, KnotVec, NurbsSurface, Vector4};

    /// A rational surface 3 control points across and 203 along: cubic in
    /// v over 200 uniform spans, on [0, 1] × [0, 1].
    fn long_surface() -> NurbsSurface<Vector4> {
        let spans = 200;
        let inner: Vec<f64> = (1..spans).map(|i| i as f64 / spans as f64).collect();
        let vknots = KnotVec::from(
            [vec![0.0; 4], inner, vec![1.0; 4]]
                .into_iter()
                .flatten()
                .collect::<Vec<_>>(),
        );
        let rows = (0..3)
            .map(|i| {
                (0..spans + 3)
                    .map(|j| {
                        let (x, y) = (i as f64, j as f64 * 0.1);
                        let w = 1.0 + 0.3 * ((i + j) as f64).sin().abs();
                        Vector4::new(x * w, y * w, (0.7 * y).sin() * w, w)
                    })
                    .collect()
            })
            .collect();
        NurbsSurface::new(BSplineSurface::new((KnotVec::bezier_knot(2), vknots), rows))
    }

    #[test]
    fn a_face_keeps_only_its_span_of_a_long_surface() {
        let whole = long_surface();
        let part = cut_to_span(&whole, (0.401, 0.449));
        let knots = part.vknot_vec();
        let (lo, hi) = (knots[0], knots[knots.len() - 1]);
        // the spans the face touches and one spare on each side
        assert!(
            (lo - 0.395).abs() < 1e-12 && (hi - 0.455).abs() < 1e-12,
            "{lo} {hi}"
        );
        assert!(
            part.control_points()[0].len() < 20,
            "{}",
            part.control_points()[0].len()
        );
        for i in 0..=10 {
            for j in 0..=50 {
                let (u, v) = (i as f64 / 10.0, lo + (hi - lo) * j as f64 / 50.0);
                let (a, b) = (whole.subs(u, v), part.subs(u, v));
                let d = DVec3::new(a.x - b.x, a.y - b.y, a.z - b.z).length();
                assert!(d < 1e-12, "{d} at ({u}, {v})");
            }
        }
        // a face over the whole surface keeps it as it is
        let kept = cut_to_span(&whole, (0.003, 0.997));
        assert_eq!(kept.control_points(), whole.control_points());
    }
}
