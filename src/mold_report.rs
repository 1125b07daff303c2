//! `report.json` of `moirecast mold`: volumes, every mold invariant of
//! METHOD §7 with its measured value, the worst draft and where it is, and
//! the positions of the gate, vents, keys and bolts. Deterministic.

use crate::report::{design_echo, CheckReport, DesignEcho, FileReport};
use moirecast_kernel::check::CheckResult;
use moirecast_mold::{Mold, MoldParams, VentPlace};
use moirecast_spec::Spec;
use serde::Serialize;
use std::collections::BTreeMap;

#[derive(Serialize)]
pub struct FrameReport {
    /// The device was rotated 180° about x (base lenses up).
    pub flip: bool,
    pub shrink_scale: f64,
    pub note: &'static str,
}

#[derive(Serialize)]
pub struct VolumeReport {
    pub block_mm3: f64,
    pub top_mm3: f64,
    pub bottom_mm3: f64,
    pub device_mm3: f64,
    /// Channels, bolt holes and key clearances inside the block, measured
    /// from the channel and key primitives.
    pub channels_mm3: f64,
    /// (top + bottom + device + channels − block) / block.
    pub sum_relative_error: f64,
}

/// Extra material to mix beyond what fills the mold: a share of the fill,
/// and at least a few grams (what stays in the cup and on the stirrer,
/// which dominates small pours).
const OVERFILL_SHARE: f64 = 0.3;
const OVERFILL_MIN_G: f64 = 5.0;

/// What to weigh out for a cast (docs/casting.md).
#[derive(Serialize)]
pub struct CastingReport {
    /// The cavity and the runner, sprue, pour cone and vents: what the
    /// material fills (mL = cm³).
    pub fill_ml: f64,
    pub cavity_ml: f64,
    pub channels_ml: f64,
    /// The material (named by `lens.material`, or the one whose index
    /// `lens.index` is, then `material_from_index`).
    pub material: Option<&'static str>,
    pub material_from_index: bool,
    /// Density, mass of the fill, and the suggested mix with its parts by
    /// mass; `None` where no source states the material's density and ratio.
    pub density_g_per_ml: Option<f64>,
    pub fill_g: Option<f64>,
    pub overfill: OverfillReport,
    pub mix_g: Option<f64>,
    pub parts: Vec<PartReport>,
    pub source: Option<&'static str>,
}

#[derive(Serialize)]
pub struct OverfillReport {
    pub share: f64,
    pub at_least_g: f64,
    pub note: &'static str,
}

#[derive(Serialize)]
pub struct PartReport {
    pub name: &'static str,
    /// Its share in the ratio by mass (10 for 10 : 1).
    pub ratio: f64,
    pub grams: f64,
}

impl CastingReport {
    pub fn new(volumes: &moirecast_mold::Volumes, spec: &Spec) -> Self {
        let (fill_ml, cavity_ml) = (volumes.fill / 1e3, volumes.device / 1e3);
        let material = spec.cast_material;
        let data = material.and_then(|(m, _)| m.casting);
        let fill_g = data.map(|c| fill_ml * c.density_g_per_ml);
        let mix_g = fill_g.map(|g| (g * (1.0 + OVERFILL_SHARE)).max(g + OVERFILL_MIN_G));
        let parts = match (data, mix_g) {
            (Some(c), Some(mix)) => {
                let total: f64 = c.parts.iter().map(|p| p.0).sum();
                c.parts
                    .iter()
                    .map(|&(ratio, name)| PartReport {
                        name,
                        ratio,
                        grams: mix * ratio / total,
                    })
                    .collect()
            }
            _ => Vec::new(),
        };
        CastingReport {
            fill_ml,
            cavity_ml,
            channels_ml: fill_ml - cavity_ml,
            material: material.map(|(m, _)| m.name),
            material_from_index: material.is_some_and(|(_, from_index)| from_index),
            density_g_per_ml: data.map(|c| c.density_g_per_ml),
            fill_g,
            overfill: OverfillReport {
                share: OVERFILL_SHARE,
                at_least_g: OVERFILL_MIN_G,
                note: "mix the fill plus this share, and at least this many grams more: what stays in the cup and on the stirrer",
            },
            mix_g,
            parts,
            source: data.map(|c| c.source),
        }
    }

