//! The printed (multi-material) device of METHOD §5.2: a clear body over
//! black bands, as two closed meshes that share their common faces.
//!
//! **Layers are measured along −z.** METHOD §5.2 offsets the band layer and
//! the backing along −n_s. We offset along −z, the draw and print
//! direction, for three reasons: every layer vertex then lies exactly below
//! a vertex of s, so the walls stay exactly vertical (METHOD §5.3) and need
//! no further solves; band sides are vertical, exactly planar quads that no
//! printer sees as overhangs; and the two bodies share every vertex by
//! construction. The top of the bands — the only face the optics sees — is
//! s itself, with its edges exactly on φ ∈ ℤ and φ ∈ ℤ + duty. The layer is
//! t_b thick along z, which is t_b·cos(slope) along the normal.
//!
//! **Construction.** The device mesher meshes the revealer, the walls and s
//! with the band edges as creases ([`crate::Design::crease_phase`]). Here
//! s is copied to z − t_b (the bands' bottom) and to z − t_b − t_back (the
//! backing's bottom), and every boundary edge of a band becomes a vertical
//! quad: a side face shared by both bodies inside the outline, an end cap of
//! the band on the walls.

use crate::design::{BaseKind, Design, PrintedBase};
use crate::device_mesh::{DeviceMesh, Patch, Side, VertexOrigin};
use crate::error::{KernelError, Result};
use crate::mesh::Mesh;
use crate::model::LensRef;
use crate::tolerance::WALL_SNAP_MM;
use glam::DVec3;

/// The two bodies of a printed device and the slab they fill.
#[derive(Clone, Debug)]
pub struct PrintedBodies {
    /// Lens surface down to the backing's bottom, minus the bands.
    pub clear: Mesh,
    /// The black bands: one closed shell per band.
    pub black: Mesh,
    /// Clear and black together: the whole device as one solid, to measure
    /// that the two fill it without gap or overlap.
    pub slab: Mesh,
    /// Per triangle of `clear`: it is a face shared with the bands (their
    /// tops, sides or bottoms), where a renderer absorbs.
    pub clear_on_band: Vec<bool>,
    /// Tangential wall touches of band edges, and their repair.
    pub wall_touches: WallTouches,
    /// What each triangle of `clear` lies on (for the B-rep).
    pub clear_faces: Vec<BodyFace>,
    /// What each triangle of `black` lies on.
    pub black_faces: Vec<BodyFace>,
    /// Per vertex of `clear`: the device-mesh vertex above it and its layer.
    pub clear_vertices: Vec<(u32, Layer)>,
    /// Per vertex of `black`: the device-mesh vertex above it and its layer.
    pub black_vertices: Vec<(u32, Layer)>,
    /// Number of band shells in `black`.
    pub bands: u32,
    /// Through-holes of `clear`: a band whose ends meet the walls in two
    /// separate places tunnels through the clear body.
    pub clear_genus: u32,
    /// Area of s inside the outline projected on xy (mm²).
    pub layer_area: f64,
    /// Area of the bands' tops projected on xy (mm²).
    pub black_area: f64,
    /// The same two areas over whole periods only: periods neither of
    /// whose two sections meets an x-wall (the walls cut the others).
    pub layer_area_whole: f64,
    pub black_area_whole: f64,
}

/// Depth layers below s: every body vertex is a device-mesh vertex moved
/// down along z to one of them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Layer {
    /// The device mesh itself (s, the revealer and the upper walls).
    Top,
    /// The bands' bottom, t_b below s.
    BandBottom,
    /// The backing's bottom, t_b + t_back below s.
    Bottom,
}

impl Layer {
    /// How far below the device-mesh vertex (mm, along −z) this layer lies.
    pub fn depth(self, pb: &PrintedBase) -> f64 {
        match self {
            Layer::Top => 0.0,
            Layer::BandBottom => pb.band_thickness,
            Layer::Bottom => pb.band_thickness + pb.backing,
        }
    }
}

