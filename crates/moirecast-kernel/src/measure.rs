//! Measurements of a built device, taken from its output geometry and
//! compared with the exact model (METHOD §7.2–§7.3). None of them trusts the
//! mesher's bookkeeping beyond "which lens is this vertex on".

use crate::check::CheckResult;
use crate::design::Design;
use crate::device_mesh::{DeviceMesh, Patch, Side, VertexOrigin};
use crate::lens::circumcircle;
use crate::model::LensRef;
use crate::solve::newton_2d;
use crate::tolerance::WALL_SNAP_MM;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// Range of a measured quantity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    pub min: f64,
    pub max: f64,
}

impl Range {
    fn empty() -> Self {
        Range {
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
        }
    }
    fn add(&mut self, v: f64) {
        self.min = self.min.min(v);
        self.max = self.max.max(v);
    }
    fn merge(self, o: Range) -> Range {
        Range {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }
}

/// Revealer lens geometry measured from mesh vertices on station rows: each
/// such row of a lens is sampled from one exact arc, so the circle through
/// its two crease vertices and its middle vertex is the lens's circle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LensStats {
    /// Chord between neighbouring creases (mm).
    pub pitch: Range,
    pub radius: Range,
    /// Angle the arc subtends at its centre (degrees).
    pub afov_deg: Range,
    pub sag: Range,
    /// Focal depth below the pitch surface, D = n·r/(n − 1) − s (mm).
    pub focal_depth: Range,
    /// Largest distance of any row vertex from its fitted circle (mm).
    pub circle_residual: f64,
    /// Arcs measured.
    pub arcs: usize,
}

pub fn revealer_lens_stats(design: &Design, dm: &DeviceMesh) -> LensStats {
    let rows = dm.revealer_rows.len();
    let n_l = design.params.lens.index;
    let per_row: Vec<LensStats> = (1..rows.saturating_sub(1))
        .into_par_iter()
        .map(|r| {
            let mut s = LensStats {
                pitch: Range::empty(),
                radius: Range::empty(),
                afov_deg: Range::empty(),
                sag: Range::empty(),
                focal_depth: Range::empty(),
                circle_residual: 0.0,
                arcs: 0,
            };
            let station = dm.revealer_rows[r];
            for (i, &cols) in dm.revealer_columns.iter().enumerate() {
                let p = |j: usize| dm.mesh.positions[dm.revealer_vertex(r, i, j) as usize];
                // rows next to a wall that a leaning lens reaches past are
                // solved onto heights, not at one station: no arcs
                let on_station = (0..=cols).all(|j| {
                    dm.origins[dm.revealer_vertex(r, i, j) as usize]
                        .params_on(LensRef::Revealer(i as i64))
                        .is_some_and(|q| q.y == station)
                });
                if !on_station {
                    continue;
                }
                let (a, m, b) = (p(0), p(cols / 2), p(cols));
                let Some((c, rad)) = circumcircle(a, m, b) else {
                    continue;
                };
                let w = (b - a).length();
                let afov = (a - c).angle_between(b - c);
                let sag = rad - (rad * rad - w * w / 4.0).max(0.0).sqrt();
                s.pitch.add(w);
                s.radius.add(rad);
                s.afov_deg.add(afov.to_degrees());
                s.sag.add(sag);
                s.focal_depth.add(n_l * rad / (n_l - 1.0) - sag);
                for j in 0..=cols {
                    s.circle_residual = s.circle_residual.max(((p(j) - c).length() - rad).abs());
                }
                s.arcs += 1;
            }
            s
        })
        .collect();
    per_row.into_iter().fold(
        LensStats {
            pitch: Range::empty(),
            radius: Range::empty(),
            afov_deg: Range::empty(),
            sag: Range::empty(),
            focal_depth: Range::empty(),
            circle_residual: 0.0,
            arcs: 0,
        },
        |a, b| LensStats {
            pitch: a.pitch.merge(b.pitch),
            radius: a.radius.merge(b.radius),
            afov_deg: a.afov_deg.merge(b.afov_deg),
            sag: a.sag.merge(b.sag),
            focal_depth: a.focal_depth.merge(b.focal_depth),
            circle_residual: a.circle_residual.max(b.circle_residual),
            arcs: a.arcs + b.arcs,
        },
    )
}

