//! Every key of the spec with its default, its range and its meaning:
//! one table, read by `moirecast --help`, by `docs/spec.md` (generated
//! from it; a test keeps the file current) and by the studio's form.
//!
//! Defaults are not written here: they are read off the spec tables'
//! `Default`s, so the table cannot disagree with the parser. Ranges come
//! from the kernel's and the mold's limit constants.

use moirecast_kernel::design::limits as design;
use moirecast_kernel::Tolerance;
use moirecast_mold::params::limits as mold;

/// What kind of value a key takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case", tag = "type", content = "choices")]
pub enum ValueKind {
    Number,
    Bool,
    /// One of these strings.
    Choice(&'static [&'static str]),
    /// Free text (a formula, a path).
    Text,
    /// A number in mm, or the word "focal".
    Distance,
    /// Two numbers, `[X, Y]`.
    Pair,
}

/// One key of the spec.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct KeyDoc {
    /// `table.key`, as written in the spec.
    pub key: &'static str,
    pub kind: ValueKind,
    /// The default as TOML, or what it is derived from when it depends on
    /// other keys ("lens.afov", "min(width, height)/4").
    pub default: String,
    /// The allowed values, in the key's unit.
    pub range: String,
    pub unit: &'static str,
    pub meaning: &'static str,
}

/// "lo to hi".
fn between((lo, hi): (f64, f64)) -> String {
    format!("{lo} to {hi}")
}

