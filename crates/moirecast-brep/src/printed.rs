//! The two bodies of a printed device (METHOD §5.2) as B-rep solids: the
//! clear body and one solid per black band.
//!
//! The bodies' meshes ([`moirecast_kernel::printed`]) label every triangle
//! with the exact surface it lies on ([`BodyFace`]) and every vertex with the
//! device-mesh vertex above it and its depth layer, so the faces and edges
//! are read off them as for the device ([`crate::topology`]). Surfaces:
//! - the revealer lenses, as in the device's B-rep;
//! - the band spans of s, moved down along z to their layer (a translation
//!   of the control points: exact);
//! - a band's side: the crease curve of s ruled straight down to the band's
//!   bottom (degree 1 vertically: exact); where a tangential wall touch was
//!   repaired (the band's outline then follows mesh edges, within the
//!   tolerance), the mesh's polyline ruled down: planar quads;
//! - the side walls' planes.
//!
//! Edges are the creases of these surfaces (cut to the run's stations and
//! moved to the layer), trims in the walls' planes, and the mesh's vertical
//! edges (wall corners, band ends) as polylines.

use crate::error::BrepError;
use crate::lenses::{worst_deviation, LensFamily};
use crate::solid::{
    assemble, boundary_span, crease_curve, cut_to_span, lens_families, surface_face, trim_curve,
    wall_face, EdgeCurve, FIT_SHARE,
};
use crate::spline::chord_lengths;
use crate::topology::{pieces, Piece, Run};
use glam::{DVec2, DVec3};
use moirecast_kernel::mesher::DeviceMesh;
use moirecast_kernel::model::LensRef;
use moirecast_kernel::printed::{BodyFace, Layer, PrintedBodies};
use moirecast_kernel::{BaseKind, Design, Mesh, PrintedBase};
use truck_modeling::{
    BSplineCurve, BSplineSurface, Curve, Face, KnotVec, NurbsSurface, Point3, Shell,
    ShellCondition, Solid, Vector4, Wire,
};

/// Counts and measurements of the printed B-rep (in `report.json`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PrintedBrepStats {
    pub clear_faces: usize,
    pub clear_edges: usize,
    pub clear_vertices: usize,
    /// Faces of the clear body with holes (a band's end notch does not
    /// make one; a face an annulus does): their inner loops.
    pub clear_inner_loops: usize,
    /// Through-holes of the clear body by the Euler–Poincaré formula on its
    /// B-rep (V − E + F − inner loops = 2 − 2g): the bands that tunnel
    /// through it.
    pub clear_genus: i64,
    pub black_solids: usize,
    pub black_faces: usize,
    /// Worst sampled distance (mm) of a lens or band surface from its exact
    /// section, and where.
    pub max_surface_deviation_mm: f64,
    pub worst_surface: String,
    /// Limit for that distance: `FIT_SHARE` × tolerance.
    pub surface_fit_mm: f64,
}

/// The printed device's bodies as B-rep solids.
pub struct PrintedBrep {
    pub clear: Solid,
    /// One solid per black band.
    pub bands: Vec<Solid>,
    pub stats: PrintedBrepStats,
}

/// The lens and band-span surfaces of a printed design, fitted over its
/// device mesh: the part of the bodies' B-rep that needs only the device
/// mesh, so it can be built while the bodies are.
pub struct PrintedSurfaces<'a> {
    design: &'a Design,
    printed: PrintedBase,
    revealer: LensFamily,
    base: LensFamily,
}

impl<'a> PrintedSurfaces<'a> {
    /// Fits the surfaces of `design` (meshed as `dm`); each is within
    /// `FIT_SHARE × tolerance` of its exact section, or
    /// [`BrepError::SurfaceFit`].
    pub fn fit(design: &'a Design, dm: &DeviceMesh) -> Result<Self, BrepError> {
        let BaseKind::Printed(printed) = design.params.base.kind else {
            return Err(BrepError::Topology(
                "the design's base is not printed".into(),
            ));
        };
        let (revealer, base) = lens_families(design, dm)?;
        Ok(PrintedSurfaces {
            design,
            printed,
            revealer,
            base,
        })
    }