/// "every vertex" or "every 7th vertex".
fn every(stride: usize, what: &str) -> String {
    match stride.max(1) {
        1 => format!("every {what}"),
        n => format!("every {n}th {what}"),
    }
}

/// Which lens a vertex lies on (for a crease: the lens to its right, or the
/// last lens for the last crease).
fn lens_of(design: &Design, o: &VertexOrigin) -> LensRef {
    match *o {
        VertexOrigin::RevealerCrease { i, .. } => {
            LensRef::Revealer(i.min(design.lenses as i64 - 1))
        }
        VertexOrigin::RevealerLens { i, .. } => LensRef::Revealer(i),
        VertexOrigin::BaseCrease { k, .. } => LensRef::Base(k.min(design.base_creases.1 - 1)),
        VertexOrigin::BaseLens { k, .. } => LensRef::Base(k),
    }
}

/// How far outside its lens's parameter range [0, 1] a re-projected
/// vertex may land (round-off at the creases).
const ON_LENS_SLACK: f64 = 1e-6;

/// Where on its lens (t across) the vertical re-projection of a vertex
/// starts: the middle first, then the two creases. On a steep lens over a
/// strongly curved base the lens may overhang, so that two of its points
/// share x and y; the vertex lies on the lens if any of them is its point,
/// and the smallest gap is the measure.
const REPROJECTION_STARTS: [f64; 3] = [0.5, 0.0, 1.0];

/// Distance (mm) from every `stride`-th vertex to its exact lens surface,
/// found afresh: solve the lens parameters (t, v) whose point has the
/// vertex's x and y, and measure the gap along the lens's normal there.
/// Each solve starts at a point across the lens (`REPROJECTION_STARTS`) at
/// the station whose point there has the vertex's y, so that on a steep
/// lens it finds a point of the lens itself, not one of the arc's circle
/// continued past a crease; a solution off the lens (t outside [0, 1])
/// does not count, and a vertex with no solution on its lens fails.
pub fn vertex_on_surface(design: &Design, dm: &DeviceMesh, stride: usize) -> CheckResult {
    let worst = (0..dm.mesh.positions.len())
        .into_par_iter()
        .step_by(stride.max(1))
        .map(|vi| {
            let p = dm.mesh.positions[vi];
            let lens = lens_of(design, &dm.origins[vi]);
            let mut dist = f64::INFINITY;
            for t0 in REPROJECTION_STARTS {
                dist = dist.min(normal_gap(design, lens, p, t0));
                if dist <= VERTEX_ON_SURFACE_MM {
                    break;
                }
            }
            (dist, vi)
        })
        .reduce(
            || (0.0, 0),
            |a, b| {
                if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }
            },
        );
    let p = dm.mesh.positions[worst.1];
    CheckResult::at_most(
        "vertex-on-surface",
        worst.0,
        VERTEX_ON_SURFACE_MM,
        "mm",
        format!(
            "{} re-projected; worst at ({:.3}, {:.3}, {:.3})",
            every(stride, "vertex"),
            p.x,
            p.y,
            p.z
        ),
    )
}

/// The limit of `vertex-on-surface`: a vertex is a solved point of its
/// lens, so only round-off separates it from the surface.
const VERTEX_ON_SURFACE_MM: f64 = 1e-9;

