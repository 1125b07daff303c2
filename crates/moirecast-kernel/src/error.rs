//! One error enum for the kernel, each variant explained.

use thiserror::Error;

/// A design parameter, named independently of any file format. The spec
/// layer maps each to its key (`Param::Afov` is `lens.afov`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Param {
    SurfaceRadius,
    SurfaceFormula,
    SurfaceHeightMap,
    Width,
    Height,
    Period,
    Afov,
    Index,
    BaseAfov,
    BaseA,
    BaseD,
    Levels,
    Duty,
    BandThickness,
    Backing,
    Blur,
    Tolerance,
    ProfileImage,
    ProfileWavelength,
    ProfileSigma,
    ViewTilt,
    ViewTiltAlong,
    ViewDistance,
    ViewCompensate,
}

impl Param {
    /// Every parameter, for exhaustive mappings and their tests.
    pub const ALL: [Param; 24] = [
        Param::SurfaceRadius,
        Param::SurfaceFormula,
        Param::SurfaceHeightMap,
        Param::Width,
        Param::Height,
        Param::Period,
        Param::Afov,
        Param::Index,
        Param::BaseAfov,
        Param::BaseA,
        Param::BaseD,
        Param::Levels,
        Param::Duty,
        Param::BandThickness,
        Param::Backing,
        Param::Blur,
        Param::Tolerance,
        Param::ProfileImage,
        Param::ProfileWavelength,
        Param::ProfileSigma,
        Param::ViewTilt,
        Param::ViewTiltAlong,
        Param::ViewDistance,
        Param::ViewCompensate,
    ];
}

/// A design that cannot be built, with everything a user needs to fix it.
#[derive(Clone, Debug, PartialEq)]
pub struct DesignError {
    /// Which parameter is at fault.
    pub param: Param,
    /// The offending value as the user wrote it (degrees for angles).
    pub value: String,
    /// What is wrong, with the allowed range and where it fails.
    pub problem: String,
    /// What to change.
    pub fix: String,
}

impl std::fmt::Display for DesignError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:?} = {}: {}. Fix: {}",
            self.param, self.value, self.problem, self.fix
        )
    }
}

#[derive(Debug, Error)]
pub enum KernelError {
    /// The design breaks a validity rule of METHOD (range, fold, steepness…).
    #[error("invalid design: {0}")]
    Design(Box<DesignError>),
    /// A Newton solve for an exact point did not converge. This is a bug or a
    /// design at the edge of validity; the message names the solve and place.
    #[error("solver did not converge: {0}")]
    Solver(String),
    /// The caller stopped the work ([`crate::progress::Progress::cancelled`]).
    #[error("cancelled: the work was no longer wanted")]
    Cancelled,
    /// A mesh failed one of its invariants (METHOD §7.1). Carries the check.
    #[error("mesh check `{name}` failed: {detail}")]
    MeshCheck { name: &'static str, detail: String },
}

impl From<DesignError> for KernelError {
    fn from(e: DesignError) -> Self {
        KernelError::Design(Box::new(e))
    }
}

pub type Result<T, E = KernelError> = std::result::Result<T, E>;
