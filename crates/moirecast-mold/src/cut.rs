//! Cutting the halves (METHOD §6): the key solids, the regions of the block
//! on each side of the parting surface (floored by the device's own faces),
//! the channels, and each half as its region minus its channels, with a
//! far patch of device faces kept out of the boolean where it can be.

use crate::boolean::{
    self, checked, cuboid, horizontal_cylinder, to_manifold, to_mesh, union_all, vertical_frustum,
    ChannelShape,
};
use crate::error::{MoldError, Result};
use crate::features::{self, Features};
use crate::params::MoldParams;
use crate::parting::{self, Face, Floor, HeightQuery, PartSide, PosedDevice, Region, WallCurves};
use crate::split;
use crate::tiling;
use glam::{DVec2, DVec3};
use manifold_rust::manifold::Manifold;
use moirecast_kernel::check::{solid_checks_of_genus, CheckResult, CheckedMesh, SolidSpec};
use moirecast_kernel::Mesh;
use rayon::prelude::*;

/// Edges shorter than this (mm) that the channels leave where they cross the
/// device's faces are collapsed: far below any tolerance, and long enough
/// that no triangle can flip when written as f32 STL.
const SLIVER_MM: f64 = 1e-6;
/// How far (mm) the parting region and through-channels reach past the block.
const PAST_BLOCK_MM: f64 = 1.0;
/// Spacing (mm) of the parting surface's grid inside the outline.
const PARTING_CELL_MM: f64 = 1.0;

/// How a half's region meets manifold: both give the same triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HalfCut {
    /// The device faces no channel comes near are left out of the boolean
    /// and put back after it, where they form one patch (`split`); the
    /// rest of the region is cut. Four to six times less work at 120 lenses.
    SplitFarPatch,
    /// The whole region is cut: for cross-checks.
    Whole,
}

/// A half, with its solid checks, and for each triangle the original ID of
/// the mesh it came from and its face there (as [`boolean::Traced`]).
pub(crate) struct Half {
    pub solid: CheckedMesh,
    pub source: Vec<(u32, u64)>,
    /// Per triangle, the surface it lies on (filled in by [`cut_half`]).
    pub surfaces: Vec<HalfSurface>,
}

/// What a triangle of a cut half lies on: the exact surface its face of
/// the half's B-rep is built on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HalfSurface {
    /// A face of the posed device: its triangle there.
    Device(u32),
    /// A surface of the half's region: its triangle there (whose
    /// `Region::surfaces` entry names the surface).
    Region(u32),
    /// The side of channel k (of the mold's channel shapes): its first
    /// half-turn from the seam (0) or its second (1).
    ChannelSide(usize, usize),
    /// The flat end of channel k.
    ChannelEnd(usize),
}

/// Where the triangles of a half came from, as [`cut_half`] traced them.
struct Origins<'a> {
    device_id: u32,
    /// The region's own original ID, and what to add to its face IDs to
    /// get the region's triangle (the split leaves out some device faces).
    own: (u32, i64),
    channels: &'a [ChannelShape],
}

impl Origins<'_> {
    /// The surface of each of `half`'s triangles.
    fn surfaces(&self, half: &Half) -> Result<Vec<HalfSurface>> {
        let by_id: std::collections::HashMap<u32, usize> = self
            .channels
            .iter()
            .enumerate()
            .map(|(k, c)| (c.id, k))
            .collect();
        let m = half.solid.mesh();
        m.triangles
            .iter()
            .zip(&half.source)
            .map(|(t, &(id, face))| {
                if id == self.device_id {
                    return Ok(HalfSurface::Device(face as u32));
                }
                if id == self.own.0 {
                    return Ok(HalfSurface::Region((face as i64 + self.own.1) as u32));
                }
                let Some(&k) = by_id.get(&id) else {
                    return Err(MoldError::NotSolid {
                        what: "mold half",
                        detail: format!("a triangle from unknown mesh {id}"),
                    });
                };
                let [a, b, c] = t.map(|v| m.positions[v as usize]);
                let normal = (b - a).cross(c - a).normalize_or_zero();
                let shape = &self.channels[k];
                Ok(if normal.dot(shape.direction()).abs() > 0.5 {
                    HalfSurface::ChannelEnd(k)
                } else {
                    HalfSurface::ChannelSide(k, shape.half((a + b + c) / 3.0))
                })
            })
            .collect()
    }
}

