//! Where the mold's features go (METHOD §6): gate and runner, sprue and pour
//! cone, vents at the ceiling's maxima, registration keys, bolt holes. Each
//! placement is checked against the device and the block here, before any
//! boolean runs, so a misfit is an error that names the parameter and place.

use crate::boolean::{channel_section, QUARTER_FACET_DEG};
use crate::error::{MoldError, MoldParam, Result};
use crate::params::{MoldParams, MIN_WALL_MM};
use crate::parting::{HeightQuery, Polyline, PosedDevice, Rect, Wall, WallCurves};
use glam::{DVec2, DVec3};
use moirecast_kernel::Design;

/// Grid nodes per side for finding the ceiling's maxima and the gate.
const SURVEY_NODES: usize = 65;
/// Gap (mm) kept between the runner and the wall's top and bottom edges.
const GATE_EDGE_GAP_MM: f64 = 0.05;
/// How far (mm) the runner reaches into the cavity, so the two touch in a
/// volume, not along a face.
const RUNNER_INTO_CAVITY_MM: f64 = 0.02;
/// How far (mm) the sprue reaches below the lowest point of the skirt
/// under it, so that it opens through the parting surface in one disk.
const SPRUE_BELOW_SKIRT_MM: f64 = 0.05;

/// Clearance of a vent's foot under the cavity's ceiling and above the
/// skirt or the floor, where the ceiling's ripple moves the foot (mm).
const VENT_FOOT_GAP_MM: f64 = 0.02;

/// Rings and spokes of the samples over a vent's disk.
const VENT_DISK_RINGS: usize = 8;
const VENT_DISK_SPOKES: usize = 48;

/// The gate on the device's wall at the parting line, the runner that feeds
/// it and the sprue above the runner's far end.
#[derive(Clone, Debug)]
pub struct Gate {
    pub wall: Wall,
    /// Centre of the gate: on the wall, at the mid-wall height.
    pub at: DVec3,
    pub radius: f64,
    /// Where the runner meets the sprue's axis.
    pub sprue_axis: DVec2,
    pub sprue_radius: f64,
    /// The sprue runs from here (the runner's floor) to the top face.
    pub sprue_bottom_z: f64,
    pub cone_radius: f64,
    pub cone_depth: f64,
}

/// Where a vent attaches to the cavity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VentPlace {
    /// At the top of a wall: the stub is on the wall, off the optics.
    Wall(Wall),
    /// At a corner of the outline.
    Corner,
    /// Inside the outline: the stub is on the lenses.
    Lenses,
}

#[derive(Clone, Debug)]
pub struct Vent {
    /// The ceiling maximum this vent serves.
    pub maximum: DVec3,
    pub place: VentPlace,
    pub axis: DVec2,
    pub radius: f64,
    /// Bottom of the vent column; it rises to the top face.
    pub foot_z: f64,
}

/// A registration key: a tapered bump on the bottom half's skirt and a
/// socket with clearance in the top half.
#[derive(Clone, Debug)]
pub struct Key {
    /// Centre of the key's base, on the skirt.
    pub at: DVec3,
}

/// Everything placed, in the mold frame.
#[derive(Clone, Debug)]
pub struct Features {
    pub block_lo: DVec3,
    pub block_hi: DVec3,
    pub gate: Gate,
    pub vents: Vec<Vent>,
    pub keys: Vec<Key>,
    pub bolts: Vec<DVec2>,
    pub warnings: Vec<String>,
}

fn misfit(
    check: &'static str,
    param: Option<MoldParam>,
    at: DVec3,
    problem: String,
    fix: String,
) -> MoldError {
    MoldError::DoesNotFit {
        check,
        param,
        at,
        problem,
        fix,
    }
}

/// The sprue's bottom: the runner's floor, or lower where the skirt under
/// the sprue dips below that floor. The skirt carries the gate wall's
/// mid-wall curve `mid` outward, so under the sprue (radius `r_s`, at `t_g`
/// along the wall) it ripples with the lenses it crossed; a sprue that
/// ended above a dip would open through the parting surface in two or
/// more pieces, each a through-hole of the top half (found by the design
/// fuzzer: tests/design-corpus/found-6252d5411ebc9c63.toml).
fn sprue_bottom_z(mid: &Polyline, t_g: f64, (r_g, r_s): (f64, f64), m_g: f64) -> f64 {
    let (skirt_low, _) = mid.range(t_g - r_s, t_g + r_s);
    let runner_floor = m_g - r_g;
    if skirt_low > runner_floor {
        runner_floor
    } else {
        skirt_low - SPRUE_BELOW_SKIRT_MM
    }
}

/// The fix for a gate that does not fit: the widest that does, or, where
/// that is under the smallest gate the spec takes, a thicker device.
fn gate_fix(widest: f64) -> String {
    let smallest = crate::params::limits::GATE_DIAMETER.0;
    let widest = (widest * 100.0).floor() / 100.0;
    if widest >= smallest {
        format!("set mold.gate_diameter to at most {widest:.2} mm")
    } else {
        format!(
            "the walls are too thin there for the smallest gate ({smallest} mm): make the device thicker at its walls (a larger base.d, or deeper lenses)"
        )
    }
}

