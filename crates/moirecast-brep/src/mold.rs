//! A parting region of the mold (the block on one side of the parting
//! surface, its floor the device's own faces) as an exact B-rep solid.
//!
//! The region's mesh labels every triangle with the surface it lies on
//! ([`RegionSurface`]), and shares every vertex by index, as the device
//! mesher does. So, as for the device, the connected pieces of one label
//! are the faces, and a loop splits into edges where the piece across it
//! changes ([`crate::topology`]). The surfaces:
//! - the device's lens faces: the device B-rep's NURBS lens surfaces,
//!   posed into the mold frame exactly (control points map as points);
//! - the device's walls, up to the mid-wall curve: planes;
//! - each wall's skirt: its mid curve (the polyline of the mid-wall
//!   points, in the wall's plane, as the mesh has it) carried horizontally
//!   out to the block's side, a B-spline surface of degree (1, 1);
//! - the corner squares, the block's sides and its cap: planes;
//! - a registration key's bump: a cone in two halves, and its flat top.
//!
//! The edges: creases and trims as the device's; the mid polyline; its copy
//! on the block's side; a bump's circles, in two arcs each; straight lines
//! elsewhere. Vertices sit at the
//! region mesh's positions (f32, as the STL halves).

use crate::channels;
use crate::ends::{into_plane, iso_edge, End, RunEnds, WallEnds, WallPlane};
use crate::error::BrepError;
use crate::lenses::LensFamily;
use crate::solid::{
    assemble, boundary_span, closed_solid, crease_curve, cubic_through, cut_to_span, face_facing,
    point3, surface_face, DeviceBrep, EdgeCurve,
};
use crate::spline::chord_lengths;
use crate::topology::{pieces, Piece, Run};
use glam::{DAffine3, DVec3};
use moirecast_kernel::measure::{closest_on_segment, closest_on_triangle};
use moirecast_kernel::mesher::Patch;
use moirecast_kernel::model::LensRef;
use moirecast_kernel::Mesh;
use moirecast_kernel::{Design, DeviceMesh};
use moirecast_mold::parting::{self, Bump, PosedDevice, Rect, Region, RegionSurface, Wall};
use moirecast_mold::{ChannelAxis, ChannelShape, HalfSurface, Mold};
use rayon::prelude::*;
use std::collections::HashMap;
use truck_modeling::{
    BSplineCurve, BSplineSurface, Curve, Cut, Face, KnotVec, Line, Matrix4, NurbsSurface,
    ParametricSurface, ParametricSurface3D, Plane, Point3, Processor, RevolutedCurve, Solid,
    Surface, Transformed, Vector3, Vector4, Wire,
};

/// What a face of a region's (or a half's) B-rep lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum RegionFace {
    Lens(LensRef),
    /// A device wall, up to (or down to) the mid-wall curve.
    Wall(Wall),
    /// Any surface of the region that is not the device's.
    Block(RegionSurface),
    /// The side of channel k, its first or second half-turn.
    ChannelSide(usize, usize),
    /// The flat end of channel k.
    ChannelEnd(usize),
}

/// A region's B-rep solid and its counts.
pub struct RegionBrep {
    pub solid: Solid,
    pub faces: usize,
    pub edges: usize,
    pub vertices: usize,
    /// Faces' boundary loops beyond their first (a corner square around a
    /// bump's foot has one): Euler–Poincaré counts them,
    /// V − E + F − rings = 2 (1 − genus).
    pub rings: usize,
    /// How far the mesh's vertices lie from their faces' exact surfaces.
    pub fit: Fit,
}

/// How far a region's or half's mesh lies from its B-rep, both ways: its
/// vertices from the exact surface of the face they are on (the faces
/// sampled at the vertices' feet), and points sampled on the faces from
/// the mesh. Vertices the device mesher placed on a lens, and triangles
/// with only such vertices, are left out: their distance from the lens's
/// NURBS surface is the device B-rep's `brep-surface-fit`, measured there.
#[derive(Clone, Copy, Debug, Default)]
pub struct Fit {
    /// The worst distance (mm) on the device's walls and the new lens
    /// vertices, the skirt, the corner squares, the sides and the cap, and
    /// where it is.
    pub block_mm: f64,
    pub block_at: DVec3,
    /// The worst distance (mm) on a channel's or key's side or end, where
    /// the mesh is a 48-gon, and where it is.
    pub channels_mm: f64,
    pub channels_at: DVec3,
    /// How many points were sampled on the faces: each mesh triangle's
    /// centroid carried onto its face's exact surface, and points along
    /// every edge's curve.
    pub samples: usize,
    /// The worst distance (mm) from the mesh of a point sampled on the
    /// mold's own exact faces and edges, and where it is.
    pub samples_mm: f64,
    pub samples_at: DVec3,
    /// The same on the channels' and keys' sides and ends.
    pub channel_samples_mm: f64,
    pub channel_samples_at: DVec3,
    /// The same on the device's lens faces and on the edges they bound
    /// (creases, rims), which carry the device B-rep's NURBS.
    pub device_samples_mm: f64,
    pub device_samples_at: DVec3,
}

/// Whose surface a sampled point lies on, which sets how near the mesh it
/// must be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sampled {
    /// The mold's own faces and edges, exact to round-off.
    Mold,
    /// A channel's or key's side or end, meshed as a 48-gon.
    Channel,
    /// The device's lens faces and their edges: the device B-rep's NURBS,
    /// themselves within the tolerance of the exact model.
    Device,
}

impl Sampled {
    /// Whose surface a point of `face` lies on.
    fn of(face: RegionFace) -> Self {
        match face {
            RegionFace::ChannelSide(..)
            | RegionFace::ChannelEnd(_)
            | RegionFace::Block(RegionSurface::BumpSide(..)) => Sampled::Channel,
            RegionFace::Lens(_) => Sampled::Device,
            _ => Sampled::Mold,
        }
    }

    /// Whose surface an edge between faces `a` and `b` lies on: a channel's
    /// where either is one (its 48-gon sets the edge's mesh run), else the
    /// device's where either is a lens.
    fn of_edge(a: RegionFace, b: RegionFace) -> Self {
        match (Sampled::of(a), Sampled::of(b)) {
            (Sampled::Channel, _) | (_, Sampled::Channel) => Sampled::Channel,
            (Sampled::Device, _) | (_, Sampled::Device) => Sampled::Device,
            _ => Sampled::Mold,
        }
    }
}

/// The region's geometry beside its mesh: where its planes lie.
struct Frame<'a> {
    outline: Rect,
    footprint: Rect,
    cap_z: f64,
    mesh: &'a moirecast_kernel::Mesh,
    /// The bump standing on each corner square that has one.
    bumps: HashMap<usize, &'a Bump>,
    /// The channels a half's `ChannelSide` and `ChannelEnd` faces index.
    channels: &'a [ChannelShape],
    /// The mesh's tolerance (mm): a vertex a channel made on a crease lies
    /// on the mesh's chord there, within this of the crease.
    tolerance: f64,
    /// Where the revealer's and the base's surfaces end in walls.
    ends: [WallEnds; 2],
    /// The mesh vertices on the device's walls, which no solved channel
    /// point moves: a vent's solved end placed a corner 0.24 µm off the
    /// wall's plane, and OpenCascade's booleans lost a quarter of that
    /// half (random design seed 10, `wall-corner-vent-mold.toml`).
    on_walls: std::collections::HashSet<u32>,
}

impl Frame<'_> {
    fn ends_of(&self, lens: LensRef) -> WallEnds {
        match lens {
            LensRef::Revealer(_) => self.ends[0],
            LensRef::Base(_) => self.ends[1],
        }
    }

    /// The plane of `wall` of the outline.
    fn wall_plane(&self, wall: Wall) -> WallPlane {
        let origin = onto(&self.outline, wall, DVec3::ZERO);
        let normal = match wall {
            Wall::XMin | Wall::XMax => DVec3::X,
            Wall::YMin | Wall::YMax => DVec3::Y,
        };
        WallPlane { origin, normal }
    }
}

/// The truck matrix of an affine map of points.
pub(crate) fn matrix_of(map: DAffine3) -> Matrix4 {
    let m = map.to_cols_array();
    Matrix4::new(
        m[0], m[1], m[2], 0.0, m[3], m[4], m[5], 0.0, m[6], m[7], m[8], 0.0, m[9], m[10], m[11],
        1.0,
    )
}

/// An edge's curve, the mesh run it was built along, and whose surface it
/// lies on: a channel's or key's if it bounds one, else the device's if it
/// bounds a lens.
type BuiltEdge = (Vec<u32>, Curve, Sampled);

/// The posed device's vertex a region's or half's vertex is, if it is one.
type DeviceVertex<'a> = &'a (dyn Fn(u32) -> Option<u32> + Sync);

