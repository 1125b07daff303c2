//! The bridge to manifold-rust (a port of Manifold 3.5.4): every operand and
//! every result has its status checked, because an invalid operand silently
//! becomes empty.

use crate::error::{MoldError, Result};
use glam::{DVec2, DVec3};
use manifold_rust::linalg::Vec3;
use manifold_rust::manifold::Manifold;
use manifold_rust::types::{Error, MeshGL64};
use moirecast_kernel::Mesh;
use std::collections::BTreeSet;

/// Facets on a full circle of a channel, key or bolt hole: 0.4 % radial
/// error, and the channels are not optical faces.
pub const CIRCLE_SEGMENTS: i32 = 48;

/// Fails unless manifold-rust reports `NoError` for `m`.
pub fn checked(operation: impl Into<String>, m: Manifold) -> Result<Manifold> {
    match m.status() {
        Error::NoError => Ok(m),
        status => Err(MoldError::Boolean {
            operation: operation.into(),
            status: format!("{status:?}"),
        }),
    }
}

/// Imports a region whose first `device_faces.len()` triangles are faces of
/// the device (traced under `device_id` with those face IDs) and whose last
/// `interface` triangles are traced under `interface_id`; the rest carry a
/// fresh original ID, which it returns, and their index as face ID.
pub fn to_region_manifold(
    what: &str,
    mesh: &Mesh,
    device_faces: &[u32],
    device_id: u32,
    (interface, interface_id): (usize, u32),
) -> Result<(Manifold, u32)> {
    let own_id = Manifold::reserve_ids(1);
    let (k, n) = (device_faces.len(), mesh.triangles.len());
    let face_id = device_faces
        .iter()
        .map(|&f| u64::from(f))
        .chain(k as u64..n as u64)
        .collect();
    let mut run_index = vec![0, 3 * k as u64, 3 * (n - interface) as u64];
    let mut run_original_id = vec![device_id, own_id];
    if interface > 0 {
        run_index.push(3 * n as u64);
        run_original_id.push(interface_id);
    }
    let m = import(
        what,
        mesh,
        Some(Runs {
            face_id,
            run_index,
            run_original_id,
        }),
    )?;
    Ok((m, own_id))
}

/// Imports a closed mesh.
pub fn to_manifold(what: &str, mesh: &Mesh) -> Result<Manifold> {
    import(what, mesh, None)
}

/// Where an imported mesh's triangles come from (MeshGL's runs).
struct Runs {
    face_id: Vec<u64>,
    run_index: Vec<u64>,
    run_original_id: Vec<u32>,
}

fn import(what: &str, mesh: &Mesh, runs: Option<Runs>) -> Result<Manifold> {
    let mut g = MeshGL64 {
        num_prop: 3,
        vert_properties: mesh.positions.iter().flat_map(|p| p.to_array()).collect(),
        tri_verts: mesh
            .triangles
            .iter()
            .flat_map(|t| t.map(u64::from))
            .collect(),
        ..MeshGL64::default()
    };
    if let Some(r) = runs {
        g.face_id = r.face_id;
        g.run_index = r.run_index;
        g.run_original_id = r.run_original_id;
    }
    let m = checked(format!("import {what}"), Manifold::from_mesh_gl64(&g))?;
    if m.num_tri() != mesh.triangles.len() {
        return Err(MoldError::Boolean {
            operation: format!("import {what}"),
            status: format!(
                "{} triangles became {} (merged or dropped)",
                mesh.triangles.len(),
                m.num_tri()
            ),
        });
    }
    Ok(m)
}

/// A mesh exported from manifold, with the source of every triangle.
#[derive(Clone)]
pub struct Traced {
    pub mesh: Mesh,
    /// For each triangle: the original ID of the mesh it came from, and its
    /// face ID there.
    pub source: Vec<(u32, u64)>,
}

impl Traced {
    /// Collapses each edge shorter than `eps` (mm) whose collapse keeps the
    /// mesh a 2-manifold (its ends share exactly the two vertices opposite
    /// it), into the end that is already an f32 point if one is. It is
    /// the last resort for a sliver manifold's `simplify` keeps, as on a
    /// rim where a channel's polygon meets another cut (found-a10d1e0cd9365149:
    /// two rim vertices 4.5e-7 mm apart that round to one f32 point). The
    /// shape moves by at most `eps`. A pass leaves the edges next to one it
    /// collapsed for the next pass (found-843101dca9a486a4), up to
    /// `COLLAPSE_PASSES`.
    pub fn collapse_short_edges(self, eps: f64) -> Traced {
        let mut traced = self;
        for _ in 0..COLLAPSE_PASSES {
            let (next, collapsed) = traced.collapse_pass(eps);
            traced = next;
            if collapsed == 0 {
                break;
            }
        }
        traced
    }