/// Distance from `p` to `lens`, measured along the lens's normal at the
/// lens point with p's x and y, solved from `t0` across the lens; infinite
/// when the solve fails or lands off the lens. The normal, not z: where the
/// lens is nearly vertical, a round-off step in x or y is a large step in z.
fn normal_gap(design: &Design, lens: LensRef, p: DVec3, t0: f64) -> f64 {
    let station = design
        .solve_station_for_y(lens, t0, p.y, p.y)
        .unwrap_or(p.y);
    let solved = newton_2d(DVec2::new(t0, station), &|| String::new(), |q| {
        design
            .lens_point(lens, q.x, q.y)
            .map(|s| DVec2::new(s.x - p.x, s.y - p.y))
            .unwrap_or(DVec2::NAN)
    });
    let gap = |q: DVec2| -> Option<f64> {
        let s = design.lens_point(lens, q.x, q.y).ok()?;
        let along_t = design.lens_point(lens, q.x + NORMAL_STEP, q.y).ok()?
            - design.lens_point(lens, q.x - NORMAL_STEP, q.y).ok()?;
        let along_v = design.lens_point(lens, q.x, q.y + NORMAL_STEP).ok()?
            - design.lens_point(lens, q.x, q.y - NORMAL_STEP).ok()?;
        let normal = along_t.cross(along_v).try_normalize()?;
        Some((s - p).dot(normal).abs())
    };
    match solved {
        Ok(q) if (-ON_LENS_SLACK..=1.0 + ON_LENS_SLACK).contains(&q.x) => {
            gap(q).unwrap_or(f64::INFINITY)
        }
        _ => f64::INFINITY,
    }
}

/// Parameter step of the central differences that give a lens's normal in
/// `normal_gap`; the normal only projects a gap of round-off size, so its
/// own error of order step² does not matter.
const NORMAL_STEP: f64 = 1e-5;