/// The label of the posed device's triangle `t` in a region or half.
fn device_label(posed: &PosedDevice, t: usize) -> RegionFace {
    match (posed.patches[t], posed.faces[t]) {
        (Patch::Lens(lens), _) => RegionFace::Lens(lens),
        (Patch::Wall(_), parting::Face::Wall(w)) => RegionFace::Wall(w),
        (Patch::Wall(_), face) => unreachable!("a wall triangle posed as {face:?}"),
    }
}

/// The label of `region`'s triangle `t`.
fn region_label(posed: &PosedDevice, region: &Region, t: usize) -> RegionFace {
    match region.surfaces[t] {
        RegionSurface::Device => device_label(posed, region.device_faces[t] as usize),
        other => RegionFace::Block(other),
    }
}

/// The B-rep of `region`, a parting region of `posed` (the device mesh `dm`
/// of `design`, posed) over `footprint`, capped at `cap_z`, with `bumps`
/// (the keys' bumps it was built with).
pub fn region_brep(
    design: &Design,
    dm: &DeviceMesh,
    posed: &PosedDevice,
    region: &Region,
    (footprint, cap_z): (Rect, f64),
    bumps: &[Bump],
) -> Result<RegionBrep, BrepError> {
    let labels: Vec<RegionFace> = (0..region.surfaces.len())
        .map(|t| region_label(posed, region, t))
        .collect();
    let device_vertex = |v: u32| region.device_vertices.get(v as usize).copied();
    let device = crate::solid::build_brep(design, dm)?;
    build(
        (design, dm, posed),
        (&region.mesh, &labels, &device_vertex),
        Frame {
            outline: posed.outline,
            footprint,
            cap_z,
            mesh: &region.mesh,
            bumps: HashMap::new(),
            channels: &[],
            tolerance: design.tolerance.mm(),
            ends: [device.revealer.ends, device.base.ends],
            on_walls: Default::default(),
        },
        (bumps, (&device.revealer, &device.base)),
    )
}

/// The B-rep of a cut half of `mold` (built from `dm` of `design`): `top`
/// or the bottom one, channels, sockets and all. Its lens faces lie on
/// `device`'s lens surfaces (the device's B-rep, built once), posed.
pub fn half_brep(
    design: &Design,
    dm: &DeviceMesh,
    mold: &Mold,
    (device, top): (&DeviceBrep, bool),
) -> Result<RegionBrep, BrepError> {
    let exact = &mold.exact;
    let (mesh, traced) = if top {
        (mold.top.mesh(), &exact.top)
    } else {
        (mold.bottom.mesh(), &exact.bottom)
    };
    let posed = &exact.posed;
    let labels: Vec<RegionFace> = traced
        .surfaces
        .iter()
        .map(|s| match *s {
            HalfSurface::Device(t) => device_label(posed, t as usize),
            HalfSurface::Region(t) => region_label(posed, &traced.region, t as usize),
            HalfSurface::ChannelSide(k, h) => RegionFace::ChannelSide(k, h),
            HalfSurface::ChannelEnd(k) => RegionFace::ChannelEnd(k),
        })
        .collect();
    // the half keeps the device's vertices where they were, to the bit
    let key = |p: DVec3| p.to_array().map(|c| (c + 0.0).to_bits());
    let posed_at: rustc_hash::FxHashMap<[u64; 3], u32> = posed
        .mesh
        .positions
        .iter()
        .enumerate()
        .map(|(i, &p)| (key(p), i as u32))
        .collect();
    // looked up once per vertex: the fit checks ask for every triangle's
    let device_of: Vec<Option<u32>> = mesh
        .positions
        .par_iter()
        .map(|&p| posed_at.get(&key(p)).copied())
        .collect();
    let device_vertex = |v: u32| device_of.get(v as usize).copied().flatten();
    build(
        (design, dm, posed),
        (mesh, &labels, &device_vertex),
        Frame {
            outline: posed.outline,
            footprint: exact.footprint,
            cap_z: traced.cap_z,
            mesh,
            bumps: HashMap::new(),
            channels: &exact.channels,
            tolerance: design.tolerance.mm(),
            ends: [device.revealer.ends, device.base.ends],
            on_walls: Default::default(),
        },
        (&exact.bumps, (&device.revealer, &device.base)),
    )
}

/// A posed lens surface whose ends lie in the device's front and back
/// walls ([`crate::ends`]), its end columns put into the mold's wall planes
/// (the outline's, where the posed mesh's f32 vertices lie; the pose moved
/// them off it by round-off).
fn ended_in_posed_walls(
    mut surface: NurbsSurface<Vector4>,
    ends: WallEnds,
    frame: &Frame,
) -> NurbsSurface<Vector4> {
    for (end, ended) in [(End::First, ends.first), (End::Last, ends.last)] {
        if ended.is_none() {
            continue;
        }
        let rows = surface.control_points();
        let column = match end {
            End::First => 0,
            End::Last => rows[0].len() - 1,
        };
        let h = rows[0][column];
        let y = h.y / h.w;
        let wall = [Wall::YMin, Wall::YMax]
            .into_iter()
            .min_by(|a, b| {
                let d = |w: &Wall| (onto(&frame.outline, *w, DVec3::ZERO).y - y).abs();
                d(a).total_cmp(&d(b))
            })
            .expect("two walls");
        if let Some(put) = into_plane(surface.clone(), end, frame.wall_plane(wall)) {
            surface = put;
        }
    }
    surface
}