/// The exact surface a triangle of a printed body lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BodyFace {
    /// Revealer lens i (the clear body's top).
    Revealer(i64),
    /// A side wall's plane: the upper walls, the clear body's lower walls
    /// and the bands' end caps.
    Wall(Side),
    /// Base section k of s (a band span), moved down to `layer`.
    Section { k: i64, layer: Layer },
    /// The vertical side of a band below base crease `crease`.
    BandSide { crease: i64 },
    /// A band side along an edge of s that is no crease: only where a
    /// tangential wall touch was repaired (see [`WallTouches`]).
    Repaired,
}

/// A mesh built from vertices of the device mesh at a depth layer, each
/// made once, numbered in first-use order (deterministic).
struct Body<'a> {
    source: &'a [DVec3],
    printed: PrintedBase,
    /// Index in this body of (source vertex, layer), or `u32::MAX`.
    index: Vec<u32>,
    /// Source vertex and layer of each vertex of this body.
    origin: Vec<(u32, Layer)>,
    /// What each triangle lies on.
    faces: Vec<BodyFace>,
    mesh: Mesh,
}

impl<'a> Body<'a> {
    /// An empty body with room for `triangles` (an estimate: the vectors
    /// grow past it, but rarely copy themselves as they grow).
    fn new(source: &'a [DVec3], pb: &PrintedBase, triangles: usize) -> Self {
        let vertices = triangles / 2 + 2;
        Body {
            source,
            printed: *pb,
            index: vec![u32::MAX; 3 * source.len()],
            origin: Vec::with_capacity(vertices),
            faces: Vec::with_capacity(triangles),
            mesh: Mesh {
                positions: Vec::with_capacity(vertices),
                triangles: Vec::with_capacity(triangles),
            },
        }
    }

    fn vertex(&mut self, v: u32, layer: Layer) -> u32 {
        let slot = 3 * v as usize + layer as usize;
        if self.index[slot] != u32::MAX {
            return self.index[slot];
        }
        let p = self.source[v as usize];
        let depth = layer.depth(&self.printed);
        let i = self.mesh.positions.len() as u32;
        self.mesh.positions.push(DVec3::new(p.x, p.y, p.z - depth));
        self.origin.push((v, layer));
        self.index[slot] = i;
        i
    }

    fn triangle(&mut self, t: [u32; 3], layer: Layer, flip: bool, face: BodyFace) {
        let [a, b, c] = t.map(|v| self.vertex(v, layer));
        self.mesh
            .triangles
            .push(if flip { [a, c, b] } else { [a, b, c] });
        self.faces.push(face);
    }

    /// The vertical quad below directed edge a→b between two layers, made
    /// to pair with a face above that holds b→a at `upper` and a face below
    /// that holds a→b at `lower` (or the reverse when `flip`).
    fn quad(&mut self, (a, b): (u32, u32), upper: Layer, lower: Layer, flip: bool, face: BodyFace) {
        let (a0, b0, a1, b1) = (
            self.vertex(a, upper),
            self.vertex(b, upper),
            self.vertex(a, lower),
            self.vertex(b, lower),
        );
        if flip {
            self.mesh.triangles.push([a0, b1, b0]);
            self.mesh.triangles.push([a0, a1, b1]);
        } else {
            self.mesh.triangles.push([a0, b0, b1]);
            self.mesh.triangles.push([a0, b1, a1]);
        }
        self.faces.extend([face; 2]);
    }
}

/// Where band edges touched a wall without crossing it, and how the bands
/// were changed there.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WallTouches {
    /// Wall vertices where a band edge touched the wall tangentially.
    pub touches: usize,
    /// Triangles of s given to the other body there.
    pub triangles_moved: usize,
    /// Largest distance (mm) from the wall of a moved triangle's vertex:
    /// how far the band's outline moved. At most the tolerance.
    pub max_shift_mm: f64,
}