    /// One pass of [`Traced::collapse_short_edges`]: the mesh, and how many
    /// edges it collapsed.
    fn collapse_pass(self, eps: f64) -> (Traced, usize) {
        let Traced { mesh, source } = self;
        let pos = &mesh.positions;
        let mut around: Vec<Vec<u32>> = vec![Vec::new(); pos.len()];
        for (k, t) in mesh.triangles.iter().enumerate() {
            for &v in t {
                around[v as usize].push(k as u32);
            }
        }
        let ring = |v: u32| -> BTreeSet<u32> {
            around[v as usize]
                .iter()
                .flat_map(|&k| mesh.triangles[k as usize])
                .filter(|&w| w != v)
                .collect()
        };
        let mut into: Vec<u32> = (0..pos.len() as u32).collect();
        let mut collapsed = 0;
        let mut touched = vec![false; pos.len()];
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if a > b || pos[a as usize].distance(pos[b as usize]) >= eps {
                    continue;
                }
                // An edge whose ends no earlier collapse of this pass
                // touched has the rings it had, so its link test still
                // holds; the rings may share vertices with earlier ones (a
                // fan's apex: found-c31f74100df48629, 27 edges of 3–9 nm
                // in a column under one vertex of the cap, one collapse a
                // pass).
                if touched[a as usize] || touched[b as usize] {
                    continue;
                }
                let (ring_a, ring_b) = (ring(a), ring(b));
                if ring_a.intersection(&ring_b).count() != 2 {
                    continue;
                }
                let (keep, gone) = if f32_exact(pos[b as usize]) == pos[b as usize] {
                    (b, a)
                } else {
                    (a, b)
                };
                into[gone as usize] = keep;
                collapsed += 1;
                for v in [a, b].into_iter().chain(ring_a).chain(ring_b) {
                    touched[v as usize] = true;
                }
            }
        }
        // drop the collapsed triangles and the vertices no triangle uses
        let mut index = vec![u32::MAX; pos.len()];
        let mut out = Traced {
            mesh: Mesh::default(),
            source: Vec::new(),
        };
        for (t, s) in mesh.triangles.iter().zip(source) {
            let t = t.map(|v| into[v as usize]);
            if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
                continue;
            }
            let t = t.map(|v| {
                if index[v as usize] == u32::MAX {
                    index[v as usize] = out.mesh.positions.len() as u32;
                    out.mesh.positions.push(pos[v as usize]);
                }
                index[v as usize]
            });
            out.mesh.triangles.push(t);
            out.source.push(s);
        }
        (out, collapsed)
    }
}

/// Passes of [`Traced::collapse_short_edges`] at most.
const COLLAPSE_PASSES: usize = 8;

pub fn to_mesh(m: &Manifold) -> Traced {
    let g = m.get_mesh_gl64(0);
    let np = g.num_prop as usize;
    let positions = g
        .vert_properties
        .chunks(np)
        .map(|p| DVec3::new(p[0], p[1], p[2]))
        .collect();
    let triangles: Vec<[u32; 3]> = g
        .tri_verts
        .chunks(3)
        .map(|t| [t[0] as u32, t[1] as u32, t[2] as u32])
        .collect();
    let mut source = vec![(u32::MAX, u64::MAX); triangles.len()];
    for (r, id) in g.run_original_id.iter().enumerate() {
        let (a, b) = (g.run_index[r] as usize / 3, g.run_index[r + 1] as usize / 3);
        for (t, s) in source.iter_mut().enumerate().take(b).skip(a) {
            *s = (*id, g.face_id.get(t).copied().unwrap_or(u64::MAX));
        }
    }
    Traced {
        mesh: Mesh {
            positions,
            triangles,
        },
        source,
    }
}

/// The nearest point with f32 coordinates. Every input of the booleans is
/// snapped to f32 first, so that the STL files (which store f32) hold
/// exactly what the halves were built from, and another tool rebuilding the
/// halves from them starts from the same geometry; only new intersection
/// vertices are rounded on writing. The snap moves a point by at most half
/// an f32 step (under 4e-6 mm within 100 mm of the origin).
pub fn f32_exact(p: DVec3) -> DVec3 {
    p.as_vec3().as_dvec3()
}

fn snapped(m: Manifold) -> Manifold {
    m.warp(|v| {
        let q = f32_exact(DVec3::new(v.x, v.y, v.z));
        *v = Vec3::new(q.x, q.y, q.z);
    })
}

pub fn v3(p: DVec3) -> Vec3 {
    Vec3::new(p.x, p.y, p.z)
}

/// An axis-aligned box.
pub fn cuboid(lo: DVec3, hi: DVec3) -> Result<Manifold> {
    checked(
        "box",
        snapped(Manifold::cube(v3(hi - lo), false).translate(v3(lo))),
    )
}