/// Every key, table by table, in the order the docs list them.
pub fn keys() -> Vec<KeyDoc> {
    use ValueKind::*;
    let defaults = crate::default_values();
    let doc = |key: &'static str,
               kind: ValueKind,
               derived: Option<&str>,
               range: String,
               unit: &'static str,
               meaning: &'static str| {
        let default = match (defaults.get(key), derived) {
            (Some(v), _) => v.clone(),
            (None, Some(d)) => d.to_string(),
            (None, None) => "(none)".to_string(),
        };
        KeyDoc {
            key,
            kind,
            default,
            range,
            unit,
            meaning,
        }
    };
    let any = || "any".to_string();
    let positive = || "> 0".to_string();
    vec![
        doc("surface.kind", Choice(&["plane", "saddle", "paraboloid", "cylinder", "sphere", "formula", "heightmap"]), None, "plane, saddle, paraboloid, cylinder, sphere, formula, heightmap".into(), "", "The pitch surface f through the lens creases (METHOD §1)."),
        doc("surface.radius", Number, None, "≠ 0; lens flanks (slope + AFOV/2) at most 80°".into(), "mm", "Radius of curvature. Paraboloid and sphere: + bowl, − dome; cylinder: + bends down, − up. Not used by plane, formula and heightmap."),
        doc("surface.z", Text, Some("(none)"), format!("a formula in x and y (mm from the centre); at most {} characters, {} operations, {} powers, parentheses {} deep", moirecast_kernel::formula::MAX_CHARS, moirecast_kernel::formula::MAX_OPERATIONS, moirecast_kernel::formula::MAX_POWERS, moirecast_kernel::formula::MAX_DEPTH), "mm", "kind = \"formula\": z = h(x, y), e.g. \"(x*x - y*y)/120\"."),
        doc("surface.image", Text, Some("(none)"), format!("a greyscale PNG (8 or 16 bit) relative to the spec, at least 4 × 4 and at most {} pixels", crate::MAX_IMAGE_PIXELS), "", "kind = \"heightmap\": the heights, black at z_min and white at z_max, the top row at +y; the surface is a C² smoothing bicubic B-spline through them."),
        doc("surface.z_min", Number, Some("0.0 with kind = \"heightmap\""), any(), "mm", "kind = \"heightmap\": the height of black."),
        doc("surface.z_max", Number, Some("1.0 with kind = \"heightmap\""), "≥ z_min".into(), "mm", "kind = \"heightmap\": the height of white."),
        doc("surface.size", Pair, Some("[layout.width, layout.height]"), "[X, Y], covering the layout".into(), "mm", "kind = \"heightmap\": the extent the image covers, centred on the layout's centre (x = u − W/2); beyond it the spline is continued."),
        doc("surface.smoothing", Number, Some("8 pixels' spacing for 16-bit images, 24 for 8-bit"), "≥ 0".into(), "mm", "kind = \"heightmap\": features shorter than this keep at most half their height (third-difference P-spline); report.json states the fit's largest deviation from the samples."),
        doc("layout.width", Number, None, format!("a whole number of periods, at most {} lenses", design::MAX_LENSES), "mm", "Width across the lenses (u, along x)."),
        doc("layout.height", Number, None, positive(), "mm", "Height along the lenses (v, along y)."),
        doc("layout.period", Number, None, between(design::PERIOD_MM), "mm", "Lens period T."),
        doc("lens.afov", Number, None, between(design::AFOV_DEG), "degrees", "Angular field of view α of every revealer lens."),
        doc("lens.index", Number, Some("1.41, or the material's"), format!("above {} and at most {}; D_s at most {} periods", design::INDEX.0, design::INDEX.1, design::MAX_FOCAL_PERIODS), "", "Refractive index n_l; overrides lens.material."),
        doc("lens.material", Choice(&["sylgard-184", "polyjet-clear", "pmma", "polycarbonate", "epoxy"]), Some("(none: index 1.41)"), "sylgard-184, polyjet-clear, pmma, polycarbonate, epoxy".into(), "", "A named material: sets the index, and the casting quantities of `moirecast mold`."),
        doc("lens.rule", Choice(&["constant-afov", "equal-radius"]), None, "constant-afov, equal-radius".into(), "", "Constant AFOV (the paper's choice), or every lens of radius r_s (Fig. 4b)."),
        doc("base.kind", Choice(&["dual-lens", "printed"]), None, "dual-lens, printed".into(), "", "Dual-lens: one clear material, cast in the mold. Printed: black bands in a clear body, for multi-material printers."),
        doc("base.a", Number, None, between((0.0, 1.0)), "", "Weight between the offset surface (0) and the focal surface (1), METHOD §3."),
        doc("base.d", Distance, None, format!("> 0 and at most {} D_s, or \"focal\" (D_s); the base may not fold: d·κ < {}", design::MAX_DEPTH_FOCAL, design::MAX_FOLD), "mm", "Offset distance of the base below the pitch surface."),
        doc("base.levels", Number, None, format!("0 to {}; the shift slope A·T·∂e/∂u below {}", design::MAX_LEVELS, design::MAX_SHIFT_SLOPE), "periods", "Elevation amplitude A: how many level lines the profile spans."),
        doc("base.afov", Number, Some("lens.afov"), between(design::AFOV_DEG), "degrees", "Dual-lens only: AFOV of the base lenses."),
        doc("base.duty", Number, Some("0.5 (printed)"), between(design::DUTY), "", "Printed only: black share of each period."),
        doc("base.band_thickness", Number, Some("0.2 (printed)"), between(design::BAND_THICKNESS_MM), "mm", "Printed only: black layer below s, along z."),
        doc("base.backing", Number, Some("1.0 (printed)"), between(design::BACKING_MM), "mm", "Printed only: clear layer below the bands, along z."),
        doc("profile.kind", Choice(&["image", "rings", "ramp", "bump", "flat"]), Some("\"rings\", or \"image\" when profile.image is given"), "image, rings, ramp, bump, flat".into(), "", "Where the elevation e comes from."),
        doc("profile.image", Text, Some("(none)"), "a PNG path relative to the spec".into(), "", "The image of the elevation profile."),
        doc("profile.mode", Choice(&["gray", "shape"]), None, "gray, shape".into(), "", "Images: \"gray\" (bright is high) or \"shape\" (dark pixels are the shape; level lines follow its outline)."),
        doc("profile.blur", Number, None, between(crate::BLUR_MM), "mm", "Gaussian σ applied to the image."),
        doc("profile.threshold", Number, None, "above 0, at most 1".into(), "", "Shape mode: luminance below this is inside."),
        doc("profile.invert", Bool, None, "true, false".into(), "", "Swap high and low (gray) or inside and outside (shape)."),
        doc("profile.wavelength", Number, Some("min(width, height)/4"), positive(), "mm", "Rings: ring spacing."),
        doc("profile.angle", Number, None, any(), "degrees", "Ramp: direction from +x."),
        doc("profile.sigma", Number, Some("min(width, height)/6"), positive(), "mm", "Bump: Gaussian σ."),
        doc("mesh.tolerance", Number, None, format!("{} to {}, and below half the lens sag", Tolerance::MIN_MM, Tolerance::MAX_MM), "mm", "Every point of the exact surface lies within this of the mesh."),
        doc("view.tilt", Number, None, format!("-{0} to {0}", crate::VIEW_TILT_DEG), "degrees", "The design view's tilt about the lens axis (y), as `moirecast render --tilts`: the view the base is compensated for, and the render's tilt 0."),
        doc("view.tilt_along", Number, None, format!("-{0} to {0}", crate::VIEW_TILT_DEG), "degrees", "The design view's tilt about x, as `moirecast render --tilt-along`."),
        doc("view.distance", Distance, None, format!("{} to {} mm, or \"infinite\"", crate::VIEW_DISTANCE_MM.0, crate::VIEW_DISTANCE_MM.1), "mm", "The eye's distance from the device's centre; \"infinite\": an orthographic view, every lens seen along the same direction."),
        doc("view.compensate", Bool, None, "true, false; the compensated base phase must still rise with u".into(), "", "Shift the base so that from the design view every lens shows the phase a flat device shows straight on (false: the uncompensated base)."),
        doc("mold.wall_thickness", Number, None, between(mold::WALL_THICKNESS), "mm", "Block material on every side of the device (MoldMaker uses 6)."),
        doc("mold.gate_diameter", Number, None, format!("{}; at most the sprue's, and must fit the wall's height", between(mold::GATE_DIAMETER)), "mm", "Gate and runner on the parting line."),
        doc("mold.sprue_diameter", Number, None, between(mold::SPRUE_DIAMETER), "mm", "Vertical sprue (MoldMaker's syringe gate)."),
        doc("mold.pour_cone_diameter", Number, None, "at least the sprue's".into(), "mm", "Pour cone at the top face."),
        doc("mold.pour_cone_depth", Number, None, between(mold::POUR_CONE_DEPTH), "mm", "Depth of the pour cone below the top face."),
        doc("mold.vent_diameter", Number, None, between(mold::VENT_DIAMETER), "mm", "Vents from the cavity's ceiling maxima to the top face (MoldMaker)."),
        doc("mold.key_diameter", Number, None, between(mold::KEY_DIAMETER), "mm", "Tapered registration bumps on the skirt's corners."),
        doc("mold.key_height", Number, None, between(mold::KEY_HEIGHT), "mm", "Height of the keys."),
        doc("mold.key_taper", Number, None, between(mold::KEY_TAPER), "degrees", "Taper of a key's side from vertical."),
        doc("mold.key_clearance", Number, None, between(mold::KEY_CLEARANCE), "mm", "Socket clearance around a key (crpalmer's molds.scad)."),
        doc("mold.bolts", Bool, None, "true, false".into(), "", "Clamp-bolt holes around the rim (FabSquare)."),
        doc("mold.bolt_diameter", Number, None, between(mold::BOLT_DIAMETER), "mm", "3.4 mm clears M3."),
        doc("mold.bolt_spacing", Number, None, between(mold::BOLT_SPACING), "mm", "Largest spacing between bolts."),
        doc("mold.shrink_scale", Number, None, between(mold::SHRINK_SCALE), "", "Scale of the cavity against shrinkage (no Sylgard 184 value is established here)."),
        doc("mold.flip", Bool, None, "true, false".into(), "", "Mould upside down (base lenses up)."),
        doc("mold.min_draft", Number, None, between(mold::MIN_DRAFT), "degrees", "Smallest lens-face draft against the draw direction."),
    ]
}

