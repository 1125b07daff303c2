//! The registry of checks: every check a build makes, by name, with what
//! it measures, its unit, whether its limit is a maximum or a minimum,
//! where the limit comes from, and the part it belongs to. The CLI, the
//! report, `docs/checks.md` and the studio's labels read it; a
//! [`CheckResult`](crate::check::CheckResult) of a name not listed here, or
//! of another unit or bound, fails a debug assertion.

/// How a check's value is held against its limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bound {
    /// The limit is a maximum: passed when value ≤ limit.
    AtMost,
    /// The limit is a minimum: passed when value ≥ limit.
    AtLeast,
    /// The value must equal the limit (a count).
    Exactly,
    /// The value must exceed the limit.
    Above,
}

impl Bound {
    /// Whether `value` passes against `limit`.
    pub fn passes(self, value: f64, limit: f64) -> bool {
        match self {
            Bound::AtMost => value <= limit,
            Bound::AtLeast => value >= limit,
            Bound::Exactly => value == limit,
            Bound::Above => value > limit,
        }
    }

    /// The relation as a reader writes it between value and limit.
    pub fn symbol(self) -> &'static str {
        match self {
            Bound::AtMost => "≤",
            Bound::AtLeast => "≥",
            Bound::Exactly => "=",
            Bound::Above => ">",
        }
    }

    /// "at most", "at least", "exactly", "more than".
    pub fn words(self) -> &'static str {
        match self {
            Bound::AtMost => "at most",
            Bound::AtLeast => "at least",
            Bound::Exactly => "exactly",
            Bound::Above => "more than",
        }
    }
}

/// The part of the output a check is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// The device's mesh and its exact surfaces.
    Device,
    /// The device's B-rep (STEP).
    DeviceBrep,
    /// Whichever solid the check was run on: the device, or a mold half
    /// (its detail then starts with `mold-top: ` or `mold-bottom: `).
    Solid,
    /// The mold as a whole: its halves, the device and the voids together.
    Mold,
    /// The cavity and the channels that fill it.
    Cavity,
    /// The mold halves' B-reps (STEP).
    MoldBrep,
}

impl Part {
    /// The part's name as the page and the docs show it.
    pub fn label(self) -> &'static str {
        match self {
            Part::Device => "device",
            Part::DeviceBrep => "device B-rep",
            Part::Solid => "each solid",
            Part::Mold => "mold",
            Part::Cavity => "cavity",
            Part::MoldBrep => "mold B-rep",
        }
    }
}

/// One check, as the registry describes it.
#[derive(Clone, Copy, Debug)]
pub struct CheckDoc {
    /// The name in reports and messages.
    pub name: &'static str,
    /// A short human label.
    pub label: &'static str,
    /// What it measures, in a sentence.
    pub measures: &'static str,
    pub unit: &'static str,
    pub bound: Bound,
    /// Where the limit comes from.
    pub limit_from: &'static str,
    pub part: Part,
}

const fn doc(
    name: &'static str,
    label: &'static str,
    measures: &'static str,
    unit: &'static str,
    bound: Bound,
    limit_from: &'static str,
    part: Part,
) -> CheckDoc {
    CheckDoc {
        name,
        label,
        measures,
        unit,
        bound,
        limit_from,
        part,
    }
}

use Bound::*;
use Part::*;