/// Barycentric sample points inside a triangle.
const SAMPLES: [[f64; 3]; 7] = [
    [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
    [0.5, 0.5, 0.0],
    [0.0, 0.5, 0.5],
    [0.5, 0.0, 0.5],
    [2.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0],
    [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0],
    [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
];

/// Closest point to `p` on triangle (a, b, c).
///
/// Built from quantities that keep their precision on slivers: the plane's
/// normal, one side test per edge, and a projection onto each edge.
/// Ericson's barycentric form (Real-Time Collision Detection §5.1.5)
/// subtracts products of the order of an edge's fourth power; on a
/// triangle 394 mm long and 1.6 µm wide that cancellation moved its answer
/// 0.34 µm off the triangle, farther than the point it was given
/// (found-666d48bc6a77002c).
pub fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let normal = (b - a).cross(c - a);
    let inside = |from: DVec3, to: DVec3| (to - from).cross(p - from).dot(normal) >= 0.0;
    let area2 = normal.length_squared();
    if area2 > 0.0 && inside(a, b) && inside(b, c) && inside(c, a) {
        return p - normal * (normal.dot(p - a) / area2);
    }
    [(a, b), (b, c), (c, a)]
        .into_iter()
        .map(|(from, to)| closest_on_segment(p, from, to))
        .min_by(|x, y| {
            (*x - p)
                .length_squared()
                .total_cmp(&(*y - p).length_squared())
        })
        .unwrap_or(a)
}

/// Closest point to `p` on the segment from `a` to `b`.
pub fn closest_on_segment(p: DVec3, a: DVec3, b: DVec3) -> DVec3 {
    let ab = b - a;
    let len2 = ab.length_squared();
    if len2 == 0.0 {
        return a;
    }
    a + ab * ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
}

/// Upper bound on the distance from the exact lens surfaces to the mesh
/// (mm), sampled on every `stride`-th lens triangle: exact points at
/// parameters interpolated over the triangle are measured against that
/// triangle, which is part of the mesh, so the true distance to the mesh can
/// only be smaller. A point farther than the tolerance from its own
/// triangle is measured against every triangle that shares a vertex with
/// it, still part of the mesh: on a long, thin triangle the point of
/// interpolated parameters can lie beside its own triangle, over a
/// neighbour (found-9363d5ee1df920e3: 1.43 µm from its own triangle, 0.74
/// µm from the mesh, against 0.96). A point of interpolated parameters
/// can also lie beyond the outline, where the exact surface is trimmed off
/// the device: between two vertices on a wall, the parameters' chord of
/// the curved trim runs outside it (found-becba66478b67e96: 0.95 µm beyond
/// the x-wall of a base 7.7 mm under a saddle). Such a point is not on the
/// device and is not measured.
pub fn surface_to_mesh(design: &Design, dm: &DeviceMesh, stride: usize) -> CheckResult {
    let tri = &dm.mesh.triangles;
    let (xl, xr) = design.outline_x;
    let on_device = |p: DVec3| p.x >= xl && p.x <= xr && p.y.abs() <= design.half_height;
    let tolerance = design.tolerance.mm();
    // vertex → the triangles around it, built only if a point needs it
    let around: std::sync::OnceLock<Vec<Vec<u32>>> = std::sync::OnceLock::new();
    let around = || {
        around.get_or_init(|| {
            let mut around = vec![Vec::new(); dm.mesh.positions.len()];
            for (t, corners) in tri.iter().enumerate() {
                for &v in corners {
                    around[v as usize].push(t as u32);
                }
            }
            around
        })
    };
    let distance = |p: DVec3, t: usize| {
        let c = tri[t].map(|v| dm.mesh.positions[v as usize]);
        (p - closest_on_triangle(p, c[0], c[1], c[2])).length()
    };
    let worst = (0..tri.len())
        .into_par_iter()
        .step_by(stride.max(1))
        .filter_map(|ti| {
            let Patch::Lens(lens) = dm.patches[ti] else {
                return None;
            };
            let idx = tri[ti];
            let params: Vec<DVec2> = idx
                .iter()
                .map(|&v| dm.origins[v as usize].params_on(lens))
                .collect::<Option<_>>()?;
            let pts = idx.map(|v| dm.mesh.positions[v as usize]);
            let mut worst = (0.0f64, DVec3::ZERO);
            for b in SAMPLES {
                let q = params[0] * b[0] + params[1] * b[1] + params[2] * b[2];
                let m = pts[0] * b[0] + pts[1] * b[1] + pts[2] * b[2];
                let Ok(p) = design.lens_point(lens, q.x, q.y) else {
                    return Some((f64::INFINITY, m));
                };
                if !on_device(p) {
                    continue;
                }
                let mut d = distance(p, ti);
                if d > tolerance {
                    let ring = idx.iter().flat_map(|&v| around()[v as usize].iter());
                    d = ring.fold(d, |d, &t| d.min(distance(p, t as usize)));
                }
                if d > worst.0 {
                    worst = (d, m);
                }
            }
            Some(worst)
        })
        .reduce(
            || (0.0, DVec3::ZERO),
            |a, b| {
                if b.0 > a.0 || (b.0 == a.0 && (b.1.x, b.1.y) < (a.1.x, a.1.y)) {
                    b
                } else {
                    a
                }
            },
        );
    CheckResult::at_most(
        "surface-to-mesh",
        worst.0,
        tolerance,
        "mm",
        format!(
            "7 samples on {}; worst near ({:.3}, {:.3}, {:.3})",
            every(stride, "lens triangle"),
            worst.1.x,
            worst.1.y,
            worst.1.z
        ),
    )
}

/// Base creases follow E (METHOD §7.3): for every `stride`-th base crease
/// vertex, find the layout point (u, v) whose base surface point has the
/// vertex's x and y, and measure how far its phase φ(u, v) is from the
/// crease's whole number.
pub fn base_creases_follow_shift(design: &Design, dm: &DeviceMesh, stride: usize) -> CheckResult {
    let creases: Vec<(usize, i64)> = dm
        .origins
        .iter()
        .enumerate()
        .filter_map(|(vi, o)| match *o {
            VertexOrigin::BaseCrease { k, .. } => Some((vi, k)),
            _ => None,
        })
        .collect();
    let worst = creases
        .par_iter()
        .step_by(stride.max(1))
        .map(|&(vi, k)| {
            let p = dm.mesh.positions[vi];
            let q = newton_2d(DVec2::new(p.x, p.y), &|| String::new(), |q| {
                let s = design.base_surface(q.x, q.y);
                DVec2::new(s.x - p.x, s.y - p.y)
            });
            let err = match q {
                Ok(q) => (design.base_phase(q.x, q.y) - design.crease_phase(k))
                    .abs()
                    .max((design.base_surface(q.x, q.y).z - p.z).abs() / design.params.period),
                Err(_) => f64::INFINITY,
            };
            (err, vi)
        })
        .reduce(
            || (0.0, 0),
            |a, b| {
                if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }
            },
        );
    let p = dm.mesh.positions.get(worst.1).cloned().unwrap_or_default();
    CheckResult::at_most(
        "base-creases-follow-shift",
        worst.0,
        1e-8,
        "periods",
        format!(
            "|φ − crease phase| at {}; worst near ({:.3}, {:.3})",
            every(stride, "base crease or band edge vertex"),
            p.x,
            p.y
        ),
    )
}

