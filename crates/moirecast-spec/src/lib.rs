//! The design spec: a TOML file, parsed and validated at the edge.
//!
//! Every key has a written default (see [`keys`] and `docs/spec.md`). An
//! unknown key, a value out of range or a missing image is a [`SpecError`]
//! that names the key, the value, what is allowed and the fix. Nothing past
//! this crate sees TOML.
//!
//! ```
//! use moirecast_spec::{parse, ImageSource};
//!
//! let spec = parse(
//!     "[surface]\nkind = \"plane\"\n[layout]\nwidth = 10\nheight = 5\n[profile]\nkind = \"ramp\"",
//!     "example.toml",
//!     ImageSource::Embedded,
//! )
//! .expect("a valid spec");
//! assert_eq!(spec.design.lenses, 20); // 10 mm of 0.5 mm lenses
//!
//! // a bad value names its key, the value, the range and the fix
//! let e = parse("[lens]\nafov = 200", "bad.toml", ImageSource::Embedded).unwrap_err();
//! assert!(e.to_string().contains("`lens.afov` = 200"), "{e}");
//! ```

use moirecast_kernel::{
    heightmap::{HeightMap, HeightSamples},
    profile::SampledProfile,
    BaseParams, Design, DesignError, DesignParams, LensParams, LensRule, Param, PitchSurface,
    PrintedBase, Profile, ProfileMode, Raster,
};
use moirecast_mold::{MoldError, MoldParam, MoldParams};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use thiserror::Error;

mod edit;
mod keys;
pub use edit::{apply_edits, EditError, EditValue, SpecEdit};
pub use keys::{defaults_help, keys, spec_markdown, KeyDoc, ValueKind};

/// The reference design (`molds/saddle-horse.toml`), built when no spec is given.
pub const DEFAULT_SPEC: &str = include_str!("../../../molds/saddle-horse.toml");
const EMBEDDED_IMAGES: &[(&str, &[u8])] = &[
    (
        "profiles/horse.png",
        include_bytes!("../../../molds/profiles/horse.png"),
    ),
    (
        "profiles/camera.png",
        include_bytes!("../../../molds/profiles/camera.png"),
    ),
    (
        "profiles/coins.png",
        include_bytes!("../../../molds/profiles/coins.png"),
    ),
];

/// The profile images shipped inside the binary, by the name the default
/// design gives them ("profiles/horse.png").
pub fn embedded_images() -> impl Iterator<Item = (&'static str, &'static [u8])> {
    EMBEDDED_IMAGES.iter().copied()
}

/// Gaussian blur σ of an image profile (mm).
pub const BLUR_MM: (f64, f64) = (0.0, 20.0);

#[derive(Debug, Error)]
pub enum SpecError {
    /// The spec file could not be read.
    #[error("cannot read spec `{path}`: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    /// TOML syntax, an unknown key or a value of the wrong type. toml's
    /// message names the key and shows the line.
    #[error("spec `{file}`: {message}")]
    Syntax { file: String, message: String },
    /// A value that parses but is not allowed.
    #[error("spec `{file}`: `{key}` = {value}: {problem}.\n  Fix: {fix}")]
    Invalid {
        file: String,
        key: &'static str,
        value: String,
        problem: String,
        fix: String,
    },
}

/// The key of each kernel parameter in the spec.
pub fn key_of(p: Param) -> &'static str {
    match p {
        Param::SurfaceRadius => "surface.radius",
        Param::SurfaceFormula => "surface.z",
        Param::SurfaceHeightMap => "surface.image",
        Param::Width => "layout.width",
        Param::Height => "layout.height",
        Param::Period => "layout.period",
        Param::Afov => "lens.afov",
        Param::Index => "lens.index",
        Param::BaseAfov => "base.afov",
        Param::BaseA => "base.a",
        Param::BaseD => "base.d",
        Param::Levels => "base.levels",
        Param::Duty => "base.duty",
        Param::BandThickness => "base.band_thickness",
        Param::Backing => "base.backing",
        Param::Blur => "profile.blur",
        Param::Tolerance => "mesh.tolerance",
        Param::ProfileImage => "profile.image",
        Param::ProfileWavelength => "profile.wavelength",
        Param::ProfileSigma => "profile.sigma",
        Param::ViewTilt => "view.tilt",
        Param::ViewTiltAlong => "view.tilt_along",
        Param::ViewDistance => "view.distance",
        Param::ViewCompensate => "view.compensate",
    }
}

/// The key of each mold parameter in the spec.
pub fn mold_key_of(p: MoldParam) -> &'static str {
    match p {
        MoldParam::WallThickness => "mold.wall_thickness",
        MoldParam::GateDiameter => "mold.gate_diameter",
        MoldParam::SprueDiameter => "mold.sprue_diameter",
        MoldParam::PourConeDiameter => "mold.pour_cone_diameter",
        MoldParam::PourConeDepth => "mold.pour_cone_depth",
        MoldParam::VentDiameter => "mold.vent_diameter",
        MoldParam::KeyDiameter => "mold.key_diameter",
        MoldParam::KeyHeight => "mold.key_height",
        MoldParam::KeyTaper => "mold.key_taper",
        MoldParam::KeyClearance => "mold.key_clearance",
        MoldParam::BoltDiameter => "mold.bolt_diameter",
        MoldParam::BoltSpacing => "mold.bolt_spacing",
        MoldParam::ShrinkScale => "mold.shrink_scale",
        MoldParam::MinDraft => "mold.min_draft",
    }
}

/// A mold error as the user sees it: parameter errors name their key.
pub fn describe_mold_error(file: &str, e: &MoldError) -> String {
    match e {
        MoldError::Param { param, .. } => format!("spec `{file}`: `{}` = {e}", mold_key_of(*param)),
        MoldError::DoesNotFit {
            param: Some(param), ..
        } => {
            format!("spec `{file}`: {e} (key `{}`)", mold_key_of(*param))
        }
        MoldError::NotCastable => format!("spec `{file}`: `base.kind` = \"printed\": {e}"),
        _ => e.to_string(),
    }
}