/// The B-rep of the closed `mesh` whose triangles lie on `labels`, its
/// device vertices' indices in the posed device given by `device_vertex`.
fn build<'a>(
    (design, dm, posed): (&Design, &DeviceMesh, &PosedDevice),
    (mesh, labels, device_vertex): (&Mesh, &[RegionFace], DeviceVertex<'_>),
    mut frame: Frame<'a>,
    (bumps, (revealer, base)): (&'a [Bump], (&LensFamily, &LensFamily)),
) -> Result<RegionBrep, BrepError> {
    let pieces = pieces(mesh, labels)?;
    let matrix = matrix_of(posed.pose.affine());
    let pose = |family: &LensFamily, s: &NurbsSurface<Vector4>| {
        ended_in_posed_walls(s.transformed(matrix), family.ends, &frame)
    };
    let posed_surfaces: HashMap<LensRef, NurbsSurface<Vector4>> = revealer
        .surfaces
        .iter()
        .map(|(&i, s)| (LensRef::Revealer(i), pose(revealer, s)))
        .chain(
            base.surfaces
                .iter()
                .map(|(&k, s)| (LensRef::Base(k), pose(base, s))),
        )
        .collect();
    // each square's bump: the one nearest a triangle of its top
    frame.bumps = pieces
        .iter()
        .filter_map(|piece| match piece.patch {
            RegionFace::Block(RegionSurface::BumpTop(k)) => {
                let p = mesh.positions[mesh.triangles[piece.triangle as usize][0] as usize];
                let nearest = bumps.iter().min_by(|a, b| {
                    let d = |b: &Bump| b.centre.distance(p.truncate());
                    d(a).total_cmp(&d(b))
                })?;
                Some((k, nearest))
            }
            _ => None,
        })
        .collect();
    frame.on_walls = pieces
        .iter()
        .filter(|piece| matches!(piece.patch, RegionFace::Wall(_)))
        .flat_map(|piece| piece.loops.iter().flatten())
        .flat_map(|run| run.vertices.iter().copied())
        .collect();
    let frame = frame;
    let crossings = crease_crossings(
        &pieces,
        mesh,
        &|v| device_vertex(v).filter(|&d| (d as usize) < dm.mesh.positions.len()),
        &posed_surfaces,
        &frame,
    );
    // a vertex's parameters on a lens: its device vertex's, or, where a
    // channel made it, its crease crossing or found on the lens's surface
    let params = |v: u32, lens: LensRef| -> Result<glam::DVec2, BrepError> {
        let known = device_vertex(v)
            .filter(|&d| (d as usize) < dm.mesh.positions.len())
            .and_then(|d| dm.origins[d as usize].params_on(lens));
        if let Some(uv) = known {
            return Ok(uv);
        }
        if let Some(&uv) = crossings.get(&(v, lens)) {
            return Ok(uv);
        }
        let p = mesh.positions[v as usize];
        let (u, w) = crate::solid::lens_params(&posed_surfaces[&lens], p, frame.tolerance);
        // on a crease to round-off: exactly on it
        let snap = |t: f64| {
            if t.abs() < 1e-9 {
                0.0
            } else if (t - 1.0).abs() < 1e-9 {
                1.0
            } else {
                t
            }
        };
        Ok(glam::DVec2::new(snap(u), w))
    };
    let mid_curves: HashMap<Wall, BSplineCurve<Point3>> = Wall::ALL
        .iter()
        .map(|&w| Some((w, mid_curve(&frame, &pieces, w)?)))
        .collect::<Option<_>>()
        .ok_or_else(|| BrepError::Topology("a wall has no mid curve".into()))?;
    // every edge's curve, the mesh run it was built along, and whose
    // surface it lies on
    let mut built_edges: Vec<BuiltEdge> = Vec::new();
    let assembled = assemble(
        &pieces,
        &mesh.positions,
        |piece| !matches!(piece.patch, RegionFace::Lens(_)),
        |piece, other, run| {
            let curve = edge_curve(
                &frame,
                (piece.patch, other.patch),
                run,
                &|lens| {
                    let (a, b) = (
                        params(run.vertices[0], lens)?,
                        params(*run.vertices.last().unwrap(), lens)?,
                    );
                    Ok((a, b, &posed_surfaces[&lens]))
                },
                &mid_curves,
            )?;
            built_edges.push((
                run.vertices.clone(),
                curve.curve.clone(),
                Sampled::of_edge(piece.patch, other.patch),
            ));
            Ok(curve)
        },
        |piece, wires| make_face(&frame, piece, wires, &params, &posed_surfaces, &mid_curves),
    )?;
    let faces = assembled.faces.len();
    let rings = pieces.iter().map(|p| p.loops.len() - 1).sum();
    let solid = closed_solid(assembled.faces, ("region shell", "region solid"))?;
    let fit = fit(
        (mesh, labels),
        &frame,
        &mid_curves,
        (&posed_surfaces, device_vertex),
        (&built_edges, design.tolerance.mm()),
    );
    Ok(RegionBrep {
        solid,
        faces,
        edges: assembled.edges,
        vertices: assembled.vertices,
        rings,
        fit,
    })
}

/// Where the lens's parameters `uw` of a channel's vertex `p` (which
/// no device vertex placed) lie on a crease: the crease's exact crossing
/// with the channel's side ([`channels::crease_crossing`]). The mesh's
/// chord puts such a vertex beside the crease (across parameters to 0.01
/// off it where the lens is steep, found-84f9858ee9297332), so a crease is
/// recognised in space: within twice the tolerance of `p`. `None` off the
/// creases.
fn on_crease_crossing(
    surface: &NurbsSurface<Vector4>,
    p: DVec3,
    uw: glam::DVec2,
    frame: &Frame,
) -> Option<glam::DVec2> {
    /// How far across a vertex may lie from a crease and still be on it.
    const ACROSS: f64 = 0.05;
    let (u, w) = (uw.x, uw.y);
    let t = [0.0, 1.0].into_iter().find(|t| (u - t).abs() < ACROSS)?;
    let near = 2.0 * frame.tolerance;
    let at = |w: f64| {
        let q = surface.subs(t, w);
        DVec3::new(q.x, q.y, q.z)
    };
    if at(w).distance(p) > near {
        return None;
    }
    let crossing = channels::crease_crossing(frame.channels, surface, glam::DVec2::new(t, w), near);
    // inside the surface's own span (a lens ended in a wall ends there)
    let (_, (first, last)) = truck_modeling::BoundedSurface::range_tuple(surface);
    crossing
        .filter(|&w| (first..=last).contains(&w) && at(w).distance(p) <= near)
        .map(|w| glam::DVec2::new(t, w))
}

/// The lens parameters of every channel vertex (one no device vertex
/// placed) at a run's end on a lens piece that lies on a crease:
/// [`on_crease_crossing`]. Where two vertices of one crease find the same
/// crossing (the mesh's run zigzags across the crease where the exact side
/// crosses it once, found with random design seed 7), neither moves: the
/// edge between them would have no length. A vertex on a device wall
/// ([`Frame::on_walls`]) stays where the lens ends in the wall.
fn crease_crossings(
    pieces: &[Piece<RegionFace>],
    mesh: &Mesh,
    device_vertex: &dyn Fn(u32) -> Option<u32>,
    surfaces: &HashMap<LensRef, NurbsSurface<Vector4>>,
    frame: &Frame,
) -> HashMap<(u32, LensRef), glam::DVec2> {
    let mut found: HashMap<(u32, LensRef), glam::DVec2> = HashMap::new();
    for piece in pieces {
        let RegionFace::Lens(lens) = piece.patch else {
            continue;
        };
        let surface = &surfaces[&lens];
        for v in piece.loops.iter().flatten().map(|run| run.vertices[0]) {
            if device_vertex(v).is_some()
                || frame.on_walls.contains(&v)
                || found.contains_key(&(v, lens))
            {
                continue;
            }
            let p = mesh.positions[v as usize];
            let (u, w) = crate::solid::lens_params(surface, p, frame.tolerance);
            if let Some(uv) = on_crease_crossing(surface, p, glam::DVec2::new(u, w), frame) {
                found.insert((v, lens), uv);
            }
        }
    }
    let shared: Vec<(u32, LensRef)> = found
        .iter()
        .filter(|&(&(v, lens), uv)| {
            found
                .iter()
                .any(|(&(w, other), xy)| w != v && other == lens && uv.distance(*xy) < 1e-9)
        })
        .map(|(&key, _)| key)
        .collect();
    for key in shared {
        found.remove(&key);
    }
    found
}

/// [`Fit`]: each triangle's vertices against the exact surface of its
/// label, and points sampled on the B-rep's faces and on its `edges`
/// (each curve with the mesh run it was built along) against the mesh. A
/// plane known only from the mesh (a corner square, a bump's top, a
/// channel's end) is the one through the first vertex of that label.
fn fit(
    (mesh, labels): (&Mesh, &[RegionFace]),
    frame: &Frame,
    mids: &HashMap<Wall, BSplineCurve<Point3>>,
    (surfaces, device_vertex): (&HashMap<LensRef, NurbsSurface<Vector4>>, DeviceVertex<'_>),
    (edges, tolerance): (&[BuiltEdge], f64),
) -> Fit {
    let mut first_at: HashMap<RegionFace, DVec3> = HashMap::new();
    for (t, &label) in labels.iter().enumerate() {
        first_at
            .entry(label)
            .or_insert(mesh.positions[mesh.triangles[t][0] as usize]);
    }
    let knees: HashMap<Wall, Vec<(f64, f64)>> = mids
        .iter()
        .map(|(&w, mid)| {
            let k = mid
                .control_points()
                .iter()
                .map(|c| (w.along(DVec3::new(c.x, c.y, c.z)), c.z))
                .collect();
            (w, k)
        })
        .collect();
    // the point of `label`'s exact surface that `p` is measured against
    // (None on the device's floor)
    let foot = |label: RegionFace, p: DVec3| -> Option<DVec3> {
        let plane_z = |z: f64| Some(DVec3::new(p.x, p.y, z));
        match label {
            RegionFace::Lens(lens) => {
                let s = &surfaces[&lens];
                let (u, w) = crate::solid::lens_params(s, p, tolerance);
                let q = s.subs(u, w);
                Some(DVec3::new(q.x, q.y, q.z))
            }
            RegionFace::Wall(w) => Some(onto(&frame.outline, w, p)),
            RegionFace::Block(RegionSurface::Side(w)) => Some(onto(&frame.footprint, w, p)),
            RegionFace::Block(RegionSurface::Cap) => plane_z(frame.cap_z),
            RegionFace::Block(RegionSurface::Skirt(w)) => {
                plane_z(polyline_z(&knees[&w], w.along(p)))
            }
            RegionFace::Block(
                RegionSurface::Corner(_) | RegionSurface::BumpTop(_) | RegionSurface::Grid,
            ) => plane_z(first_at[&label].z),
            RegionFace::Block(RegionSurface::BumpSide(k, _)) => {
                let centre = frame.bumps.get(&k)?.centre.extend(p.z);
                let radial = (p - centre).normalize_or_zero();
                Some(centre + bump_radius(frame.bumps[&k], p.z) * radial)
            }
            RegionFace::Block(RegionSurface::Device) => None,
            RegionFace::ChannelSide(k, _) => {
                let c = &frame.channels[k];
                let f = channels::frame(c);
                let axis = f.origin + f.along(p) * f.axis;
                let radial = (p - axis).normalize_or_zero();
                Some(axis + channels::radius_at(c, f.along(p)) * radial)
            }
            RegionFace::ChannelEnd(k) => {
                let f = channels::frame(&frame.channels[k]);
                let h = f.along(p) - f.along(first_at[&label]);
                Some(p - h * f.axis)
            }
        }
    };
    let worst = |a: (f64, DVec3), b: (f64, DVec3)| if b.0 > a.0 { b } else { a };
    // (distance, whose surface, where), folded into the worst of each
    // kind: the mold's, the channels', the device's
    let fold = |items: Vec<(f64, Sampled, DVec3)>| {
        items
            .into_iter()
            .fold([(0.0, DVec3::ZERO); 3], |mut w, (d, kind, p)| {
                w[kind as usize] = worst(w[kind as usize], (d, p));
                w
            })
    };
    // the vertices; a device vertex on a lens is the device B-rep's to measure
    let on_device_lens = |label: RegionFace, v: u32| {
        matches!(label, RegionFace::Lens(_)) && device_vertex(v).is_some()
    };
    let vertices: Vec<(f64, Sampled, DVec3)> = mesh
        .triangles
        .par_iter()
        .zip(labels)
        .flat_map_iter(|(t, &label)| t.map(|v| (label, v)))
        .filter(|&(label, v)| !on_device_lens(label, v))
        .filter_map(|(label, v)| {
            let p = mesh.positions[v as usize];
            let (q, kind) = (foot(label, p)?, Sampled::of(label));
            Some((p.distance(q), kind, p))
        })
        .collect();
    // a lens vertex a channel made is held to the tolerance, as the
    // mold's own are
    let [mold_vertices, (channels_mm, channels_at), lens_vertices] = fold(vertices);
    let (block_mm, block_at) = worst(mold_vertices, lens_vertices);
    // the faces sampled: each triangle's centroid carried onto its face's
    // exact surface, measured against that triangle, and every edge's
    // curve, against its mesh run (upper bounds on the distance to the
    // mesh; the whole mesh is searched only where one is over half the
    // tolerance)
    let grid = std::sync::OnceLock::new();
    let to_mesh = |p: DVec3, bound: f64| {
        if bound > 0.5 * tolerance {
            grid.get_or_init(|| crate::crosscheck::TriangleGrid::new(mesh))
                .distance(p)
        } else {
            bound
        }
    };
    let centroids: Vec<(f64, Sampled, DVec3)> = mesh
        .triangles
        .par_iter()
        .zip(labels)
        .filter_map(|(t, &label)| {
            if t.iter().all(|&v| on_device_lens(label, v)) {
                return None;
            }
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            let (q, kind) = (foot(label, (a + b + c) / 3.0)?, Sampled::of(label));
            let own = q.distance(closest_on_triangle(q, a, b, c));
            Some((to_mesh(q, own), kind, q))
        })
        .collect();
    let edge_distances = edge_distances(mesh, edges, &to_mesh);
    let sampled = centroids.len() + edge_distances.len();
    let [(samples_mm, samples_at), (channel_samples_mm, channel_samples_at), (device_samples_mm, device_samples_at)] =
        fold(centroids.into_iter().chain(edge_distances).collect());
    Fit {
        block_mm,
        block_at,
        channels_mm,
        channels_at,
        samples: sampled,
        samples_mm,
        samples_at,
        channel_samples_mm,
        channel_samples_at,
        device_samples_mm,
        device_samples_at,
    }
}

/// Points along each of `edges` ([`curve_samples`]), with their distance
/// from the mesh run the edge was built along (mesh edges, so it bounds
/// the distance to the mesh from above), passed through `to_mesh` (the
/// whole mesh's distance where that bound is large), and whose surface the
/// edge lies on. The run alone is not enough where an edge ends on a line
/// nearly tangent to it: a 48-gon crosses a skirt's knee line 14 µm from
/// where its exact circle does, near the circle's extreme
/// (found-a489ac3620f261e7), though both lie on the same skirt plane.
fn edge_distances(
    mesh: &Mesh,
    edges: &[BuiltEdge],
    to_mesh: &(dyn Fn(DVec3, f64) -> f64 + Sync),
) -> Vec<(f64, Sampled, DVec3)> {
    edges
        .par_iter()
        .flat_map_iter(|(run, curve, kind)| {
            let segments = RunSegments::new(
                run.windows(2)
                    .map(|w| (mesh.positions[w[0] as usize], mesh.positions[w[1] as usize])),
            );
            curve_samples(curve)
                .into_iter()
                .map(move |p| (to_mesh(p, segments.distance(p)), *kind, p))
        })
        .collect()
}

/// The segments of a mesh run, sorted by their middles along the axis the
/// run spans most, so that a point's nearest segment is found among the
/// few whose extent along that axis comes within the best distance yet.
/// Exact: the same minimum as a scan of every segment (a mid curve has
/// 1,500 segments and as many samples).
struct RunSegments {
    axis: usize,
    /// (middle along `axis`, ends), in increasing middle
    sorted: Vec<(f64, DVec3, DVec3)>,
    /// the largest half-extent of a segment along `axis`
    reach: f64,
}

impl RunSegments {
    fn new(segments: impl Iterator<Item = (DVec3, DVec3)>) -> Self {
        let segments: Vec<(DVec3, DVec3)> = segments.collect();
        let (lo, hi) = segments.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), &(a, b)| (lo.min(a.min(b)), hi.max(a.max(b))),
        );
        let span = hi - lo;
        let axis = if span.x >= span.y && span.x >= span.z {
            0
        } else if span.y >= span.z {
            1
        } else {
            2
        };
        let mut sorted: Vec<(f64, DVec3, DVec3)> = segments
            .iter()
            .map(|&(a, b)| (0.5 * (a[axis] + b[axis]), a, b))
            .collect();
        sorted.sort_by(|x, y| x.0.total_cmp(&y.0));
        let reach = segments
            .iter()
            .map(|&(a, b)| 0.5 * (a[axis] - b[axis]).abs())
            .fold(0.0, f64::max);
        Self {
            axis,
            sorted,
            reach,
        }
    }

    /// The distance from `p` to the nearest segment (infinite for none).
    fn distance(&self, p: DVec3) -> f64 {
        let key = p[self.axis];
        let at = self.sorted.partition_point(|s| s.0 < key);
        let to = |&(_, a, b): &(f64, DVec3, DVec3)| p.distance(closest_on_segment(p, a, b));
        let mut best = self.sorted[at.saturating_sub(1)..(at + 1).min(self.sorted.len())]
            .iter()
            .map(to)
            .fold(f64::INFINITY, f64::min);
        // a segment whose middle lies farther along the axis than best +
        // reach has every point farther than best
        let lo = self
            .sorted
            .partition_point(|s| s.0 < key - best - self.reach);
        let hi = self
            .sorted
            .partition_point(|s| s.0 <= key + best + self.reach);
        for s in &self.sorted[lo..hi] {
            best = best.min(to(s));
        }
        best
    }
}

