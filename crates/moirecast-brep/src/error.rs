//! The one error type of this crate; each variant says what went wrong and
//! where, in words a user can act on.

use crate::array::Array;
use moirecast_kernel::KernelError;

#[derive(Debug, thiserror::Error)]
pub enum BrepError {
    /// The exact model could not be evaluated (a crease solve failed).
    #[error("evaluating the exact model: {0}")]
    Model(#[from] KernelError),
    /// Station refinement did not bring a lens surface within the fit.
    #[error("{array:?} lens surfaces are still farther than {fit_mm} mm from the exact lenses after refining to {stations} stations")]
    SurfaceFit {
        array: Array,
        stations: usize,
        fit_mm: f64,
    },
    /// The mesh's face partition does not describe a B-rep (a mesher defect).
    #[error("B-rep topology: {0}")]
    Topology(String),
    /// truck refused a face, shell or solid.
    #[error("truck refused the {what}: {detail}")]
    Truck { what: &'static str, detail: String },
    /// The STEP text did not read back as the solid written.
    #[error("STEP round trip: {0}")]
    StepRoundTrip(String),
    /// truck-meshalgo's tessellation did not give a closed mesh.
    #[error("truck-meshalgo tessellation: {0}")]
    Tessellation(String),
}