// ---- the file format ------------------------------------------------------

#[derive(Deserialize, Serialize, Debug, Default)]
#[serde(deny_unknown_fields)]
struct SpecFile {
    #[serde(default)]
    surface: SurfaceTable,
    #[serde(default)]
    layout: LayoutTable,
    #[serde(default)]
    lens: LensTable,
    #[serde(default)]
    base: BaseTable,
    #[serde(default)]
    profile: ProfileTable,
    #[serde(default)]
    mesh: MeshTable,
    #[serde(default)]
    view: ViewTable,
    #[serde(default)]
    mold: MoldTable,
}

#[derive(Deserialize, Serialize, Debug, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
enum SurfaceKind {
    Plane,
    Saddle,
    Paraboloid,
    Cylinder,
    Sphere,
    Formula,
    Heightmap,
}

#[derive(Deserialize, Serialize, Debug)]
#[serde(deny_unknown_fields, default)]
struct SurfaceTable {
    kind: SurfaceKind,
    radius: f64,
    z: Option<String>,
    image: Option<String>,
    z_min: Option<f64>,
    z_max: Option<f64>,
    size: Option<[f64; 2]>,
    smoothing: Option<f64>,
}
impl Default for SurfaceTable {
    fn default() -> Self {
        SurfaceTable {
            kind: SurfaceKind::Saddle,
            radius: 60.0,
            z: None,
            image: None,
            z_min: None,
            z_max: None,
            size: None,
            smoothing: None,
        }
    }
}

#[derive(Deserialize, Serialize, Debug)]
#[serde(deny_unknown_fields, default)]
struct LayoutTable {
    width: f64,
    height: f64,
    period: f64,
}
impl Default for LayoutTable {
    fn default() -> Self {
        LayoutTable {
            width: 60.0,
            height: 60.0,
            period: 0.5,
        }
    }
}

#[derive(Deserialize, Serialize, Debug, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
enum RuleKey {
    ConstantAfov,
    EqualRadius,
}

/// A named material: its refractive index and, for the two-part resins a
/// mold is cast in, what a person weighs out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub name: &'static str,
    pub index: f64,
    pub index_source: &'static str,
    /// Casting data, where a source states them.
    pub casting: Option<CastingData>,
}

/// How a cast material is mixed.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CastingData {
    /// Density of the mixed material (g/cm³, which is g/mL).
    pub density_g_per_ml: f64,
    /// Parts by mass, and their names: (10, "base"), (1, "curing agent").
    pub parts: [(f64, &'static str); 2],
    /// Where the density and the ratio come from.
    pub source: &'static str,
}

/// Named materials: `lens.material`.
pub const MATERIALS: &[Material] = &[
    Material {
        name: "sylgard-184",
        index: 1.41,
        index_source: "Dow datasheet 1.4118 at 632.8 nm",
        casting: Some(CastingData {
            density_g_per_ml: 1.03,
            parts: [(10.0, "base"), (1.0, "curing agent")],
            source: "Dow, SYLGARD 184 Silicone Elastomer technical data sheet: specific gravity (cured) 1.03; mix ratio 10 : 1 base to curing agent by weight",
        }),
    },
    Material {
        name: "polyjet-clear",
        index: 1.5,
        index_source: "the paper's assumption for PolyJet clear",
        casting: None,
    },
    Material {
        name: "pmma",
        index: 1.49,
        index_source: "acrylic",
        casting: None,
    },
    Material {
        name: "polycarbonate",
        index: 1.585,
        index_source: "",
        casting: None,
    },
    Material {
        name: "epoxy",
        index: 1.55,
        index_source: "typical clear casting epoxy",
        casting: None,
    },
];

/// The material a spec casts, and whether it was taken from the index
/// rather than named: the one `lens.material` names, or else the one
/// whose index `index` is (1.41, the default, is Sylgard 184's).
fn cast_material(lens: &LensTable, index: f64) -> Option<(&'static Material, bool)> {
    match &lens.material {
        Some(m) => MATERIALS
            .iter()
            .find(|mat| mat.name == m)
            .map(|m| (m, false)),
        None => MATERIALS
            .iter()
            .find(|m| m.index == index)
            .map(|m| (m, true)),
    }
}

#[derive(Deserialize, Serialize, Debug)]
#[serde(deny_unknown_fields, default)]
struct LensTable {
    afov: f64,
    index: Option<f64>,
    material: Option<String>,
    rule: RuleKey,
}
impl Default for LensTable {
    fn default() -> Self {
        LensTable {
            afov: 60.0,
            index: None,
            material: None,
            rule: RuleKey::ConstantAfov,
        }
    }
}

#[derive(Deserialize, Serialize, Debug, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
enum BaseKind {
    DualLens,
    Printed,
}

#[derive(Deserialize, Serialize, Debug, Clone)]
#[serde(untagged)]
enum Distance {
    Mm(f64),
    Named(String),
}

#[derive(Deserialize, Serialize, Debug)]
#[serde(deny_unknown_fields, default)]
struct BaseTable {
    kind: BaseKind,
    a: f64,
    d: Distance,
    levels: f64,
    afov: Option<f64>,
    duty: Option<f64>,
    band_thickness: Option<f64>,
    backing: Option<f64>,
}
impl Default for BaseTable {
    fn default() -> Self {
        BaseTable {
            kind: BaseKind::DualLens,
            a: 0.0,
            d: Distance::Named("focal".into()),
            levels: 1.0,
            afov: None,
            duty: None,
            band_thickness: None,
            backing: None,
        }
    }
}

#[derive(Deserialize, Serialize, Debug, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
enum ProfileKind {
    Image,
    Rings,
    Ramp,
    Bump,
    Flat,
}

impl ProfileKind {
    /// The kind as the spec writes it.
    fn name(self) -> &'static str {
        match self {
            ProfileKind::Image => "image",
            ProfileKind::Rings => "rings",
            ProfileKind::Ramp => "ramp",
            ProfileKind::Bump => "bump",
            ProfileKind::Flat => "flat",
        }
    }
}