/// Every wall vertex lies on its wall plane, to within [`WALL_SNAP_MM`]: a
/// base crease that passes closer than that to a wall (it may touch it
/// tangentially) is taken as lying on it, so no sliver triangles appear.
pub fn walls_on_outline(design: &Design, dm: &DeviceMesh) -> CheckResult {
    let (xl, xr) = design.outline_x;
    let hh = design.half_height;
    let mut worst = (0.0f64, DVec3::ZERO, Side::Left, 0u32);
    for (t, patch) in dm.mesh.triangles.iter().zip(&dm.patches) {
        let Patch::Wall(side) = patch else { continue };
        for &v in t {
            let p = dm.mesh.positions[v as usize];
            let d = match side {
                Side::Left => p.x - xl,
                Side::Right => p.x - xr,
                Side::Front => p.y + hh,
                Side::Back => p.y - hh,
            };
            if d.abs() > worst.0 {
                worst = (d.abs(), p, *side, v);
            }
        }
    }
    let (d, p, side, v) = worst;
    CheckResult::at_most(
        "walls-on-outline",
        d,
        WALL_SNAP_MM,
        "mm",
        format!("distance of wall vertices from their wall planes; worst on the {side:?} wall at ({:.4}, {:.4}, {:.4}), {:?}", p.x, p.y, p.z, dm.origins[v as usize]),
    )
}

/// Every wall triangle faces out of the device through its wall: none is
/// folded over its neighbours, which would leave the wall overlapping
/// itself in its plane (closed and oriented, yet not a simple surface; the
/// mold's cavity would lose the overlapped area).
pub fn walls_face_out(dm: &DeviceMesh) -> CheckResult {
    let mut folded = 0usize;
    let mut worst = (f64::INFINITY, DVec3::ZERO, Side::Left);
    for (t, patch) in dm.mesh.triangles.iter().zip(&dm.patches) {
        let Patch::Wall(side) = patch else { continue };
        let outward = match side {
            Side::Left => DVec3::NEG_X,
            Side::Right => DVec3::X,
            Side::Front => DVec3::NEG_Y,
            Side::Back => DVec3::Y,
        };
        let [a, b, c] = t.map(|v| dm.mesh.positions[v as usize]);
        let facing = (b - a).cross(c - a).dot(outward);
        if facing <= 0.0 {
            folded += 1;
        }
        if facing < worst.0 {
            worst = (facing, (a + b + c) / 3.0, *side);
        }
    }
    let (facing, p, side) = worst;
    CheckResult::at_most(
        "walls-face-out",
        folded as f64,
        0.0,
        "triangles",
        format!(
            "wall triangles whose normal points into the device; least outward (twice the area {facing:.3e} mm²) on the {side:?} wall near ({:.3}, {:.3}, {:.3})",
            p.x, p.y, p.z
        ),
    )
}