/// The radius of `bump`'s cone at height `z` (linear between its bottom
/// and top circles).
fn bump_radius(bump: &Bump, z: f64) -> f64 {
    let (a, b) = (bump.bottom[0], bump.top[0]);
    let along = (z - a.z) / (b.z - a.z);
    (a + along * (b - a)).truncate().distance(bump.centre)
}

/// Points along `curve`, where it strays farthest from the mesh points it
/// was built through: the middle of each of its knot spans, and at least
/// 16 evenly spaced.
fn curve_samples(curve: &Curve) -> Vec<DVec3> {
    let knots: Vec<f64> = match curve {
        Curve::BSplineCurve(c) => c.knot_vec().to_vec(),
        Curve::NurbsCurve(c) => c.knot_vec().to_vec(),
        _ => Vec::new(),
    };
    let (t0, t1) = truck_modeling::BoundedCurve::range_tuple(curve);
    let even = (0..=16).map(|i| t0 + (t1 - t0) * i as f64 / 16.0);
    let mids = knots
        .windows(2)
        .filter(|w| w[1] > w[0])
        .map(|w| 0.5 * (w[0] + w[1]));
    even.chain(mids)
        .map(|t| {
            let p = truck_modeling::ParametricCurve::subs(curve, t);
            DVec3::new(p.x, p.y, p.z)
        })
        .collect()
}

/// Puts `p` exactly into the plane of `wall` of `rect`.
fn onto(rect: &Rect, wall: Wall, p: DVec3) -> DVec3 {
    match wall {
        Wall::XMin => DVec3::new(rect.x0, p.y, p.z),
        Wall::XMax => DVec3::new(rect.x1, p.y, p.z),
        Wall::YMin => DVec3::new(p.x, rect.y0, p.z),
        Wall::YMax => DVec3::new(p.x, rect.y1, p.z),
    }
}

/// The mid curve of `wall`: the polyline (a B-spline of degree 1) of the
/// mid-wall points, in increasing along-coordinate, read off the edge
/// between the wall's skirt and the block's side (the mid curve carried
/// out, whole even where a channel cuts the parting line), put back into
/// the wall's plane.
/// It is the parting line the mesh halves are built on, not a curve of
/// the exact model: the mid points of the wall's rungs, which zigzag over
/// the lenses' creases; a cubic through them rounds each corner and moved
/// the parting surface (by 8 mm³ on `plane-rings`, 2e-4 of a half).
fn mid_curve(
    frame: &Frame,
    pieces: &[Piece<RegionFace>],
    wall: Wall,
) -> Option<BSplineCurve<Point3>> {
    let skirt = RegionFace::Block(RegionSurface::Skirt(wall));
    let side = RegionFace::Block(RegionSurface::Side(wall));
    let mut runs = pieces
        .iter()
        .filter(|p| p.patch == side)
        .flat_map(|p| p.loops.iter().flatten())
        .filter(|run| pieces[run.neighbour].patch == skirt);
    let run = runs.next()?;
    if runs.next().is_some() {
        return None;
    }
    let mut pts: Vec<DVec3> = run
        .vertices
        .iter()
        .map(|&v| frame.mesh.positions[v as usize])
        .collect();
    if wall.along(pts[0]) > wall.along(pts[pts.len() - 1]) {
        pts.reverse();
    }
    let pts: Vec<Point3> = pts
        .iter()
        .map(|&p| point3(onto(&frame.outline, wall, p)))
        .collect();
    let s = chord_lengths(
        &pts.iter()
            .map(|p| DVec3::new(p.x, p.y, p.z))
            .collect::<Vec<_>>(),
    );
    let mut knots = vec![s[0]];
    knots.extend_from_slice(&s);
    knots.push(s[s.len() - 1]);
    Some(BSplineCurve::new(KnotVec::from(knots), pts))
}

