//! Two-piece casting molds around a moirecast device (METHOD §6), and the
//! mold invariants of METHOD §7 measured on the result.
//!
//! The mold is built in the mold frame: the device posed (flipped and
//! scaled against shrinkage), a block around it, a parting surface, and
//! channels and keys placed and checked before any boolean runs. Booleans are
//! manifold-rust's; every operand and result has its status checked. No I/O.

pub mod boolean;
pub mod error;
pub mod features;
pub mod params;
pub mod parting;
pub mod split;
pub mod tiling;

pub use error::{MoldError, MoldParam, Result};
pub use features::{Features, Gate, Key, Vent, VentPlace};
pub use params::{MoldParams, MIN_WALL_MM};

use boolean::{
    checked, cuboid, horizontal_cylinder, to_manifold, to_mesh, union_all, vertical_frustum,
};
use glam::{DVec2, DVec3};
use manifold_rust::manifold::Manifold;
use moirecast_kernel::check::{solid_checks_of_genus, CheckResult, CheckedMesh, SolidSpec};
use moirecast_kernel::progress::Progress;
use moirecast_kernel::{Design, DeviceMesh, Mesh};
use parting::{Face, Floor, HeightQuery, PartSide, PosedDevice, Region};
use rayon::prelude::*;

/// Mold volumes sum to the block's to this relative error (METHOD §7.4).
pub const VOLUME_SUM_REL: f64 = 1e-6;
/// Largest overlap (mm³) between parts that rounding can explain (METHOD §7.5).
pub const OVERLAP_MM3: f64 = 1e-4;
/// Cavity faces lie on the device's faces to this distance (mm): far below
/// any tolerance, so the cavity is within tolerance of the exact surface
/// exactly when the device mesh is (METHOD §7.6).
pub const CAVITY_ON_DEVICE_MM: f64 = 1e-6;
/// Edges shorter than this (mm) that the channels leave where they cross the
/// device's faces are collapsed: far below any tolerance, and long enough
/// that no triangle can flip when written as f32 STL.
const SLIVER_MM: f64 = 1e-6;
/// The cavity's faces and the device's surface inside the channels make up
/// the device's surface to this relative error: rounding of the channels'
/// intersection points, and slivers collapsed by up to `SLIVER_MM`.
const COVER_REL: f64 = 1e-6;
/// How far (mm) the parting region and through-channels reach past the block.
const PAST_BLOCK_MM: f64 = 1.0;
/// Spacing (mm) of the parting surface's grid inside the outline.
const PARTING_CELL_MM: f64 = 1.0;

/// The worst draft of a half's cavity against its draw direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Draft {
    /// asin(n·draw) of the worst lens face, in degrees: 90° for a face square
    /// to the draw direction, 0° for a vertical face, negative for an overhang.
    pub degrees: f64,
    pub at: DVec3,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Volumes {
    pub block: f64,
    pub top: f64,
    pub bottom: f64,
    pub device: f64,
    /// Channels, bolt holes and key clearances inside the block.
    pub voids: f64,
}

/// A built mold, measured.
pub struct Mold {
    /// The cavity's shape: the device in the mold frame (flipped, scaled).
    pub device: Mesh,
    /// The halves, with the solid checks they passed as they were cut.
    pub top: CheckedMesh,
    pub bottom: CheckedMesh,
    pub features: Features,
    pub volumes: Volumes,
    pub draft_top: Draft,
    pub draft_bottom: Draft,
    /// Through-holes (genus) of each half: sprue, vents and bolts in the
    /// top; bolts in the bottom.
    pub genus_top: u32,
    pub genus_bottom: u32,
    pub parting_triangles: usize,
    /// Every invariant of METHOD §7 that concerns the mold, measured.
    pub checks: Vec<CheckResult>,
    /// The solids the halves were made from, so that another tool can
    /// rebuild the halves from them and the device (see `assembly.scad`).
    pub construction: Vec<ConstructionSolid>,
}

/// A solid the halves were built from.
pub struct ConstructionSolid {
    /// "above" and "below" (the block on each side of the parting surface),
    /// "channels" (runner, sprue, cone, vents, bolts), "key-bumps", "key-sockets".
    pub name: &'static str,
    pub mesh: Mesh,
    /// Connected pieces it must have.
    pub shells: u32,
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
    let half = checked(
        format!("{what}, slivers collapsed"),
        half.simplify(SLIVER_MM),
    )?;
    Ok(join(to_mesh(&half)).map(checked_half))
}