/// How close (mm) the parting line may pass over the runner's polygon and
/// still count as over it, in [`runner_cuts_island`]: a touch within
/// round-off is taken as a sliver, never as a joint.
const RUNNER_TOUCH_MM: f64 = 1e-4;

/// Whether a runner of radius `r` centred at height `m_g` on the parting
/// line `mid` (carried straight out from the wall, so the same in every
/// cross-section) leaves a loose sliver of a half: the parting line rising
/// over the runner's top (or dipping under its floor) and coming back
/// inside the runner's width. Such a stretch does not reach the runner's
/// sides, where the half's material would hold it (found-71819e0da782288f:
/// a second shell of the bottom half along the runner).
///
/// The runner is the polygon the cut uses, at each turn the cut may take
/// and its mirror image, not its circle: a margin on the circle merged a
/// sliver 1 µm over the polygon with the stretch beside it, 8 µm inside
/// (found-dfeb79e5db90b7e2). The parting line and the polygon's top and
/// floor are both piecewise linear across the width, so their order at the
/// breakpoints of both decides every stretch exactly.
fn runner_cuts_island(mid: &Polyline, t_g: f64, m_g: f64, r: f64) -> bool {
    let half = crate::boolean::HALF_FACET_DEG;
    [0.0, QUARTER_FACET_DEG, -QUARTER_FACET_DEG - 2.0 * half]
        .into_iter()
        .any(|twist| polygon_cuts_island(mid, t_g, m_g, &channel_section(r, twist)))
}

/// [`runner_cuts_island`] for one polygon `section` (across, up) of the
/// runner.
fn polygon_cuts_island(mid: &Polyline, t_g: f64, m_g: f64, section: &[DVec2]) -> bool {
    let (a, b) = section
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.x), hi.max(p.x))
        });
    let mut ts: Vec<f64> = section
        .iter()
        .map(|p| t_g + p.x)
        .chain(
            mid.t
                .iter()
                .copied()
                .filter(|&t| t > t_g + a && t < t_g + b),
        )
        .collect();
    ts.sort_by(f64::total_cmp);
    // +1 over the top, -1 under the floor, 0 inside the polygon
    let sides: Vec<i32> = ts
        .iter()
        .map(|&t| {
            let (floor, top) = polygon_span(section, (t - t_g).clamp(a, b));
            let z = mid.eval(t) - m_g;
            if z > top - RUNNER_TOUCH_MM {
                1
            } else if z < floor + RUNNER_TOUCH_MM {
                -1
            } else {
                0
            }
        })
        .collect();
    // a run of +1 (or -1) that touches neither end of the width is loose
    let (first, last) = (sides[0], sides[sides.len() - 1]);
    let mut k = 0;
    while k < sides.len() {
        let s = sides[k];
        let start = k;
        while k < sides.len() && sides[k] == s {
            k += 1;
        }
        let touches_end = (start == 0 && s == first) || (k == sides.len() && s == last);
        if s != 0 && !touches_end {
            return true;
        }
    }
    false
}

/// The floor and top of the polygon `section` (across, up) at `s` across.
fn polygon_span(section: &[DVec2], s: f64) -> (f64, f64) {
    let mut range = (f64::INFINITY, f64::NEG_INFINITY);
    for (p, q) in section.iter().zip(section.iter().cycle().skip(1)) {
        let (lo, hi) = (p.x.min(q.x), p.x.max(q.x));
        if s < lo || s > hi {
            continue;
        }
        let z = if hi > lo {
            p.y + (q.y - p.y) * (s - p.x) / (q.x - p.x)
        } else {
            p.y.max(q.y)
        };
        range = (range.0.min(z), range.1.max(z));
    }
    range
}

/// A smooth (lens-ripple-free) surface of the posed device on a grid over
/// the layout: the crease surfaces, where the lenses start.
struct Survey {
    /// points[j][i], in the mold frame.
    points: Vec<Vec<DVec3>>,
}

impl Survey {
    fn new(design: &Design, device: &PosedDevice, surface: impl Fn(f64, f64) -> DVec3) -> Self {
        let (w, h) = (design.params.width, design.params.height);
        let n = SURVEY_NODES;
        let points = (0..n)
            .map(|j| {
                let v = -h / 2.0 + h * j as f64 / (n - 1) as f64;
                (0..n)
                    .map(|i| {
                        let u = -w / 2.0 + w * i as f64 / (n - 1) as f64;
                        device.pose(surface(u, v))
                    })
                    .collect()
            })
            .collect();
        Survey { points }
    }