/// The part of `curve` (a whole mid curve or its copy, a polyline in
/// increasing along-coordinate of `wall`) between the run's first vertex
/// and its last, running from the first to the last. A channel through the
/// parting line leaves only parts of it to an edge.
fn along_run(curve: BSplineCurve<Point3>, wall: Wall, run: &Run, frame: &Frame) -> Curve {
    let at = |v: u32| frame.mesh.positions[v as usize];
    // the polyline's parameter at the point nearest `p`, in the wall's
    // plane (along, z): its knots are its corners' parameters, each
    // corner's repeated once at the ends. (The polyline may rise straight
    // up at a crease, so along alone does not place a point.)
    let knees: Vec<glam::DVec2> = curve
        .control_points()
        .iter()
        .map(|c| glam::DVec2::new(wall.along(DVec3::new(c.x, c.y, c.z)), c.z))
        .collect();
    let knots = curve.knot_vec();
    let param = |p: DVec3| {
        let q = glam::DVec2::new(wall.along(p), p.z);
        let (mut best, mut at) = (f64::INFINITY, knots[0]);
        for i in 1..knees.len() {
            let (k0, k1) = (knees[i - 1], knees[i]);
            let d = k1 - k0;
            let f = if d.length_squared() > 0.0 {
                ((q - k0).dot(d) / d.length_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let gap = q.distance(k0 + f * d);
            if gap < best {
                best = gap;
                at = knots[i] + (knots[i + 1] - knots[i]) * f;
            }
        }
        at
    };
    let (start, end) = (
        param(at(run.vertices[0])),
        param(at(*run.vertices.last().unwrap())),
    );
    let (lo, hi) = (start.min(end), start.max(end));
    let (first, last) = (knots[0], knots[knots.len() - 1]);
    let mut part = curve;
    if lo > first {
        part = part.cut(lo);
    }
    if hi < last {
        let _after = part.cut(hi);
    }
    if start > end {
        part.invert();
    }
    Curve::BSplineCurve(part)
}

/// A mid curve carried out to the block's side beyond its wall.
fn carried_out(frame: &Frame, wall: Wall, mid: &BSplineCurve<Point3>) -> BSplineCurve<Point3> {
    let ctrl: Vec<Point3> = mid
        .control_points()
        .iter()
        .map(|c| point3(onto(&frame.footprint, wall, DVec3::new(c.x, c.y, c.z))))
        .collect();
    BSplineCurve::new(mid.knot_vec().clone(), ctrl)
}

type LensEnds<'s> = Result<(glam::DVec2, glam::DVec2, &'s NurbsSurface<Vector4>), BrepError>;

/// The curve of the edge along `run` between faces on `pair` (this piece's
/// first), from the run's first vertex to its last.
fn edge_curve<'s>(
    frame: &Frame,
    pair: (RegionFace, RegionFace),
    run: &Run,
    lens_ends: &dyn Fn(LensRef) -> LensEnds<'s>,
    mids: &HashMap<Wall, BSplineCurve<Point3>>,
) -> Result<EdgeCurve, BrepError> {
    use RegionFace::{Block, Lens, Wall as DeviceWall};
    let at = |v: u32| frame.mesh.positions[v as usize];
    let pts: Vec<DVec3> = run.vertices.iter().map(|&v| at(v)).collect();
    let line = || Curve::Line(Line(point3(pts[0]), point3(pts[pts.len() - 1])));
    if matches!(
        pair,
        (RegionFace::ChannelSide(..) | RegionFace::ChannelEnd(_), _)
            | (_, RegionFace::ChannelSide(..) | RegionFace::ChannelEnd(_))
    ) {
        // a side's crossing with a lens is curved however few points its
        // run has (a straight one across a lens's sliver lay 1.8 µm off it)
        let on_lens = matches!(
            pair,
            (RegionFace::ChannelSide(..), Lens(_)) | (Lens(_), RegionFace::ChannelSide(..))
        );
        return if collinear(&pts) && !on_lens {
            Ok(line().into())
        } else {
            let curve = channel_edge(frame, pair, &pts, lens_ends, mids)?;
            // a solved end places its vertex, but on a wall
            let ends = [run.vertices[0], run.vertices[run.vertices.len() - 1]];
            let places = ends.map(|v| !frame.on_walls.contains(&v));
            Ok(match on_lens {
                true => EdgeCurve::solved(curve, places),
                false => curve.into(),
            })
        };
    }
    match pair {
        (Lens(lens), Lens(_)) => {
            let (a, b, surface) = lens_ends(lens)?;
            // a channel's vertex on a crease lies on the mesh's chord there,
            // within the tolerance of the crease; the surface's point nearest
            // it lies within that again along the crease. Its across
            // parameter may be far from the crease's where the lens is steep
            // (found-84f9858ee9297332: 0.0101 at 108.7° AFOV), so the ends
            // are held to the crease in space, not in parameter.
            let (_, (first, last)) = truck_modeling::BoundedSurface::range_tuple(surface);
            let near_crease = |t: f64, end: DVec3, along: f64| {
                // a surface ended in a wall ends at or before its wall vertices
                let q = surface.subs(t, along.clamp(first, last));
                end.distance(DVec3::new(q.x, q.y, q.z)) <= 2.0 * frame.tolerance
            };
            let t = [0.0, 1.0]
                .into_iter()
                .find(|&t| near_crease(t, pts[0], a.y) && near_crease(t, pts[pts.len() - 1], b.y))
                .ok_or_else(|| {
                    BrepError::Topology(format!(
                        "{lens:?} meets a lens away from a crease, from {} to {}",
                        pts[0],
                        pts[pts.len() - 1]
                    ))
                })?;
            Ok(EdgeCurve::fixed(Curve::BSplineCurve(crease_curve(
                surface, t, a.y, b.y,
            )?)))
        }
        (Lens(lens), DeviceWall(w)) | (DeviceWall(w), Lens(lens)) => {
            let (a, b, surface) = lens_ends(lens)?;
            match (w, frame.ends_of(lens).end_of(a.y, b.y)) {
                (Wall::YMin | Wall::YMax, Some(end)) => {
                    let sides = [Wall::XMin, Wall::XMax].map(|w| frame.wall_plane(w));
                    let ends_at = [pts[0], pts[pts.len() - 1]];
                    Ok(EdgeCurve::fixed(iso_edge(
                        surface,
                        end,
                        RunEnds {
                            t: [a.x, b.x],
                            at: ends_at,
                        },
                        &sides,
                        frame.tolerance,
                    )))
                }
                _ => Ok(
                    Curve::BSplineCurve(cubic_through(&pts, |p| onto(&frame.outline, w, p))).into(),
                ),
            }
        }
        (DeviceWall(w), Block(RegionSurface::Skirt(_)))
        | (Block(RegionSurface::Skirt(_)), DeviceWall(w)) => {
            Ok(along_run(mids[&w].clone(), w, run, frame).into())
        }
        (Block(RegionSurface::Skirt(w)), Block(RegionSurface::Side(_)))
        | (Block(RegionSurface::Side(_)), Block(RegionSurface::Skirt(w))) => {
            Ok(along_run(carried_out(frame, w, &mids[&w]), w, run, frame).into())
        }
        (Block(RegionSurface::BumpSide(k, _)), Block(_))
        | (Block(_), Block(RegionSurface::BumpSide(k, _)))
            if !collinear(&pts) =>
        {
            let bump = frame.bumps.get(&k).ok_or_else(|| {
                BrepError::Topology(format!("corner square {k} has a bump side but no bump"))
            })?;
            Ok(arc(bump, &pts).into())
        }
        // wall corners, skirt ends, a bump's seams, the corner squares',
        // the sides' and the cap's edges: straight
        _ if collinear(&pts) => Ok(line().into()),
        (a, b) => Err(BrepError::Topology(format!(
            "no edge curve for {a:?} against {b:?} along {} points",
            pts.len()
        ))),
    }
}

