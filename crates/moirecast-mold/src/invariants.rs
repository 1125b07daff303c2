//! The mold invariants of METHOD §7.4–§7.7, measured on the cut halves:
//! volumes, overlaps, the cavity against the device, demoulding and filling.

use crate::boolean::{self, checked, to_mesh};
use crate::cut::{Cut, Half};
use crate::error::{MoldError, MoldParam, Result};
use crate::features::Features;
use crate::params::MoldParams;
use crate::parting::{Face, PosedDevice};
use glam::DVec3;
use manifold_rust::manifold::Manifold;
use moirecast_kernel::check::CheckResult;
use rayon::prelude::*;

/// Mold volumes sum to the block's to this relative error (METHOD §7.4).
pub const VOLUME_SUM_REL: f64 = 1e-6;
/// Largest overlap (mm³) between parts that rounding can explain (METHOD §7.5).
pub const OVERLAP_MM3: f64 = 1e-4;
/// Cavity faces lie on the device's faces to this distance (mm): far below
/// any tolerance, so the cavity is within tolerance of the exact surface
/// exactly when the device mesh is (METHOD §7.6).
pub const CAVITY_ON_DEVICE_MM: f64 = 1e-6;
/// The cavity's faces and the device's surface inside the channels make up
/// the device's surface to this relative error: rounding of the channels'
/// intersection points, and slivers collapsed by up to `SLIVER_MM`.
const COVER_REL: f64 = 1e-6;

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
    /// What the cast material fills: the cavity (the device) and the
    /// runner, sprue, pour cone and vents inside the block.
    pub fill: f64,
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

/// The worst drafts of the top and bottom halves' cavities; a draft under
/// `min_draft` is a misfit naming the place.
pub(crate) fn drafts(posed: &PosedDevice, p: &MoldParams) -> Result<(Draft, Draft)> {
    let draft_top = worst_draft(posed, Face::Upper, 1.0);
    let draft_bottom = worst_draft(posed, Face::Lower, -1.0);
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
    Ok((draft_top, draft_bottom))
}

/// The halves' solid checks, each named for its file.
pub(crate) fn solid_checks(cut: &Cut) -> Vec<CheckResult> {
    let mut checks = Vec::new();
    for (name, h) in [("top", &cut.top), ("bottom", &cut.bottom)] {
        for c in h.solid.checks() {
            let mut c = c.clone();
            c.detail = format!("mold-{name}: {}", c.detail);
            checks.push(c);
        }
    }
    checks
}

/// §7.4 volumes. The voids are measured from the channel and key
/// primitives and the halves before their channels, not from the halves
/// themselves: the channels in the cavity are what the regions leave of
/// them. Keys lie outside the outline (checked when they were placed),
/// where the block above the parting surface is the top half before its
/// channels.
pub(crate) fn volumes(
    cut: &Cut,
    posed: &PosedDevice,
    (f, block): (&Features, &Manifold),
    (above, bumps, sockets): (&Manifold, &Manifold, &Manifold),
) -> Result<(Volumes, CheckResult)> {
    let (v_top, v_bottom) = (
        cut.top.solid.mesh().volume(),
        cut.bottom.solid.mesh().volume(),
    );
    let v_device = posed.mesh.volume();
    let v_block = (f.block_hi - f.block_lo).element_product();
    let clearances = checked(
        "key clearances",
        sockets.intersection(above).difference(bumps),
    )?;
    let v_voids =
        cut.channels_in_block.volume() - cut.channels_in_device.volume() + clearances.volume();
    let sum = v_top + v_bottom + v_device + v_voids;
    let check = CheckResult::at_most(
        "mold-volumes-sum",
        ((sum - v_block) / v_block).abs(),
        VOLUME_SUM_REL,
        "relative",
        format!("top {v_top:.6} + bottom {v_bottom:.6} + device {v_device:.6} + voids {v_voids:.6} = {sum:.6} mm³; block {v_block:.6} mm³"),
    );
    // the channels the material fills (not the bolt holes), less their
    // part inside the cavity, which the device's volume counts
    let fill_in_block = checked(
        "runner, sprue and vents in the block",
        cut.channels.fill.intersection(block),
    )?;
    let volumes = Volumes {
        block: v_block,
        top: v_top,
        bottom: v_bottom,
        device: v_device,
        voids: v_voids,
        fill: v_device + fill_in_block.volume() - cut.channels_in_device.volume(),
    };
    Ok((volumes, check))
}