    /// The one line `moirecast mold` prints.
    pub fn line(&self) -> String {
        let fill = format!(
            "casting: fill {:.2} mL (cavity {:.2} + channels {:.2})",
            self.fill_ml, self.cavity_ml, self.channels_ml
        );
        match (self.material, self.fill_g, self.mix_g) {
            (Some(m), Some(g), Some(mix)) => {
                let parts: Vec<String> = self
                    .parts
                    .iter()
                    .map(|p| format!("{:.2} g {}", p.grams, p.name))
                    .collect();
                let ratio: Vec<String> =
                    self.parts.iter().map(|p| format!("{}", p.ratio)).collect();
                format!(
                    "{fill} = {g:.2} g of {m}; mix {mix:.1} g: {} ({} by mass)",
                    parts.join(" + "),
                    ratio.join(" : ")
                )
            }
            (m, ..) => format!(
                "{fill}; {}: weigh out fill × density from its datasheet",
                m.map_or("no material named".to_string(), |m| format!(
                    "no density or ratio is known for {m}"
                ))
            ),
        }
    }
}

#[derive(Serialize)]
pub struct DraftReport {
    pub degrees: f64,
    pub at: [f64; 3],
}

#[derive(Serialize)]
pub struct GateReport {
    pub wall: &'static str,
    pub at: [f64; 3],
    pub diameter_mm: f64,
    /// Horizontal runner from the gate to the sprue, on the parting line.
    pub runner_to: [f64; 3],
    pub sprue_axis: [f64; 2],
    pub sprue_diameter_mm: f64,
    pub sprue_z: [f64; 2],
    pub pour_cone_diameter_mm: f64,
    pub pour_cone_depth_mm: f64,
}

#[derive(Serialize)]
pub struct VentReport {
    /// Where the ceiling (without the ripple of single lenses) is highest.
    pub maximum: [f64; 3],
    /// "wall x-max", "corner" or "lenses" (a stub on the optics).
    pub attaches: String,
    pub axis: [f64; 2],
    pub diameter_mm: f64,
    pub z: [f64; 2],
}

#[derive(Serialize)]
pub struct KeyReport {
    /// Centre of the bump's base on the skirt; the socket is in the top half.
    pub at: [f64; 3],
}

#[derive(Serialize)]
pub struct MoldReport {
    pub moirecast: &'static str,
    pub spec: String,
    pub design: DesignEcho,
    pub view: crate::report::ViewReport,
    pub mold: MoldParams,
    pub frame: FrameReport,
    pub block_min: [f64; 3],
    pub block_max: [f64; 3],
    pub files: BTreeMap<String, FileReport>,
    /// `device.step`: the cavity's shape as an exact B-rep solid, the
    /// device's own in the mold frame.
    pub device_brep: crate::report::BrepReport,
    /// `mold-top.step` and `mold-bottom.step`: the halves as exact B-rep
    /// solids.
    pub halves_brep: HalvesBrepReport,
    pub volumes: VolumeReport,
    pub casting: CastingReport,
    /// Through-holes of each half (its genus): the channels through it.
    pub channels_through_top: u32,
    pub channels_through_bottom: u32,
    pub draft_top: DraftReport,
    pub draft_bottom: DraftReport,
    pub gate: GateReport,
    pub vents: Vec<VentReport>,
    pub keys: Vec<KeyReport>,
    pub key_diameter_mm: f64,
    pub bolts: Vec<[f64; 2]>,
    pub parting_surface_triangles: usize,
    pub warnings: Vec<String>,
    /// Names of the checks that failed (written only with --force).
    pub failed: Vec<&'static str>,
    pub checks: Vec<CheckReport>,
}

/// A half's B-rep: its STEP text's size and its counts.
#[derive(Serialize)]
pub struct HalfBrepReport {
    pub step_bytes: usize,
    pub faces: usize,
    pub edges: usize,
    pub vertices: usize,
    /// Faces' boundary loops beyond their first.
    pub inner_loops: usize,
}