/// The curve of an edge of a channel's side or end along the mesh points
/// `pts` (from the run's first vertex to its last), between the faces on
/// `pair`: a circle where a side crosses a plane across its axis, else the
/// cubic through points solved onto both exact surfaces
/// ([`channels::solve_on_side`]), broken where the skirt has a crease.
fn channel_edge<'s>(
    frame: &Frame,
    pair: (RegionFace, RegionFace),
    pts: &[DVec3],
    lens_ends: &dyn Fn(LensRef) -> LensEnds<'s>,
    mids: &HashMap<Wall, BSplineCurve<Point3>>,
) -> Result<Curve, BrepError> {
    use RegionFace::{Block, ChannelEnd, ChannelSide, Lens, Wall as DeviceWall};
    let shapes = frame.channels;
    let vertical = |k: usize| matches!(shapes[k].axis, ChannelAxis::Vertical(_));
    let refuse = || {
        BrepError::Topology(format!(
            "no edge curve for {:?} against {:?} along {} points",
            pair.0,
            pair.1,
            pts.len()
        ))
    };
    let (k, other) = match pair {
        (ChannelSide(k, _), o) | (o, ChannelSide(k, _)) => (k, o),
        _ => return Err(refuse()),
    };
    if let Lens(lens) = other {
        let (a, b, surface) = lens_ends(lens)?;
        return side_across_lens(&shapes[k], pts, surface, [a, b], frame.tolerance);
    }
    let fk = channels::frame(&shapes[k]);
    let section = || Ok(channels::section_arc(&shapes[k], fk.along(pts[0]), pts));
    // planes across the axis, and coaxial sides: circles
    match other {
        Block(
            RegionSurface::Cap
            | RegionSurface::Corner(_)
            | RegionSurface::BumpTop(_)
            | RegionSurface::Grid,
        ) if vertical(k) => return section(),
        ChannelEnd(j) if channels::frame(&shapes[j]).axis.dot(fk.axis).abs() > 1.0 - 1e-12 => {
            return section()
        }
        ChannelSide(j, _) if vertical(k) && vertical(j) => {
            let fj = channels::frame(&shapes[j]);
            if fj.origin.distance(fk.origin) < 1e-9 {
                return section();
            }
        }
        DeviceWall(w) | Block(RegionSurface::Side(w))
            if w.outward().extend(0.0).dot(fk.axis).abs() > 1.0 - 1e-12 =>
        {
            return section()
        }
        _ => {}
    }
    // planes along the axis: the side's straight generators (far from the
    // origin f32 rounding can bend the mesh's run past `collinear`)
    let along_axis = |n: DVec3| n.dot(fk.axis).abs() < 1e-12;
    let line = || {
        Ok(Curve::Line(Line(
            point3(pts[0]),
            point3(pts[pts.len() - 1]),
        )))
    };
    match other {
        DeviceWall(w) | Block(RegionSurface::Side(w)) if along_axis(w.outward().extend(0.0)) => {
            return line()
        }
        Block(
            RegionSurface::Cap
            | RegionSurface::Corner(_)
            | RegionSurface::BumpTop(_)
            | RegionSurface::Grid,
        ) if along_axis(DVec3::Z) => return line(),
        ChannelEnd(j) if along_axis(channels::frame(&shapes[j]).axis) => return line(),
        _ => {}
    }
    // a vertical side against the runner: solved on the runner, whose
    // lines along its axis cross the vertical side at an angle
    let (k, other) = match other {
        ChannelSide(j, h) if vertical(k) && !vertical(j) => (j, ChannelSide(k, h)),
        _ => (k, other),
    };
    let (shape, f) = (&shapes[k], channels::frame(&shapes[k]));
    let z_at = pts[0].z;
    let plane_normal = |w: Wall| w.outward().extend(0.0);
    let mut breaks = Vec::new();
    let implicit: Box<dyn Fn(DVec3) -> f64> = match other {
        DeviceWall(w) | Block(RegionSurface::Side(w)) => {
            let (o, n) = (pts[0], plane_normal(w));
            Box::new(move |x: DVec3| (x - o).dot(n))
        }
        Block(RegionSurface::Skirt(w)) => {
            let mid = &mids[&w];
            let knees: Vec<(f64, f64)> = mid
                .control_points()
                .iter()
                .map(|c| (w.along(DVec3::new(c.x, c.y, c.z)), c.z))
                .collect();
            breaks = pts
                .iter()
                .enumerate()
                .filter(|(_, &p)| {
                    let t = w.along(p);
                    knees.iter().any(|&(a, _)| (a - t).abs() < 1e-9)
                })
                .map(|(i, _)| i)
                .collect();
            if vertical(k) && shape.radii.0 == shape.radii.1 {
                if let Some(curve) = skirt_ellipse(shape, w, &knees, pts, &breaks) {
                    return Ok(curve);
                }
            }
            Box::new(move |x: DVec3| x.z - polyline_z(&knees, w.along(x)))
        }
        Block(
            RegionSurface::Cap
            | RegionSurface::Corner(_)
            | RegionSurface::BumpTop(_)
            | RegionSurface::Grid,
        ) => Box::new(move |x: DVec3| x.z - z_at),
        ChannelSide(j, _) => {
            let (sj, fj) = (shapes[j], channels::frame(&shapes[j]));
            Box::new(move |x: DVec3| fj.distance(x) - channels::radius_at(&sj, fj.along(x)))
        }
        ChannelEnd(j) => {
            let fj = channels::frame(&shapes[j]);
            let h = fj.along(pts[0]);
            Box::new(move |x: DVec3| fj.along(x) - h)
        }
        _ => return Err(refuse()),
    };
    let on_other = channels::Other::Implicit(&*implicit);
    let solved = pts
        .iter()
        .map(|&p| channels::solve_on_side(shape, &f, &on_other, p))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(channels::piecewise_cubic(&solved, &breaks))
}

/// Where the side of channel `shape` crosses a lens, along the mesh points
/// `pts`: the cubic through points solved onto both, refined to
/// [`channels::EDGE_SHARE`] of the `tolerance`, whose ends on a crease are
/// the crease's crossings with the side (the lens's parameters there, the
/// run's `ends`, are solved so by [`on_crease_crossing`]).
fn side_across_lens(
    shape: &ChannelShape,
    pts: &[DVec3],
    surface: &NurbsSurface<Vector4>,
    ends: [glam::DVec2; 2],
    tolerance: f64,
) -> Result<Curve, BrepError> {
    let f = channels::frame(shape);
    let on_lens = channels::Other::Lens(surface, tolerance);
    let solve = |p| channels::solve_on_side(shape, &f, &on_lens, p);
    let mut solved = pts
        .iter()
        .map(|&p| solve(p))
        .collect::<Result<Vec<_>, _>>()?;
    let last = solved.len() - 1;
    for (i, end) in [(0, ends[0]), (last, ends[1])] {
        if end.x == 0.0 || end.x == 1.0 {
            let q = surface.subs(end.x, end.y);
            solved[i] = DVec3::new(q.x, q.y, q.z);
        }
    }
    channels::refined_cubic(solved, solve, channels::EDGE_SHARE * tolerance)
}

/// Where a vertical cylinder `shape` crosses wall `w`'s skirt along the
/// mesh points `pts`, broken at `breaks` (the points on the skirt's knees):
/// exact ellipse arcs. Each strip of the skirt between two knees is a
/// plane, and lifting the plane z = 0 onto it keeps x and y, an affine map,
/// so the circle of the side lifted onto the strip is the exact curve
/// where the two meet ([`channels::lifted_arc`]). The arcs meet at the
/// circle's exact crossings with the knee lines. `None` where a piece of
/// `pts` does not lie on one strip (left to the solved cubic).
fn skirt_ellipse(
    shape: &ChannelShape,
    w: Wall,
    knees: &[(f64, f64)],
    pts: &[DVec3],
    breaks: &[usize],
) -> Option<Curve> {
    let f = channels::frame(shape);
    let r = shape.radii.0;
    let along_axis = match w {
        Wall::XMin | Wall::XMax => DVec3::Y,
        Wall::YMin | Wall::YMax => DVec3::X,
    };
    let across = DVec3::Z.cross(along_axis);
    let centre = DVec3::new(f.origin.x, f.origin.y, 0.0);
    // the circle's point on knee line `a` nearest `p`
    let on_knee = |a: f64, p: DVec3| {
        let d = a - w.along(centre);
        let s = (r * r - d * d).max(0.0).sqrt();
        let side = if (p - centre).dot(across) >= 0.0 {
            s
        } else {
            -s
        };
        centre + d * along_axis + side * across
    };
    let knee_near = |t: f64| {
        knees
            .iter()
            .map(|&(a, _)| a)
            .min_by(|x, y| (x - t).abs().total_cmp(&(y - t).abs()))
    };
    let bounds = channels::piece_bounds(pts.len(), breaks);
    let mut arcs = Vec::new();
    for (n, pair) in bounds.windows(2).enumerate() {
        let mut piece = pts[pair[0]..=pair[1]].to_vec();
        let last = piece.len() - 1;
        if n > 0 {
            piece[0] = on_knee(knee_near(w.along(piece[0]))?, piece[0]);
        }
        if n + 2 < bounds.len() {
            piece[last] = on_knee(knee_near(w.along(piece[last]))?, piece[last]);
        }
        // the strip holding the piece: z = z0 + slope (along - a0)
        let mid = w.along(piece[last / 2]);
        let i = knees.partition_point(|&(a, _)| a <= mid);
        let (a_lo, a_hi, z0, slope) = if i == 0 {
            (f64::NEG_INFINITY, knees[0].0, knees[0].1, 0.0)
        } else if i == knees.len() {
            (knees[i - 1].0, f64::INFINITY, knees[i - 1].1, 0.0)
        } else {
            let ((a0, z0), (a1, z1)) = (knees[i - 1], knees[i]);
            (
                a0,
                a1,
                z0 - (z1 - z0) / (a1 - a0) * a0,
                (z1 - z0) / (a1 - a0),
            )
        };
        let slack = 1e-6;
        if piece
            .iter()
            .any(|&p| w.along(p) < a_lo - slack || w.along(p) > a_hi + slack)
        {
            return None;
        }
        let arc = channels::circle_arc(centre, (DVec3::X, DVec3::Y), r, &piece);
        arcs.push(channels::lifted_arc(arc, |p| z0 + slope * w.along(p)));
    }
    Some(channels::join_arcs(arcs))
}

