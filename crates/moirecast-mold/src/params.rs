//! Mold parameters (METHOD §6) with their written defaults and the range
//! checks that need no device.

use crate::error::{MoldError, MoldParam, Result};

/// Least material (mm) between any two features, and between a feature and
/// the outside of the block or the cavity. Walls thinner than this tear or
/// print badly.
pub const MIN_WALL_MM: f64 = 1.0;

/// Allowed ranges of the mold parameters, written once: validation and the
/// spec's documentation both read them.
pub mod limits {
    use super::MIN_WALL_MM;
    pub const WALL_THICKNESS: (f64, f64) = (MIN_WALL_MM, 100.0);
    pub const GATE_DIAMETER: (f64, f64) = (0.2, 20.0);
    pub const SPRUE_DIAMETER: (f64, f64) = (0.5, 20.0);
    pub const VENT_DIAMETER: (f64, f64) = (0.2, 10.0);
    pub const POUR_CONE_DEPTH: (f64, f64) = (0.0, 50.0);
    pub const KEY_DIAMETER: (f64, f64) = (0.5, 50.0);
    pub const KEY_HEIGHT: (f64, f64) = (0.2, 50.0);
    pub const KEY_TAPER: (f64, f64) = (0.0, 30.0);
    pub const KEY_CLEARANCE: (f64, f64) = (0.0, 2.0);
    pub const BOLT_DIAMETER: (f64, f64) = (1.0, 20.0);
    pub const BOLT_SPACING: (f64, f64) = (5.0, 500.0);
    pub const SHRINK_SCALE: (f64, f64) = (0.9, 1.1);
    pub const MIN_DRAFT: (f64, f64) = (0.0, 45.0);
}

/// Every dimension of the mold, in mm and degrees.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MoldParams {
    /// Block material on every side of the device (t_w). MoldMaker uses 6 mm;
    /// 10 mm leaves room for a 7 mm pour cone beside the device.
    pub wall_thickness: f64,
    /// Diameter of the gate and of the runner that feeds it, on the parting
    /// line. Must fit the device's wall height at the gate.
    pub gate_diameter: f64,
    /// Diameter of the vertical sprue (MoldMaker's syringe gate: 3.2 mm).
    pub sprue_diameter: f64,
    /// Diameter of the pour cone at the top face.
    pub pour_cone_diameter: f64,
    /// Depth of the pour cone below the top face.
    pub pour_cone_depth: f64,
    /// Diameter of the vents (MoldMaker: 0.8 mm).
    pub vent_diameter: f64,
    /// Base diameter of the registration keys (tapered bumps).
    pub key_diameter: f64,
    pub key_height: f64,
    /// Taper of a key's side from vertical, so the halves self-centre.
    pub key_taper_deg: f64,
    /// Radial and top clearance of a socket around its key (crpalmer: 0.2 mm).
    pub key_clearance: f64,
    /// Clamp-bolt holes through both halves around the rim (FabSquare).
    pub bolts: bool,
    /// 3.4 mm clears an M3 bolt.
    pub bolt_diameter: f64,
    /// Largest spacing between bolts along the rim (FabSquare: 25 mm).
    pub bolt_spacing: f64,
    /// Scale of the cavity against shrinkage. 1.0: no value for Sylgard 184
    /// is established here.
    pub shrink_scale: f64,
    /// Mould the device upside down (rotated 180° about x), so the base
    /// lenses face up; offered when the ceiling has maxima inside the outline.
    pub flip: bool,
    /// Smallest draft of any lens face against its half's draw direction.
    pub min_draft_deg: f64,
}

impl Default for MoldParams {
    fn default() -> Self {
        MoldParams {
            wall_thickness: 10.0,
            gate_diameter: 1.0,
            sprue_diameter: 3.2,
            pour_cone_diameter: 7.0,
            pour_cone_depth: 4.0,
            vent_diameter: 0.8,
            key_diameter: 4.0,
            key_height: 2.0,
            key_taper_deg: 10.0,
            key_clearance: 0.2,
            bolts: false,
            bolt_diameter: 3.4,
            bolt_spacing: 25.0,
            shrink_scale: 1.0,
            flip: false,
            min_draft_deg: 1.0,
        }
    }
}