#[derive(Deserialize, Serialize, Debug, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
enum ModeKey {
    Gray,
    Shape,
}

#[derive(Deserialize, Serialize, Debug)]
#[serde(deny_unknown_fields, default)]
struct ProfileTable {
    kind: Option<ProfileKind>,
    image: Option<String>,
    mode: ModeKey,
    blur: f64,
    threshold: f64,
    invert: bool,
    wavelength: Option<f64>,
    angle: f64,
    sigma: Option<f64>,
}
impl Default for ProfileTable {
    fn default() -> Self {
        ProfileTable {
            kind: None,
            image: None,
            mode: ModeKey::Shape,
            blur: 1.0,
            threshold: 0.5,
            invert: false,
            wavelength: None,
            angle: 90.0,
            sigma: None,
        }
    }
}

#[derive(Deserialize, Serialize, Debug)]
#[serde(deny_unknown_fields, default)]
struct MeshTable {
    tolerance: f64,
}
impl Default for MeshTable {
    fn default() -> Self {
        MeshTable { tolerance: 0.002 }
    }
}

/// `[view]`: the design view the base is compensated for (docs/method.md).
#[derive(Deserialize, Serialize, Debug)]
#[serde(deny_unknown_fields, default)]
struct ViewTable {
    tilt: f64,
    tilt_along: f64,
    distance: Distance,
    compensate: bool,
}
impl Default for ViewTable {
    fn default() -> Self {
        ViewTable {
            tilt: 0.0,
            tilt_along: 0.0,
            distance: Distance::Named("infinite".into()),
            compensate: true,
        }
    }
}

/// Largest design-view tilt (degrees) either way: past it a lens is seen
/// nearly edge on.
pub const VIEW_TILT_DEG: f64 = 60.0;
/// Nearest design-view eye (mm): nearer than a hand's width a device is
/// not looked at.
pub const VIEW_DISTANCE_MM: (f64, f64) = (50.0, 1e6);

/// `[view]` as the kernel's design view.
fn design_view(file: &str, v: &ViewTable) -> Result<moirecast_kernel::DesignView, SpecError> {
    let tilt = |key: &'static str, deg: f64| {
        let deg = finite(file, key, deg)?;
        if deg.abs() > VIEW_TILT_DEG {
            return Err(invalid(
                file,
                key,
                deg,
                format!("must be between -{VIEW_TILT_DEG} and {VIEW_TILT_DEG} degrees"),
                "use a view closer to straight down",
            ));
        }
        Ok(deg.to_radians())
    };
    let distance = match &v.distance {
        Distance::Mm(d) => {
            let d = finite(file, "view.distance", *d)?;
            let (lo, hi) = VIEW_DISTANCE_MM;
            if !(lo..=hi).contains(&d) {
                return Err(invalid(file, "view.distance", d, format!("must be between {lo} and {hi} mm, or \"infinite\""), "write the eye's distance from the device in mm, or \"infinite\" for a view from afar"));
            }
            Some(d)
        }
        Distance::Named(n) if n == "infinite" => None,
        Distance::Named(n) => {
            return Err(invalid(
                file,
                "view.distance",
                format!("{n:?}"),
                "must be a distance in mm or \"infinite\"",
                "write distance = \"infinite\" or a number",
            ))
        }
    };
    Ok(moirecast_kernel::DesignView {
        tilt: tilt("view.tilt", v.tilt)?,
        tilt_along: tilt("view.tilt_along", v.tilt_along)?,
        distance,
        compensate: v.compensate,
    })
}

/// `[mold]`: every dimension of the two-piece mold (METHOD §6), in mm and
/// degrees. Defaults are `MoldParams::default()`.
#[derive(Deserialize, Serialize, Debug)]
#[serde(deny_unknown_fields, default)]
struct MoldTable {
    wall_thickness: f64,
    gate_diameter: f64,
    sprue_diameter: f64,
    pour_cone_diameter: f64,
    pour_cone_depth: f64,
    vent_diameter: f64,
    key_diameter: f64,
    key_height: f64,
    key_taper: f64,
    key_clearance: f64,
    bolts: bool,
    bolt_diameter: f64,
    bolt_spacing: f64,
    shrink_scale: f64,
    flip: bool,
    min_draft: f64,
}
impl Default for MoldTable {
    fn default() -> Self {
        let d = MoldParams::default();
        MoldTable {
            wall_thickness: d.wall_thickness,
            gate_diameter: d.gate_diameter,
            sprue_diameter: d.sprue_diameter,
            pour_cone_diameter: d.pour_cone_diameter,
            pour_cone_depth: d.pour_cone_depth,
            vent_diameter: d.vent_diameter,
            key_diameter: d.key_diameter,
            key_height: d.key_height,
            key_taper: d.key_taper_deg,
            key_clearance: d.key_clearance,
            bolts: d.bolts,
            bolt_diameter: d.bolt_diameter,
            bolt_spacing: d.bolt_spacing,
            shrink_scale: d.shrink_scale,
            flip: d.flip,
            min_draft: d.min_draft_deg,
        }
    }
}
impl MoldTable {
    fn params(&self) -> MoldParams {
        MoldParams {
            wall_thickness: self.wall_thickness,
            gate_diameter: self.gate_diameter,
            sprue_diameter: self.sprue_diameter,
            pour_cone_diameter: self.pour_cone_diameter,
            pour_cone_depth: self.pour_cone_depth,
            vent_diameter: self.vent_diameter,
            key_diameter: self.key_diameter,
            key_height: self.key_height,
            key_taper_deg: self.key_taper,
            key_clearance: self.key_clearance,
            bolts: self.bolts,
            bolt_diameter: self.bolt_diameter,
            bolt_spacing: self.bolt_spacing,
            shrink_scale: self.shrink_scale,
            flip: self.flip,
            min_draft_deg: self.min_draft,
        }
    }
}

