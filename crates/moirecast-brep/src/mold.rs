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

use crate::error::BrepError;
use crate::solid::{
    assemble, closed_solid, crease_curve, face_facing, lens_families, point3, surface_face,
};
use crate::spline::{chord_lengths, clamped_knots, interpolate};
use crate::topology::{pieces, Piece, Run};
use glam::{DAffine3, DVec3};
use moirecast_kernel::mesher::Patch;
use moirecast_kernel::model::LensRef;
use moirecast_kernel::{Design, DeviceMesh};
use moirecast_mold::parting::{self, Bump, PosedDevice, Rect, Region, RegionSurface, Wall};
use std::collections::HashMap;
use truck_modeling::{
    BSplineCurve, BSplineSurface, Curve, Face, KnotVec, Line, Matrix4, NurbsCurve, NurbsSurface,
    ParametricSurface, ParametricSurface3D, Plane, Point3, Processor, RevolutedCurve, Solid,
    Surface, Transformed, Vector3, Vector4, Wire,
};

/// What a face of a region's B-rep lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RegionFace {
    Lens(LensRef),
    /// A device wall, up to (or down to) the mid-wall curve.
    Wall(Wall),
    /// Any surface of the region that is not the device's.
    Block(RegionSurface),
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
}

/// The region's geometry beside its mesh: where its planes lie.
struct Frame<'a> {
    outline: Rect,
    footprint: Rect,
    cap_z: f64,
    mesh: &'a moirecast_kernel::Mesh,
    /// The bump standing on each corner square that has one.
    bumps: HashMap<usize, &'a Bump>,
}