#[derive(Serialize)]
pub struct HalvesBrepReport {
    pub top: HalfBrepReport,
    pub bottom: HalfBrepReport,
}

impl HalvesBrepReport {
    fn of(halves: &moirecast_brep::MoldStep) -> Self {
        let half = |b: &moirecast_brep::mold::RegionBrep, step: &moirecast_brep::StepText| {
            HalfBrepReport {
                step_bytes: step.len(),
                faces: b.faces,
                edges: b.edges,
                vertices: b.vertices,
                inner_loops: b.rings,
            }
        };
        HalvesBrepReport {
            top: half(&halves.top, &halves.top_step),
            bottom: half(&halves.bottom, &halves.bottom_step),
        }
    }
}

pub fn mold_report(
    spec: &Spec,
    mold: &Mold,
    checks: &[CheckResult],
    files: BTreeMap<String, FileReport>,
    (device_step, halves): (&moirecast_brep::DeviceStep, &moirecast_brep::MoldStep),
) -> MoldReport {
    let f = &mold.features;
    let v = &mold.volumes;
    let g = &f.gate;
    let (from, dir, length) = moirecast_mold::features::runner_span(g);
    let runner_to = from + (dir * length).extend(0.0);
    let top = f.block_hi.z;
    MoldReport {
        moirecast: env!("CARGO_PKG_VERSION"),
        spec: crate::report::spec_name(spec),
        design: design_echo(spec),
        view: crate::report::ViewReport::of(&spec.design),
        mold: spec.mold.clone(),
        frame: FrameReport {
            flip: spec.mold.flip,
            shrink_scale: spec.mold.shrink_scale,
            note: "all files share the mold frame: device.stl and device.step are the cavity's shape (the device rotated 180° about x if flipped, scaled by shrink_scale about its outline's centre)",
        },
        block_min: f.block_lo.to_array(),
        block_max: f.block_hi.to_array(),
        files,
        device_brep: crate::report::BrepReport::of(device_step),
        halves_brep: HalvesBrepReport::of(halves),
        volumes: VolumeReport {
            block_mm3: v.block,
            top_mm3: v.top,
            bottom_mm3: v.bottom,
            device_mm3: v.device,
            channels_mm3: v.voids,
            sum_relative_error: (v.top + v.bottom + v.device + v.voids - v.block) / v.block,
        },
        casting: CastingReport::new(v, spec),
        channels_through_top: mold.genus_top,
        channels_through_bottom: mold.genus_bottom,
        draft_top: DraftReport {
            degrees: mold.draft_top.degrees,
            at: mold.draft_top.at.to_array(),
        },
        draft_bottom: DraftReport {
            degrees: mold.draft_bottom.degrees,
            at: mold.draft_bottom.at.to_array(),
        },
        gate: GateReport {
            wall: g.wall.name(),
            at: g.at.to_array(),
            diameter_mm: 2.0 * g.radius,
            runner_to: runner_to.to_array(),
            sprue_axis: g.sprue_axis.to_array(),
            sprue_diameter_mm: 2.0 * g.sprue_radius,
            sprue_z: [g.sprue_bottom_z, top],
            pour_cone_diameter_mm: 2.0 * g.cone_radius,
            pour_cone_depth_mm: g.cone_depth,
        },
        vents: f
            .vents
            .iter()
            .map(|v| VentReport {
                maximum: v.maximum.to_array(),
                attaches: match v.place {
                    VentPlace::Wall(w) => format!("wall {}", w.name()),
                    VentPlace::Corner => "corner".into(),
                    VentPlace::Lenses => "lenses".into(),
                },
                axis: v.axis.to_array(),
                diameter_mm: 2.0 * v.radius,
                z: [v.foot_z, top],
            })
            .collect(),
        keys: f.keys.iter().map(|k| KeyReport { at: k.at.to_array() }).collect(),
        key_diameter_mm: spec.mold.key_diameter,
        bolts: f.bolts.iter().map(|b| b.to_array()).collect(),
        parting_surface_triangles: mold.parting_triangles,
        warnings: f.warnings.clone(),
        failed: checks.iter().filter(|c| !c.passed).map(|c| c.name).collect(),
        checks: checks.iter().map(CheckReport::from).collect(),
    }
}