    /// The plateaus of local maxima (nodes no neighbour exceeds, joined
    /// where they tie), each as its nodes (i, j), in scan order.
    fn plateaus(&self) -> Vec<Vec<(usize, usize)>> {
        let n = SURVEY_NODES;
        let z = |i: usize, j: usize| self.points[j][i].z;
        let span_z = {
            let all = self.points.iter().flatten().map(|q| q.z);
            let (a, b) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), z| {
                (a.min(z), b.max(z))
            });
            b - a
        };
        let tie = 1e-9 * (1.0 + span_z);
        let neighbours = |i: usize, j: usize| {
            let mut out = Vec::with_capacity(8);
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    let (ni, nj) = (i as i64 + di, j as i64 + dj);
                    if (di, dj) != (0, 0)
                        && ni >= 0
                        && nj >= 0
                        && (ni as usize) < n
                        && (nj as usize) < n
                    {
                        out.push((ni as usize, nj as usize));
                    }
                }
            }
            out
        };
        let is_max = |i: usize, j: usize| {
            neighbours(i, j)
                .iter()
                .all(|&(a, b)| z(a, b) <= z(i, j) + tie)
        };
        let mut component = vec![usize::MAX; n * n];
        let mut plateaus: Vec<Vec<(usize, usize)>> = Vec::new();
        for j in 0..n {
            for i in 0..n {
                if component[j * n + i] != usize::MAX || !is_max(i, j) {
                    continue;
                }
                let id = plateaus.len();
                let mut members = vec![(i, j)];
                component[j * n + i] = id;
                let mut k = 0;
                while k < members.len() {
                    let (a, b) = members[k];
                    for (c, d) in neighbours(a, b) {
                        if component[d * n + c] == usize::MAX
                            && (z(c, d) - z(a, b)).abs() <= tie
                            && is_max(c, d)
                        {
                            component[d * n + c] = id;
                            members.push((c, d));
                        }
                    }
                    k += 1;
                }
                plateaus.push(members);
            }
        }
        plateaus
    }

    /// The wall a border node lies on (corners: None).
    fn border(&self, i: usize, j: usize) -> Option<Option<Wall>> {
        let last = SURVEY_NODES - 1;
        let on_x = i == 0 || i == last;
        let on_y = j == 0 || j == last;
        match (on_x, on_y) {
            (false, false) => None,
            (true, true) => Some(None),
            _ => {
                // Which wall in the mold frame: read it off the posed point.
                Some(Some(if on_x {
                    let (a, b) = (self.points[j][0].x, self.points[j][last].x);
                    if (self.points[j][i].x - a.min(b)).abs()
                        < (self.points[j][i].x - a.max(b)).abs()
                    {
                        Wall::XMin
                    } else {
                        Wall::XMax
                    }
                } else {
                    let (a, b) = (self.points[0][i].y, self.points[last][i].y);
                    if (self.points[j][i].y - a.min(b)).abs()
                        < (self.points[j][i].y - a.max(b)).abs()
                    {
                        Wall::YMin
                    } else {
                        Wall::YMax
                    }
                }))
            }
        }
    }
}

/// Places and checks every feature: the keys at the skirt's corners, the
/// gate at the mid-wall curve's lowest point with its runner and sprue,
/// a vent at each of the ceiling's maxima, and the optional bolts.
pub fn place(
    design: &Design,
    device: &PosedDevice,
    walls: &[WallCurves],
    upper: &HeightQuery,
    lower: &HeightQuery,
    p: &MoldParams,
) -> Result<Features> {
    let outline = device.outline;
    let (lo, hi) = device.mesh.bounds();
    let tw = p.wall_thickness;
    let site = Site {
        outline,
        block: outline.grown(tw),
        block_lo: crate::boolean::f32_exact(DVec3::new(
            outline.x0 - tw,
            outline.y0 - tw,
            lo.z - tw,
        )),
        block_hi: crate::boolean::f32_exact(DVec3::new(
            outline.x1 + tw,
            outline.y1 + tw,
            hi.z + tw,
        )),
        device_top: hi.z,
        walls,
        p,
        socket_r: p.key_diameter / 2.0 + p.key_clearance,
    };
    // Ceiling (the crease surface under the top half) and the smooth mid
    // surface, free of the ripple of single lenses.
    let revealer = |u: f64, v: f64| design.surface().point(u, v);
    let base = |u: f64, v: f64| design.base_surface(u, v);
    let ceiling = if device.pose.flip {
        Survey::new(design, device, base)
    } else {
        Survey::new(design, device, revealer)
    };
    let mid = Survey::new(design, device, |u, v| 0.5 * (revealer(u, v) + base(u, v)));

    let keys = site.keys()?;
    let gate = site.gate(&mid)?;
    let mut warnings = Vec::new();
    let vents = site.vents(&ceiling, &gate, (upper, lower), &mut warnings)?;
    site.check_columns(&vents, &gate, &keys)?;
    let bolts = if p.bolts {
        site.bolts(&keys, &gate, &vents)?
    } else {
        Vec::new()
    };
    Ok(Features {
        block_lo: site.block_lo,
        block_hi: site.block_hi,
        gate,
        vents,
        keys,
        bolts,
        warnings,
    })
}

/// What every placement needs: the outline, the block and the walls.
struct Site<'a> {
    outline: Rect,
    /// The block's footprint.
    block: Rect,
    block_lo: DVec3,
    block_hi: DVec3,
    /// The highest point of the posed device.
    device_top: f64,
    walls: &'a [WallCurves],
    p: &'a MoldParams,
    /// A key socket's radius, clearance included.
    socket_r: f64,
}