/// The truck matrix of an affine map of points.
pub(crate) fn matrix_of(map: DAffine3) -> Matrix4 {
    let m = map.to_cols_array();
    Matrix4::new(
        m[0], m[1], m[2], 0.0, m[3], m[4], m[5], 0.0, m[6], m[7], m[8], 0.0, m[9], m[10], m[11],
        1.0,
    )
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
    let labels: Vec<RegionFace> = region
        .surfaces
        .iter()
        .enumerate()
        .map(|(t, surface)| match surface {
            RegionSurface::Device => {
                let posed_t = region.device_faces[t] as usize;
                match (posed.patches[posed_t], posed.faces[posed_t]) {
                    (Patch::Lens(lens), _) => RegionFace::Lens(lens),
                    (Patch::Wall(_), parting::Face::Wall(w)) => RegionFace::Wall(w),
                    (Patch::Wall(_), face) => unreachable!("a wall triangle posed as {face:?}"),
                }
            }
            other => RegionFace::Block(*other),
        })
        .collect();
    let (pieces, families) = rayon::join(
        || pieces(&region.mesh, &labels),
        || lens_families(design, dm),
    );
    let (pieces, (revealer, base)) = (pieces?, families?);
    let matrix = matrix_of(posed.pose.affine());
    let posed_surfaces: HashMap<LensRef, NurbsSurface<Vector4>> = revealer
        .surfaces
        .iter()
        .map(|(&i, s)| (LensRef::Revealer(i), s.transformed(matrix)))
        .chain(
            base.surfaces
                .iter()
                .map(|(&k, s)| (LensRef::Base(k), s.transformed(matrix))),
        )
        .collect();
    // each square's bump: the one nearest a triangle of its top
    let bumps: HashMap<usize, &Bump> = pieces
        .iter()
        .filter_map(|piece| match piece.patch {
            RegionFace::Block(RegionSurface::BumpTop(k)) => {
                let p = region.mesh.positions
                    [region.mesh.triangles[piece.triangle as usize][0] as usize];
                let nearest = bumps.iter().min_by(|a, b| {
                    let d = |b: &Bump| b.centre.distance(p.truncate());
                    d(a).total_cmp(&d(b))
                })?;
                Some((k, nearest))
            }
            _ => None,
        })
        .collect();
    let frame = Frame {
        outline: posed.outline,
        footprint,
        cap_z,
        mesh: &region.mesh,
        bumps,
    };
    // the device vertex a region vertex is, for its lens parameters
    let device_vertex = |v: u32| -> Option<usize> {
        let p = *region.device_vertices.get(v as usize)?;
        (p != u32::MAX && (p as usize) < dm.mesh.positions.len()).then_some(p as usize)
    };
    let params = |v: u32, lens: LensRef| -> Result<glam::DVec2, BrepError> {
        device_vertex(v)
            .and_then(|d| dm.origins[d].params_on(lens))
            .ok_or_else(|| {
                BrepError::Topology(format!("region vertex {v} has no parameters on {lens:?}"))
            })
    };
    let mid_curves: HashMap<Wall, BSplineCurve<Point3>> = Wall::ALL
        .iter()
        .map(|&w| Some((w, mid_curve(&frame, &pieces, w)?)))
        .collect::<Option<_>>()
        .ok_or_else(|| BrepError::Topology("a wall has no mid curve".into()))?;
    let assembled = assemble(
        &pieces,
        &region.mesh.positions,
        |piece| !matches!(piece.patch, RegionFace::Lens(_)),
        |piece, other, run| {
            edge_curve(
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
            )
        },
        |piece, wires| make_face(&frame, piece, wires, &params, &posed_surfaces, &mid_curves),
    )?;
    let faces = assembled.faces.len();
    let rings = pieces.iter().map(|p| p.loops.len() - 1).sum();
    let solid = closed_solid(assembled.faces, ("region shell", "region solid"))?;
    Ok(RegionBrep {
        solid,
        faces,
        edges: assembled.edges,
        vertices: assembled.vertices,
        rings,
    })
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

/// The C² cubic through `pts` (in order), each put into the plane of
/// `wall` of `rect`.
fn cubic_in_wall(rect: &Rect, wall: Wall, pts: &[DVec3]) -> BSplineCurve<Point3> {
    let pts: Vec<DVec3> = pts.iter().map(|&p| onto(rect, wall, p)).collect();
    let s = chord_lengths(&pts);
    let data: Vec<[f64; 3]> = pts.iter().map(|p| p.to_array()).collect();
    let ctrl: Vec<Point3> = interpolate(&s, &data)
        .into_iter()
        .map(|c| point3(onto(rect, wall, DVec3::from_array(c))))
        .collect();
    BSplineCurve::new(clamped_knots(&s), ctrl)
}

/// The mid curve of `wall`: the polyline (a B-spline of degree 1) of the
/// run between its wall face and its skirt, in increasing along-coordinate.
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
    let run = pieces
        .iter()
        .filter(|p| p.patch == RegionFace::Wall(wall))
        .find_map(|p| {
            p.loops
                .iter()
                .flatten()
                .find(|run| pieces[run.neighbour].patch == skirt)
        })?;
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

/// `curve` (a whole mid curve or its copy) running from the run's first
/// vertex to its last.
fn along_run(mut curve: BSplineCurve<Point3>, wall: Wall, run: &Run, frame: &Frame) -> Curve {
    let at = |v: u32| frame.mesh.positions[v as usize];
    if wall.along(at(run.vertices[0])) > wall.along(at(*run.vertices.last().unwrap())) {
        curve.invert();
    }
    Curve::BSplineCurve(curve)
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
) -> Result<Curve, BrepError> {
    use RegionFace::{Block, Lens, Wall as DeviceWall};
    let at = |v: u32| frame.mesh.positions[v as usize];
    let pts: Vec<DVec3> = run.vertices.iter().map(|&v| at(v)).collect();
    let line = || Curve::Line(Line(point3(pts[0]), point3(pts[pts.len() - 1])));
    match pair {
        (Lens(lens), Lens(_)) => {
            let (a, b, surface) = lens_ends(lens)?;
            let t = [0.0, 1.0]
                .into_iter()
                .find(|&t| a.x == t && b.x == t)
                .ok_or_else(|| {
                    BrepError::Topology(format!("{lens:?} meets a lens away from a crease"))
                })?;
            Ok(Curve::BSplineCurve(crease_curve(surface, t, a.y, b.y)))
        }
        (Lens(_), DeviceWall(w)) | (DeviceWall(w), Lens(_)) => {
            Ok(Curve::BSplineCurve(cubic_in_wall(&frame.outline, w, &pts)))
        }
        (DeviceWall(w), Block(RegionSurface::Skirt(_)))
        | (Block(RegionSurface::Skirt(_)), DeviceWall(w)) => {
            Ok(along_run(mids[&w].clone(), w, run, frame))
        }
        (Block(RegionSurface::Skirt(w)), Block(RegionSurface::Side(_)))
        | (Block(RegionSurface::Side(_)), Block(RegionSurface::Skirt(w))) => {
            Ok(along_run(carried_out(frame, w, &mids[&w]), w, run, frame))
        }
        (Block(RegionSurface::BumpSide(k, _)), Block(_))
        | (Block(_), Block(RegionSurface::BumpSide(k, _)))
            if !collinear(&pts) =>
        {
            let bump = frame.bumps.get(&k).ok_or_else(|| {
                BrepError::Topology(format!("corner square {k} has a bump side but no bump"))
            })?;
            Ok(arc(bump, &pts))
        }
        // wall corners, skirt ends, a bump's seams, the corner squares',
        // the sides' and the cap's edges: straight
        _ if collinear(&pts) => Ok(line()),
        (a, b) => Err(BrepError::Topology(format!(
            "no edge curve for {a:?} against {b:?} along {} points",
            pts.len()
        ))),
    }
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
            return surface_face(&surfaces[&lens], outward, (a + b + c) / 3.0, wires)
                .map_err(refuse);
        }
        RegionFace::Wall(w) => axis_plane(onto(&out, w, p0)),
        RegionFace::Block(RegionSurface::Side(w)) => axis_plane(onto(&fp, w, p0)),
        RegionFace::Block(RegionSurface::Cap) => axis_plane(DVec3::new(p0.x, p0.y, frame.cap_z)),
        RegionFace::Block(RegionSurface::Corner(_) | RegionSurface::BumpTop(_)) => axis_plane(p0),
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
/// the cone's side edges cross that height, rational quadratic pieces of
/// at most a quarter turn.
fn arc(bump: &Bump, pts: &[DVec3]) -> Curve {
    let c = bump.centre;
    let z = pts[0].z;
    let (a, b) = (bump.bottom[0], bump.top[0]);
    let along = (z - a.z) / (b.z - a.z);
    let r = (a + along * (b - a)).truncate().distance(c);
    let angle = |p: DVec3| (p.y - c.y).atan2(p.x - c.x);
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
        Vector4::new(
            (c.x + radius * t.cos()) * w,
            (c.y + radius * t.sin()) * w,
            z * w,
            w,
        )
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
    Curve::NurbsCurve(NurbsCurve::new(BSplineCurve::new(
        KnotVec::from(knots),
        ctrl,
    )))
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

    /// Both parting regions of a small cylinder's device, flipped and not,
    /// the lower one with a key's bump on each corner square: each B-rep
    /// is one closed shell of genus 0 (V − E + F − rings = 2) with the faces the
    /// labels give (the device's lens faces on its side, 4 wall parts, 4
    /// skirts, 4 corner squares, 4 sides, the cap; and 3 per bump), and
    /// truck's own tessellation of it (unflipped) encloses the region
    /// mesh's volume to 1e-4: the lens chords and the bumps' 48-gons
    /// differ by less. (Coarser tessellations miss by more than that.)
    #[test]
    fn a_plain_region_is_one_closed_exact_solid() {
        let mut params =
            DesignParams::with_defaults(PitchSurface::Cylinder { radius: -40.0 }, 10.0, 8.0, 0.5);
        params.tolerance = 0.01;
        let design = Design::new(params).unwrap();
        let dm = mesh_device(&design, &Silent).unwrap();
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
                let tessellated = crate::tessellate(&b.solid, 0.005).unwrap().volume();
                let mesh = region.mesh.volume();
                assert!(
                    (tessellated / mesh - 1.0).abs() < 1e-4,
                    "flip {flip}, {side:?}: {tessellated} against {mesh}"
                );
            }
        }
    }
}