/// Every check, in the order a mold report lists them.
pub const CHECKS: &[CheckDoc] = &[
    doc("finite-coordinates", "Finite coordinates", "Vertices with a coordinate that is not a finite number.", "vertices", AtMost, "none may be", Solid),
    doc("closed-oriented", "Closed and oriented", "Directed edges not matched by exactly one opposite edge: a watertight, consistently oriented surface has none.", "edges", AtMost, "none may be", Solid),
    doc("shells", "One piece", "Connected shells of the solid.", "shells", Exactly, "the solid's design (one, or one per printed band)", Solid),
    doc("genus", "Holes (genus)", "Handles through the solid, from its Euler characteristic.", "holes", Exactly, "the solid's design (a mold top has one per channel through it)", Solid),
    doc("positive-volume", "Positive volume", "The enclosed volume: positive when the surface faces out.", "mm³", Above, "zero", Solid),
    doc("f32-safe-triangles", "STL-safe triangles", "Triangles that collapse or flip when their vertices are rounded to the STL's 32-bit floats.", "triangles", AtMost, "none may be", Solid),
    doc("f32-distinct-vertices", "STL-distinct vertices", "Vertices that round to the same 32-bit point as another vertex.", "vertices", AtMost, "none may be", Solid),
    doc("no-degenerate-triangles", "No degenerate triangles", "The smallest altitude of any triangle.", "mm", AtLeast, "10 nm on the device, far below any tolerance; round-off on a mold half", Solid),
    doc("vertex-on-surface", "Vertices on the exact lenses", "The largest distance of a re-projected vertex from its exact lens surface.", "mm", AtMost, "round-off (1 nm): a vertex is a solved point of its lens", Device),
    doc("surface-to-mesh", "Mesh within tolerance", "The largest distance from the exact lens surfaces to the mesh, sampled inside the triangles.", "mm", AtMost, "mesh.tolerance", Device),
    doc("walls-on-outline", "Walls on the outline", "The largest distance of a wall vertex from its wall plane.", "mm", AtMost, "a share of mesh.tolerance", Device),
    doc("walls-face-out", "Walls face out", "Wall triangles whose normal points into the device.", "triangles", AtMost, "none may", Device),
    doc("creases-shared", "Creases shared", "The largest gap between neighbouring lenses' arc ends at a crease.", "mm", AtMost, "round-off: both lenses end on one solved crease point", Device),
    doc("base-creases-follow-shift", "Base follows the profile", "The largest |φ − crease phase| at the base's crease vertices: how far the base strays from the level-line shift.", "periods", AtMost, "round-off of the crease solve", Device),
    doc("surfaces-are-graphs", "Lenses do not fold", "Lens triangles that project with the wrong orientation over their surface.", "triangles", AtMost, "none may", Device),
    doc("min-thickness", "Thickness", "The thinnest distance of the revealer above the base.", "mm", AtLeast, "the mesh tolerance: the layers must not touch", Device),
    doc("measured-afov", "Lens field of view", "The largest difference between a lens arc's measured angular field of view and its design value.", "degrees", AtMost, "round-off (10⁻⁶ degrees)", Device),
    doc("arcs-are-circles", "Lenses are circular arcs", "The largest distance of a station-row vertex from its lens circle.", "mm", AtMost, "round-off (1 nm)", Device),
    doc("bodies-fill-device", "Printed bodies fill the device", "How far the clear and black bodies' volumes together differ from the device's, relative.", "relative", AtMost, "round-off of the two meshes' volumes", Device),
    doc("brep-surface-fit", "B-rep on the exact lenses", "The worst sampled distance of a lens or band face of the B-rep from its exact section.", "mm", AtMost, "mesh.tolerance", DeviceBrep),
    doc("brep-mesh-solid", "B-rep tessellation is solid", "Solid checks the B-rep's own tessellation fails (with --mesher brep).", "failed checks", AtMost, "none may fail", DeviceBrep),
    doc("brep-mesh-hausdorff", "B-rep tessellation near the mesh", "The largest distance between the B-rep's tessellation and the direct mesh, both ways.", "mm", AtMost, "twice mesh.tolerance: each is within it of the exact surface", DeviceBrep),
    doc("brep-mesh-volume", "B-rep tessellation's volume", "How far the tessellation's volume differs from the direct mesh's, relative.", "relative", AtMost, "lens area × mesh.tolerance over the volume", DeviceBrep),
    doc("mold-volumes-sum", "Parts fill the block", "How far top + bottom + device + channel voids differ from the block's volume, relative.", "relative", AtMost, "round-off (10⁻⁶)", Mold),
    doc("mold-parts-tile-block", "Parts tile the block", "The share of the block's surface left uncovered where the parts' faces do not cancel in pairs.", "of the block's surface", AtMost, "round-off (10⁻⁹)", Mold),
    doc("mold-no-overlaps", "Parts do not overlap", "The largest volume shared by two parts (top, bottom, device).", "mm³", AtMost, "round-off (10⁻⁴ mm³)", Mold),
    doc("cavity-on-device", "Cavity on the device", "The largest distance of a cavity-face vertex from the device.", "mm", AtMost, "round-off (1 nm)", Cavity),
    doc("cavity-covers-device", "Cavity covers the device", "The share of the device's surface the cavity faces leave uncovered.", "of the device's area", AtMost, "round-off (10⁻⁶)", Cavity),
    doc("demouldable", "Draft for demoulding", "The worst draft angle of a lens face against the direction its half lifts off.", "degrees", AtLeast, "1 degree", Cavity),
    doc("cavity-reachable", "Cavity reachable", "Connected pieces of the cavity with its channels: one when the gate and every vent reach it.", "connected pieces", AtMost, "one piece", Cavity),
    doc("vents-not-below-sprue", "Vents open at the top", "How far the lowest vent opens above the sprue's top.", "mm", AtLeast, "zero: air leaves last through the vents", Cavity),
    doc("mold-brep-euler", "Halves' B-reps closed", "Euler-characteristic defects of the halves' B-reps: each is one closed shell.", "", AtMost, "none may be", MoldBrep),
    doc("mold-brep-fit", "Halves' B-reps on the mesh", "The worst distance of a mesh half's vertex from its B-rep face's exact surface.", "mm", AtMost, "mesh.tolerance", MoldBrep),
    doc("mold-brep-channels-fit", "Channels' B-rep on the mesh", "The same, for vertices on a channel or key.", "mm", AtMost, "the channels' polygon sagitta and the STL's float step", MoldBrep),
    doc("mold-brep-samples-fit", "Halves' B-reps, sampled", "The worst distance from the mesh half of points sampled on both halves' B-rep faces.", "mm", AtMost, "mesh.tolerance and the STL's float step", MoldBrep),
    doc("mold-brep-channel-samples-fit", "Channels' B-rep, sampled", "The same, on the channels' and keys' sides and ends.", "mm", AtMost, "the channels' polygon sagitta, mesh.tolerance and the float step", MoldBrep),
    doc("mold-brep-device-samples-fit", "Cavity's B-rep, sampled", "The same, on the device's lens faces and the creases and rims they bound.", "mm", AtMost, "twice mesh.tolerance and the float step", MoldBrep),
];