impl Site<'_> {
    fn curve(&self, w: Wall) -> &WallCurves {
        self.walls.iter().find(|c| c.wall == w).expect("four walls")
    }

    /// The keys, at the middle of each corner square of the skirt, clear
    /// of the cavity, the outside and the block's faces.
    fn keys(&self) -> Result<Vec<Key>> {
        let (outline, block, p) = (self.outline, self.block, self.p);
        let (tw, socket_r) = (p.wall_thickness, self.socket_r);
        let (block_lo, block_hi) = (self.block_lo, self.block_hi);
        let corner_mid = |w: Wall, end: bool| {
            let c = &self.curve(w).mid;
            if end {
                *c.z.last().unwrap()
            } else {
                c.z[0]
            }
        };
        let keys: Vec<Key> = [
            (
                DVec2::new(outline.x0 - tw / 2.0, outline.y0 - tw / 2.0),
                corner_mid(Wall::YMin, false),
            ),
            (
                DVec2::new(outline.x1 + tw / 2.0, outline.y0 - tw / 2.0),
                corner_mid(Wall::YMin, true),
            ),
            (
                DVec2::new(outline.x1 + tw / 2.0, outline.y1 + tw / 2.0),
                corner_mid(Wall::YMax, true),
            ),
            (
                DVec2::new(outline.x0 - tw / 2.0, outline.y1 + tw / 2.0),
                corner_mid(Wall::YMax, false),
            ),
        ]
        .into_iter()
        .map(|(xy, z)| Key { at: xy.extend(z) })
        .collect();

        for k in &keys {
            let xy = k.at.truncate();
            let to_cavity = outline.signed_distance(xy) - socket_r;
            let to_outside = -block.signed_distance(xy) - socket_r;
            if to_cavity < MIN_WALL_MM || to_outside < MIN_WALL_MM {
                // the socket stands in the middle of a wall_thickness square
                let widest = tw - 2.0 * MIN_WALL_MM - 2.0 * p.key_clearance;
                let thick_enough = 2.0 * (socket_r + MIN_WALL_MM);
                let (param, fix) = if widest >= 0.1 {
                    (
                        MoldParam::KeyDiameter,
                        format!("make mold.key_diameter at most {widest:.1} mm or mold.wall_thickness at least {thick_enough:.1} mm"),
                    )
                } else {
                    (
                        MoldParam::WallThickness,
                        format!("make mold.wall_thickness at least {thick_enough:.1} mm: no key fits a {tw} mm wall with {MIN_WALL_MM} mm of mold on each side"),
                    )
                };
                return Err(misfit(
                    "keys-clear-cavity",
                    Some(param),
                    k.at,
                    format!(
                        "a key socket {:.1} mm wide here comes {:.2} mm from the cavity and {:.2} mm from the block's side (at least {MIN_WALL_MM} mm needed)",
                        2.0 * socket_r,
                        to_cavity,
                        to_outside
                    ),
                    fix,
                ));
            }
            let socket_top = k.at.z + p.key_height + p.key_clearance;
            let bump_bottom = k.at.z - 0.5 * p.key_height;
            if block_hi.z - socket_top < MIN_WALL_MM || bump_bottom - block_lo.z < MIN_WALL_MM {
                return Err(misfit(
                    "keys-clear-cavity",
                    Some(MoldParam::KeyHeight),
                    k.at,
                    "the key is too tall for the block's height here".into(),
                    "make mold.key_height smaller or mold.wall_thickness larger".into(),
                ));
            }
        }
        Ok(keys)
    }

    /// The gate: the lowest point of the smooth mid-wall curve, away from
    /// the corners (where the keys are); ties go to the point nearest a
    /// wall's middle. With it the runner, the sprue and the pour cone.
    fn gate(&self, mid: &Survey) -> Result<Gate> {
        let (outline, p) = (self.outline, self.p);
        let (tw, socket_r, block_hi) = (p.wall_thickness, self.socket_r, self.block_hi);
        let hi_z = self.device_top;
        let (r_g, r_s, r_c) = (
            p.gate_diameter / 2.0,
            p.sprue_diameter / 2.0,
            p.pour_cone_diameter / 2.0,
        );
        let keepout = (r_c + socket_r + MIN_WALL_MM - tw / 2.0).max(r_g + MIN_WALL_MM);
        let n = SURVEY_NODES;
        let mut best: Option<(f64, f64, Wall, f64)> = None; // (z, distance to wall middle, wall, t)
        for j in 0..n {
            for i in 0..n {
                let Some(Some(wall)) = mid.border(i, j) else {
                    continue;
                };
                let q = mid.points[j][i];
                let (s0, s1) = wall.span(&outline);
                let t = wall.along(q).clamp(s0, s1);
                if t < s0 + keepout || t > s1 - keepout {
                    continue;
                }
                let key = (q.z, (t - 0.5 * (s0 + s1)).abs(), wall, t);
                let better = match best {
                    None => true,
                    Some(b) => {
                        key.0 < b.0 - 1e-6 || ((key.0 - b.0).abs() <= 1e-6 && key.1 < b.1 - 1e-9)
                    }
                };
                if better {
                    best = Some(key);
                }
            }
        }
        let Some((_, _, gate_wall, t_g)) = best else {
            return Err(misfit(
                "gate-fits-wall",
                Some(MoldParam::WallThickness),
                outline.centre().extend(0.0),
                format!("no wall is long enough to take a gate {keepout:.1} mm or more from its corner keys"),
                "make the device larger, or the pour cone and keys smaller".into(),
            ));
        };
        let wc = self.curve(gate_wall);
        let m_g = wc.mid.eval(t_g);
        let at = gate_wall.point(&outline, t_g, m_g);
        let (top_min, _) = wc.upper.range(t_g - r_g, t_g + r_g);
        let (_, bottom_max) = wc.lower.range(t_g - r_g, t_g + r_g);
        let room = (top_min - m_g).min(m_g - bottom_max) - GATE_EDGE_GAP_MM;
        if r_g > room {
            return Err(misfit(
                "gate-fits-wall",
                Some(MoldParam::GateDiameter),
                at,
                format!(
                    "a gate {} mm wide does not fit the {} wall, which is {:.3} mm high there",
                    p.gate_diameter,
                    gate_wall.name(),
                    top_min - bottom_max
                ),
                gate_fix(2.0 * room),
            ));
        }
        if runner_cuts_island(&wc.mid, t_g, m_g, r_g) {
            let fits = std::iter::successors(Some(r_g), |r| Some(r * 0.9))
                .take_while(|&r| r > 1e-3)
                .find(|&r| !runner_cuts_island(&wc.mid, t_g, m_g, r));
            return Err(misfit(
                "gate-fits-wall",
                Some(MoldParam::GateDiameter),
                at,
                format!(
                    "the parting line on the {} wall rises over a runner {} mm wide and falls back inside its width: a sliver of the mold would come loose between them",
                    gate_wall.name(),
                    p.gate_diameter
                ),
                gate_fix(fits.map_or(0.0, |r| 2.0 * r)),
            ));
        }
        let out = gate_wall.outward();
        let sprue_axis = at.truncate() + out * (tw / 2.0);
        if tw / 2.0 - r_s < MIN_WALL_MM {
            return Err(misfit(
                "sprue-fits-wall",
                Some(MoldParam::SprueDiameter),
                sprue_axis.extend(m_g),
                format!(
                    "a sprue {} mm wide in the middle of a {tw} mm wall leaves less than {MIN_WALL_MM} mm to the cavity and the outside",
                    p.sprue_diameter
                ),
                format!("make mold.wall_thickness at least {:.1} mm or the sprue narrower", 2.0 * (r_s + MIN_WALL_MM)),
            ));
        }
        if tw / 2.0 - r_c < MIN_WALL_MM - 1e-12 {
            return Err(misfit(
                "sprue-fits-wall",
                Some(MoldParam::PourConeDiameter),
                sprue_axis.extend(block_hi.z),
                format!(
                    "a pour cone {} mm wide leaves less than {MIN_WALL_MM} mm to the block's side",
                    p.pour_cone_diameter
                ),
                format!(
                    "set mold.pour_cone_diameter to at most {:.1} mm",
                    tw - 2.0 * MIN_WALL_MM
                ),
            ));
        }
        let cone_floor = block_hi.z - p.pour_cone_depth;
        if cone_floor - hi_z < MIN_WALL_MM {
            return Err(misfit(
                "sprue-fits-wall",
                Some(MoldParam::PourConeDepth),
                sprue_axis.extend(cone_floor),
                "the pour cone reaches within 1 mm of the cavity's height".into(),
                "make the pour cone shallower or the walls thicker".into(),
            ));
        }
        Ok(Gate {
            wall: gate_wall,
            at,
            radius: r_g,
            sprue_axis,
            sprue_radius: r_s,
            sprue_bottom_z: sprue_bottom_z(&wc.mid, t_g, (r_g, r_s), m_g),
            cone_radius: r_c,
            cone_depth: p.pour_cone_depth,
        })
    }

    /// A vent at each plateau of the ceiling's local maxima: on the wall
    /// or corner where the plateau reaches the outline, else on the lenses
    /// (with a warning: its stub is on the optics).
    fn vents(
        &self,
        ceiling: &Survey,
        gate: &Gate,
        (upper, lower): (&HeightQuery, &HeightQuery),
        warnings: &mut Vec<String>,
    ) -> Result<Vec<Vent>> {
        let (outline, p) = (self.outline, self.p);
        let r_v = p.vent_diameter / 2.0;
        let overlap = r_v / 2.0;
        let mut vents: Vec<Vent> = Vec::new();
        for members in ceiling.plateaus() {
            // A plateau that reaches the outline is vented there, as far from
            // the gate as it can be; otherwise at its highest node.
            let on_border: Vec<_> = members
                .iter()
                .filter(|&&(i, j)| ceiling.border(i, j).is_some())
                .copied()
                .collect();
            let (i, j) = if on_border.is_empty() {
                *members
                    .iter()
                    .max_by(|a, b| {
                        ceiling.points[a.1][a.0]
                            .z
                            .total_cmp(&ceiling.points[b.1][b.0].z)
                    })
                    .expect("non-empty plateau")
            } else {
                *on_border
                    .iter()
                    .max_by(|a, b| {
                        let da = ceiling.points[a.1][a.0]
                            .truncate()
                            .distance(gate.at.truncate());
                        let db = ceiling.points[b.1][b.0]
                            .truncate()
                            .distance(gate.at.truncate());
                        da.total_cmp(&db)
                    })
                    .expect("non-empty border")
            };
            let q = ceiling.points[j][i];
            let clamped = DVec2::new(
                q.x.clamp(outline.x0, outline.x1),
                q.y.clamp(outline.y0, outline.y1),
            );
            let vent = match ceiling.border(i, j) {
                Some(Some(wall)) => {
                    let c = self.curve(wall);
                    let t = wall.along(clamped.extend(0.0));
                    let foot = 0.5 * (c.mid.eval(t) + c.upper.eval(t));
                    let on = wall.point(&outline, t, foot).truncate();
                    Vent {
                        maximum: q,
                        place: VentPlace::Wall(wall),
                        axis: on + wall.outward() * (r_v - overlap),
                        radius: r_v,
                        foot_z: foot,
                    }
                }
                Some(None) => {
                    let corner = DVec2::new(
                        if clamped.x - outline.x0 < outline.x1 - clamped.x {
                            outline.x0
                        } else {
                            outline.x1
                        },
                        if clamped.y - outline.y0 < outline.y1 - clamped.y {
                            outline.y0
                        } else {
                            outline.y1
                        },
                    );
                    let wall = if corner.y == outline.y0 {
                        Wall::YMin
                    } else {
                        Wall::YMax
                    };
                    let c = self.curve(wall);
                    let t = corner.x;
                    let foot = 0.5 * (c.mid.eval(t) + c.upper.eval(t));
                    let dir =
                        (corner - outline.centre()).signum() * std::f64::consts::FRAC_1_SQRT_2;
                    Vent {
                        maximum: q,
                        place: VentPlace::Corner,
                        axis: corner + dir * (r_v - overlap),
                        radius: r_v,
                        foot_z: foot,
                    }
                }
                None => {
                    let (top, bottom) = (upper.height(clamped), lower.height(clamped));
                    let (Some(top), Some(bottom)) = (top, bottom) else {
                        return Err(MoldError::NotSolid {
                            what: "device",
                            detail: format!("no device above ({:.3}, {:.3})", clamped.x, clamped.y),
                        });
                    };
                    warnings.push(format!(
                        "the cavity's ceiling has a maximum inside the outline at ({:.2}, {:.2}) mm: its vent leaves a {:.1} mm stub on the lenses{}",
                        clamped.x,
                        clamped.y,
                        p.vent_diameter,
                        if p.flip { "" } else { "; set mold.flip = true to mould the device upside down" }
                    ));
                    // the vent must open in the ceiling, not over a wall
                    let to_wall = (clamped.x - outline.x0)
                        .min(outline.x1 - clamped.x)
                        .min(clamped.y - outline.y0)
                        .min(outline.y1 - clamped.y);
                    if r_v >= to_wall {
                        return Err(misfit(
                            "vent-fits-ceiling",
                            Some(MoldParam::VentDiameter),
                            clamped.extend(q.z),
                            format!(
                                "a vent {} mm wide at the ceiling's maximum ({:.2}, {:.2}) mm would reach over the wall {to_wall:.3} mm away",
                                p.vent_diameter, clamped.x, clamped.y
                            ),
                            format!("set mold.vent_diameter below {:.2} mm, or make the device larger", 2.0 * to_wall),
                        ));
                    }
                    Vent {
                        maximum: q,
                        place: VentPlace::Lenses,
                        axis: clamped,
                        radius: r_v,
                        foot_z: 0.5 * (top + bottom),
                    }
                }
            };
            let vent = Vent {
                foot_z: self.vent_foot(&vent, (upper, lower))?,
                ..vent
            };
            // Plateaus next to each other share a vent.
            if vents
                .iter()
                .any(|v| v.axis.distance(vent.axis) < 2.0 * r_v + MIN_WALL_MM)
            {
                continue;
            }
            vents.push(vent);
        }
        Ok(vents)
    }

    /// The vent's foot: where `vent` puts it (a wall's upper quarter, or
    /// the device's middle under a maximum) unless the cavity's ceiling dips
    /// below that somewhere over the vent's disk. On a thin wall the lenses'
    /// ripple does, and the vent would open into the cavity in two places:
    /// a handle of the top half (tests/design-corpus/found-b2de7d0aad0f8feb.toml).
    /// Then the foot drops under the lowest ceiling over the disk. It also
    /// rises over the skirt and the floor under the disk, which a corner
    /// vent's other wall can carry above a foot set on one wall
    /// (found-0bc3e504cec33309).
    fn vent_foot(&self, vent: &Vent, (upper, lower): (&HeightQuery, &HeightQuery)) -> Result<f64> {
        let (outline, r) = (self.outline, vent.radius);
        let (mut ceiling, mut below) = (f64::INFINITY, f64::NEG_INFINITY);
        // The walls the disk crosses: their top and mid curves, exactly.
        for c in self.walls {
            let w = c.wall;
            let (s0, s1) = w.span(&outline);
            let across = w
                .outward()
                .dot(vent.axis - w.point(&outline, 0.0, 0.0).truncate());
            if across.abs() >= r {
                continue;
            }
            let along = w.along(vent.axis.extend(0.0));
            let half_chord = (r * r - across * across).sqrt();
            let (a, b) = ((along - half_chord).max(s0), (along + half_chord).min(s1));
            if a <= b {
                ceiling = ceiling.min(c.upper.range(a, b).0);
                below = below.max(c.mid.range(a, b).1);
            }
        }
        // The disk's inside (ceiling and floor) and outside (the skirt,
        // each wall's mid curve carried out; flat in the corner squares).
        for ring in 0..=VENT_DISK_RINGS {
            let rho = r * ring as f64 / VENT_DISK_RINGS as f64;
            let spokes = if ring == 0 { 1 } else { VENT_DISK_SPOKES };
            for k in 0..spokes {
                let angle = std::f64::consts::TAU * k as f64 / spokes as f64;
                let q = vent.axis + rho * DVec2::from_angle(angle);
                if outline.contains(q) {
                    if let Some(z) = upper.height(q) {
                        ceiling = ceiling.min(z);
                    }
                    if let Some(z) = lower.height(q) {
                        below = below.max(z);
                    }
                    continue;
                }
                for c in self.walls {
                    let w = c.wall;
                    let across = w.outward().dot(q - w.point(&outline, 0.0, 0.0).truncate());
                    if across > 0.0 {
                        let (s0, s1) = w.span(&outline);
                        below = below.max(c.mid.eval(w.along(q.extend(0.0)).clamp(s0, s1)));
                    }
                }
            }
        }
        let (lowest, highest) = (below + VENT_FOOT_GAP_MM, ceiling - VENT_FOOT_GAP_MM);
        let foot = vent.foot_z.max(lowest).min(highest);
        if foot < lowest {
            return Err(misfit(
                "vent-fits-wall",
                Some(MoldParam::VentDiameter),
                vent.axis.extend(foot),
                format!(
                    "a vent {} mm wide at ({:.2}, {:.2}) mm spans a dip of the cavity's ceiling to {:.3} mm, within {VENT_FOOT_GAP_MM} mm of the parting surface or the floor under it ({:.3} mm): it would open into the cavity in two places",
                    self.p.vent_diameter, vent.axis.x, vent.axis.y, ceiling, below
                ),
                "make mold.vent_diameter smaller, or the device thicker where its ceiling is highest".into(),
            ));
        }
        Ok(foot)
    }

    /// Every vent column rises to the top face inside the block, clear of
    /// the runner, the sprue, the pour cone and the key sockets; no key
    /// socket runs into the sprue.
    fn check_columns(&self, vents: &[Vent], gate: &Gate, keys: &[Key]) -> Result<()> {
        let (block, p, socket_r) = (self.block, self.p, self.socket_r);
        let r_c = gate.cone_radius;
        for v in vents {
            let at = v.axis.extend(v.foot_z);
            let side_gap = -block.signed_distance(v.axis) - v.radius;
            if side_gap < MIN_WALL_MM {
                return Err(misfit(
                    "vents-reach-top-face",
                    Some(MoldParam::VentDiameter),
                    at,
                    format!(
                        "a vent {} mm wide here passes {side_gap:.2} mm from the block's side on its way to the top face (at least {MIN_WALL_MM} mm needed)",
                        p.vent_diameter
                    ),
                    "make mold.vent_diameter smaller or mold.wall_thickness larger".into(),
                ));
            }
            let sprue_gap = v.axis.distance(gate.sprue_axis) - v.radius - r_c;
            if sprue_gap < MIN_WALL_MM {
                return Err(misfit(
                    "vents-reach-top-face",
                    Some(MoldParam::VentDiameter),
                    at,
                    format!(
                        "the vent column runs into the sprue and pour cone ({sprue_gap:.2} mm apart)"
                    ),
                    "make the vents or the pour cone narrower".into(),
                ));
            }
            // a column that starts below the runner's top and beside it
            // opens into it (found-30761c8351245e78: a wall vent 0.08 mm beside
            // the gate), one channel where two were meant
            let runner_gap = runner_gap(gate, v.axis) - v.radius;
            if runner_gap < MIN_WALL_MM && v.foot_z < gate.at.z + gate.radius + MIN_WALL_MM {
                return Err(misfit(
                    "vents-reach-top-face",
                    Some(MoldParam::VentDiameter),
                    at,
                    format!("the vent column runs into the runner ({runner_gap:.2} mm apart)"),
                    "make mold.vent_diameter or mold.gate_diameter smaller".into(),
                ));
            }
            for k in keys {
                let gap = v.axis.distance(k.at.truncate()) - v.radius - socket_r;
                if gap < MIN_WALL_MM {
                    return Err(misfit(
                        "vents-reach-top-face",
                        Some(MoldParam::VentDiameter),
                        at,
                        format!("the vent column runs into a key socket ({gap:.2} mm apart)"),
                        "make the vents or the keys smaller".into(),
                    ));
                }
            }
        }

        for k in keys {
            let xy = k.at.truncate();
            let gap = xy.distance(gate.sprue_axis) - socket_r - r_c;
            if gap < MIN_WALL_MM {
                return Err(misfit(
                    "keys-clear-cavity",
                    Some(MoldParam::KeyDiameter),
                    k.at,
                    format!("the key socket runs into the sprue ({gap:.2} mm apart)"),
                    "make the keys or the pour cone smaller".into(),
                ));
            }
        }
        Ok(())
    }

    /// Bolt holes along the rim's middle line, between the keys, where they
    /// clear the runner, the sprue, the vents and the keys.
    fn bolts(&self, keys: &[Key], gate: &Gate, vents: &[Vent]) -> Result<Vec<DVec2>> {
        let (p, socket_r) = (self.p, self.socket_r);
        let (tw, r_c) = (p.wall_thickness, gate.cone_radius);
        let mut bolts = Vec::new();
        let r_b = p.bolt_diameter / 2.0;
        if tw / 2.0 - r_b < MIN_WALL_MM {
            return Err(misfit(
                "bolts-fit-rim",
                Some(MoldParam::BoltDiameter),
                keys[0].at,
                format!(
                    "bolt holes {} mm wide leave less than {MIN_WALL_MM} mm in a {tw} mm rim",
                    p.bolt_diameter
                ),
                format!(
                    "make mold.wall_thickness at least {:.1} mm",
                    2.0 * (r_b + MIN_WALL_MM)
                ),
            ));
        }
        for k in 0..4 {
            let (a, b) = (keys[k].at.truncate(), keys[(k + 1) % 4].at.truncate());
            let pieces = (a.distance(b) / p.bolt_spacing).ceil().max(1.0) as usize;
            for s in 1..pieces {
                let q = a + (b - a) * (s as f64 / pieces as f64);
                let clear = q.distance(gate.sprue_axis) - r_c - r_b >= MIN_WALL_MM
                    && runner_gap(gate, q) - r_b >= MIN_WALL_MM
                    && vents
                        .iter()
                        .all(|v| q.distance(v.axis) - v.radius - r_b >= MIN_WALL_MM)
                    && keys
                        .iter()
                        .all(|k| q.distance(k.at.truncate()) - socket_r - r_b >= MIN_WALL_MM);
                if clear {
                    bolts.push(q);
                }
            }
        }
        Ok(bolts)
    }
}

