//! One error enum for the mold crate, each variant explained.

use glam::DVec3;
use thiserror::Error;

/// A mold parameter, named independently of any file format. The spec layer
/// maps each to its key (`MoldParam::WallThickness` is `mold.wall_thickness`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MoldParam {
    WallThickness,
    GateDiameter,
    SprueDiameter,
    PourConeDiameter,
    PourConeDepth,
    VentDiameter,
    KeyDiameter,
    KeyHeight,
    KeyTaper,
    KeyClearance,
    BoltDiameter,
    BoltSpacing,
    ShrinkScale,
    MinDraft,
}

impl MoldParam {
    /// Every parameter, for exhaustive mappings and their tests.
    pub const ALL: [MoldParam; 14] = [
        MoldParam::WallThickness,
        MoldParam::GateDiameter,
        MoldParam::SprueDiameter,
        MoldParam::PourConeDiameter,
        MoldParam::PourConeDepth,
        MoldParam::VentDiameter,
        MoldParam::KeyDiameter,
        MoldParam::KeyHeight,
        MoldParam::KeyTaper,
        MoldParam::KeyClearance,
        MoldParam::BoltDiameter,
        MoldParam::BoltSpacing,
        MoldParam::ShrinkScale,
        MoldParam::MinDraft,
    ];
}

#[derive(Clone, Debug, Error, PartialEq)]
pub enum MoldError {
    /// A parameter is out of its range on its own, whatever the device.
    #[error("{value}: {problem}. Fix: {fix}")]
    Param {
        param: MoldParam,
        value: f64,
        problem: String,
        fix: String,
    },
    /// The parameters are fine alone but do not fit this device: a gate wider
    /// than the wall, keys that cut the cavity, a vent that cannot reach the
    /// top face, a surface that cannot release along z. Names the check, the
    /// parameter to change (if one is to blame) and the place.
    #[error("mold check `{check}` failed at ({:.3}, {:.3}, {:.3}) mm: {problem}. Fix: {fix}", at.x, at.y, at.z)]
    DoesNotFit {
        check: &'static str,
        param: Option<MoldParam>,
        at: DVec3,
        problem: String,
        fix: String,
    },
    /// The design is a printed (multi-material) device: it has black bands
    /// inside a clear body and is printed, not cast in one material.
    #[error("a printed (multi-material) device is printed, not cast: its black bands sit inside the clear body, which one silicone pour cannot make. Fix: `moirecast device` writes its STLs and 3MF for the printer; for a castable device set base.kind = \"dual-lens\"")]
    NotCastable,
    /// manifold-rust reported a status other than `NoError` for an operand or
    /// a result. An invalid operand silently becomes empty, so every one is
    /// checked; this is a bug in moirecast, not in the spec.
    #[error("mesh boolean `{operation}` failed: manifold status {status}")]
    Boolean { operation: String, status: String },
    /// A mesh built here is not a closed solid (a bug in moirecast).
    #[error("internal mesh `{what}` is not a solid: {detail}")]
    NotSolid { what: &'static str, detail: String },
}

pub type Result<T> = std::result::Result<T, MoldError>;