/// Outline vertices of s where two band-edge segments meet: there a band
/// edge touches a wall tangentially (the mesher takes a crease within
/// `WALL_SNAP_MM` of a wall as lying on it), and the region between the
/// edge and the wall is pinched to a point, which would pinch that body to
/// a vertical line (four faces on one edge). Rings and images whose
/// elevation reaches 0 or 1 at the wall do this wherever E is a whole
/// number of periods there.
fn pinches(vertices: usize, s_tris: &[([u32; 3], bool)], on_s: &EdgeMap<bool>) -> Vec<u32> {
    let mut on_outline = vec![false; vertices];
    let mut band_edges_at = vec![0u8; vertices];
    for (t, black) in s_tris {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            match on_s.get(b, a) {
                None => {
                    on_outline[a as usize] = true;
                    on_outline[b as usize] = true;
                }
                Some(other) if *black && !other => {
                    band_edges_at[a as usize] += 1;
                    band_edges_at[b as usize] += 1;
                }
                Some(_) => {}
            }
        }
    }
    (0..vertices as u32)
        .filter(|&v| on_outline[v as usize] && band_edges_at[v as usize] >= 2)
        .collect()
}

/// Repairs every tangential wall touch: the sliver between the band edge
/// and the wall next to the touch (the triangles at the touching vertex on
/// the wall's side, which all have the colour of the wall edges there)
/// goes to the other body, so the band edge meets the wall at the
/// neighbouring rows instead of touching it at a point. The band outline
/// moves by the sliver's width, which must stay within the tolerance.
/// `on_s` is the edge map of `s_tris`; it is rebuilt here if colours change.
fn repair_wall_touches(
    design: &Design,
    pos: &[DVec3],
    s_tris: &mut [([u32; 3], bool)],
    on_s: &mut EdgeMap<bool>,
) -> Result<WallTouches> {
    let mut found = WallTouches::default();
    let touches = pinches(pos.len(), s_tris, on_s);
    if touches.is_empty() {
        return Ok(found);
    }
    let (xl, xr) = design.outline_x;
    let hh = design.half_height;
    let wall_distance = |p: DVec3| {
        (p.x - xl)
            .abs()
            .min((p.x - xr).abs())
            .min((p.y + hh).abs())
            .min((p.y - hh).abs())
    };
    for &v in &touches {
        // the colour of the wall edges at v: the pinched region's
        let pinched = s_tris.iter().find_map(|(t, black)| {
            (0..3).find_map(|e| {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                ((a == v || b == v) && on_s.get(b, a).is_none()).then_some(*black)
            })
        });
        let Some(pinched) = pinched else { continue };
        found.touches += 1;
        for (t, black) in s_tris.iter_mut() {
            if *black == pinched && t.contains(&v) {
                *black = !pinched;
                found.triangles_moved += 1;
                for &w in t.iter() {
                    found.max_shift_mm = found.max_shift_mm.max(wall_distance(pos[w as usize]));
                }
            }
        }
    }
    *on_s = EdgeMap::new(pos.len(), s_tris);
    let left = pinches(pos.len(), s_tris, on_s);
    if let Some(&v) = left.first() {
        let p = pos[v as usize];
        return Err(band_touches_wall(
            design,
            format!(
                "a band edge touches the side wall at ({:.4}, {:.4}) mm without crossing it, which would pinch a body to a line, and moving the sliver next to it did not help (band-touches-wall)",
                p.x, p.y
            ),
        ));
    }
    if found.max_shift_mm > design.tolerance.mm() {
        return Err(band_touches_wall(
            design,
            format!(
                "a band edge touches a side wall without crossing it at {} places; closing the pinch there moves the band's outline by {:.2} µm, more than the {:.2} µm tolerance (band-touches-wall)",
                found.touches,
                found.max_shift_mm * 1e3,
                design.tolerance.mm() * 1e3
            ),
        ));
    }
    Ok(found)
}

/// A printed design refused because a band edge touches a side wall: a
/// rule of the design (its elevation at the walls), named by its levels.
fn band_touches_wall(design: &Design, problem: String) -> KernelError {
    crate::DesignError {
        param: crate::Param::Levels,
        value: design.params.base.levels.to_string(),
        problem,
        fix: "change the width, the levels or the blur slightly".into(),
    }
    .into()
}