/// §7.5 overlaps. The halves before their channels and the device tile
/// the block: their faces cancel in pairs, leaving the block's boundary
/// (the tiling check). The halves are those minus channels and sockets,
/// the bottom one with the key bumps added; so they can overlap only
/// where a bump is not inside its socket, or a bump reaches the device.
pub(crate) fn overlaps(
    posed: &PosedDevice,
    (above, bumps, sockets): (&Manifold, &Manifold, &Manifold),
    bump_boxes: &[manifold_rust::types::Box],
) -> Result<CheckResult> {
    let bumps_out_of_sockets = checked(
        "key bumps outside their sockets",
        bumps.intersection(above).difference(sockets),
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
    Ok(CheckResult::at_most(
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
    ))
}

/// §7.6 the cavity is the device: faces traced back to the device lie on
/// their source triangles, and cover it but for the channel openings.
pub(crate) fn cavity(cut: &Cut, posed: &PosedDevice) -> [CheckResult; 2] {
    let (mut worst_off, mut worst_at) = (0.0f64, DVec3::ZERO);
    let mut cavity_area = 0.0;
    for half in [&cut.top, &cut.bottom] {
        let worst = (&mut cavity_area, &mut worst_off, &mut worst_at);
        cavity_faces(half, cut.device_id, posed, worst);
    }
    let device_area = posed.mesh.area();
    let on_device = CheckResult::at_most(
        "cavity-on-device",
        worst_off,
        CAVITY_ON_DEVICE_MM,
        "mm",
        format!(
            "largest distance of a cavity-face vertex from the device (from the triangle it came from, or the nearest if that is farther), at ({:.3}, {:.3}, {:.3})",
            worst_at.x, worst_at.y, worst_at.z
        ),
    );
    // The device's surface inside the channels, from their own boolean with
    // the device: the openings the cavity must lack, and nothing more.
    let openings: f64 = {
        let inside = to_mesh(&cut.channels_in_device);
        inside
            .mesh
            .triangles
            .iter()
            .zip(&inside.source)
            .filter(|(_, &(id, _))| id == cut.device_id)
            .map(|(t, _)| inside.mesh.triangle_area(t))
            .sum()
    };
    let covers = CheckResult::at_most(
        "cavity-covers-device",
        (device_area - cavity_area - openings).abs() / device_area,
        COVER_REL,
        "of the device's area",
        format!(
            "cavity faces {cavity_area:.6} mm² of the device's {device_area:.6} mm²; the device's surface inside the gate and vents is {openings:.6} mm²"
        ),
    );
    [on_device, covers]
}

/// Adds a half's cavity faces' area to `area`, and raises `worst_off` to
/// the largest distance of one of their vertices from the device, found
/// at `worst_at`.
fn cavity_faces(
    half: &Half,
    device_id: u32,
    posed: &PosedDevice,
    (area, worst_off, worst_at): (&mut f64, &mut f64, &mut DVec3),
) {
    let mesh = half.solid.mesh();
    for (t, &(id, face)) in mesh.triangles.iter().zip(&half.source) {
        if id != device_id {
            continue;
        }
        *area += mesh.triangle_area(t);
        let Some(src) = posed.mesh.triangles.get(face as usize) else {
            *worst_off = f64::INFINITY;
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
            if off > *worst_off {
                (*worst_off, *worst_at) = (off, q);
            }
        }
    }
}

/// §7.7 demoulding and filling: the worst draft, the void connected
/// through the channels, and no vent opening below the sprue's.
pub(crate) fn filling(
    cut: &Cut,
    f: &Features,
    (draft_top, draft_bottom): (Draft, Draft),
    min_draft_deg: f64,
) -> [CheckResult; 3] {
    let draft = draft_top.degrees.min(draft_bottom.degrees);
    let demouldable = CheckResult::at_least(
        "demouldable",
        draft,
        min_draft_deg,
        "degrees",
        format!(
            "worst lens-face draft: top half {:.2}° at ({:.2}, {:.2}, {:.2}), bottom half {:.2}° at ({:.2}, {:.2}, {:.2}); walls are vertical and split at mid-height",
            draft_top.degrees, draft_top.at.x, draft_top.at.y, draft_top.at.z,
            draft_bottom.degrees, draft_bottom.at.x, draft_bottom.at.y, draft_bottom.at.z
        ),
    );
    // The void is connected when every connected piece of the channels
    // (runner with sprue and cone; each vent) reaches into the cavity.
    let fill = &cut.channels.fill;
    let reaching = fill
        .decompose()
        .iter()
        .filter(|piece| piece.intersection(&cut.channels_in_device).volume() > 0.0)
        .count();
    let pieces = 1 + fill.decompose().len() - reaching;
    let reachable = CheckResult::at_most(
        "cavity-reachable",
        pieces as f64,
        1.0,
        "connected pieces",
        format!("{reaching} channel pieces (runner with sprue, and each vent) reach into the cavity; the void has {pieces} connected piece(s)"),
    );
    let sprue_top = f.block_hi.z;
    let lowest_vent_top = f
        .vents
        .iter()
        .map(|_| f.block_hi.z)
        .fold(f64::INFINITY, f64::min);
    let vents = CheckResult::at_least(
        "vents-not-below-sprue",
        lowest_vent_top - sprue_top,
        0.0,
        "mm",
        format!(
            "{} vents; every vent and the sprue open on the top face",
            f.vents.len()
        ),
    );
    [demouldable, reachable, vents]
}