/// A half, checked, with its mesh and its solid checks (genus `genus`). If
/// the channels left slivers where they cross the device's faces at a
/// shallow angle (edges shorter than `SLIVER_MM`, or triangles and vertices
/// the solid checks reject: needles, f32 rounding faults), they are
/// collapsed first and the half checked again (manifold's `simplify`; it
/// costs a pass over the whole half, so it runs only when needed).
fn sliver_free(
    what: &str,
    half: Manifold,
    genus: u32,
    join: impl Fn(boolean::Traced) -> Option<boolean::Traced>,
) -> Result<Option<Half>> {
    let half = checked(what, half)?;
    let spec = SolidSpec::boolean_result(genus);
    let checked_half = |traced: boolean::Traced| Half {
        solid: CheckedMesh::check(traced.mesh, spec),
        source: traced.source,
        surfaces: Vec::new(),
    };
    let Some(traced) = join(to_mesh(&half)) else {
        return Ok(None);
    };
    let done = checked_half(traced);
    let m = done.solid.mesh();
    let shortest = m
        .triangles
        .par_iter()
        .flat_map_iter(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
        .map(|(a, b)| m.positions[a as usize].distance(m.positions[b as usize]))
        .reduce(|| f64::INFINITY, f64::min);
    if shortest >= SLIVER_MM && !has_slivers(done.solid.checks()) {
        return Ok(Some(done));
    }
    let simplified = |eps: f64| -> Result<Option<boolean::Traced>> {
        let half = checked(format!("{what}, slivers collapsed"), half.simplify(eps))?;
        Ok(join(to_mesh(&half)))
    };
    let done = simplified(SLIVER_MM)?.map(checked_half);
    // Far from the origin f32 is coarser than SLIVER_MM (its spacing is
    // 1.5e-5 mm at 150 mm): a sliver that still flips in f32 is collapsed
    // again at a few f32 spacings of the half's extent (found-ede40982785487f7, a
    // 297 mm wide device).
    let Some(d) = done.as_ref().filter(|d| has_slivers(d.solid.checks())) else {
        return Ok(done);
    };
    let extent = d
        .solid
        .mesh()
        .positions
        .iter()
        .fold(0.0f64, |m, p| m.max(p.abs().max_element()));
    let f32_spacing = extent as f32 - (extent as f32).next_down();
    let eps = (4.0 * f32_spacing as f64).max(2.0 * SLIVER_MM);
    let Some(traced) = simplified(eps)? else {
        return Ok(None);
    };
    let done = checked_half(traced.clone());
    if !has_slivers(done.solid.checks()) {
        return Ok(Some(done));
    }
    Ok(Some(checked_half(traced.collapse_short_edges(eps))))
}

/// The bottom and top rings of a vertical key frustum over `centre`, as
/// the bottom region builds its bump from them: vertex k of each on the
/// same side edge, counter-clockwise seen from above.
fn frustum_rings(centre: DVec2, frustum: &Manifold) -> parting::Bump {
    let mesh = to_mesh(frustum).mesh;
    let (z0, z1) = mesh
        .positions
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.z), hi.max(p.z))
        });
    let ring = |z: f64| {
        let mut r: Vec<DVec3> = mesh
            .positions
            .iter()
            .copied()
            .filter(|p| p.z == z && p.truncate().distance(centre) > 1e-9)
            .collect();
        r.sort_by(|a, b| {
            let angle = |p: &DVec3| (p.y - centre.y).atan2(p.x - centre.x);
            angle(a).total_cmp(&angle(b))
        });
        r
    };
    parting::Bump {
        centre,
        bottom: ring(z0),
        top: ring(z1),
    }
}