/// The default of every key that has a value of its own, as TOML text,
/// read off the tables' `Default`s: `"lens.afov"` → `"60.0"`.
pub(crate) fn default_values() -> std::collections::BTreeMap<String, String> {
    let value = toml::Value::try_from(SpecFile::default()).expect("the defaults serialise");
    let mut out = std::collections::BTreeMap::new();
    for (table, keys) in value.as_table().expect("a table of tables") {
        for (key, v) in keys.as_table().expect("each table is a table") {
            out.insert(format!("{table}.{key}"), v.to_string());
        }
    }
    out
}

// ---- loading --------------------------------------------------------------

/// Where images named in a spec come from.
pub enum ImageSource<'a> {
    /// Relative to this directory (the spec file's).
    Dir(&'a Path),
    /// The images shipped inside the binary (for the default design).
    Embedded,
}

/// A loaded, validated spec.
#[derive(Debug)]
pub struct Spec {
    pub design: Design,
    /// Where the spec came from (a path, or `<default: …>`).
    pub origin: String,
    /// The profile's source, for reports: "rings", "profiles/horse.png (shape)".
    pub profile_source: String,
    pub material: Option<String>,
    /// The material the device is cast in (see `docs/casting.md`): the one
    /// `lens.material` names, or the one whose index `lens.index` is, then
    /// marked as taken from the index.
    pub cast_material: Option<(&'static Material, bool)>,
    /// The `[mold]` table, range-checked; fits to the device are checked
    /// when the mold is built.
    pub mold: MoldParams,
    /// The spec's text and the image it read: a run's folder keeps them, so
    /// that it can be rebuilt.
    pub source: SpecSource,
}

/// The text a spec was parsed from, and the images it read.
pub struct SpecSource {
    pub text: String,
    pub images: Vec<SpecImage>,
}

/// An image a spec read: the key that names it, its name as the spec
/// gives it, and its bytes.
pub struct SpecImage {
    /// `profile.image` or `surface.image`.
    pub key: &'static str,
    pub name: String,
    pub bytes: Vec<u8>,
}

impl std::fmt::Debug for SpecSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let images: Vec<String> = self
            .images
            .iter()
            .map(|i| format!("{} = {}: {} bytes", i.key, i.name, i.bytes.len()))
            .collect();
        f.debug_struct("SpecSource")
            .field("text", &format_args!("{} bytes", self.text.len()))
            .field("images", &images)
            .finish()
    }
}

/// Loads the spec at `path`; images resolve relative to its directory.
pub fn load(path: &Path) -> Result<Spec, SpecError> {
    let text = std::fs::read_to_string(path).map_err(|source| SpecError::Read {
        path: path.to_owned(),
        source,
    })?;
    let dir = path.parent().unwrap_or(Path::new("."));
    parse(&text, &path.display().to_string(), ImageSource::Dir(dir))
}

/// The embedded default design.
pub fn default_spec() -> Result<Spec, SpecError> {
    parse(
        DEFAULT_SPEC,
        "<default: molds/saddle-horse.toml>",
        ImageSource::Embedded,
    )
}

fn invalid(
    file: &str,
    key: &'static str,
    value: impl ToString,
    problem: impl Into<String>,
    fix: impl Into<String>,
) -> SpecError {
    SpecError::Invalid {
        file: file.to_owned(),
        key,
        value: value.to_string(),
        problem: problem.into(),
        fix: fix.into(),
    }
}

/// A kernel design error as the user sees it: the key, the value, the
/// problem and the fix.
pub fn from_design_error(file: &str, e: DesignError) -> SpecError {
    SpecError::Invalid {
        file: file.to_owned(),
        key: key_of(e.param),
        value: e.value,
        problem: e.problem,
        fix: e.fix,
    }
}

fn finite(file: &str, key: &'static str, v: f64) -> Result<f64, SpecError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(invalid(
            file,
            key,
            v,
            "must be a finite number",
            "write a number",
        ))
    }
}