/// Neighbouring revealer lenses share their creases: the arc formula of
/// lens i at its right end and of lens i+1 at its left end meet (checked at
/// every station row), and the mesh uses one vertex for both.
pub fn creases_shared(design: &Design, dm: &DeviceMesh) -> CheckResult {
    let mut worst = 0.0f64;
    let mut unshared = 0usize;
    let last = dm.revealer_rows.len() - 1;
    let mut lens_tris = vec![0usize; dm.mesh.positions.len()];
    for (t, patch) in dm.mesh.triangles.iter().zip(&dm.patches) {
        if let Patch::Lens(LensRef::Revealer(i)) = patch {
            for &v in t {
                lens_tris[v as usize] |= 1 << (i % 2);
            }
        }
    }
    for r in 1..last {
        let v = dm.revealer_rows[r];
        for i in 0..design.lenses.saturating_sub(1) {
            let left = design.revealer_arc(i as i64, v).point_by_formula(1.0);
            let right = design.revealer_arc(i as i64 + 1, v).point_by_formula(0.0);
            worst = worst.max((left - right).length());
            let shared = dm.revealer_vertex(r, i + 1, 0);
            if lens_tris[shared as usize] != 0b11 {
                unshared += 1;
            }
        }
    }
    CheckResult::at_most(
        "creases-shared",
        worst + unshared as f64,
        1e-12,
        "mm",
        format!("largest gap between neighbouring arc ends; {unshared} crease vertices not used by both lenses"),
    )
}

/// E over the layout Ω, sampled on a 101 × 101 grid (mm).
pub fn shift_range(design: &Design) -> Range {
    let mut r = Range::empty();
    let (hw, hh) = (design.params.width / 2.0, design.half_height);
    for j in 0..=100 {
        for i in 0..=100 {
            r.add(design.shift(
                -hw + 2.0 * hw * i as f64 / 100.0,
                -hh + 2.0 * hh * j as f64 / 100.0,
            ));
        }
    }
    r
}

/// No self-intersection, part 1 (METHOD §7.1): both lens surfaces are graphs
/// over xy. Every revealer triangle must face up and every base triangle
/// down in projection; with the consistent orientation and the outline
/// boundary, a surface whose triangles all project positively cannot fold
/// over itself. Counts the triangles that do not.
pub fn surfaces_are_graphs(dm: &DeviceMesh) -> CheckResult {
    let (bad, worst) = dm
        .mesh
        .triangles
        .par_iter()
        .zip(&dm.patches)
        .enumerate()
        .filter_map(|(i, (t, patch))| {
            let sign = match patch {
                Patch::Lens(LensRef::Revealer(_)) => 1.0,
                Patch::Lens(LensRef::Base(_)) => -1.0,
                Patch::Wall(_) => return None,
            };
            let [a, b, c] = t.map(|v| dm.mesh.positions[v as usize]);
            let projected = (b - a).truncate().perp_dot((c - a).truncate()) * sign;
            (projected <= 0.0).then_some(i)
        })
        .fold(|| (0usize, usize::MAX), |(n, w), i| (n + 1, w.min(i)))
        .reduce(|| (0, usize::MAX), |a, b| (a.0 + b.0, a.1.min(b.1)));
    let at = dm
        .mesh
        .triangles
        .get(worst)
        .map(|t| dm.mesh.positions[t[0] as usize])
        .unwrap_or_default();
    CheckResult::at_most(
        "surfaces-are-graphs",
        bad as f64,
        0.0,
        "triangles",
        if bad == 0 {
            "every lens triangle projects with the orientation of its surface".into()
        } else {
            format!("first fold-over near ({:.3}, {:.3})", at.x, at.y)
        },
    )
}