/// The runner from just inside the cavity to the sprue's axis.
pub fn runner_span(gate: &Gate) -> (DVec3, DVec2, f64) {
    let dir = (gate.sprue_axis - gate.at.truncate()).normalize();
    let from = gate.at - (dir * RUNNER_INTO_CAVITY_MM).extend(0.0);
    let length = gate.at.truncate().distance(gate.sprue_axis) + RUNNER_INTO_CAVITY_MM;
    (from, dir, length)
}

/// How far (mm) the point `q` lies from the runner's side, seen from
/// above: a bolt hole runs through the runner's height.
fn runner_gap(gate: &Gate, q: DVec2) -> f64 {
    let (from, dir, length) = runner_span(gate);
    let along = (q - from.truncate()).dot(dir).clamp(0.0, length);
    q.distance(from.truncate() + dir * along) - gate.radius
}

/// The block's footprint rectangle.
pub fn block_rect(f: &Features) -> Rect {
    Rect {
        x0: f.block_lo.x,
        x1: f.block_hi.x,
        y0: f.block_lo.y,
        y1: f.block_hi.y,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parting line across a runner of radius 0.5 centred at height 0:
    /// inside the runner, then `over` above its top at 0.34 across, then
    /// 8 µm inside again, then out over the top to the runner's side.
    fn ridge(over: f64) -> Polyline {
        let top = |s: f64| polygon_span(&channel_section(0.5, 0.0), s).1;
        let t = vec![-0.6, 0.0, 0.3188, 0.3439, 0.3687, 0.4, 0.6];
        let z = vec![
            0.0,
            0.0,
            top(0.3188) - 0.05,
            top(0.3439) + over,
            top(0.3687) - 0.008,
            top(0.4) + 0.05,
            0.3,
        ];
        Polyline { t, z }
    }

    #[test]
    fn a_micron_ridge_over_the_runner_is_a_loose_sliver() {
        // found-dfeb79e5db90b7e2: a margin of 0.01 mm on the circle took
        // the stretch 8 µm inside for "over" and joined the ridge to it
        assert!(runner_cuts_island(&ridge(1e-3), 0.0, 0.0, 0.5));
    }

    #[test]
    fn a_parting_line_that_stays_inside_past_the_ridge_cuts_nothing() {
        // the same line, its ridge under the runner's top
        assert!(!runner_cuts_island(&ridge(-2e-3), 0.0, 0.0, 0.5));
    }
}