/// Parses and validates spec text. `file` names it in errors.
pub fn parse(text: &str, file: &str, images: ImageSource) -> Result<Spec, SpecError> {
    let raw: SpecFile = toml::from_str(text).map_err(|e| SpecError::Syntax {
        file: file.to_owned(),
        message: e.to_string().trim_end().to_owned(),
    })?;
    let layout = &raw.layout;
    let (w, h) = (
        finite(file, "layout.width", layout.width)?,
        finite(file, "layout.height", layout.height)?,
    );
    let (surface, surface_image) = surface(
        file,
        &raw.surface,
        LayoutSize {
            width: w,
            height: h,
        },
        &images,
    )?;
    let index = lens_index(file, &raw.lens)?;
    let base_kind = base_kind(file, &raw.base)?;
    let d = base_d(file, &raw.base.d)?;
    let afov = finite(file, "lens.afov", raw.lens.afov)?.to_radians();
    let base_afov = raw
        .base
        .afov
        .map(|a| finite(file, "base.afov", a).map(f64::to_radians))
        .transpose()?;
    let mut params = DesignParams {
        surface,
        width: w,
        height: h,
        period: finite(file, "layout.period", layout.period)?,
        lens: LensParams {
            afov,
            index,
            rule: match raw.lens.rule {
                RuleKey::ConstantAfov => LensRule::ConstantAfov,
                RuleKey::EqualRadius => LensRule::EqualRadius,
            },
        },
        base: BaseParams {
            kind: base_kind,
            a: finite(file, "base.a", raw.base.a)?,
            d,
            levels: finite(file, "base.levels", raw.base.levels)?,
            afov: base_afov,
        },
        profile: Profile::Flat,
        tolerance: finite(file, "mesh.tolerance", raw.mesh.tolerance)?,
        view: design_view(file, &raw.view)?,
    };
    // An image's grid must reach as far past the layout as the base reads
    // it: the design's margin, which neither the profile nor the view
    // compensation changes (so this probe leaves the compensation out).
    let reach = match raw.profile.image {
        Some(_) => {
            let mut probe = params.clone();
            probe.view.compensate = false;
            // a design refused without its profile (a layout a kilometre
            // wide) is refused for that, before its image is resampled
            Design::new(probe)
                .map_err(|e| from_design_error(file, e))?
                .margin
        }
        None => 0.0,
    };
    let (profile, profile_source, image) = profile(file, &raw.profile, (w, h, reach), &images)?;
    params.profile = profile;
    let design = Design::new(params).map_err(|e| from_design_error(file, e))?;
    let mold = raw.mold.params();
    mold.validate().map_err(|e| match e {
        MoldError::Param {
            param,
            value,
            problem,
            fix,
        } => invalid(file, mold_key_of(param), value, problem, fix),
        other => SpecError::Syntax {
            file: file.to_owned(),
            message: other.to_string(),
        },
    })?;
    Ok(Spec {
        mold,
        design,
        origin: file.to_owned(),
        profile_source,
        source: SpecSource {
            text: text.to_owned(),
            images: [image, surface_image].into_iter().flatten().collect(),
        },
        material: raw.lens.material.clone(),
        cast_material: cast_material(&raw.lens, index),
    })
}

/// The pitch surface of `[surface]` over a layout of `w` × `h` mm, and
/// the image it read (a height map's).
fn surface(
    file: &str,
    s: &SurfaceTable,
    layout: LayoutSize,
    images: &ImageSource,
) -> Result<(PitchSurface, ReadImage), SpecError> {
    let radius = finite(file, "surface.radius", s.radius)?;
    only_with_kind(file, s)?;
    let surface =
        match s.kind {
            SurfaceKind::Plane => PitchSurface::Plane,
            SurfaceKind::Saddle => PitchSurface::Saddle { radius },
            SurfaceKind::Paraboloid => PitchSurface::Paraboloid { radius },
            SurfaceKind::Cylinder => PitchSurface::Cylinder { radius },
            SurfaceKind::Sphere => PitchSurface::Sphere { radius },
            SurfaceKind::Formula => {
                let z = s.z.as_deref().ok_or_else(|| {
                    invalid(
                        file,
                        "surface.z",
                        "(missing)",
                        "kind = \"formula\" needs z = h(x, y), in mm",
                        "add e.g. z = \"(x*x - y*y)/120\"",
                    )
                })?;
                PitchSurface::Formula(moirecast_kernel::surface::FormulaSurface::parse(z).map_err(
                    |e| invalid(file, "surface.z", format!("{z:?}"), e.to_string(), e.fix),
                )?)
            }
            SurfaceKind::Heightmap => {
                let (map, image) = height_map(file, s, layout, images)?;
                return Ok((
                    PitchSurface::HeightMap(std::sync::Arc::new(map)),
                    Some(image),
                ));
            }
        };
    Ok((surface, None))
}

/// Refuses `[surface]` keys that the chosen kind does not use.
fn only_with_kind(file: &str, s: &SurfaceTable) -> Result<(), SpecError> {
    if s.z.is_some() && s.kind != SurfaceKind::Formula {
        return Err(invalid(
            file,
            "surface.z",
            format!("{:?}", s.z.as_deref().unwrap_or("")),
            "is only used with kind = \"formula\"",
            "set surface.kind = \"formula\" or remove surface.z",
        ));
    }
    if s.kind != SurfaceKind::Heightmap {
        let given = [
            ("surface.image", s.image.is_some()),
            ("surface.z_min", s.z_min.is_some()),
            ("surface.z_max", s.z_max.is_some()),
            ("surface.size", s.size.is_some()),
            ("surface.smoothing", s.smoothing.is_some()),
        ];
        if let Some((key, _)) = given.iter().find(|(_, given)| *given) {
            return Err(invalid(
                file,
                key,
                "(given)",
                "is only used with kind = \"heightmap\"",
                format!("set surface.kind = \"heightmap\" or remove {key}"),
            ));
        }
    }
    Ok(())
}

/// A height map's samples: the image `surface.image` names, black at
/// `z_min` and white at `z_max`, over `size`, with its bit depth.
struct HeightImage {
    samples: HeightSamples,
    bits: u8,
    image: SpecImage,
}

/// The height map of a `kind = "heightmap"` surface over a layout of
/// `w` × `h` mm, and the image it read.
fn height_map(
    file: &str,
    s: &SurfaceTable,
    layout: LayoutSize,
    images: &ImageSource,
) -> Result<(HeightMap, SpecImage), SpecError> {
    let read = height_image(file, s, layout, images)?;
    let (sx, sy) = read.samples.extent;
    let spacing = (sx / read.samples.columns as f64).max(sy / read.samples.rows as f64);
    // heights come in steps of the range over 255 or 65535: noise that an
    // interpolating spline turns into curvature (0.018/mm at 16 bits and
    // 0.25 mm spacing), so both are smoothed over a few pixels by default
    let smoothing = match s.smoothing {
        Some(v) => finite(file, "surface.smoothing", v)?,
        None if read.bits <= 8 => HEIGHTMAP_SMOOTHING_PX.0 * spacing,
        None => HEIGHTMAP_SMOOTHING_PX.1 * spacing,
    };
    if smoothing < 0.0 {
        return Err(invalid(
            file,
            "surface.smoothing",
            smoothing,
            "must be zero or positive",
            "0 interpolates the samples; the default is 8 pixels' spacing (24 for 8-bit images)",
        ));
    }
    let map = HeightMap::fit(&read.samples, smoothing).map_err(|e| {
        invalid(
            file,
            "surface.image",
            format!("{:?}", read.image.name),
            e.to_string(),
            "use a greyscale PNG of at least 4 × 4 pixels",
        )
    })?;
    Ok((map, read.image))
}