/// Turn (degrees) of every channel's polygon about its axis: half a facet,
/// so that no polygon vertex sits at 0°, 90°, 180° or 270°. A channel
/// centred on a symmetric device's middle, or on the parting line, would
/// otherwise run an edge along a wall's rung or through the skirt, and the
/// booleans would leave vertices nanometres apart there.
pub const HALF_FACET_DEG: f64 = 180.0 / CIRCLE_SEGMENTS as f64;

/// A further turn (degrees) of the channels' polygons: a quarter facet,
/// still clear of the axes. The mold takes it when a channel's edge happens
/// to cross a wall within nanometres of a device vertex, a sliver manifold
/// will not collapse.
pub const QUARTER_FACET_DEG: f64 = HALF_FACET_DEG / 2.0;

/// The polygon of a horizontal channel of radius `r` in its cross-section,
/// its polygon turned `twist` degrees past the half facet: each vertex as
/// (across the axis, up from it), in order around the polygon. Which way
/// "across" points depends on the channel's direction, so a caller that
/// needs every case also takes the mirror image (`twist` → −`twist` − 2 ×
/// half facet, the polygon at −α for every vertex angle α).
pub fn channel_section(r: f64, twist: f64) -> Vec<DVec2> {
    (0..CIRCLE_SEGMENTS)
        .map(|k| {
            let a = (HALF_FACET_DEG + twist + 360.0 * f64::from(k) / f64::from(CIRCLE_SEGMENTS))
                .to_radians();
            DVec2::new(r * a.sin(), -r * a.cos())
        })
        .collect()
}

/// Where a channel primitive's axis runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ChannelAxis {
    /// Vertical, through this xy point; positions along it are heights.
    Vertical(DVec2),
    /// Horizontal, from `from` along the unit xy direction `dir`;
    /// positions along it are distances from `from`.
    Horizontal { from: DVec3, dir: DVec2 },
}

/// The exact solid a channel primitive's polygon stands for: a cylinder or
/// a frustum of revolution. The booleans carry the primitive's original
/// ID to every triangle of a half that lies on it, so a half's faces can
/// be traced back to this shape (the mold's exact B-rep builds them on it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelShape {
    /// manifold's original ID of the primitive.
    pub id: u32,
    pub axis: ChannelAxis,
    /// Where the primitive starts and ends along its axis.
    pub span: (f64, f64),
    /// Its radius at the span's start and at its end.
    pub radii: (f64, f64),
    /// The angle (radians, as [`ChannelShape::angle`] measures) of one of
    /// the polygon's vertices: the side's two halves meet there and at the
    /// opposite vertex, along polygon edges.
    pub seam: f64,
}

impl ChannelShape {
    /// The angle of `p` about the axis: for a vertical axis from +x towards
    /// +y; for a horizontal one from the direction across it (`dir` turned
    /// a quarter counter-clockwise) towards +z.
    pub fn angle(&self, p: DVec3) -> f64 {
        match self.axis {
            ChannelAxis::Vertical(c) => (p.y - c.y).atan2(p.x - c.x),
            ChannelAxis::Horizontal { from, dir } => {
                let across = DVec2::new(-dir.y, dir.x);
                let d = p - from;
                (d.z).atan2(d.truncate().dot(across))
            }
        }
    }

    /// Which half of the side `p` is on: 0 within half a turn past the
    /// seam, else 1.
    pub fn half(&self, p: DVec3) -> usize {
        let turn = (self.angle(p) - self.seam).rem_euclid(std::f64::consts::TAU);
        usize::from(turn >= std::f64::consts::PI)
    }

    /// The unit direction of the axis.
    pub fn direction(&self) -> DVec3 {
        match self.axis {
            ChannelAxis::Vertical(_) => DVec3::Z,
            ChannelAxis::Horizontal { dir, .. } => dir.extend(0.0),
        }
    }
}

/// A channel primitive: its polygonal solid and the exact shape it stands for.
#[derive(Clone)]
pub struct Channel {
    pub solid: Manifold,
    pub shape: ChannelShape,
}

/// The original ID every triangle of the primitive `m` carries.
fn original_id_of(m: &Manifold) -> u32 {
    to_mesh(m).source.first().map_or(u32::MAX, |s| s.0)
}