/// The height of the polyline `knees` ((along, z), in increasing along) at
/// `t`, held level past its ends.
fn polyline_z(knees: &[(f64, f64)], t: f64) -> f64 {
    let i = knees.partition_point(|&(a, _)| a <= t);
    if i == 0 {
        return knees[0].1;
    }
    if i == knees.len() {
        return knees[knees.len() - 1].1;
    }
    let ((a0, z0), (a1, z1)) = (knees[i - 1], knees[i]);
    z0 + (z1 - z0) * (t - a0) / (a1 - a0)
}

/// Whether `pts` lie on the segment between the first and the last, to
/// round-off of the f32 positions.
fn collinear(pts: &[DVec3]) -> bool {
    let (a, b) = (pts[0], pts[pts.len() - 1]);
    let d = (b - a).normalize_or_zero();
    pts.iter()
        .all(|&p| ((p - a) - (p - a).dot(d) * d).length() <= 1e-5)
}

/// The plane through `o` whose normal is `normal`'s (a unit axis).
fn plane(o: DVec3, normal: DVec3) -> Surface {
    let a = if normal.x.abs() > 0.5 {
        DVec3::Y
    } else {
        DVec3::X
    };
    let a = (a - a.dot(normal) * normal).normalize();
    let b = normal.cross(a);
    Surface::Plane(Plane::new(point3(o), point3(o + a), point3(o + b)))
}

fn make_face(
    frame: &Frame,
    piece: &Piece<RegionFace>,
    wires: Vec<Wire>,
    params: &dyn Fn(u32, LensRef) -> Result<glam::DVec2, BrepError>,
    surfaces: &HashMap<LensRef, NurbsSurface<Vector4>>,
    mids: &HashMap<Wall, BSplineCurve<Point3>>,
) -> Result<Face, BrepError> {
    let refuse = |e: truck_topology::errors::Error| BrepError::Truck {
        what: "region face",
        detail: format!("{:?}: {e}", piece.patch),
    };
    let tri = frame.mesh.triangles[piece.triangle as usize];
    let [p0, p1, p2] = tri.map(|v| frame.mesh.positions[v as usize]);
    let outward = (p1 - p0).cross(p2 - p0);
    // a plane, facing the axis direction the piece's triangle faces
    let axis_plane = |o: DVec3| {
        let n = outward.normalize();
        let axis = [DVec3::X, DVec3::Y, DVec3::Z]
            .into_iter()
            .max_by(|a, b| a.dot(n).abs().total_cmp(&b.dot(n).abs()))
            .expect("three axes");
        plane(o, axis * axis.dot(n).signum())
    };
    let (fp, out) = (frame.footprint, frame.outline);
    let surface = match piece.patch {
        RegionFace::Lens(lens) => {
            let (a, b, c) = (
                params(tri[0], lens)?,
                params(tri[1], lens)?,
                params(tri[2], lens)?,
            );
            let span = boundary_span(piece, |v| params(v, lens))?;
            let surface = cut_to_span(&surfaces[&lens], span);
            return surface_face(surface, outward, (a + b + c) / 3.0, wires).map_err(refuse);
        }
        RegionFace::Wall(w) => axis_plane(onto(&out, w, p0)),
        RegionFace::Block(RegionSurface::Side(w)) => axis_plane(onto(&fp, w, p0)),
        RegionFace::Block(RegionSurface::Cap) => axis_plane(DVec3::new(p0.x, p0.y, frame.cap_z)),
        RegionFace::Block(RegionSurface::Corner(_) | RegionSurface::BumpTop(_))
        | RegionFace::ChannelEnd(_) => axis_plane(p0),
        RegionFace::ChannelSide(k, _) => {
            let shape = &frame.channels[k];
            let side = channels::side_surface(shape);
            let natural_is_outward =
                channels::natural_is_outward(&side, &channels::frame(shape), outward, p0);
            return face_facing(
                Surface::RevolutedCurve(Processor::new(side)),
                natural_is_outward,
                wires,
            )
            .map_err(refuse);
        }
        RegionFace::Block(RegionSurface::BumpSide(k, _)) => {
            let bump = frame.bumps.get(&k).ok_or_else(|| {
                BrepError::Topology(format!("corner square {k} has a bump side but no bump"))
            })?;
            let cone = cone(bump);
            // the natural normal at a point of this piece, against its
            // triangle's (both horizontal parts point off the axis or onto it)
            let off_axis = |n: DVec3, at: DVec3| (at - bump.centre.extend(at.z)).dot(n);
            let nat = cone.normal(0.5, 0.0);
            let at = cone.subs(0.5, 0.0);
            let natural_is_outward = off_axis(
                DVec3::new(nat.x, nat.y, nat.z),
                DVec3::new(at.x, at.y, at.z),
            ) * off_axis(outward, p0)
                > 0.0;
            return face_facing(
                Surface::RevolutedCurve(Processor::new(cone)),
                natural_is_outward,
                wires,
            )
            .map_err(refuse);
        }
        RegionFace::Block(RegionSurface::Skirt(w)) => {
            let mid = &mids[&w];
            let out = carried_out(frame, w, mid);
            let skirt = BSplineSurface::new(
                (mid.knot_vec().clone(), KnotVec::bezier_knot(1)),
                mid.control_points()
                    .iter()
                    .zip(out.control_points())
                    .map(|(&a, &b)| vec![a, b])
                    .collect(),
            );
            let nat = skirt.normal(
                0.5 * (mid.knot_vec()[0] + mid.knot_vec()[mid.knot_vec().len() - 1]),
                0.5,
            );
            // a graph over xy: its normal's z decides
            return face_facing(
                Surface::BSplineSurface(skirt),
                nat.z * outward.z > 0.0,
                wires,
            )
            .map_err(refuse);
        }
        RegionFace::Block(other) => {
            return Err(BrepError::Topology(format!(
                "no exact surface for a region's {other:?} yet"
            )))
        }
    };
    Face::try_new(wires, surface).map_err(refuse)
}

/// A bump's cone: its first side edge, extended a tenth beyond both
/// rings, turned about its vertical axis.
fn cone(bump: &Bump) -> RevolutedCurve<Curve> {
    let (a, b) = (bump.bottom[0], bump.top[0]);
    let (a, b) = (a - 0.1 * (b - a), b + 0.1 * (b - a));
    RevolutedCurve::by_revolution(
        Curve::Line(Line(point3(a), point3(b))),
        point3(bump.centre.extend(0.0)),
        Vector3::unit_z(),
    )
}