/// The solid checks that fail on slivers: a half failing one of them has
/// its slivers collapsed (see [`sliver_free`]).
const SLIVER_CHECKS: [&str; 3] = [
    "no-degenerate-triangles",
    "f32-safe-triangles",
    "f32-distinct-vertices",
];

/// Whether any of the [`SLIVER_CHECKS`] failed.
fn has_slivers(checks: &[CheckResult]) -> bool {
    checks
        .iter()
        .any(|c| !c.passed && SLIVER_CHECKS.contains(&c.name))
}

/// The registration keys as solids: a tapered bump on the bottom half, in
/// a socket with clearance in the top half.
pub(crate) struct KeySolids {
    pub bumps: Vec<Manifold>,
    pub sockets: Vec<Manifold>,
    /// The sockets' exact shapes.
    pub socket_shapes: Vec<ChannelShape>,
    /// Each bump's rings, as the bottom region builds its bump from them.
    pub rings: Vec<parting::Bump>,
}

impl KeySolids {
    pub fn new(f: &Features, p: &MoldParams) -> Result<Self> {
        let tan = p.key_taper_deg.to_radians().tan();
        let (h, c) = (p.key_height, p.key_clearance);
        let r_low = p.key_diameter / 2.0 + 0.5 * h * tan;
        let mut bumps = Vec::new();
        let (mut sockets, mut socket_shapes) = (Vec::new(), Vec::new());
        for k in &f.keys {
            let (xy, z) = (k.at.truncate(), k.at.z);
            bumps.push(
                vertical_frustum(xy, z - 0.5 * h, z + h, (r_low, r_low - 1.5 * h * tan), 0.0)?
                    .solid,
            );
            let socket = vertical_frustum(
                xy,
                z - 0.5 * h,
                z + h + c,
                (r_low + c, r_low + c - (1.5 * h + c) * tan),
                0.0,
            )?;
            sockets.push(socket.solid);
            socket_shapes.push(socket.shape);
        }
        let rings = f
            .keys
            .iter()
            .zip(&bumps)
            .map(|(k, solid)| frustum_rings(k.at.truncate(), solid))
            .collect();
        Ok(KeySolids {
            bumps,
            sockets,
            socket_shapes,
            rings,
        })
    }
}

/// The block on each side of the parting surface, as closed meshes.
pub(crate) struct Regions {
    /// The halves before their channels: the device's own faces, walls
    /// split at the parting line, and the skirt; the bottom one with the
    /// key bumps.
    pub top: Region,
    pub bottom: Region,
    /// The bottom half before its channels without its bumps (for the
    /// tiling check).
    pub bottom_plain: Region,
    /// The regions over a grid through the device: what another tool
    /// rebuilds the halves from (block side minus device).
    pub above: Mesh,
    pub below: Mesh,
}

impl Regions {
    /// Every region, side by side, each checked to be a closed solid.
    pub fn new(
        posed: &PosedDevice,
        walls: &[WallCurves],
        f: &Features,
        bump_rings: &[parting::Bump],
        (upper_q, lower_q): (&HeightQuery, &HeightQuery),
    ) -> Result<Self> {
        let o = posed.outline;
        let cells = (
            (((o.x1 - o.x0) / PARTING_CELL_MM).ceil() as usize).clamp(4, 128),
            (((o.y1 - o.y0) / PARTING_CELL_MM).ceil() as usize).clamp(4, 128),
        );
        let interior_mid = |q: DVec2| match (upper_q.height(q), lower_q.height(q)) {
            (Some(a), Some(b)) => 0.5 * (a + b),
            _ => f64::NAN,
        };
        let footprint = features::block_rect(f);
        let region = |floor: Floor, side: PartSide, bumps: &[parting::Bump]| -> Result<Region> {
            let cap_z = match side {
                PartSide::Above => f.block_hi.z,
                PartSide::Below => f.block_lo.z,
            };
            let grid = matches!(floor, Floor::Grid { .. });
            let r = parting::parting_region(walls, floor, &footprint, cap_z, side, bumps);
            if let Some(c) = solid_checks_of_genus(&r.mesh, 0)
                .into_iter()
                .find(|c| !c.passed)
            {
                return Err(MoldError::NotSolid {
                    what: if grid {
                        "parting region"
                    } else {
                        "mold half before its channels"
                    },
                    detail: format!("{side:?}: {}: {} ({})", c.name, c.value, c.detail),
                });
            }
            Ok(r)
        };
        let grid = || Floor::Grid {
            interior_mid: &interior_mid,
            cells,
        };
        let ((top, (bottom, bottom_plain)), (above, below)) = rayon::join(
            || {
                rayon::join(
                    || region(Floor::Device(posed), PartSide::Above, &[]),
                    || {
                        (
                            region(Floor::Device(posed), PartSide::Below, bump_rings),
                            region(Floor::Device(posed), PartSide::Below, &[]),
                        )
                    },
                )
            },
            || {
                (
                    region(grid(), PartSide::Above, &[]).map(|r| r.mesh),
                    region(grid(), PartSide::Below, &[]).map(|r| r.mesh),
                )
            },
        );
        Ok(Regions {
            top: top?,
            bottom: bottom?,
            bottom_plain: bottom_plain?,
            above: above?,
            below: below?,
        })
    }
}