/// A printed design refused because its base layer is one colour: one
/// band covers all of it (`black`), or no band reaches it. Either way no
/// level line shows; a whole black layer would also split the clear body
/// in two (the lenses above it, the backing below), and no band leaves no
/// black body. Only a layout about one period wide can do this.
fn one_colour_base(design: &Design, black: bool) -> KernelError {
    let BaseKind::Printed(pb) = design.params.base.kind else {
        unreachable!("callers build printed designs only")
    };
    let periods = design.params.width / design.params.period;
    let (problem, fix) = if black {
        (
            format!(
                "one black band covers the whole base layer (the layout is {periods:.2} periods wide): \
                 no clear gap shows a level line, and the clear body would come apart"
            ),
            "lower base.duty, or widen layout.width to two periods or more",
        )
    } else {
        (
            format!(
                "no black band reaches the base layer (the layout is {periods:.2} periods wide): \
                 there is nothing to show a level line"
            ),
            "raise base.duty, or widen layout.width to two periods or more",
        )
    };
    crate::DesignError {
        param: crate::Param::Duty,
        value: pb.duty.to_string(),
        problem,
        fix: fix.into(),
    }
    .into()
}

/// The side wall nearest to `p` (a point of the outline).
fn wall_side(design: &Design, p: DVec3) -> Side {
    let (xl, xr) = design.outline_x;
    let h = design.half_height;
    [
        ((p.x - xl).abs(), Side::Left),
        ((p.x - xr).abs(), Side::Right),
        ((p.y + h).abs(), Side::Front),
        ((p.y - h).abs(), Side::Back),
    ]
    .into_iter()
    .min_by(|a, b| a.0.total_cmp(&b.0))
    .map(|(_, side)| side)
    .expect("four walls")
}

/// Extends `flags` to every triangle of `body` made so far with `value`.
fn mark(body: &Body, flags: &mut Vec<bool>, value: bool) {
    flags.resize(body.mesh.triangles.len(), value);
}

/// Area of a triangle projected on xy.
fn xy_area(m: &[DVec3], t: &[u32; 3]) -> f64 {
    let [a, b, c] = t.map(|i| m[i as usize]);
    0.5 * ((b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y)).abs()
}

/// Builds the clear and black bodies from the device mesh of a printed
/// design. The device mesh must be closed and oriented (it is checked
/// before this runs); the bodies are checked by the caller.
pub fn printed_bodies(design: &Design, dm: &DeviceMesh) -> Result<PrintedBodies> {
    let BaseKind::Printed(pb) = design.params.base.kind else {
        return Err(KernelError::MeshCheck {
            name: "printed-base",
            detail: "the design's base is not printed".into(),
        });
    };
    let (s_faces, on_s, repair) = faces_of_s(design, dm)?;
    let walk = Walk {
        design,
        dm,
        pb: &pb,
        s_faces: &s_faces,
    };
    // The three bodies are built side by side, each from the same walk over
    // s, so each numbers its vertices in the same first-use order as one
    // walk building all three would.
    let ((clear, clear_on_band), (black, slab)) = rayon::join(
        || walk.clear(),
        || rayon::join(|| walk.black(), || walk.slab()),
    );
    let areas = band_areas(design, &dm.mesh.positions, &s_faces);
    let (bands, caps) = shells_and_caps(&black.mesh, &black.origin, &on_s);
    let clear_genus = caps.iter().map(|&c| c.saturating_sub(1)).sum();
    Ok(PrintedBodies {
        clear_faces: clear.faces,
        black_faces: black.faces,
        clear_vertices: clear.origin,
        black_vertices: black.origin,
        clear: clear.mesh,
        clear_on_band,
        wall_touches: repair,
        black: black.mesh,
        slab: slab.mesh,
        bands,
        clear_genus,
        layer_area: areas[0],
        black_area: areas[1],
        layer_area_whole: areas[2],
        black_area_whole: areas[3],
    })
}