/// No self-intersection, part 2: the revealer lies above the base. At every
/// `stride`-th base vertex, the exact revealer height at the same x, y is
/// solved afresh; reports the smallest thickness (mm), which must be positive.
pub fn min_thickness(design: &Design, dm: &DeviceMesh, stride: usize) -> CheckResult {
    let crease_x: Vec<f64> = (0..=design.lenses as i64)
        .map(|i| design.crease_point(i, 0.0).x)
        .collect();
    let (thin, at) = (0..dm.mesh.positions.len())
        .into_par_iter()
        .step_by(stride.max(1))
        .filter(|&v| {
            matches!(
                dm.origins[v],
                VertexOrigin::BaseCrease { .. } | VertexOrigin::BaseLens { .. }
            )
        })
        .map(|v| {
            let p = dm.mesh.positions[v];
            let i = (crease_x.partition_point(|&x| x <= p.x).saturating_sub(1))
                .min(design.lenses - 1) as i64;
            let t0 = ((p.x - crease_x[i as usize])
                / (crease_x[i as usize + 1] - crease_x[i as usize]))
                .clamp(0.0, 1.0);
            let top = newton_2d(DVec2::new(t0, p.y), &String::new, |q| {
                let s = design.revealer_point(i, q.x, q.y);
                DVec2::new(s.x - p.x, s.y - p.y)
            })
            .map(|q| design.revealer_point(i, q.x, q.y).z)
            .unwrap_or(f64::NEG_INFINITY);
            (top - p.z, p)
        })
        .reduce(
            || (f64::INFINITY, DVec3::ZERO),
            |a, b| {
                if b.0 < a.0 || (b.0 == a.0 && (b.1.x, b.1.y) < (a.1.x, a.1.y)) {
                    b
                } else {
                    a
                }
            },
        );
    CheckResult::at_least(
        "min-thickness",
        thin,
        design.tolerance.mm(),
        "mm",
        format!(
            "revealer above base at {}; thinnest at ({:.3}, {:.3})",
            every(stride, "base vertex"),
            at.x,
            at.y
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::closest_on_triangle;
    use glam::DVec3;
    use proptest::prelude::*;

    fn vec3() -> impl Strategy<Value = DVec3> {
        (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64).prop_map(|(x, y, z)| DVec3::new(x, y, z))
    }

    proptest! {
        /// A point straight above a triangle's point is its height away,
        /// on slivers down to a millionth as wide as long: the device's
        /// long lenses make such triangles (found-666d48bc6a77002c).
        #[test]
        fn a_point_above_a_sliver_is_its_height_away(
            a in vec3(),
            along in vec3(),
            across in vec3(),
            length in 1.0..400.0f64,
            log_width in -6.0..0.0f64,
            (s, r) in (0.0..1.0f64, 0.0..1.0f64),
            height in -1e-3..1e-3f64,
        ) {
            prop_assume!(along.length() > 0.1 && along.cross(across).length() > 0.1);
            let along = along.normalize();
            let across = along.cross(across).cross(along).normalize();
            let b = a + along * length;
            let c = a + along * (0.3 * length) + across * (length * 10f64.powf(log_width));
            let (s, r) = if s + r > 1.0 { (1.0 - s, 1.0 - r) } else { (s, r) };
            let on = a + (b - a) * s + (c - a) * r;
            let normal = (b - a).cross(c - a).normalize();
            let p = on + normal * height;
            let d = (closest_on_triangle(p, a, b, c) - p).length();
            prop_assert!((d - height.abs()).abs() <= 1e-9 * length, "{d} vs {height}");
        }

        /// No point of the triangle is nearer than the answer.
        #[test]
        fn no_point_of_the_triangle_is_nearer(a in vec3(), b in vec3(), c in vec3(), p in vec3()) {
            let d = (closest_on_triangle(p, a, b, c) - p).length();
            for i in 0..=16 {
                for j in 0..=16 - i {
                    let q = a + (b - a) * (i as f64 / 16.0) + (c - a) * (j as f64 / 16.0);
                    prop_assert!(d <= (q - p).length() + 1e-12);
                }
            }
        }
    }
}