    /// The design the surfaces were fitted for.
    pub fn design(&self) -> &'a Design {
        self.design
    }

    /// Band span k of s moved down to `layer`.
    fn section(&self, k: i64, layer: Layer) -> Result<NurbsSurface<Vector4>, BrepError> {
        let surface = self.base.surfaces.get(&k).ok_or_else(|| {
            BrepError::Topology(format!("band span {k} has no face on the device"))
        })?;
        Ok(moved_down(surface, layer.depth(&self.printed)))
    }

    /// The side of a band below base crease `c`: the crease curve ruled
    /// straight down by the band thickness. Parameters: (0 at the top to 1
    /// at the bottom, station v).
    fn band_side(&self, c: i64) -> Result<NurbsSurface<Vector4>, BrepError> {
        let (surface, row) = match (self.base.surfaces.get(&c), self.base.surfaces.get(&(c - 1))) {
            (Some(s), _) => (s, 0),
            (None, Some(s)) => (s, s.control_points().len() - 1),
            (None, None) => {
                return Err(BrepError::Topology(format!(
                    "band crease {c} borders no band span"
                )))
            }
        };
        let top: Vec<Vector4> = surface.control_points()[row].clone();
        let bottom: Vec<Vector4> = top
            .iter()
            .map(|h| down(h, self.printed.band_thickness))
            .collect();
        Ok(NurbsSurface::new(BSplineSurface::new(
            (KnotVec::bezier_knot(1), surface.vknot_vec().clone()),
            vec![top, bottom],
        )))
    }
}

/// A homogeneous control point moved `depth` mm down along z (exact: by
/// −depth·w in its z coordinate).
fn down(h: &Vector4, depth: f64) -> Vector4 {
    Vector4::new(h.x, h.y, h.z - h.w * depth, h.w)
}

/// `surface` moved `depth` mm down along z, control point by control point.
fn moved_down(surface: &NurbsSurface<Vector4>, depth: f64) -> NurbsSurface<Vector4> {
    if depth == 0.0 {
        return surface.clone();
    }
    let rows = surface
        .control_points()
        .iter()
        .map(|row| row.iter().map(|h| down(h, depth)).collect())
        .collect();
    NurbsSurface::new(BSplineSurface::new(
        (surface.uknot_vec().clone(), surface.vknot_vec().clone()),
        rows,
    ))
}

/// Degree-1 knots over `params` (clamped).
fn linear_knots(params: &[f64]) -> KnotVec {
    let mut knots = vec![params[0]];
    knots.extend_from_slice(params);
    knots.push(*params.last().expect("two or more points"));
    KnotVec::from(knots)
}

/// The polyline through `pts` as a degree-1 B-spline (exact).
fn polyline(pts: &[DVec3]) -> BSplineCurve<Point3> {
    BSplineCurve::new(
        linear_knots(&chord_lengths(pts)),
        pts.iter().map(|p| Point3::new(p.x, p.y, p.z)).collect(),
    )
}

/// The polyline through `pts` ruled straight down by `depth`: planar quads
/// (each segment and its translate are parallel). Parameters: (0 at the top
/// to 1 at the bottom, chord length); also the vertices' chord lengths.
fn ruled_down(pts: &[DVec3], depth: f64) -> (NurbsSurface<Vector4>, Vec<f64>) {
    let params = chord_lengths(pts);
    let row = |dz: f64| -> Vec<Vector4> {
        pts.iter()
            .map(|p| down(&Vector4::new(p.x, p.y, p.z, 1.0), dz))
            .collect()
    };
    let surface = NurbsSurface::new(BSplineSurface::new(
        (KnotVec::bezier_knot(1), linear_knots(&params)),
        vec![row(0.0), row(depth)],
    ));
    (surface, params)
}

/// One printed body's mesh with what its triangles and vertices are.
struct Body<'a> {
    mesh: &'a Mesh,
    faces: &'a [BodyFace],
    vertices: &'a [(u32, Layer)],
}

/// Builds the B-rep of both printed bodies of `design` (meshed as `dm`,
/// its bodies `bodies`). Every lens and band surface is within
/// `FIT_SHARE × tolerance` of its exact section, or this fails with
/// [`BrepError::SurfaceFit`]; every shell is closed, or it fails.
pub fn build_printed_brep(
    design: &Design,
    dm: &DeviceMesh,
    bodies: &PrintedBodies,
) -> Result<PrintedBrep, BrepError> {
    build_printed_brep_on(&PrintedSurfaces::fit(design, dm)?, dm, bodies)
}