fn param(
    param: MoldParam,
    value: f64,
    problem: impl Into<String>,
    fix: impl Into<String>,
) -> MoldError {
    MoldError::Param {
        param,
        value,
        problem: problem.into(),
        fix: fix.into(),
    }
}

fn in_range(p: MoldParam, value: f64, (lo, hi): (f64, f64), what: &str) -> Result<()> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(param(
            p,
            value,
            format!("{what} must be in [{lo}, {hi}]"),
            format!("use a value in [{lo}, {hi}]"),
        ))
    }
}

impl MoldParams {
    /// Checks every parameter on its own and against the others. Fits to a
    /// particular device are checked when the mold is built.
    pub fn validate(&self) -> Result<()> {
        use MoldParam::*;
        if !(self.wall_thickness.is_finite() && self.wall_thickness >= MIN_WALL_MM) {
            return Err(param(
                WallThickness,
                self.wall_thickness,
                format!("mold walls thinner than {MIN_WALL_MM} mm tear and print badly"),
                "use at least 1 mm; 10 mm (the default) leaves room for the sprue, keys and bolts",
            ));
        }
        in_range(
            WallThickness,
            self.wall_thickness,
            limits::WALL_THICKNESS,
            "the wall thickness",
        )?;
        in_range(
            GateDiameter,
            self.gate_diameter,
            limits::GATE_DIAMETER,
            "the gate diameter",
        )?;
        in_range(
            SprueDiameter,
            self.sprue_diameter,
            limits::SPRUE_DIAMETER,
            "the sprue diameter",
        )?;
        in_range(
            VentDiameter,
            self.vent_diameter,
            limits::VENT_DIAMETER,
            "the vent diameter",
        )?;
        in_range(
            PourConeDepth,
            self.pour_cone_depth,
            limits::POUR_CONE_DEPTH,
            "the pour cone depth",
        )?;
        in_range(
            KeyDiameter,
            self.key_diameter,
            limits::KEY_DIAMETER,
            "the key diameter",
        )?;
        in_range(
            KeyHeight,
            self.key_height,
            limits::KEY_HEIGHT,
            "the key height",
        )?;
        in_range(
            KeyTaper,
            self.key_taper_deg,
            limits::KEY_TAPER,
            "the key taper",
        )?;
        in_range(
            KeyClearance,
            self.key_clearance,
            limits::KEY_CLEARANCE,
            "the key clearance",
        )?;
        in_range(
            BoltDiameter,
            self.bolt_diameter,
            limits::BOLT_DIAMETER,
            "the bolt hole diameter",
        )?;
        in_range(
            BoltSpacing,
            self.bolt_spacing,
            limits::BOLT_SPACING,
            "the bolt spacing",
        )?;
        in_range(
            ShrinkScale,
            self.shrink_scale,
            limits::SHRINK_SCALE,
            "the shrink scale",
        )?;
        in_range(
            MinDraft,
            self.min_draft_deg,
            limits::MIN_DRAFT,
            "the smallest draft",
        )?;
        if self.gate_diameter > self.sprue_diameter {
            return Err(param(
                GateDiameter,
                self.gate_diameter,
                format!(
                    "the gate is wider than the sprue ({} mm) that feeds it",
                    self.sprue_diameter
                ),
                "make the gate narrower than the sprue",
            ));
        }
        if self.pour_cone_diameter < self.sprue_diameter || !self.pour_cone_diameter.is_finite() {
            return Err(param(
                PourConeDiameter,
                self.pour_cone_diameter,
                format!(
                    "the pour cone must be at least as wide as the sprue ({} mm)",
                    self.sprue_diameter
                ),
                "make the pour cone wider than the sprue",
            ));
        }
        let top_radius = self.key_radius_top();
        if top_radius < 0.1 {
            return Err(param(
                KeyTaper,
                self.key_taper_deg,
                format!(
                    "a key {} mm wide and {} mm high with this taper comes to a point",
                    self.key_diameter, self.key_height
                ),
                "reduce the taper or the key height, or widen the key",
            ));
        }
        Ok(())
    }

    /// Radius of a key's flat top.
    pub fn key_radius_top(&self) -> f64 {
        self.key_diameter / 2.0 - self.key_height * self.key_taper_deg.to_radians().tan()
    }
}