/// s's triangles with their sections and neighbours' colours, after the
/// band edges that touch a wall are repaired; the map of s's edges; the
/// repairs.
fn faces_of_s(
    design: &Design,
    dm: &DeviceMesh,
) -> Result<(Vec<SFace>, EdgeMap<bool>, WallTouches)> {
    let (tris, pos) = (&dm.mesh.triangles, &dm.mesh.positions);
    // s's triangles and the band each lies in
    let band_of = |ti: usize| match dm.patches[ti] {
        Patch::Lens(LensRef::Base(k)) => Some(design.is_black_band(k)),
        _ => None,
    };
    // s's triangles (device-mesh index) and whether each is black
    let mut s_tris: Vec<([u32; 3], bool)> = Vec::new();
    let mut s_index: Vec<usize> = Vec::new();
    for (ti, t) in tris.iter().enumerate() {
        if let Some(black) = band_of(ti) {
            s_tris.push((*t, black));
            s_index.push(ti);
        }
    }
    for black in [false, true] {
        if !s_tris.iter().any(|&(_, b)| b == black) {
            return Err(one_colour_base(design, !black));
        }
    }
    let mut on_s = EdgeMap::new(pos.len(), &s_tris);
    let repair = repair_wall_touches(design, pos, &mut s_tris, &mut on_s)?;
    let s_faces: Vec<SFace> = s_tris
        .iter()
        .zip(&s_index)
        .map(|(&(t, is_black), &ti)| {
            let Patch::Lens(LensRef::Base(k)) = dm.patches[ti] else {
                unreachable!("s_tris holds base triangles only")
            };
            let across = std::array::from_fn(|e| on_s.get(t[(e + 1) % 3], t[e]));
            SFace {
                t,
                is_black,
                k,
                across,
            }
        })
        .collect();
    Ok((s_faces, on_s, repair))
}

/// One walk over s that builds a body: what every body's faces come from.
struct Walk<'a> {
    design: &'a Design,
    dm: &'a DeviceMesh,
    pb: &'a PrintedBase,
    s_faces: &'a [SFace],
}