/// [`build_printed_brep`] on surfaces already fitted over `dm`.
pub fn build_printed_brep_on(
    surfaces: &PrintedSurfaces,
    dm: &DeviceMesh,
    bodies: &PrintedBodies,
) -> Result<PrintedBrep, BrepError> {
    let design = surfaces.design;
    let clear = Body {
        mesh: &bodies.clear,
        faces: &bodies.clear_faces,
        vertices: &bodies.clear_vertices,
    };
    let black = Body {
        mesh: &bodies.black,
        faces: &bodies.black_faces,
        vertices: &bodies.black_vertices,
    };
    // the two bodies share only the lens surfaces: built side by side
    let (clear_shells, black_shells) = rayon::join(
        || body_shells(surfaces, dm, &clear),
        || body_shells(surfaces, dm, &black),
    );
    let ((clear_shells, clear_counts), (black_shells, black_counts)) =
        (clear_shells?, black_shells?);
    let closed = |shell: &Shell, what: &str| {
        let condition = shell.shell_condition();
        if condition == ShellCondition::Closed {
            Ok(())
        } else {
            Err(BrepError::Truck {
                what: "shell",
                detail: format!("{what}: shell condition is {condition:?}, not Closed"),
            })
        }
    };
    let solid = |shell: Shell| {
        Solid::try_new(vec![shell]).map_err(|e| BrepError::Truck {
            what: "solid",
            detail: e.to_string(),
        })
    };
    let [clear_shell]: [Shell; 1] = clear_shells.try_into().map_err(|shells: Vec<Shell>| {
        BrepError::Topology(format!(
            "the clear body's faces form {} shells, not one",
            shells.len()
        ))
    })?;
    closed(&clear_shell, "clear body")?;
    let black_faces = black_counts.faces;
    let bands: Vec<Solid> = black_shells
        .into_iter()
        .enumerate()
        .map(|(i, shell)| {
            closed(&shell, &format!("black band {i}"))?;
            solid(shell)
        })
        .collect::<Result<_, _>>()?;
    let Counts {
        faces,
        edges,
        vertices,
        inner_loops,
    } = clear_counts;
    let (deviation, worst) = worst_deviation(&[
        (&surfaces.revealer, "revealer lens"),
        (&surfaces.base, "band span"),
    ]);
    let stats = PrintedBrepStats {
        clear_faces: faces,
        clear_edges: edges,
        clear_vertices: vertices,
        clear_inner_loops: inner_loops,
        clear_genus: 1 - (vertices as i64 - edges as i64 + faces as i64 - inner_loops as i64) / 2,
        black_solids: bands.len(),
        black_faces,
        max_surface_deviation_mm: deviation,
        worst_surface: worst,
        surface_fit_mm: FIT_SHARE * design.tolerance.mm(),
    };
    Ok(PrintedBrep {
        clear: solid(clear_shell)?,
        bands,
        stats,
    })
}

/// Sizes of one body's B-rep.
struct Counts {
    faces: usize,
    edges: usize,
    vertices: usize,
    /// Wires beyond the first of every face.
    inner_loops: usize,
}

/// Which lens or band surface a body face lies on, and at which layer.
fn lens_of(face: BodyFace) -> Option<(LensRef, Layer)> {
    match face {
        BodyFace::Revealer(i) => Some((LensRef::Revealer(i), Layer::Top)),
        BodyFace::Section { k, layer } => Some((LensRef::Base(k), layer)),
        _ => None,
    }
}

/// The exact geometry of one body's faces and edges.
struct BodyGeometry<'a> {
    surfaces: &'a PrintedSurfaces<'a>,
    dm: &'a DeviceMesh,
    body: &'a Body<'a>,
}