/// The default smoothing of a height map, in pixels' spacing: of an 8-bit
/// image, and of a 16-bit one (heightmap.rs's
/// `the_default_smoothing_quiets_quantised_heights`).
pub const HEIGHTMAP_SMOOTHING_PX: (f64, f64) = (24.0, 8.0);

/// The heights (mm) of black and white in a height map, unless the spec
/// gives them: a relief of 1 mm to start from.
pub const HEIGHTMAP_Z: (f64, f64) = (0.0, 1.0);

/// Reads `surface.image` and its keys into height samples.
fn height_image(
    file: &str,
    s: &SurfaceTable,
    layout: LayoutSize,
    images: &ImageSource,
) -> Result<HeightImage, SpecError> {
    let (w, h) = (layout.width, layout.height);
    let name = s.image.clone().ok_or_else(|| {
        invalid(
            file,
            "surface.image",
            "(missing)",
            "kind = \"heightmap\" needs a greyscale PNG of heights",
            "add image = \"surfaces/NAME.png\" (8 or 16 bit)",
        )
    })?;
    let (z_min, z_max) = (
        finite(file, "surface.z_min", s.z_min.unwrap_or(HEIGHTMAP_Z.0))?,
        finite(file, "surface.z_max", s.z_max.unwrap_or(HEIGHTMAP_Z.1))?,
    );
    if z_max < z_min {
        return Err(invalid(
            file,
            "surface.z_max",
            z_max,
            format!("is below surface.z_min ({z_min} mm)"),
            "white is z_max and black z_min: give z_max ≥ z_min",
        ));
    }
    let [sx, sy] = s.size.unwrap_or([w, h]);
    let (sx, sy) = (
        finite(file, "surface.size", sx)?,
        finite(file, "surface.size", sy)?,
    );
    if sx < w || sy < h {
        return Err(invalid(
            file,
            "surface.size",
            format!("[{sx}, {sy}]"),
            format!("must cover the layout ({w} × {h} mm): the height map is centred on it"),
            format!("give size = [{w}, {h}] or larger"),
        ));
    }
    let key = "surface.image";
    let bytes = image_bytes(file, ImageRef { key, name: &name }, images)?;
    let img = decode_image(file, ImageRef { key, name: &name }, &bytes)?;
    let bits = if img.color().bits_per_pixel() / u16::from(img.color().channel_count()) > 8 {
        16
    } else {
        8
    };
    let grey = img.to_luma16();
    let (columns, rows) = (grey.width() as usize, grey.height() as usize);
    let z = grey
        .pixels()
        .map(|p| z_min + (z_max - z_min) * f64::from(p.0[0]) / 65535.0)
        .collect();
    Ok(HeightImage {
        samples: HeightSamples {
            columns,
            rows,
            z,
            extent: (sx, sy),
        },
        bits,
        image: SpecImage { key, name, bytes },
    })
}

/// The refractive index: `lens.index`, or `lens.material`'s, or 1.41.
fn lens_index(file: &str, lens: &LensTable) -> Result<f64, SpecError> {
    Ok(match (&lens.index, &lens.material) {
        (Some(i), _) => finite(file, "lens.index", *i)?,
        (None, Some(m)) => MATERIALS
            .iter()
            .find(|mat| mat.name == m)
            .map(|mat| mat.index)
            .ok_or_else(|| {
                let names: Vec<&str> = MATERIALS.iter().map(|m| m.name).collect();
                invalid(
                    file,
                    "lens.material",
                    format!("{m:?}"),
                    format!("is not a known material ({})", names.join(", ")),
                    "use one of those, or give lens.index",
                )
            })?,
        (None, None) => 1.41,
    })
}

/// The base's kind, with a printed base's band keys.
fn base_kind(file: &str, base: &BaseTable) -> Result<moirecast_kernel::BaseKind, SpecError> {
    Ok(match base.kind {
        BaseKind::DualLens => {
            let printed_only = [
                ("base.duty", base.duty),
                ("base.band_thickness", base.band_thickness),
                ("base.backing", base.backing),
            ];
            if let Some((key, Some(v))) = printed_only.into_iter().find(|(_, v)| v.is_some()) {
                return Err(invalid(
                    file,
                    key,
                    v,
                    "only a printed base has bands",
                    "remove it, or set base.kind = \"printed\"",
                ));
            }
            moirecast_kernel::BaseKind::DualLens
        }
        BaseKind::Printed => {
            if let Some(afov) = base.afov {
                return Err(invalid(
                    file,
                    "base.afov",
                    afov,
                    "a printed base has no lenses",
                    "remove it, or set base.kind = \"dual-lens\"",
                ));
            }
            let defaults = PrintedBase::default();
            let key = |key: &'static str, v: Option<f64>, default: f64| {
                v.map_or(Ok(default), |v| finite(file, key, v))
            };
            moirecast_kernel::BaseKind::Printed(PrintedBase {
                duty: key("base.duty", base.duty, defaults.duty)?,
                band_thickness: key(
                    "base.band_thickness",
                    base.band_thickness,
                    defaults.band_thickness,
                )?,
                backing: key("base.backing", base.backing, defaults.backing)?,
            })
        }
    })
}

/// `base.d`: a distance in mm, or `None` for "focal" (D_s).
fn base_d(file: &str, d: &Distance) -> Result<Option<f64>, SpecError> {
    Ok(match d {
        Distance::Mm(d) => Some(finite(file, "base.d", *d)?),
        Distance::Named(n) if n == "focal" => None,
        Distance::Named(n) => {
            return Err(invalid(
                file,
                "base.d",
                format!("{n:?}"),
                "must be a distance in mm or \"focal\"",
                "write d = \"focal\" or a number",
            ))
        }
    })
}