impl Walk<'_> {
    /// What a vertical quad below edge a→b of s lies on.
    fn band_side(&self, a: u32, b: u32) -> BodyFace {
        match (self.dm.origins[a as usize], self.dm.origins[b as usize]) {
            (VertexOrigin::BaseCrease { k: c, .. }, VertexOrigin::BaseCrease { k: d, .. })
                if c == d =>
            {
                BodyFace::BandSide { crease: c }
            }
            _ => BodyFace::Repaired,
        }
    }

    fn wall(&self, a: u32, b: u32) -> BodyFace {
        let pos = &self.dm.mesh.positions;
        BodyFace::Wall(wall_side(
            self.design,
            0.5 * (pos[a as usize] + pos[b as usize]),
        ))
    }

    /// The revealer and the upper walls: they belong to the clear body and
    /// the slab.
    fn upper(&self, body: &mut Body) {
        for (ti, t) in self.dm.mesh.triangles.iter().enumerate() {
            let face = match self.dm.patches[ti] {
                Patch::Lens(LensRef::Revealer(i)) => BodyFace::Revealer(i),
                Patch::Wall(side) => BodyFace::Wall(side),
                Patch::Lens(LensRef::Base(_)) => continue,
            };
            body.triangle(*t, Layer::Top, false, face);
        }
    }

    /// Room for the upper faces: the device's triangles not on s.
    fn upper_count(&self) -> usize {
        self.dm.mesh.triangles.len() - self.s_faces.len()
    }

    /// Room for band sides (about one quad per face of s on the reference
    /// designs) and a margin.
    fn sides_and_margin(&self) -> (usize, usize) {
        (self.s_faces.len(), self.s_faces.len() / 8)
    }

    fn black_count(&self) -> usize {
        self.s_faces.iter().filter(|f| f.is_black).count()
    }

    /// The clear body, and per triangle whether it is a face it shares with
    /// a band (which absorbs).
    fn clear(&self) -> (Body<'_>, Vec<bool>) {
        let (pos, pb) = (&self.dm.mesh.positions, self.pb);
        let (upper_count, black_count) = (self.upper_count(), self.black_count());
        let (sides, margin) = self.sides_and_margin();
        let mut clear = Body::new(
            pos,
            pb,
            upper_count + self.s_faces.len() + 2 * black_count + sides + margin,
        );
        let mut on_band: Vec<bool> = Vec::new();
        self.upper(&mut clear);
        for &SFace {
            t,
            is_black,
            k,
            across,
        } in self.s_faces
        {
            // s faces down in the device mesh; the backing's bottom does too
            clear.triangle(
                t,
                Layer::Bottom,
                false,
                BodyFace::Section {
                    k,
                    layer: Layer::Bottom,
                },
            );
            if is_black {
                mark(&clear, &mut on_band, false);
                clear.triangle(
                    t,
                    Layer::Top,
                    false,
                    BodyFace::Section {
                        k,
                        layer: Layer::Top,
                    },
                );
                clear.triangle(
                    t,
                    Layer::BandBottom,
                    true,
                    BodyFace::Section {
                        k,
                        layer: Layer::BandBottom,
                    },
                );
                mark(&clear, &mut on_band, true);
            }
            for (edge, other) in edges(t).zip(across) {
                match other {
                    // interior edge of s: a band side where black meets clear
                    Some(other) => {
                        if is_black && !other {
                            mark(&clear, &mut on_band, false);
                            let side = self.band_side(edge.0, edge.1);
                            clear.quad(edge, Layer::Top, Layer::BandBottom, true, side);
                            mark(&clear, &mut on_band, true);
                        }
                    }
                    // on the outline: the lower wall
                    None => {
                        let w = self.wall(edge.0, edge.1);
                        if !is_black {
                            clear.quad(edge, Layer::Top, Layer::BandBottom, false, w);
                        }
                        clear.quad(edge, Layer::BandBottom, Layer::Bottom, false, w);
                    }
                }
            }
        }
        mark(&clear, &mut on_band, false);
        (clear, on_band)
    }

    /// The black bands.
    fn black(&self) -> Body<'_> {
        let (pos, pb) = (&self.dm.mesh.positions, self.pb);
        let black_count = self.black_count();
        let (sides, margin) = self.sides_and_margin();
        let mut black = Body::new(pos, pb, 2 * black_count + sides + margin);
        for &SFace {
            t,
            is_black,
            k,
            across,
        } in self.s_faces.iter().filter(|f| f.is_black)
        {
            black.triangle(
                t,
                Layer::Top,
                true,
                BodyFace::Section {
                    k,
                    layer: Layer::Top,
                },
            );
            black.triangle(
                t,
                Layer::BandBottom,
                false,
                BodyFace::Section {
                    k,
                    layer: Layer::BandBottom,
                },
            );
            for (edge, other) in edges(t).zip(across) {
                let face = match other {
                    Some(true) => continue,
                    Some(false) => self.band_side(edge.0, edge.1),
                    None => self.wall(edge.0, edge.1),
                };
                debug_assert!(is_black);
                black.quad(edge, Layer::Top, Layer::BandBottom, false, face);
            }
        }
        black
    }

    /// The whole device, clear and black together, as one solid.
    fn slab(&self) -> Body<'_> {
        let (pos, pb) = (&self.dm.mesh.positions, self.pb);
        let upper_count = self.upper_count();
        let (_, margin) = self.sides_and_margin();
        let mut slab = Body::new(pos, pb, upper_count + self.s_faces.len() + margin);
        self.upper(&mut slab);
        for &SFace { t, k, across, .. } in self.s_faces {
            slab.triangle(
                t,
                Layer::Bottom,
                false,
                BodyFace::Section {
                    k,
                    layer: Layer::Bottom,
                },
            );
            for (edge, other) in edges(t).zip(across) {
                if other.is_none() {
                    slab.quad(
                        edge,
                        Layer::Top,
                        Layer::Bottom,
                        false,
                        self.wall(edge.0, edge.1),
                    );
                }
            }
        }
        slab
    }
}

/// The band layer's xy area and its black part, over the whole layer and
/// over whole periods only (the walls cut the first and last period of
/// each line anywhere): `[layer, black, layer whole, black whole]`.
fn band_areas(design: &Design, pos: &[DVec3], s_faces: &[SFace]) -> [f64; 4] {
    let (mut layer_area, mut black_area) = (0.0, 0.0);
    // per period m: xy area of its band, of all of it, and whether it meets an x-wall
    let mut periods: std::collections::BTreeMap<i64, (f64, f64, bool)> = Default::default();
    let (xl, xr) = design.outline_x;
    for &SFace { t, is_black, k, .. } in s_faces {
        let area = xy_area(pos, &t);
        layer_area += area;
        let period = periods.entry(k.div_euclid(2)).or_default();
        period.1 += area;
        if is_black {
            period.0 += area;
            black_area += area;
        }
        period.2 |= t.iter().any(|&v| {
            let x = pos[v as usize].x;
            (x - xl).abs() <= WALL_SNAP_MM || (x - xr).abs() <= WALL_SNAP_MM
        });
    }
    let whole = periods.values().filter(|p| !p.2);
    let (black_area_whole, layer_area_whole) =
        whole.fold((0.0, 0.0), |(b, l), p| (b + p.0, l + p.1));
    [layer_area, black_area, layer_area_whole, black_area_whole]
}