impl BodyGeometry<'_> {
    fn at(&self, v: u32) -> DVec3 {
        self.body.mesh.positions[v as usize]
    }

    /// The (t, v) parameters of a body vertex on a revealer lens or band span.
    fn params_on(&self, v: u32, lens: LensRef) -> Result<DVec2, BrepError> {
        let (source, _) = self.body.vertices[v as usize];
        self.dm.origins[source as usize]
            .params_on(lens)
            .ok_or_else(|| BrepError::Topology(format!("body vertex {v} is not on {lens:?}")))
    }

    fn surface_of(&self, lens: LensRef, layer: Layer) -> Result<NurbsSurface<Vector4>, BrepError> {
        match lens {
            LensRef::Revealer(i) => Ok(self.surfaces.revealer.surfaces[&i].clone()),
            LensRef::Base(k) => self.surfaces.section(k, layer),
        }
    }

    /// The curve of `run`, the edge between `piece` and `other`.
    fn curve(
        &self,
        piece: &Piece<BodyFace>,
        other: &Piece<BodyFace>,
        run: &Run,
    ) -> Result<EdgeCurve, BrepError> {
        // the face with a lens or band surface decides the curve
        let (surface_face, other_face) = match (lens_of(piece.patch), lens_of(other.patch)) {
            (Some(_), _) => (piece.patch, other.patch),
            (None, Some(_)) => (other.patch, piece.patch),
            (None, None) => {
                // walls and band sides meet in vertical lines: the mesh's
                // (a wall corner's vertices lie on the outline only to the
                // mesher's wall snap, as in the device's B-rep)
                let pts: Vec<DVec3> = run.vertices.iter().map(|&v| self.at(v)).collect();
                return Ok(Curve::BSplineCurve(polyline(&pts)).into());
            }
        };
        let (lens, layer) = lens_of(surface_face).expect("chosen for its surface");
        if other_face == BodyFace::Repaired {
            // the band's repaired outline: the mesh's own edges
            let pts: Vec<DVec3> = run.vertices.iter().map(|&v| self.at(v)).collect();
            return Ok(Curve::BSplineCurve(polyline(&pts)).into());
        }
        if let BodyFace::Wall(side) = other_face {
            let pts: Vec<DVec3> = run.vertices.iter().map(|&v| self.at(v)).collect();
            return Ok(trim_curve(self.surfaces.design, side, &pts).into());
        }
        // a crease of the surface: t = 0 or t = 1 at every vertex
        let params: Vec<DVec2> = run
            .vertices
            .iter()
            .map(|&v| self.params_on(v, lens))
            .collect::<Result<_, _>>()?;
        let Some(t) = [0.0, 1.0]
            .into_iter()
            .find(|&t| params.iter().all(|p| p.x == t))
        else {
            return Err(BrepError::Topology(format!(
                "{surface_face:?} meets {other_face:?} away from a crease"
            )));
        };
        let surface = self.surface_of(lens, layer)?;
        let (v0, v1) = (params[0].y, params.last().unwrap().y);
        Ok(EdgeCurve::fixed(Curve::BSplineCurve(crease_curve(
            &surface, t, v0, v1,
        )?)))
    }

    /// The face of `piece`, bounded by `wires`, on its exact surface.
    fn face(&self, piece: &Piece<BodyFace>, wires: Vec<Wire>) -> Result<Face, BrepError> {
        let refuse = |e: truck_topology::errors::Error| BrepError::Truck {
            what: "face",
            detail: format!("{:?}: {e}", piece.patch),
        };
        let tri = self.body.mesh.triangles[piece.triangle as usize];
        let [p0, p1, p2] = tri.map(|v| self.at(v));
        let outward = (p1 - p0).cross(p2 - p0);
        match piece.patch {
            BodyFace::Wall(side) => wall_face(self.surfaces.design, side, wires).map_err(refuse),
            BodyFace::Revealer(_) | BodyFace::Section { .. } => {
                let (lens, layer) = lens_of(piece.patch).expect("a lens or band face");
                let pv = tri
                    .iter()
                    .map(|&v| self.params_on(v, lens))
                    .collect::<Result<Vec<_>, _>>()?;
                let at = (pv[0] + pv[1] + pv[2]) / 3.0;
                let span = boundary_span(piece, |v| self.params_on(v, lens))?;
                let surface = cut_to_span(&self.surface_of(lens, layer)?, span);
                surface_face(surface, outward, at, wires).map_err(refuse)
            }
            BodyFace::BandSide { crease } => {
                // parameters: (0 at the top, 1 at the bottom; the station v)
                let pv = tri
                    .iter()
                    .map(|&v| -> Result<DVec2, BrepError> {
                        let (_, layer) = self.body.vertices[v as usize];
                        let tv = self.params_on(v, LensRef::Base(crease))?;
                        Ok(DVec2::new(
                            if layer == Layer::Top { 0.0 } else { 1.0 },
                            tv.y,
                        ))
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                let at = (pv[0] + pv[1] + pv[2]) / 3.0;
                let span = boundary_span(piece, |v| self.params_on(v, LensRef::Base(crease)))?;
                let surface = cut_to_span(&self.surfaces.band_side(crease)?, span);
                surface_face(surface, outward, at, wires).map_err(refuse)
            }
            BodyFace::Repaired => self.repaired_face(piece, tri, outward, wires),
        }
    }

    /// A band side along a repaired wall touch: the top polyline (the
    /// outer loop's vertices at the top layer, which run consecutively: a
    /// strip of vertical quads) ruled straight down.
    fn repaired_face(
        &self,
        piece: &Piece<BodyFace>,
        tri: [u32; 3],
        outward: DVec3,
        wires: Vec<Wire>,
    ) -> Result<Face, BrepError> {
        // the top polyline: the piece's outer loop's vertices at the
        // top layer, which run consecutively (a strip of vertical quads)
        let ring: Vec<u32> = piece.loops[0]
            .iter()
            .flat_map(|run| &run.vertices[1..])
            .copied()
            .collect();
        let top = |v: u32| self.body.vertices[v as usize].1 == Layer::Top;
        let start = (0..ring.len())
            .find(|&i| top(ring[i]) && !top(ring[(i + ring.len() - 1) % ring.len()]))
            .ok_or_else(|| BrepError::Topology("a repaired band side has no top edge".into()))?;
        let upper: Vec<u32> = (0..ring.len())
            .map(|i| ring[(start + i) % ring.len()])
            .take_while(|&v| top(v))
            .collect();
        let sources: Vec<u32> = upper
            .iter()
            .map(|&v| self.body.vertices[v as usize].0)
            .collect();
        let pts: Vec<DVec3> = upper.iter().map(|&v| self.at(v)).collect();
        let (surface, knots) = ruled_down(&pts, self.surfaces.printed.band_thickness);
        // the triangle's parameters: its vertices' places on the polyline
        let pv = tri
            .iter()
            .map(|&v| {
                let (source, layer) = self.body.vertices[v as usize];
                let i = sources.iter().position(|&s| s == source).ok_or_else(|| {
                    BrepError::Topology("a repaired band side's triangle leaves its strip".into())
                })?;
                Ok(DVec2::new(
                    if layer == Layer::Top { 0.0 } else { 1.0 },
                    knots[i],
                ))
            })
            .collect::<Result<Vec<_>, BrepError>>()?;
        let at = (pv[0] + pv[1] + pv[2]) / 3.0;
        surface_face(surface, outward, at, wires).map_err(|e| BrepError::Truck {
            what: "face",
            detail: format!("{:?}: {e}", piece.patch),
        })
    }
}

/// The faces of one body as shells, one per connected set of faces in the
/// order of their first triangle (deterministic), and the body's counts.
fn body_shells(
    surfaces: &PrintedSurfaces,
    dm: &DeviceMesh,
    body: &Body,
) -> Result<(Vec<Shell>, Counts), BrepError> {
    let pieces = pieces(body.mesh, body.faces)?;
    let geometry = BodyGeometry { surfaces, dm, body };
    let assembled = assemble(
        &pieces,
        &body.mesh.positions,
        |piece| lens_of(piece.patch).is_none(),
        |piece, other, run| geometry.curve(piece, other, run),
        |piece, wires| geometry.face(piece, wires),
    )?;
    let counts = Counts {
        faces: pieces.len(),
        edges: assembled.edges,
        vertices: assembled.vertices,
        inner_loops: pieces.iter().map(|p| p.loops.len() - 1).sum(),
    };
    Ok((connected_shells(&pieces, assembled.faces), counts))
}

/// `faces` (one per piece) grouped into shells by the runs their pieces
/// share; a shell's root is its set's first piece.
fn connected_shells(pieces: &[Piece<BodyFace>], faces: Vec<Face>) -> Vec<Shell> {
    let mut root: Vec<usize> = (0..pieces.len()).collect();
    fn find(root: &mut [usize], mut x: usize) -> usize {
        while root[x] != x {
            root[x] = root[root[x]];
            x = root[x];
        }
        x
    }
    for (p, piece) in pieces.iter().enumerate() {
        for run in piece.loops.iter().flatten() {
            let (a, b) = (find(&mut root, p), find(&mut root, run.neighbour));
            root[a.max(b)] = a.min(b);
        }
    }
    let mut shells: Vec<Vec<Face>> = Vec::new();
    let mut shell_of = vec![usize::MAX; pieces.len()];
    for (p, face) in faces.into_iter().enumerate() {
        let r = find(&mut root, p);
        if shell_of[r] == usize::MAX {
            shell_of[r] = shells.len();
            shells.push(Vec::new());
        }
        shells[shell_of[r]].push(face);
    }
    shells.into_iter().map(Shell::from).collect()
}