/// The channels, their polygons turned some degrees past the half facet.
pub(crate) struct Channels {
    /// What the silicone fills: runner, sprue, pour cone and vents.
    pub fill: Manifold,
    /// Those and the bolt holes.
    pub all: Manifold,
    /// Those and the key sockets: what the top half loses.
    pub top_cut: Manifold,
    /// The exact shape of every primitive of `top_cut`.
    pub shapes: Vec<ChannelShape>,
}

impl Channels {
    pub fn new(
        f: &Features,
        p: &MoldParams,
        (sockets, socket_shapes): (&Manifold, &[ChannelShape]),
        twist: f64,
    ) -> Result<Self> {
        let past_top = f.block_hi.z + PAST_BLOCK_MM;
        let g = &f.gate;
        let (from, dir, length) = features::runner_span(g);
        let mut fill = vec![
            horizontal_cylinder(from, dir, length, g.radius, twist)?,
            vertical_frustum(
                g.sprue_axis,
                g.sprue_bottom_z,
                past_top,
                (g.sprue_radius, g.sprue_radius),
                twist,
            )?,
        ];
        // no cone: an empty solid in its place, so the union sees the
        // same operands in the same order
        let cone = if g.cone_depth > 0.0 {
            let floor = f.block_hi.z - g.cone_depth;
            let r_top = g.sprue_radius
                + (g.cone_radius - g.sprue_radius) * (past_top - floor) / g.cone_depth.max(1e-9);
            Some(vertical_frustum(
                g.sprue_axis,
                floor,
                past_top,
                (g.sprue_radius, r_top),
                twist,
            )?)
        } else {
            None
        };
        fill.extend(cone);
        for v in &f.vents {
            fill.push(vertical_frustum(
                v.axis,
                v.foot_z,
                past_top,
                (v.radius, v.radius),
                twist,
            )?);
        }
        let bolt_r = p.bolt_diameter / 2.0;
        let bolts = f
            .bolts
            .iter()
            .map(|&b| {
                vertical_frustum(
                    b,
                    f.block_lo.z - PAST_BLOCK_MM,
                    past_top,
                    (bolt_r, bolt_r),
                    twist,
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let shapes = fill
            .iter()
            .chain(&bolts)
            .map(|c| c.shape)
            .chain(socket_shapes.iter().copied())
            .collect();
        let mut fill_solids: Vec<Manifold> = fill.into_iter().map(|c| c.solid).collect();
        if g.cone_depth <= 0.0 {
            fill_solids.insert(2, Manifold::empty());
        }
        let fill = union_all("runner, sprue and vents", fill_solids)?;
        let bolts = union_all("bolt holes", bolts.into_iter().map(|c| c.solid).collect())?;
        let all = checked("channels", fill.union(&bolts))?;
        let top_cut = checked("channels and sockets", all.union(sockets))?;
        Ok(Channels {
            fill,
            all,
            top_cut,
            shapes,
        })
    }
}

/// The two halves, cut, and what the cut measured.
pub(crate) struct Cut {
    pub top: Half,
    pub bottom: Half,
    pub channels: Channels,
    /// The channels' part inside the block.
    pub channels_in_block: Manifold,
    /// The channels' part inside the cavity (the device).
    pub channels_in_device: Manifold,
    /// The manifold ID of the device's faces in the halves' sources.
    pub device_id: u32,
    /// The halves before their channels and the device tile the block.
    pub tiling: CheckResult,
    /// Why the channels were turned further than usual, if they were.
    pub turned_note: Option<String>,
}

/// What cutting the halves takes.
pub(crate) struct CutInputs<'a> {
    pub posed: &'a PosedDevice,
    pub f: &'a Features,
    pub p: &'a MoldParams,
    pub regions: &'a Regions,
    pub block: &'a Manifold,
    pub sockets: &'a Manifold,
    pub socket_shapes: &'a [ChannelShape],
    pub cut_by: HalfCut,
}

/// Cuts each half's region by its channels (and the top one by the key
/// sockets); beside them, the exact tiling certificate of the regions. If a
/// channel's edge left a sliver manifold will not collapse, the channels
/// are built again turned a quarter facet.
pub(crate) fn cut_halves(c: &CutInputs) -> Result<Cut> {
    let (f, regions) = (c.f, c.regions);
    let mut channels = Channels::new(f, c.p, (c.sockets, c.socket_shapes), 0.0)?;
    let genus_top = 1 + f.vents.len() as u32 + f.bolts.len() as u32;
    let genus_bottom = f.bolts.len() as u32;
    let device_id = Manifold::reserve_ids(1);
    let interface_id = Manifold::reserve_ids(1);
    let mut channels_in_block =
        checked("channels in the block", channels.all.intersection(c.block))?;
    let ids = (device_id, interface_id);
    let above_side = (Face::Upper, 1.0, f.block_hi.z);
    let below_side = (Face::Lower, -1.0, f.block_lo.z);
    let top_chain = |ch: &Channels, channels_in_block: &Manifold| -> Result<_> {
        let (half, top) = cut_half(
            c,
            ("top half", &regions.top),
            above_side,
            (&ch.top_cut, &ch.shapes),
            genus_top,
            ids,
        )?;
        let beside_top = checked(
            "channels outside the top half",
            channels_in_block.difference(&top),
        )?;
        Ok((half, beside_top))
    };
    let bottom_chain = |ch: &Channels| -> Result<_> {
        cut_half(
            c,
            ("bottom half", &regions.bottom),
            below_side,
            (&ch.all, &ch.shapes),
            genus_bottom,
            ids,
        )
    };
    // The tiling certificate needs only the regions: it runs beside the
    // booleans, whose two chains leave a core partly idle.
    let ((top_t, bottom_t), tiling) = rayon::join(
        || {
            rayon::join(
                || top_chain(&channels, &channels_in_block),
                || bottom_chain(&channels),
            )
        },
        || {
            tiling::tiles_block(
                &[&regions.top.mesh, &regions.bottom_plain.mesh, &c.posed.mesh],
                (f.block_lo, f.block_hi),
            )
        },
    );
    let ((mut top_h, mut beside_top), (mut bottom_h, bottom_before)) = (top_t?, bottom_t?);
    // Rarely a channel's edge crosses a wall within nanometres of a device
    // vertex, and manifold will not collapse the sliver between them: then
    // the channels are built again turned a quarter facet.
    let mut turned_note = None;
    if has_slivers(top_h.solid.checks()) || has_slivers(bottom_h.solid.checks()) {
        channels = Channels::new(
            f,
            c.p,
            (c.sockets, c.socket_shapes),
            boolean::QUARTER_FACET_DEG,
        )?;
        channels_in_block = checked("channels in the block", channels.all.intersection(c.block))?;
        let (t, b) = rayon::join(
            || top_chain(&channels, &channels_in_block),
            || bottom_chain(&channels),
        );
        ((top_h, beside_top), (bottom_h, _)) = (t?, b?);
        turned_note = Some(format!(
            "the channels' polygons are turned {:.3}° more than usual: at the usual turn a channel crossed a wall within nanometres of a device vertex",
            boolean::QUARTER_FACET_DEG
        ));
    }
    // The regions and the device tile the block (checked exactly), so
    // what of the channels lies in neither region lies in the device.
    let channels_in_device = checked(
        "channels in the cavity",
        beside_top.difference(&bottom_before),
    )?;
    Ok(Cut {
        top: top_h,
        bottom: bottom_h,
        channels,
        channels_in_block,
        channels_in_device,
        device_id,
        tiling,
        turned_note,
    })
}

/// A half: its region minus `cut`, and the solid manifold held of the
/// region, which equals it wherever `cut` is (all of it, or all but a far
/// patch of device faces that `cut` misses; see `split`).
fn cut_half(
    c: &CutInputs,
    (what, region): (&str, &Region),
    (kind, side, cap_z): (Face, f64, f64),
    (cut, shapes): (&Manifold, &[ChannelShape]),
    genus: u32,
    (device_id, interface_id): (u32, u32),
) -> Result<(Half, Manifold)> {
    let split = match c.cut_by {
        HalfCut::SplitFarPatch => {
            // The xy boxes of the cut's pieces, which the patch keeps clear of.
            let clear: Vec<(DVec2, DVec2)> = cut
                .decompose()
                .iter()
                .map(|piece| {
                    let b = piece.bounding_box();
                    (DVec2::new(b.min.x, b.min.y), DVec2::new(b.max.x, b.max.y))
                })
                .collect();
            split::split(region, c.posed, kind, side, &clear, cap_z)
        }
        HalfCut::Whole => None,
    };
    let traced = |mut half: Half, own: (u32, i64)| -> Result<Half> {
        half.surfaces = Origins {
            device_id,
            own,
            channels: shapes,
        }
        .surfaces(&half)?;
        Ok(half)
    };
    if let Some(s) = split {
        let (near, own_id) = boolean::to_region_manifold(
            what,
            &s.near,
            &s.near_device_faces,
            device_id,
            (s.interface, interface_id),
        )?;
        let joined = sliver_free(what, near.difference(cut), genus, |t| {
            s.join(region, t, interface_id, device_id)
        })?;
        if let Some(done) = joined {
            // the near part's own faces are the region's, past the
            // device faces the patch took
            let skipped = region.device_faces.len() as i64 - s.near_device_faces.len() as i64;
            return Ok((traced(done, (own_id, skipped))?, near));
        }
    }
    let (whole, own_id) = boolean::to_region_manifold(
        what,
        &region.mesh,
        &region.device_faces,
        device_id,
        (0, interface_id),
    )?;
    let done = sliver_free(what, whole.difference(cut), genus, Some)?
        .expect("a whole region needs no joining");
    Ok((traced(done, (own_id, 0))?, whole))
}

/// The block's two parts as manifolds: the box itself and the region above
/// the parting surface.
pub(crate) fn block_solids(f: &Features, regions: &Regions) -> Result<(Manifold, Manifold)> {
    let above = to_manifold("block above the parting surface", &regions.above)?;
    let block = cuboid(f.block_lo, f.block_hi)?;
    Ok((above, block))
}

#[cfg(test)]
mod tests {
    use super::*;
    use moirecast_kernel::check::solid_checks_for;

    /// `sliver_free` picks its checks by name: every name must be one the
    /// kernel's solid checks report, or a renamed check would silently stop
    /// slivers from being collapsed.
    #[test]
    fn sliver_checks_are_solid_checks() {
        let cube = to_mesh(&cuboid(DVec3::ZERO, DVec3::ONE).unwrap()).mesh;
        let names: Vec<&str> = solid_checks_for(&cube, SolidSpec::boolean_result(0))
            .iter()
            .map(|c| c.name)
            .collect();
        for name in SLIVER_CHECKS {
            assert!(names.contains(&name), "{name} is not among {names:?}");
        }
    }
}