/// An image the spec read, if it read one.
type ReadImage = Option<SpecImage>;

/// The elevation profile of `[profile]` on a layout of `w` × `h` mm, how
/// the report names its source, and the image it read.
fn profile(
    file: &str,
    p: &ProfileTable,
    (w, h, reach): (f64, f64, f64),
    images: &ImageSource,
) -> Result<(Profile, String, ReadImage), SpecError> {
    let blur = finite(file, "profile.blur", p.blur)?;
    if !(BLUR_MM.0..=BLUR_MM.1).contains(&blur) {
        return Err(invalid(
            file,
            "profile.blur",
            blur,
            format!("must be between {} and {} mm", BLUR_MM.0, BLUR_MM.1),
            "1 mm suits a 0.5 mm period",
        ));
    }
    let kind = match (p.kind, &p.image) {
        (None, Some(_)) | (Some(ProfileKind::Image), Some(_)) => ProfileKind::Image,
        (Some(ProfileKind::Image), None) => {
            return Err(invalid(
                file,
                "profile.image",
                "(missing)",
                "kind = \"image\" needs an image",
                "add image = \"profiles/horse.png\"",
            ))
        }
        (Some(k), Some(img)) => {
            return Err(invalid(
                file,
                "profile.image",
                format!("{img:?}"),
                format!("is given together with kind = \"{}\"", k.name()),
                "remove one of profile.kind and profile.image",
            ))
        }
        (Some(k), None) => k,
        (None, None) => ProfileKind::Rings,
    };
    let positive = |key: &'static str, v: f64| -> Result<f64, SpecError> {
        finite(file, key, v)?;
        if v <= 0.0 {
            return Err(invalid(
                file,
                key,
                v,
                "must be positive",
                "give a length in mm",
            ));
        }
        Ok(v)
    };
    let mut image = None;
    let (profile, source) = match kind {
        ProfileKind::Flat => (Profile::Flat, "flat".to_string()),
        ProfileKind::Rings => {
            let wl = positive("profile.wavelength", p.wavelength.unwrap_or(w.min(h) / 4.0))?;
            (
                Profile::Rings { wavelength: wl },
                format!("rings (wavelength {wl} mm)"),
            )
        }
        ProfileKind::Ramp => (
            Profile::ramp(finite(file, "profile.angle", p.angle)?.to_radians(), w, h),
            format!("ramp ({}°)", p.angle),
        ),
        ProfileKind::Bump => {
            let s = positive("profile.sigma", p.sigma.unwrap_or(w.min(h) / 6.0))?;
            (Profile::Bump { sigma: s }, format!("bump (sigma {s} mm)"))
        }
        ProfileKind::Image => {
            let name = p.image.clone().unwrap_or_default();
            let threshold = finite(file, "profile.threshold", p.threshold)?;
            if !(0.0..=1.0).contains(&threshold) || threshold == 0.0 {
                return Err(invalid(
                    file,
                    "profile.threshold",
                    threshold,
                    "must be in (0, 1]",
                    "0.5 splits dark from light",
                ));
            }
            let (raster, bytes) = read_raster(file, &name, images)?;
            image = Some(SpecImage {
                key: "profile.image",
                name: name.clone(),
                bytes,
            });
            let mode = match p.mode {
                ModeKey::Gray => ProfileMode::Gray,
                ModeKey::Shape => ProfileMode::Shape { threshold },
            };
            if w <= 0.0 || h <= 0.0 {
                return Err(invalid(
                    file,
                    "layout.width",
                    w,
                    "the layout must have a positive size",
                    "give width and height in mm",
                ));
            }
            let sampled = SampledProfile::reaching(&raster, (mode, p.invert, blur), (w, h), reach)
                .map_err(|e| {
                    invalid(
                        file,
                        "profile.image",
                        format!("{name:?}"),
                        e,
                        "check profile.threshold and profile.invert",
                    )
                })?;
            (
                Profile::Sampled(sampled),
                format!("{name} ({:?}, blur {blur} mm)", p.mode).to_lowercase(),
            )
        }
    };
    Ok((profile, source, image))
}

/// The most pixels an image in a spec may have (a profile's or a height
/// map's): 4096 × 4096. Larger images, and files whose header claims more
/// than this, are refused before they are decoded.
pub const MAX_IMAGE_PIXELS: u64 = 4096 * 4096;

/// The most memory (bytes) decoding one image may take: a 4096 × 4096
/// image at 16 bits per channel, four channels, with room to spare.
const MAX_IMAGE_ALLOC: u64 = 512 << 20;

/// The layout's width and height (mm), as the surface reads them.
#[derive(Clone, Copy, Debug)]
struct LayoutSize {
    width: f64,
    height: f64,
}

/// A file a spec names: the key that names it, and the name it gives.
#[derive(Clone, Copy, Debug)]
struct ImageRef<'a> {
    key: &'static str,
    name: &'a str,
}

/// The bytes of the image `key` names: from the spec's folder, or
/// embedded in the binary.
fn image_bytes(file: &str, image: ImageRef, images: &ImageSource) -> Result<Vec<u8>, SpecError> {
    let ImageRef { key, name } = image;
    match images {
        ImageSource::Dir(dir) => {
            let path = dir.join(name);
            std::fs::read(&path).map_err(|e| {
                invalid(
                    file,
                    key,
                    format!("{name:?}"),
                    format!("cannot read {}: {e}", path.display()),
                    "give a PNG path relative to the spec file",
                )
            })
        }
        ImageSource::Embedded => EMBEDDED_IMAGES
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, b)| b.to_vec())
            .ok_or_else(|| {
                invalid(
                    file,
                    key,
                    format!("{name:?}"),
                    "is not an embedded image",
                    "give a spec file",
                )
            }),
    }
}