/// The registry's entry for the check `name`.
pub fn check_doc(name: &str) -> Option<&'static CheckDoc> {
    CHECKS.iter().find(|d| d.name == name)
}

/// The part a check's result belongs to: its registry part, or for a
/// check run on each solid, the solid its detail names (`mold-top: …`,
/// `mold-bottom: …`; the device otherwise).
pub fn part_of(name: &str, detail: &str) -> &'static str {
    match check_doc(name).map(|d| d.part) {
        Some(Part::Solid) if detail.starts_with("mold-top: ") => "mold top",
        Some(Part::Solid) if detail.starts_with("mold-bottom: ") => "mold bottom",
        Some(Part::Solid) | None => "device",
        Some(part) => part.label(),
    }
}

/// The registry as a Markdown page (docs/checks.md, kept current by a
/// test).
pub fn markdown() -> String {
    let mut out = String::from(
        "# Checks\n\nEvery check a build makes, from the registry in \
         `crates/moirecast-kernel/src/checks.rs` (this page is generated from it \
         and kept current by a test). A build that fails a check writes nothing (`moirecast mold --force` aside).\n\n\
         | check | label | measures | passes when | limit from | part |\n|---|---|---|---|---|---|\n",
    );
    for d in CHECKS {
        let unit = if d.unit.is_empty() {
            String::new()
        } else {
            format!(" ({})", d.unit)
        };
        out += &format!(
            "| `{}` | {} | {} | value {} limit{} | {} | {} |\n",
            d.name,
            d.label,
            d.measures,
            d.bound.symbol(),
            unit,
            d.limit_from,
            d.part.label()
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_parts_resolve() {
        for (i, d) in CHECKS.iter().enumerate() {
            assert!(CHECKS[..i].iter().all(|e| e.name != d.name), "{}", d.name);
        }
        assert_eq!(
            part_of("genus", "mold-top: Euler characteristic -4"),
            "mold top"
        );
        assert_eq!(part_of("genus", "Euler characteristic 2"), "device");
        assert_eq!(part_of("demouldable", ""), "cavity");
    }
}
