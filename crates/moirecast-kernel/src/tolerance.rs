//! Typed tolerances. A tolerance is a promise about distance between an
//! approximation and the exact geometry; it is never a bare epsilon.

/// The largest distance (mm) between a mesh and the exact surface it
/// approximates: every point of the exact surface lies within this of the mesh.
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd)]
pub struct Tolerance(f64);

impl Tolerance {
    /// Smallest and largest tolerance the mesher accepts (mm). Below 0.1 µm
    /// the meshes grow past what a printer resolves; above 0.1 mm the lenses
    /// (sags of tens of µm) would not be represented at all.
    pub const MIN_MM: f64 = 1e-4;
    pub const MAX_MM: f64 = 0.1;

    /// `None` if `mm` is not finite or outside `[MIN_MM, MAX_MM]`.
    pub fn from_mm(mm: f64) -> Option<Self> {
        (mm.is_finite() && (Self::MIN_MM..=Self::MAX_MM).contains(&mm)).then_some(Tolerance(mm))
    }

    pub fn mm(self) -> f64 {
        self.0
    }
}

/// Distance (mm) to which the exact-point solvers converge. Coordinates are
/// tens of mm, so f64 round-off there is ~1e-14 mm; 1e-11 mm leaves margin
/// for the error of finite-difference Jacobians. Vertices "on the exact
/// surface" are on it to this distance.
pub const SOLVE_RESIDUAL_MM: f64 = 1e-11;

/// Distance (mm) under which a base crease counts as lying on a side wall
/// (it may touch the wall tangentially). Four times
/// [`crate::check::MIN_ALTITUDE_MM`]: a crease just outside the snap leaves
/// wall triangles that thin, and the mold, splitting the wall's rungs at
/// mid-height, halves that; twice the smallest altitude still leaves room
/// for the triangles the mold fans to those points at an angle. Far below
/// any tolerance.
pub const WALL_SNAP_MM: f64 = 4e-5;