/// `bytes` decoded as the image `key` names, within [`MAX_IMAGE_PIXELS`]
/// and [`MAX_IMAGE_ALLOC`].
fn decode_image(
    file: &str,
    image: ImageRef,
    bytes: &[u8],
) -> Result<image::DynamicImage, SpecError> {
    let ImageRef { key, name } = image;
    let unreadable = |e: image::ImageError| {
        invalid(
            file,
            key,
            format!("{name:?}"),
            format!("is not a readable image: {e}"),
            "use a PNG file",
        )
    };
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| unreadable(e.into()))?;
    let (w, h) = reader.into_dimensions().map_err(unreadable)?;
    if u64::from(w) * u64::from(h) > MAX_IMAGE_PIXELS {
        return Err(invalid(
            file,
            key,
            format!("{name:?}"),
            format!("is {w} × {h} pixels: at most {MAX_IMAGE_PIXELS} pixels (4096 × 4096)"),
            "scale the image down",
        ));
    }
    reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| unreadable(e.into()))?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    limits.max_alloc = Some(MAX_IMAGE_ALLOC);
    reader.limits(limits);
    reader.decode().map_err(unreadable)
}

/// Reads an image as luminance composited over white, with the file's
/// bytes (which the run's folder keeps beside its spec).
fn read_raster(
    file: &str,
    name: &str,
    images: &ImageSource,
) -> Result<(Raster, Vec<u8>), SpecError> {
    let key = "profile.image";
    let bytes = image_bytes(file, ImageRef { key, name }, images)?;
    let img = decode_image(file, ImageRef { key, name }, &bytes)?;
    let la = img.to_luma_alpha32f();
    let (width, height) = (la.width() as usize, la.height() as usize);
    let luminance = la
        .pixels()
        .map(|p| p.0[1] * p.0[0] + (1.0 - p.0[1]))
        .collect();
    Ok((
        Raster {
            width,
            height,
            luminance,
        },
        bytes,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(text: &str) -> Result<Spec, SpecError> {
        parse(text, "test.toml", ImageSource::Embedded)
    }

    #[test]
    fn an_empty_spec_uses_the_written_defaults() {
        let s = parse_str("").unwrap();
        let p = &s.design.params;
        assert!(matches!(p.surface, PitchSurface::Saddle { radius } if radius == 60.0));
        assert_eq!((p.width, p.height, p.period), (60.0, 60.0, 0.5));
        assert!((p.lens.afov.to_degrees() - 60.0).abs() < 1e-12);
        assert_eq!(p.lens.index, 1.41);
        assert_eq!(p.base.d, None, "d defaults to the focal depth");
        assert_eq!(p.base.levels, 1.0);
        assert!(matches!(p.profile, Profile::Rings { wavelength } if wavelength == 15.0));
        assert_eq!(s.design.tolerance.mm(), 0.002);
    }

    #[test]
    fn the_default_design_is_the_reference_with_its_image() {
        let s = default_spec().unwrap();
        assert_eq!(s.design.lenses, 120);
        assert!(matches!(s.design.params.profile, Profile::Sampled(_)));
        assert!(s.profile_source.contains("horse"));
    }

    #[test]
    fn materials_set_the_index() {
        let s = parse_str("[lens]\nmaterial = \"polycarbonate\"").unwrap();
        assert_eq!(s.design.params.lens.index, 1.585);
        // an explicit index wins over the material
        let s = parse_str("[lens]\nmaterial = \"pmma\"\nindex = 1.6").unwrap();
        assert_eq!(s.design.params.lens.index, 1.6);
    }

    #[test]
    fn d_is_a_distance_or_focal() {
        let s = parse_str("[base]\nd = 1.2").unwrap();
        assert_eq!(s.design.d, 1.2);
        let e = parse_str("[base]\nd = \"deep\"").unwrap_err().to_string();
        assert!(e.contains("base.d") && e.contains("\"focal\""), "{e}");
    }

    #[test]
    fn every_kernel_parameter_has_a_key() {
        let keys: std::collections::BTreeSet<&str> =
            Param::ALL.iter().map(|p| key_of(*p)).collect();
        assert_eq!(keys.len(), Param::ALL.len(), "keys are distinct");
        assert!(keys.iter().all(|k| k.contains('.')), "keys are table.key");
    }

    #[test]
    fn printed_bases_take_their_keys_and_defaults() {
        let s = parse_str("[base]\nkind = \"printed\"\nduty = 0.4").unwrap();
        let moirecast_kernel::BaseKind::Printed(pb) = s.design.params.base.kind else {
            panic!("printed")
        };
        assert_eq!((pb.duty, pb.band_thickness, pb.backing), (0.4, 0.2, 1.0));
        let e = parse_str("[base]\nduty = 0.4").unwrap_err().to_string();
        assert!(e.contains("base.duty") && e.contains("printed"), "{e}");
        let e = parse_str("[base]\nkind = \"printed\"\nafov = 40")
            .unwrap_err()
            .to_string();
        assert!(e.contains("base.afov"), "{e}");
        let e = parse_str("[base]\nkind = \"printed\"\nduty = 1.2")
            .unwrap_err()
            .to_string();
        assert!(e.contains("base.duty") && e.contains("0.95"), "{e}");
    }

    #[test]
    fn a_formula_surface_parses() {
        let s = parse_str("[surface]\nkind = \"formula\"\nz = \"(x*x - y*y)/120\"").unwrap();
        assert!(matches!(s.design.params.surface, PitchSurface::Formula(_)));
        let e = parse_str("[surface]\nkind = \"saddle\"\nz = \"x\"")
            .unwrap_err()
            .to_string();
        assert!(e.contains("surface.z"), "{e}");
    }
}

#[cfg(test)]
mod heightmap_tests;