/// The arc of a bump's circle through `pts` (on one horizontal circle
/// about its axis, in order), from the first to the last: its radius where
/// the cone's side edges cross that height.
fn arc(bump: &Bump, pts: &[DVec3]) -> Curve {
    let z = pts[0].z;
    let (a, b) = (bump.bottom[0], bump.top[0]);
    let along = (z - a.z) / (b.z - a.z);
    let r = (a + along * (b - a)).truncate().distance(bump.centre);
    Curve::NurbsCurve(channels::circle_arc(
        bump.centre.extend(z),
        (DVec3::X, DVec3::Y),
        r,
        pts,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use moirecast_kernel::{mesher::mesh_device, progress::Silent, DesignParams, PitchSurface};
    use moirecast_mold::parting::{Floor, PartSide};

    /// A regular 48-gon frustum standing on the middle of the square from
    /// `corner` (the block's) to `inner` (the outline's) at height `z`,
    /// its rings in f32 as manifold's are.
    fn bump(corner: (f64, f64), inner: (f64, f64), z: f64) -> Bump {
        let c = glam::DVec2::new(0.5 * (corner.0 + inner.0), 0.5 * (corner.1 + inner.1));
        let ring = |r: f64, z: f64| -> Vec<DVec3> {
            (0..48)
                .map(|k| {
                    let t = std::f64::consts::TAU * (k as f64 + 0.25) / 48.0;
                    DVec3::new(c.x + r * t.cos(), c.y + r * t.sin(), z)
                        .as_vec3()
                        .as_dvec3()
                })
                .collect()
        };
        Bump {
            centre: c,
            bottom: ring(1.2, z - 1.0),
            top: ring(0.8, z + 1.5),
        }
    }

    /// A 10 × 8 mm cylinder's design (lenses of 0.5 mm) and its device mesh.
    fn small_cylinder() -> (Design, DeviceMesh) {
        let mut params =
            DesignParams::with_defaults(PitchSurface::Cylinder { radius: -40.0 }, 10.0, 8.0, 0.5);
        params.tolerance = 0.01;
        let design = Design::new(params).unwrap();
        let dm = mesh_device(&design, &Silent).unwrap();
        (design, dm)
    }

    /// The tessellation the region B-reps' volumes are measured by: fine,
    /// so that its own chords (at most this far inside the exact faces)
    /// stay well below the device mesh's.
    const TESSELLATION: f64 = 0.001;

    /// How far an exact region's volume may lie from its mesh's: the device
    /// mesh's lens chords stray up to the design's tolerance from the exact
    /// lenses, and the tessellation's as far as [`TESSELLATION`], over the
    /// lens faces' area; each bump's 48-gon frustum holds less than its
    /// cone by the polygon's share of the circle.
    fn chord_bound(design: &Design, posed: &PosedDevice, region: &Region, bumps: &[Bump]) -> f64 {
        let lens_area: f64 = region
            .mesh
            .triangles
            .iter()
            .zip(&region.surfaces)
            .enumerate()
            .filter(|(t, (_, s))| {
                **s == RegionSurface::Device
                    && !matches!(
                        posed.faces[region.device_faces[*t] as usize],
                        parting::Face::Wall(_)
                    )
            })
            .map(|(_, (t, _))| {
                let [a, b, c] = t.map(|i| region.mesh.positions[i as usize]);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum();
        let n = 48.0;
        let polygon_share = n / std::f64::consts::TAU * (std::f64::consts::TAU / n).sin();
        let cones: f64 = bumps
            .iter()
            .map(|k| {
                let (r0, r1) = (bump_radius(k, k.bottom[0].z), bump_radius(k, k.top[0].z));
                let h = k.top[0].z - k.bottom[0].z;
                std::f64::consts::PI * h / 3.0 * (r0 * r0 + r0 * r1 + r1 * r1)
            })
            .sum();
        lens_area * (design.params.tolerance + TESSELLATION) + cones * (1.0 - polygon_share)
    }

    /// Both parting regions of a small cylinder's device, flipped and not,
    /// the lower one with a key's bump on each corner square: each B-rep
    /// is one closed shell of genus 0 (V − E + F − rings = 2) with the faces the
    /// labels give (the device's lens faces on its side, 4 wall parts, 4
    /// skirts, 4 corner squares, 4 sides, the cap; and 3 per bump), and
    /// truck's own tessellation of it (unflipped) encloses the region
    /// mesh's volume to the lens chords' and the bumps' 48-gons' bound
    /// ([`chord_bound`]).
    #[test]
    fn a_plain_region_is_one_closed_exact_solid() {
        let (design, dm) = small_cylinder();
        let device = crate::build_brep(&design, &dm).unwrap().stats;
        for flip in [false, true] {
            let posed = PosedDevice::new(&design, &dm, flip, 1.0).unwrap();
            let walls = parting::wall_curves(&posed).unwrap();
            let f32_rect = |r: Rect| Rect {
                x0: r.x0 as f32 as f64,
                x1: r.x1 as f32 as f64,
                y0: r.y0 as f32 as f64,
                y1: r.y1 as f32 as f64,
            };
            let (o, fp) = (posed.outline, f32_rect(posed.outline.grown(4.0)));
            let z = posed.mesh.positions.iter().map(|p| p.z);
            let (lo, hi) = z.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
                (lo.min(z), hi.max(z))
            });
            let corner_z = |x: f64, y: f64| {
                walls
                    .iter()
                    .flat_map(|w| &w.mid_points)
                    .find(|p| p.x == x && p.y == y)
                    .expect("a corner's mid point")
                    .z
            };
            let bumps: Vec<Bump> = [
                ((fp.x0, fp.y0), (o.x0, o.y0)),
                ((fp.x1, fp.y0), (o.x1, o.y0)),
                ((fp.x1, fp.y1), (o.x1, o.y1)),
                ((fp.x0, fp.y1), (o.x0, o.y1)),
            ]
            .map(|(c, i)| bump(c, i, corner_z(i.0, i.1)))
            .into();
            for (side, cap, with) in [
                (PartSide::Above, (hi + 3.0) as f32 as f64, &[][..]),
                (PartSide::Below, (lo - 3.0) as f32 as f64, &bumps[..]),
            ] {
                let region =
                    parting::parting_region(&walls, Floor::Device(&posed), &fp, cap, side, with);
                let b = region_brep(&design, &dm, &posed, &region, (fp, cap), with)
                    .unwrap_or_else(|e| panic!("flip {flip}, {side:?}: {e}"));
                let revealer_side = (side == PartSide::Above) != flip;
                let lens_faces = if revealer_side {
                    device.revealer_faces
                } else {
                    device.base_faces
                };
                assert_eq!(
                    b.faces,
                    lens_faces + 17 + 3 * with.len(),
                    "flip {flip}, {side:?}"
                );
                assert_eq!(b.rings, with.len(), "flip {flip}, {side:?}");
                assert_eq!(
                    b.vertices + b.faces,
                    b.edges + b.rings + 2,
                    "flip {flip}, {side:?}"
                );
                if flip {
                    // the same surfaces, turned: the volumes once suffice
                    continue;
                }
                let tessellated = crate::tessellate(&b.solid, TESSELLATION).unwrap().volume();
                let mesh = region.mesh.volume();
                let bound = chord_bound(&design, &posed, &region, with);
                assert!(
                    (tessellated - mesh).abs() <= bound,
                    "flip {flip}, {side:?}: {tessellated} against {mesh}, more than {bound} apart"
                );
            }
        }
    }

    /// The cut halves of a small cylinder's mold (gate, runner, sprue and
    /// pour cone, vents, keys' bumps and sockets): each B-rep is one closed
    /// shell whose Euler–Poincaré count has the half's genus, and truck's
    /// own tessellation of it encloses the mesh half's volume to 1e-4 (the
    /// channels' 48-gons and the lens chords differ by less). Their STEP
    /// texts pass the halves' checks, are deterministic, and read back.
    #[test]
    fn the_cut_halves_are_closed_exact_solids() {
        let (design, dm) = small_cylinder();
        let mold = moirecast_mold::build_mold(
            &design,
            &dm,
            &moirecast_mold::MoldParams::default(),
            &Silent,
        )
        .unwrap();
        let device = crate::build_brep(&design, &dm).unwrap();
        for (top, genus, mesh) in [
            (true, mold.genus_top, mold.top.mesh()),
            (false, mold.genus_bottom, mold.bottom.mesh()),
        ] {
            let b = half_brep(&design, &dm, &mold, (&device, top))
                .unwrap_or_else(|e| panic!("top {top}: {e}"));
            let chi = b.vertices as i64 + b.faces as i64 - b.edges as i64 - b.rings as i64;
            assert_eq!(chi, 2 * (1 - genus as i64), "top {top}");
            let tessellated = crate::tessellate(&b.solid, 0.005).unwrap().volume();
            let volume = mesh.volume();
            eprintln!(
                "top {top}: {} faces, {tessellated} against {volume}",
                b.faces
            );
            assert!(
                (tessellated / volume - 1.0).abs() < 1e-4,
                "top {top}: {tessellated} against {volume}"
            );
        }
        // the STEP texts: every check passes, the same bytes on every
        // build, and truck-stepio reads back one shell of the faces built
        let texts = |m: &crate::MoldStep| (m.top_step.to_text(), m.bottom_step.to_text());
        let first = crate::mold_step(&design, &dm, &mold, &device).unwrap();
        for c in &first.checks {
            assert!(
                c.passed,
                "{}: {} against {} ({})",
                c.name, c.value, c.limit, c.detail
            );
        }
        let again = crate::mold_step(&design, &dm, &mold, &device).unwrap();
        assert!(
            texts(&first) == texts(&again),
            "the STEP texts differ between builds"
        );
        let (top_text, bottom_text) = texts(&first);
        assert_eq!(
            crate::read_back_faces(&top_text).unwrap(),
            vec![first.top.faces]
        );
        assert_eq!(
            crate::read_back_faces(&bottom_text).unwrap(),
            vec![first.bottom.faces]
        );
    }
}
