//! How a run ends when it writes nothing, typed so that callers (the CLI,
//! the design fuzzer) can tell a refused input from a bug in moirecast.

use moirecast_kernel::check::CheckResult;
use moirecast_kernel::checks::check_doc;
use moirecast_kernel::KernelError;
use moirecast_mold::MoldError;
use moirecast_spec::{Spec, SpecError};

/// What every bug's message ends with.
const BUG: &str = "The spec passed validation, but its mesh did not: this is a bug in moirecast, not in your spec. Nothing was written; please report it with this spec file";

/// Why a run wrote nothing.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The spec breaks a rule (found while parsing, or while meshing: the
    /// mesh budget, a band touching a wall). Names the key, the value, the
    /// allowed range and the fix.
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// The mold's parameters do not fit this device (or it is not
    /// castable): names the mold check, the key to change and the place.
    #[error("{message}")]
    MoldMisfit { message: String, error: MoldError },
    /// A check failed on the mesh of an accepted spec: a bug.
    #[error("check `{name}` ({label}) failed: measured {value} {unit}, where it must be {bound} {limit} ({detail}).\n  {BUG}.{hint}")]
    CheckFailed {
        name: &'static str,
        /// The registry's label and bound words ("at most", …).
        label: &'static str,
        bound: &'static str,
        value: f64,
        limit: f64,
        unit: &'static str,
        detail: String,
        /// What the command offers beyond a report (`--force` for molds).
        hint: &'static str,
    },
    /// A solver or an internal mesh failed on an accepted spec: a bug.
    #[error("{stage}: {detail}.\n  {BUG}.")]
    Internal { stage: &'static str, detail: String },
}

impl RunError {
    /// A kernel error while `stage` ran on `spec`: a broken rule is the
    /// spec's; anything else is a bug.
    pub fn kernel(spec: &Spec, stage: &'static str, e: KernelError) -> Self {
        match e {
            KernelError::Design(d) => {
                RunError::Spec(moirecast_spec::from_design_error(&spec.origin, *d))
            }
            other => RunError::Internal {
                stage,
                detail: other.to_string(),
            },
        }
    }

    /// A mold error on `spec`: misfits and printed designs are the spec's;
    /// failed booleans and broken internal meshes are bugs.
    pub fn mold(spec: &Spec, e: MoldError) -> Self {
        match e {
            MoldError::Param { .. } | MoldError::DoesNotFit { .. } | MoldError::NotCastable => {
                RunError::MoldMisfit {
                    message: moirecast_spec::describe_mold_error(&spec.origin, &e),
                    error: e,
                }
            }
            MoldError::Boolean { .. } | MoldError::NotSolid { .. } => RunError::Internal {
                stage: "building the mold",
                detail: e.to_string(),
            },
        }
    }

    /// The first failed check, if one failed, with `hint` appended.
    pub fn first_failed(checks: &[CheckResult], hint: &'static str) -> Result<(), RunError> {
        match checks.iter().find(|c| !c.passed) {
            None => Ok(()),
            Some(c) => Err(RunError::CheckFailed {
                name: c.name,
                label: check_doc(c.name).map_or(c.name, |d| d.label),
                bound: check_doc(c.name).map_or("within", |d| d.bound.words()),
                value: c.value,
                limit: c.limit,
                unit: c.unit,
                detail: c.detail.clone(),
                hint,
            }),
        }
    }

    /// Whether the spec was refused by a named rule (not a bug).
    pub fn is_refusal(&self) -> bool {
        matches!(self, RunError::Spec(_) | RunError::MoldMisfit { .. })
    }
}