/// A half, with its solid checks, and for each triangle the original ID of
/// the mesh it came from and its face there (as [`boolean::Traced`]).
struct Half {
    solid: CheckedMesh,
    source: Vec<(u32, u64)>,
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

/// Distance from `q` to the triangle `corners`.
fn distance_to(q: DVec3, [a, b, c]: [DVec3; 3]) -> f64 {
    (moirecast_kernel::measure::closest_on_triangle(q, a, b, c) - q).length()
}

/// Worst draft of the faces of one kind against `draw` (±z).
fn worst_draft(device: &PosedDevice, kind: Face, draw: f64) -> Draft {
    device
        .mesh
        .triangles
        .par_iter()
        .zip(&device.faces)
        .filter(|(_, f)| **f == kind)
        .map(|(t, _)| {
            let [a, b, c] = t.map(|i| device.mesh.positions[i as usize]);
            let n = (b - a).cross(c - a).normalize();
            Draft {
                degrees: (n.z * draw).clamp(-1.0, 1.0).asin().to_degrees(),
                at: (a + b + c) / 3.0,
            }
        })
        .reduce(
            || Draft {
                degrees: f64::INFINITY,
                at: DVec3::ZERO,
            },
            |x, y| {
                if y.degrees < x.degrees
                    || (y.degrees == x.degrees && (y.at.x, y.at.y) < (x.at.x, x.at.y))
                {
                    y
                } else {
                    x
                }
            },
        )
}

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

/// Builds the two-piece mold of `device` (a mesh of `design`) and measures
/// it. Misfits of the parameters to this device are errors; failed
/// invariants are returned in `checks` for the caller to act on.
pub fn build_mold(
    design: &Design,
    device: &DeviceMesh,
    p: &MoldParams,
    progress: &dyn Progress,
) -> Result<Mold> {
    build_mold_with(design, device, p, progress, HalfCut::SplitFarPatch)
}

/// [`build_mold`], with the halves cut as `cut` says.
pub fn build_mold_with(
    design: &Design,
    device: &DeviceMesh,
    p: &MoldParams,
    progress: &dyn Progress,
    cut_by: HalfCut,
) -> Result<Mold> {
    if let moirecast_kernel::BaseKind::Printed(_) = design.params.base.kind {
        return Err(MoldError::NotCastable);
    }
    p.validate()?;
    progress.stage("placing mold features", 1);
    let posed = PosedDevice::new(design, device, p.flip, p.shrink_scale)?;
    let draft_top = worst_draft(&posed, Face::Upper, 1.0);
    let draft_bottom = worst_draft(&posed, Face::Lower, -1.0);
    for d in [draft_top, draft_bottom] {
        if d.degrees < p.min_draft_deg {
            return Err(MoldError::DoesNotFit {
                check: "releases-along-z",
                param: Some(MoldParam::MinDraft),
                at: d.at,
                problem: format!(
                    "a lens face has a draft of {:.2}° against its half's draw direction (at least {}° needed): the device cannot release along z",
                    d.degrees, p.min_draft_deg
                ),
                fix: "reduce the surface's slope or curvature, or the lens AFOV".into(),
            });
        }
    }
    let walls = parting::wall_curves(&posed)?;
    let upper_q = HeightQuery::new(
        &posed.mesh,
        (0..posed.faces.len()).filter(|&t| posed.faces[t] == Face::Upper),
    );
    let lower_q = HeightQuery::new(
        &posed.mesh,
        (0..posed.faces.len()).filter(|&t| posed.faces[t] == Face::Lower),
    );
    let f = features::place(design, &posed, &walls, &upper_q, &lower_q, p)?;
    progress.tick(1);

    progress.stage("building the parting surface", 1);
    let o = posed.outline;
    let cells = (
        (((o.x1 - o.x0) / PARTING_CELL_MM).ceil() as usize).clamp(4, 128),
        (((o.y1 - o.y0) / PARTING_CELL_MM).ceil() as usize).clamp(4, 128),
    );
    let interior_mid = |q: DVec2| match (upper_q.height(q), lower_q.height(q)) {
        (Some(a), Some(b)) => 0.5 * (a + b),
        _ => f64::NAN,
    };
    let footprint = features::block_rect(&f);
    // The keys: a tapered bump on the bottom half, in a socket with
    // clearance in the top half.
    let tan = p.key_taper_deg.to_radians().tan();
    let (h, c) = (p.key_height, p.key_clearance);
    let r_low = p.key_diameter / 2.0 + 0.5 * h * tan;
    let mut bump_solids = Vec::new();
    let mut sockets = Vec::new();
    for k in &f.keys {
        let (xy, z) = (k.at.truncate(), k.at.z);
        bump_solids.push(vertical_frustum(
            xy,
            z - 0.5 * h,
            z + h,
            (r_low, r_low - 1.5 * h * tan),
            0.0,
        )?);
        sockets.push(vertical_frustum(
            xy,
            z - 0.5 * h,
            z + h + c,
            (r_low + c, r_low + c - (1.5 * h + c) * tan),
            0.0,
        )?);
    }
    let bump_rings: Vec<parting::Bump> = f
        .keys
        .iter()
        .zip(&bump_solids)
        .map(|(k, solid)| frustum_rings(k.at.truncate(), solid))
        .collect();
    let region = |floor: Floor, side: PartSide, bumps: &[parting::Bump]| -> Result<Region> {
        let cap_z = match side {
            PartSide::Above => f.block_hi.z,
            PartSide::Below => f.block_lo.z,
        };
        let grid = matches!(floor, Floor::Grid { .. });
        let r = parting::parting_region(&walls, floor, &footprint, cap_z, side, bumps);
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
    // The halves before their channels: the device's own faces, walls
    // split at the parting line, and the skirt, the bottom one with the
    // key bumps (and without, for the tiling check). The regions over the
    // grid are what another tool rebuilds them from (block side minus device).
    let ((top_region, (bottom_region, bottom_plain)), (above_mesh, below_mesh)) = rayon::join(
        || {
            rayon::join(
                || region(Floor::Device(&posed), PartSide::Above, &[]),
                || {
                    (
                        region(Floor::Device(&posed), PartSide::Below, &bump_rings),
                        region(Floor::Device(&posed), PartSide::Below, &[]),
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
    let (top_region, bottom_region, bottom_plain) = (top_region?, bottom_region?, bottom_plain?);
    let (above_mesh, below_mesh) = (above_mesh?, below_mesh?);
    progress.tick(1);

    progress.stage("mold booleans", 1);
    let above = to_manifold("block above the parting surface", &above_mesh)?;
    let block = cuboid(f.block_lo, f.block_hi)?;
    let past_top = f.block_hi.z + PAST_BLOCK_MM;
    let bump_boxes: Vec<_> = bump_solids.iter().map(|b| b.bounding_box()).collect();
    let bumps = union_all("key bumps", bump_solids)?;
    let sockets = union_all("key sockets", sockets)?;
    // The channels (runner, sprue, cone and vents; bolt holes), their
    // polygons turned `twist` degrees past the half facet: (fill, all
    // channels, all channels and the key sockets).
    let channels_turned = |twist: f64| -> Result<(Manifold, Manifold, Manifold)> {
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
            {
                let floor = f.block_hi.z - g.cone_depth;
                let r_top = g.sprue_radius
                    + (g.cone_radius - g.sprue_radius) * (past_top - floor)
                        / g.cone_depth.max(1e-9);
                if g.cone_depth > 0.0 {
                    vertical_frustum(
                        g.sprue_axis,
                        floor,
                        past_top,
                        (g.sprue_radius, r_top),
                        twist,
                    )?
                } else {
                    Manifold::empty()
                }
            },
        ];
        for v in &f.vents {
            fill.push(vertical_frustum(
                v.axis,
                v.foot_z,
                past_top,
                (v.radius, v.radius),
                twist,
            )?);
        }
        let fill = union_all("runner, sprue and vents", fill)?;
        let bolt_r = p.bolt_diameter / 2.0;
        let bolts = union_all(
            "bolt holes",
            f.bolts
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
                .collect::<Result<_>>()?,
        )?;
        let channels = checked("channels", fill.union(&bolts))?;
        let top_cut = checked("channels and sockets", channels.union(&sockets))?;
        Ok((fill, channels, top_cut))
    };
    let (mut fill, mut channels, mut top_cut) = channels_turned(0.0)?;
    let genus_top = 1 + f.vents.len() as u32 + f.bolts.len() as u32;
    let genus_bottom = f.bolts.len() as u32;
    let device_id = Manifold::reserve_ids(1);
    let interface_id = Manifold::reserve_ids(1);
    let channels_in_block = checked("channels in the block", channels.intersection(&block))?;
    // A half: its region minus `cut`, and the solid manifold held of the
    // region, which equals it wherever `cut` is (all of it, or all but a far
    // patch of device faces that `cut` misses; see `split`).
    let half = |what: &str,
                region: &Region,
                (kind, side, cap_z): (Face, f64, f64),
                cut: &Manifold,
                genus: u32|
     -> Result<(Half, Manifold)> {
        let split = match cut_by {
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
                split::split(region, &posed, kind, side, &clear, cap_z)
            }
            HalfCut::Whole => None,
        };
        if let Some(s) = split {
            let near = boolean::to_region_manifold(
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
                return Ok((done, near));
            }
        }
        let whole = boolean::to_region_manifold(
            what,
            &region.mesh,
            &region.device_faces,
            device_id,
            (0, interface_id),
        )?;
        let done = sliver_free(what, whole.difference(cut), genus, Some)?
            .expect("a whole region needs no joining");
        Ok((done, whole))
    };
    let above_side = (Face::Upper, 1.0, f.block_hi.z);
    let below_side = (Face::Lower, -1.0, f.block_lo.z);
    let top_chain = |top_cut: &Manifold, channels_in_block: &Manifold| -> Result<_> {
        let (half, top) = half("top half", &top_region, above_side, top_cut, genus_top)?;
        let beside_top = checked(
            "channels outside the top half",
            channels_in_block.difference(&top),
        )?;
        Ok((half, beside_top))
    };
    let bottom_chain = |channels: &Manifold| -> Result<_> {
        half(
            "bottom half",
            &bottom_region,
            below_side,
            channels,
            genus_bottom,
        )
    };
    // The tiling certificate (§7.5, below) needs only the regions: it runs
    // beside the booleans, whose two chains leave a core partly idle.
    let ((top_t, bottom_t), tiling) = rayon::join(
        || {
            rayon::join(
                || top_chain(&top_cut, &channels_in_block),
                || bottom_chain(&channels),
            )
        },
        || {
            tiling::tiles_block(
                &[&top_region.mesh, &bottom_plain.mesh, &posed.mesh],
                (f.block_lo, f.block_hi),
            )
        },
    );
    let ((mut top_h, mut beside_top), (mut bottom_h, bottom_before)) = (top_t?, bottom_t?);
    // Rarely a channel's edge crosses a wall within nanometres of a device
    // vertex, and manifold will not collapse the sliver between them: then
    // the channels are built again turned a quarter facet.
    let mut turned_note = None;
    let mut channels_in_block = channels_in_block;
    if has_slivers(top_h.solid.checks()) || has_slivers(bottom_h.solid.checks()) {
        (fill, channels, top_cut) = channels_turned(boolean::QUARTER_FACET_DEG)?;
        channels_in_block = checked("channels in the block", channels.intersection(&block))?;
        let (t, b) = rayon::join(
            || top_chain(&top_cut, &channels_in_block),
            || bottom_chain(&channels),
        );
        ((top_h, beside_top), (bottom_h, _)) = (t?, b?);
        turned_note = Some(format!(
            "the channels' polygons are turned {:.3}° more than usual: at the usual turn a channel crossed a wall within nanometres of a device vertex",
            boolean::QUARTER_FACET_DEG
        ));
    }
    // The regions and the device tile the block (checked exactly below), so
    // what of the channels lies in neither region lies in the device.
    let channels_in_device = checked(
        "channels in the cavity",
        beside_top.difference(&bottom_before),
    )?;
    progress.tick(1);

    progress.stage("mold solid checks", 1);
    let mut checks = Vec::new();
    for (name, h) in [("top", &top_h), ("bottom", &bottom_h)] {
        for c in h.solid.checks() {
            let mut c = c.clone();
            c.detail = format!("mold-{name}: {}", c.detail);
            checks.push(c);
        }
    }

    progress.tick(1);
    progress.stage("mold volumes", 1);
    // §7.4 volumes. The voids are measured from the channel and key
    // primitives and the halves before their channels, not from the halves
    // themselves: the channels in the cavity are what the regions leave of
    // them. Keys lie outside the outline (checked when they were placed),
    // where the block above the parting surface is the top half before its
    // channels.
    let (v_top, v_bottom) = (top_h.solid.mesh().volume(), bottom_h.solid.mesh().volume());
    let v_device = posed.mesh.volume();
    let v_block = (f.block_hi - f.block_lo).element_product();
    let clearances = checked(
        "key clearances",
        sockets.intersection(&above).difference(&bumps),
    )?;
    let v_voids = channels_in_block.volume() - channels_in_device.volume() + clearances.volume();
    let sum = v_top + v_bottom + v_device + v_voids;
    checks.push(CheckResult::at_most(
        "mold-volumes-sum",
        ((sum - v_block) / v_block).abs(),
        VOLUME_SUM_REL,
        "relative",
        format!("top {v_top:.6} + bottom {v_bottom:.6} + device {v_device:.6} + voids {v_voids:.6} = {sum:.6} mm³; block {v_block:.6} mm³"),
    ));

    progress.tick(1);
    progress.stage("mold overlaps", 1);
    // §7.5 overlaps. The halves before their channels and the device tile
    // the block: their faces cancel in pairs, leaving the block's boundary
    // (checked below, exactly). The halves are those minus channels and
    // sockets, the bottom one with the key bumps added; so they can overlap
    // only where a bump is not inside its socket, or a bump reaches the
    // device.
    checks.push(tiling);
    let bumps_out_of_sockets = checked(
        "key bumps outside their sockets",
        bumps.intersection(&above).difference(&sockets),
    )?;
    // The bumps stand outside the outline (checked when the keys were
    // placed): where their bounding box misses the device's, they cannot
    // meet it, and the device need not be imported to show it.
    let (lo, hi) = posed.mesh.bounds();
    let boxes_apart = bump_boxes.iter().all(|b| {
        b.min.x > hi.x
            || b.max.x < lo.x
            || b.min.y > hi.y
            || b.max.y < lo.y
            || b.min.z > hi.z
            || b.max.z < lo.z
    });
    let bumps_in_device = if boxes_apart {
        0.0
    } else {
        let dev = boolean::to_manifold("device", &posed.mesh)?;
        checked("key bumps in the device", bumps.intersection(&dev))?.volume()
    };
    let overlaps: Vec<(&str, f64)> = vec![
        ("top ∩ bottom", bumps_out_of_sockets.volume()),
        (
            if boxes_apart {
                "bottom ∩ device (key bumps' boxes apart from the device's)"
            } else {
                "bottom ∩ device"
            },
            bumps_in_device,
        ),
    ];
    let worst = overlaps
        .iter()
        .copied()
        .fold(("", 0.0f64), |w, o| if o.1 > w.1 { o } else { w });
    checks.push(CheckResult::at_most(
        "mold-no-overlaps",
        worst.1,
        OVERLAP_MM3,
        "mm³",
        overlaps
            .iter()
            .map(|(n, v)| format!("{n}: {v:.3e}"))
            .chain(["top ∩ device: none (tiling)".to_string()])
            .collect::<Vec<_>>()
            .join(", "),
    ));

    progress.tick(1);
    progress.stage("mold cavity checks", 1);
    // §7.6 the cavity is the device: faces traced back to the device lie on
    // their source triangles, and cover it but for the channel openings.
    let (mut worst_off, mut worst_at) = (0.0f64, DVec3::ZERO);
    let mut cavity_area = 0.0;
    for half in [&top_h, &bottom_h] {
        let mesh = half.solid.mesh();
        for (t, &(id, face)) in mesh.triangles.iter().zip(&half.source) {
            if id != device_id {
                continue;
            }
            cavity_area += mesh.triangle_area(t);
            let Some(src) = posed.mesh.triangles.get(face as usize) else {
                worst_off = f64::INFINITY;
                continue;
            };
            let [a, b, c] = src.map(|i| posed.mesh.positions[i as usize]);
            for &v in t {
                let q = mesh.positions[v as usize];
                let mut off = distance_to(q, [a, b, c]);
                if off > CAVITY_ON_DEVICE_MM {
                    // The booleans may move a vertex within a plane of
                    // several device triangles (a wall): measure against them all.
                    off = posed
                        .mesh
                        .triangles
                        .par_iter()
                        .map(|t| distance_to(q, t.map(|i| posed.mesh.positions[i as usize])))
                        .reduce(|| f64::INFINITY, f64::min);
                }
                if off > worst_off {
                    (worst_off, worst_at) = (off, q);
                }
            }
        }
    }
    let device_area = posed.mesh.area();
    checks.push(CheckResult::at_most(
        "cavity-on-device",
        worst_off,
        CAVITY_ON_DEVICE_MM,
        "mm",
        format!(
            "largest distance of a cavity-face vertex from the device (from the triangle it came from, or the nearest if that is farther), at ({:.3}, {:.3}, {:.3})",
            worst_at.x, worst_at.y, worst_at.z
        ),
    ));
    // The device's surface inside the channels, from their own boolean with
    // the device: the openings the cavity must lack, and nothing more.
    let openings: f64 = {
        let inside = to_mesh(&channels_in_device);
        inside
            .mesh
            .triangles
            .iter()
            .zip(&inside.source)
            .filter(|(_, &(id, _))| id == device_id)
            .map(|(t, _)| inside.mesh.triangle_area(t))
            .sum()
    };
    checks.push(CheckResult::at_most(
        "cavity-covers-device",
        (device_area - cavity_area - openings).abs() / device_area,
        COVER_REL,
        "of the device's area",
        format!(
            "cavity faces {cavity_area:.6} mm² of the device's {device_area:.6} mm²; the device's surface inside the gate and vents is {openings:.6} mm²"
        ),
    ));

    progress.tick(1);
    progress.stage("mold filling checks", 1);
    // §7.7 demoulding and filling.
    let draft = draft_top.degrees.min(draft_bottom.degrees);
    checks.push(CheckResult::at_least(
        "demouldable",
        draft,
        p.min_draft_deg,
        "degrees",
        format!(
            "worst lens-face draft: top half {:.2}° at ({:.2}, {:.2}, {:.2}), bottom half {:.2}° at ({:.2}, {:.2}, {:.2}); walls are vertical and split at mid-height",
            draft_top.degrees, draft_top.at.x, draft_top.at.y, draft_top.at.z,
            draft_bottom.degrees, draft_bottom.at.x, draft_bottom.at.y, draft_bottom.at.z
        ),
    ));
    // The void is connected when every connected piece of the channels
    // (runner with sprue and cone; each vent) reaches into the cavity.
    let reaching = fill
        .decompose()
        .iter()
        .filter(|piece| piece.intersection(&channels_in_device).volume() > 0.0)
        .count();
    let pieces = 1 + fill.decompose().len() - reaching;
    checks.push(CheckResult::at_most(
        "cavity-reachable",
        pieces as f64,
        1.0,
        "connected pieces",
        format!("{reaching} channel pieces (runner with sprue, and each vent) reach into the cavity; the void has {pieces} connected piece(s)"),
    ));
    let sprue_top = f.block_hi.z;
    let lowest_vent_top = f
        .vents
        .iter()
        .map(|_| f.block_hi.z)
        .fold(f64::INFINITY, f64::min);
    checks.push(CheckResult::at_least(
        "vents-not-below-sprue",
        lowest_vent_top - sprue_top,
        0.0,
        "mm",
        format!(
            "{} vents; every vent and the sprue open on the top face",
            f.vents.len()
        ),
    ));
    progress.tick(1);

    Ok(Mold {
        device: posed.mesh,
        top: top_h.solid,
        bottom: bottom_h.solid,
        volumes: Volumes {
            block: v_block,
            top: v_top,
            bottom: v_bottom,
            device: v_device,
            voids: v_voids,
        },
        features: {
            let mut features = f.clone();
            features.warnings.extend(turned_note);
            features
        },
        draft_top,
        draft_bottom,
        genus_top,
        genus_bottom,
        parting_triangles: above_mesh.triangles.len(),
        checks,
        construction: vec![
            ConstructionSolid {
                name: "above",
                mesh: above_mesh,
                shells: 1,
            },
            ConstructionSolid {
                name: "below",
                mesh: below_mesh,
                shells: 1,
            },
            ConstructionSolid {
                name: "channels",
                mesh: to_mesh(&channels).mesh,
                shells: 1 + f.vents.len() as u32 + f.bolts.len() as u32,
            },
            ConstructionSolid {
                name: "key-bumps",
                mesh: to_mesh(&bumps).mesh,
                shells: f.keys.len() as u32,
            },
            ConstructionSolid {
                name: "key-sockets",
                mesh: to_mesh(&sockets).mesh,
                shells: f.keys.len() as u32,
            },
        ],
    })
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