/// A vertical frustum over `axis` from `z0` (radius `r0`) to `z1` (radius
/// `r1`), its polygon turned `twist` degrees past the half facet.
pub fn vertical_frustum(
    axis: DVec2,
    z0: f64,
    z1: f64,
    (r0, r1): (f64, f64),
    twist: f64,
) -> Result<Channel> {
    let solid = checked(
        "vertical channel",
        snapped(
            Manifold::cylinder(z1 - z0, r0, r1, CIRCLE_SEGMENTS)
                .rotate(0.0, 0.0, HALF_FACET_DEG + twist)
                .translate(v3(axis.extend(z0))),
        ),
    )?;
    let shape = ChannelShape {
        id: original_id_of(&solid),
        axis: ChannelAxis::Vertical(axis),
        span: (z0, z1),
        radii: (r0, r1),
        seam: (HALF_FACET_DEG + twist).to_radians(),
    };
    Ok(Channel { solid, shape })
}

/// A horizontal cylinder of radius `r` from `from` along the unit xy
/// direction `dir` for `length`, its polygon turned `twist` degrees past
/// the half facet.
pub fn horizontal_cylinder(
    from: DVec3,
    dir: DVec2,
    length: f64,
    r: f64,
    twist: f64,
) -> Result<Channel> {
    let angle = dir.y.atan2(dir.x).to_degrees();
    let solid = checked(
        "runner",
        snapped(
            Manifold::cylinder(length, r, r, CIRCLE_SEGMENTS)
                .rotate(0.0, 0.0, HALF_FACET_DEG + twist)
                .rotate(0.0, 90.0, 0.0)
                .rotate(0.0, 0.0, angle)
                .translate(v3(from)),
        ),
    )?;
    // a vertex at angle a about z goes to (across r sin a, up -r cos a),
    // as in `channel_section`: at a - 90° about the runner's axis
    let shape = ChannelShape {
        id: original_id_of(&solid),
        axis: ChannelAxis::Horizontal { from, dir },
        span: (0.0, length),
        radii: (r, r),
        seam: (HALF_FACET_DEG + twist - 90.0).to_radians(),
    };
    Ok(Channel { solid, shape })
}

pub fn union_all(what: &str, parts: Vec<Manifold>) -> Result<Manifold> {
    if parts.is_empty() {
        return Ok(Manifold::empty());
    }
    checked(
        what,
        Manifold::batch_boolean(&parts, manifold_rust::types::OpType::Add),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A double cone over a ring of 3 far points and a chain of 13 points
    /// 1e-6 mm apart: every short edge of the chain has both apexes in its
    /// ring, as the column under one vertex of found-c31f74100df48629 had.
    fn double_cone_with_a_chain() -> Traced {
        let corner = |deg: f64| DVec3::new(deg.to_radians().cos(), deg.to_radians().sin(), 0.0);
        let mut ring = vec![corner(0.0), corner(120.0), corner(240.0)];
        let tangent = DVec3::new(300f64.to_radians().sin(), -300f64.to_radians().cos(), 0.0);
        ring.extend((0..13).map(|k| corner(300.0) - f64::from(k) * 1e-6 * tangent));
        let n = ring.len() as u32;
        let (top, bottom) = (n, n + 1);
        let mut positions = ring;
        positions.extend([DVec3::Z, -DVec3::Z]);
        let triangles: Vec<[u32; 3]> = (0..n)
            .flat_map(|i| [[top, i, (i + 1) % n], [bottom, (i + 1) % n, i]])
            .collect();
        let source = (0..triangles.len() as u64).map(|k| (0, k)).collect();
        Traced {
            mesh: Mesh {
                positions,
                triangles,
            },
            source,
        }
    }

    fn shortest_edge(m: &Mesh) -> f64 {
        m.triangles
            .iter()
            .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
            .map(|(a, b)| m.positions[a as usize].distance(m.positions[b as usize]))
            .fold(f64::INFINITY, f64::min)
    }

    /// Every directed edge once, and its reverse once: closed and oriented.
    fn closed_and_oriented(m: &Mesh) -> bool {
        let mut edges: Vec<(u32, u32)> = m
            .triangles
            .iter()
            .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
            .collect();
        edges.sort_unstable();
        let unique = edges.windows(2).all(|w| w[0] != w[1]);
        unique
            && edges
                .iter()
                .all(|&(a, b)| edges.binary_search(&(b, a)).is_ok())
    }

    #[test]
    fn a_chain_of_short_edges_under_one_apex_collapses_whole() {
        let cone = double_cone_with_a_chain();
        assert!(closed_and_oriented(&cone.mesh));
        assert!(shortest_edge(&cone.mesh) < 1e-5);
        let done = cone.collapse_short_edges(1e-4);
        assert!(closed_and_oriented(&done.mesh));
        assert!(shortest_edge(&done.mesh) >= 1e-4);
        // the chain is one vertex: 3 far ring points, it and the apexes
        assert_eq!(done.mesh.positions.len(), 6);
        assert_eq!(done.mesh.triangles.len(), 8);
        assert_eq!(done.source.len(), 8);
    }
}