/// The defaults of every key, as `moirecast --help` shows them.
pub fn defaults_help() -> String {
    let mut out =
        String::from("Spec defaults (every key is optional; docs/spec.md lists them all):\n");
    let mut table = "";
    for k in keys().into_iter().filter(|k| k.default != "(none)") {
        let (t, name) = k.key.split_once('.').expect("table.key");
        if t != table {
            out.push_str(&format!("\n[{t}]"));
            table = t;
        }
        out.push_str(&format!(" {name} = {};", k.default));
    }
    out.push('\n');
    out
}

/// `docs/spec.md`: every key, table by table, as Markdown.
pub fn spec_markdown() -> String {
    let mut out = String::from(
        "# The design spec\n\n\
         <!-- Generated from crates/moirecast-spec/src/keys.rs by \
         `MOIRECAST_BLESS=1 cargo test -p moirecast-spec`; a test fails when it is stale. -->\n\n\
         A spec is a TOML file. Every key is optional and has the default shown; an \
         unknown key is an error. Lengths are in mm, angles in degrees. A value out of \
         range is refused before anything is built, with the key, the value, the \
         allowed range and the fix. `[mold]` is read only by `moirecast mold`.\n",
    );
    let mut table = "";
    for k in keys() {
        let (t, name) = k.key.split_once('.').expect("table.key");
        if t != table {
            out.push_str(&format!(
                "\n## `[{t}]`\n\n| key | default | range | unit | meaning |\n|---|---|---|---|---|\n"
            ));
            table = t;
        }
        let cell = |s: &str| s.replace('|', "\\|");
        out.push_str(&format!(
            "| `{name}` | `{}` | {} | {} | {} |\n",
            cell(&k.default),
            cell(&k.range),
            k.unit,
            cell(k.meaning)
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// The names serde expects where `text` has an unknown one, read off
    /// its error ("unknown field `x`, expected one of `a`, `b`").
    fn expected(text: &str) -> BTreeSet<String> {
        let e = crate::parse(text, "t.toml", crate::ImageSource::Embedded)
            .unwrap_err()
            .to_string();
        let after = e.split("expected").nth(1).unwrap_or_else(|| panic!("{e}"));
        after
            .split('`')
            .skip(1)
            .step_by(2)
            .map(str::to_string)
            .collect()
    }

    /// The table lists exactly the keys the parser takes, table by table.
    #[test]
    fn the_table_lists_every_key_the_parser_takes() {
        let listed: BTreeSet<String> = keys().iter().map(|k| k.key.to_string()).collect();
        let mut parsed = BTreeSet::new();
        for table in expected("xyzzy = 1") {
            for key in expected(&format!("[{table}]\nxyzzy = 1")) {
                parsed.insert(format!("{table}.{key}"));
            }
        }
        assert_eq!(listed, parsed);
    }

    /// Every choice the table offers is one the parser takes, and no other.
    #[test]
    fn choices_are_the_parsers() {
        for k in keys() {
            let ValueKind::Choice(choices) = k.kind else {
                continue;
            };
            let (table, key) = k.key.split_once('.').unwrap();
            if k.key == "lens.material" {
                let names: Vec<&str> = crate::MATERIALS.iter().map(|m| m.name).collect();
                assert_eq!(choices, &names[..]);
                continue;
            }
            let parser = expected(&format!("[{table}]\n{key} = \"xyzzy\""));
            let ours: BTreeSet<String> = choices.iter().map(|c| c.to_string()).collect();
            assert_eq!(ours, parser, "{}", k.key);
        }
    }

    /// `docs/spec.md` is what the table says; `MOIRECAST_BLESS=1` rewrites it.
    #[test]
    fn docs_spec_md_is_current() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/spec.md");
        let want = spec_markdown();
        if std::env::var_os("MOIRECAST_BLESS").is_some() {
            std::fs::write(path, &want).unwrap();
        }
        let have = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            have == want,
            "docs/spec.md is stale: run `MOIRECAST_BLESS=1 cargo test -p moirecast-spec`"
        );
    }
}