/// The edges a→b of triangle `t`, in order.
fn edges(t: [u32; 3]) -> impl Iterator<Item = (u32, u32)> {
    (0..3).map(move |e| (t[e], t[(e + 1) % 3]))
}

/// A triangle of s with its section and, per edge a→b, the colour of the
/// triangle across it (None on the outline).
#[derive(Clone, Copy)]
struct SFace {
    t: [u32; 3],
    is_black: bool,
    k: i64,
    across: [Option<bool>; 3],
}

/// Directed edges a→b of a triangle set, each with a value, looked up by
/// scanning a's few outgoing edges (CSR by a).
struct EdgeMap<T> {
    start: Vec<u32>,
    to: Vec<(u32, T)>,
}

impl<T: Copy + Default> EdgeMap<T> {
    fn new(vertices: usize, triangles: &[([u32; 3], T)]) -> Self {
        let mut start = vec![0u32; vertices + 1];
        for (t, _) in triangles {
            for &a in t {
                start[a as usize + 1] += 1;
            }
        }
        for i in 0..vertices {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut to = vec![(0u32, T::default()); start[vertices] as usize];
        for (t, value) in triangles {
            for e in 0..3 {
                let a = t[e] as usize;
                to[fill[a] as usize] = (t[(e + 1) % 3], *value);
                fill[a] += 1;
            }
        }
        EdgeMap { start, to }
    }

    fn get(&self, a: u32, b: u32) -> Option<T> {
        let a = a as usize;
        self.to[self.start[a] as usize..self.start[a + 1] as usize]
            .iter()
            .find(|(to, _)| *to == b)
            .map(|(_, v)| *v)
    }
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (a, b) = (find(parent, a), find(parent, b));
    parent[a.max(b) as usize] = a.min(b);
}

/// Connected shells of the black mesh and, per shell, the number of
/// separate places where it meets the walls (connected groups of end caps).
/// `origin` is the device-mesh vertex under each black vertex (and its layer).
fn shells_and_caps(black: &Mesh, origin: &[(u32, Layer)], on_s: &EdgeMap<bool>) -> (u32, Vec<u32>) {
    let n = black.triangles.len() as u32;
    // a vertical quad's triangle has two vertices over one source vertex;
    // it is an end cap when its source edge lies on the outline (one-sided on s)
    let is_cap = |t: &[u32; 3]| {
        let o = t.map(|i| origin[i as usize].0);
        let (a, b) = if o[0] == o[1] {
            (o[0], o[2])
        } else if o[1] == o[2] {
            (o[1], o[0])
        } else if o[0] == o[2] {
            (o[0], o[1])
        } else {
            return false;
        };
        on_s.get(a, b).is_none() || on_s.get(b, a).is_none()
    };
    let caps: Vec<bool> = black.triangles.iter().map(is_cap).collect();
    let indexed: Vec<([u32; 3], u32)> = black
        .triangles
        .iter()
        .enumerate()
        .map(|(ti, t)| (*t, ti as u32))
        .collect();
    let by_edge = EdgeMap::new(black.positions.len(), &indexed);
    // union over shared edges: all triangles (shells), and caps among caps
    let mut shell: Vec<u32> = (0..n).collect();
    let mut cap_group: Vec<u32> = (0..n).collect();
    for (t, ti) in &indexed {
        for e in 0..3 {
            if let Some(tj) = by_edge.get(t[(e + 1) % 3], t[e]) {
                union(&mut shell, *ti, tj);
                if caps[*ti as usize] && caps[tj as usize] {
                    union(&mut cap_group, *ti, tj);
                }
            }
        }
    }
    let mut groups: std::collections::BTreeMap<u32, std::collections::BTreeSet<u32>> =
        Default::default();
    for ti in 0..n {
        let root = find(&mut shell, ti);
        let entry = groups.entry(root).or_default();
        if caps[ti as usize] {
            entry.insert(find(&mut cap_group, ti));
        }
    }
    (
        groups.len() as u32,
        groups.values().map(|g| g.len() as u32).collect(),
    )
}

/// The duty cycle measured on the output along lines y = const over s:
/// the black share of each line between its first and its last band start
/// (whole periods only; the walls cut partial periods at both ends).
#[derive(Clone, Debug, PartialEq)]
pub struct LineDuty {
    /// Black share over all lines' whole periods.
    pub duty: f64,
    /// Worst |line duty − duty| over the lines.
    pub worst_line_deviation: f64,
    /// Lines measured and whole periods crossed in all.
    pub lines: usize,
    pub periods: usize,
}

/// Measures the duty cycle of the bands of `dm` (a printed design's device
/// mesh) along `lines` lines spread over the height, from the bands' top
/// triangles projected on xy.
pub fn duty_along_lines(design: &Design, dm: &DeviceMesh, lines: usize) -> LineDuty {
    let hh = design.half_height;
    let tris = &dm.mesh.triangles;
    let pos = &dm.mesh.positions;
    let black: Vec<[DVec3; 3]> = tris
        .iter()
        .zip(&dm.patches)
        .filter(|(_, p)| matches!(p, Patch::Lens(LensRef::Base(k)) if design.is_black_band(*k)))
        .map(|(t, _)| t.map(|i| pos[i as usize]))
        .collect();
    let target = match design.params.base.kind {
        BaseKind::Printed(pb) => pb.duty,
        BaseKind::DualLens => 0.0,
    };
    // lines in parallel, summed in line order afterwards (deterministic)
    use rayon::prelude::*;
    let per_line: Vec<Option<(f64, f64, usize)>> = (0..lines)
        .into_par_iter()
        .map(|l| {
            let y = -hh + 2.0 * hh * (l as f64 + 0.5) / lines as f64;
            let mut spans: Vec<(f64, f64)> = black
                .iter()
                .filter_map(|t| line_through_triangle(t, y))
                .collect();
            spans.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut merged: Vec<(f64, f64)> = Vec::new();
            for (a, b) in spans {
                match merged.last_mut() {
                    Some(last) if a <= last.1 + 1e-9 => last.1 = last.1.max(b),
                    _ => merged.push((a, b)),
                }
            }
            let (xl, _) = design.outline_x;
            // band starts: left ends not on the left wall
            let starts: Vec<f64> = merged
                .iter()
                .map(|s| s.0)
                .filter(|&x| x > xl + 1e-6)
                .collect();
            if starts.len() < 2 {
                return None;
            }
            let (w0, w1) = (starts[0], *starts.last().unwrap());
            let inside: f64 = merged
                .iter()
                .map(|&(a, b)| (b.min(w1) - a.max(w0)).max(0.0))
                .sum();
            Some((inside, w1 - w0, starts.len() - 1))
        })
        .collect();
    let (mut black_len, mut window_len, mut periods, mut worst) = (0.0, 0.0, 0, 0.0f64);
    for (inside, window, n) in per_line.into_iter().flatten() {
        black_len += inside;
        window_len += window;
        periods += n;
        worst = worst.max((inside / window - target).abs());
    }
    LineDuty {
        duty: if window_len > 0.0 {
            black_len / window_len
        } else {
            f64::NAN
        },
        worst_line_deviation: worst,
        lines,
        periods,
    }
}

/// The x-interval where the line y = `y` crosses triangle `t` projected on xy.
fn line_through_triangle(t: &[DVec3; 3], y: f64) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for e in 0..3 {
        let (a, b) = (t[e], t[(e + 1) % 3]);
        if (a.y - y) * (b.y - y) <= 0.0 && a.y != b.y {
            let x = a.x + (b.x - a.x) * (y - a.y) / (b.y - a.y);
            (lo, hi) = (lo.min(x), hi.max(x));
        }
    }
    (hi > lo).then_some((lo, hi))
}
