//! Two-piece casting molds around a moirecast device (METHOD §6), and the
//! mold invariants of METHOD §7 measured on the result.
//!
//! The mold is built in the mold frame: the device posed (flipped and
//! scaled against shrinkage), a block around it, a parting surface, and
//! channels and keys placed and checked before any boolean runs. Booleans are
//! manifold-rust's; every operand and result has its status checked. No I/O.
//!
//! ```
//! use moirecast_kernel::{mesher::mesh_device, progress::Silent, Design, DesignParams, PitchSurface};
//! use moirecast_mold::{build_mold, MoldParams};
//!
//! let mut params = DesignParams::with_defaults(PitchSurface::Cylinder { radius: -40.0 }, 10.0, 8.0, 0.5);
//! params.tolerance = 0.01;
//! let design = Design::new(params).unwrap();
//! let device = mesh_device(&design, &Silent).unwrap();
//! let mold = build_mold(&design, &device, &MoldParams::default(), &Silent).expect("the mold fits");
//! // every invariant of METHOD §7 was measured, and holds
//! assert!(mold.checks.iter().all(|c| c.passed));
//! let v = mold.volumes;
//! assert!(((v.top + v.bottom + v.device + v.voids) / v.block - 1.0).abs() < 1e-6);
//! ```

pub mod boolean;
mod cut;
pub mod error;
pub mod features;
mod invariants;
pub mod params;
pub mod parting;
pub mod split;
pub mod tiling;

pub use boolean::{ChannelAxis, ChannelShape};
pub use cut::{HalfCut, HalfSurface};
pub use error::{MoldError, MoldParam, Result};
pub use features::{Features, Gate, Key, Vent, VentPlace};
pub use invariants::{Draft, Volumes, CAVITY_ON_DEVICE_MM, OVERLAP_MM3, VOLUME_SUM_REL};
pub use params::{MoldParams, MIN_WALL_MM};
pub use parting::Pose;

use boolean::{to_mesh, union_all};
use cut::{Channels, CutInputs, KeySolids, Regions};
use manifold_rust::manifold::Manifold;
use moirecast_kernel::check::{CheckResult, CheckedMesh};
use moirecast_kernel::progress::Progress;
use moirecast_kernel::{Design, DeviceMesh, Mesh};
use parting::{Face, HeightQuery, PosedDevice};

/// A built mold, measured.
pub struct Mold {
    /// The halves, with the solid checks they passed as they were cut.
    pub top: CheckedMesh,
    pub bottom: CheckedMesh,
    pub features: Features,
    pub volumes: Volumes,
    pub draft_top: Draft,
    pub draft_bottom: Draft,
    /// Through-holes (genus) of each half: sprue, vents and bolts in the
    /// top; bolts in the bottom.
    pub genus_top: u32,
    pub genus_bottom: u32,
    pub parting_triangles: usize,
    /// Every invariant of METHOD §7 that concerns the mold, measured.
    pub checks: Vec<CheckResult>,
    /// The solids the halves were made from, so that another tool can
    /// rebuild the halves from them and the device (see `assembly.scad`).
    pub construction: Vec<ConstructionSolid>,
    /// What the halves' exact B-rep is built from.
    pub exact: ExactParts,
}

impl Mold {
    /// The cavity's shape: the device in the mold frame (flipped, scaled).
    pub fn device(&self) -> &Mesh {
        &self.exact.posed.mesh
    }
}

/// What the halves' exact B-rep is built from: the posed device, each
/// half's region with the surface every triangle of the half lies on, and
/// the channels' exact shapes.
pub struct ExactParts {
    pub posed: PosedDevice,
    /// The block's footprint.
    pub footprint: parting::Rect,
    /// Every channel primitive, sockets last ([`HalfSurface`] indexes it).
    pub channels: Vec<ChannelShape>,
    /// The key bumps the bottom region stands on its corner squares.
    pub bumps: Vec<parting::Bump>,
    pub top: TracedHalf,
    pub bottom: TracedHalf,
}

/// A half as traced through the booleans.
pub struct TracedHalf {
    /// The half before its channels.
    pub region: parting::Region,
    /// The height of its cap (the block's top or bottom face).
    pub cap_z: f64,
    /// Per triangle of the half's mesh, the surface it lies on.
    pub surfaces: Vec<HalfSurface>,
}

/// A solid the halves were built from.
pub struct ConstructionSolid {
    /// "above" and "below" (the block on each side of the parting surface),
    /// "channels" (runner, sprue, cone, vents, bolts), "key-bumps", "key-sockets".
    pub name: &'static str,
    pub mesh: Mesh,
    /// Connected pieces it must have.
    pub shells: u32,
}

/// Builds the two-piece mold of `device` (a mesh of `design`) and measures
/// it. Misfits of the parameters to this device are errors; failed
/// invariants are returned in `checks` for the caller to act on.
pub fn build_mold(
    design: &Design,
    device: &DeviceMesh,
    p: &MoldParams,
    progress: &dyn Progress,
) -> Result<Mold> {
    build_mold_with(design, device, p, progress, HalfCut::SplitFarPatch)
}

/// [`build_mold`], with the halves cut as `cut_by` says: place the
/// features, build the regions on each side of the parting surface, cut
/// the halves, then measure every invariant.
pub fn build_mold_with(
    design: &Design,
    device: &DeviceMesh,
    p: &MoldParams,
    progress: &dyn Progress,
    cut_by: HalfCut,
) -> Result<Mold> {
    if let moirecast_kernel::BaseKind::Printed(_) = design.params.base.kind {
        return Err(MoldError::NotCastable);
    }
    p.validate()?;
    progress.stage("placing mold features", 1);
    let posed = PosedDevice::new(design, device, p.flip, p.shrink_scale)?;
    let drafts = invariants::drafts(&posed, p)?;
    let walls = parting::wall_curves(&posed)?;
    let face_query = |face: Face| {
        HeightQuery::new(
            &posed.mesh,
            (0..posed.faces.len()).filter(|&t| posed.faces[t] == face),
        )
    };
    let (upper_q, lower_q) = (face_query(Face::Upper), face_query(Face::Lower));
    let f = features::place(design, &posed, &walls, &upper_q, &lower_q, p)?;
    progress.tick(1);

    progress.stage("building the parting surface", 1);
    let keys = KeySolids::new(&f, p)?;
    let regions = Regions::new(&posed, &walls, &f, &keys.rings, (&upper_q, &lower_q))?;
    progress.tick(1);

    progress.stage("mold booleans", 1);
    let (above, block) = cut::block_solids(&f, &regions)?;
    let bump_boxes: Vec<_> = keys.bumps.iter().map(|b| b.bounding_box()).collect();
    let bumps = union_all("key bumps", keys.bumps)?;
    let sockets = union_all("key sockets", keys.sockets)?;
    let cut = cut::cut_halves(&CutInputs {
        posed: &posed,
        f: &f,
        p,
        regions: &regions,
        block: &block,
        sockets: &sockets,
        socket_shapes: &keys.socket_shapes,
        cut_by,
    })?;
    progress.tick(1);

    let key_solids = (&above, &bumps, &sockets);
    progress.stage("mold solid checks", 1);
    let mut checks = invariants::solid_checks(&cut);
    progress.tick(1);
    progress.stage("mold volumes", 1);
    let (volumes, sum) = invariants::volumes(&cut, &posed, (&f, &block), key_solids)?;
    checks.push(sum);
    progress.tick(1);
    progress.stage("mold overlaps", 1);
    checks.push(cut.tiling.clone());
    checks.push(invariants::overlaps(&posed, key_solids, &bump_boxes)?);
    progress.tick(1);
    progress.stage("mold cavity checks", 1);
    checks.extend(invariants::cavity(&cut, &posed));
    progress.tick(1);
    progress.stage("mold filling checks", 1);
    checks.extend(invariants::filling(&cut, &f, drafts, p.min_draft_deg));
    progress.tick(1);

    Ok(assemble(
        posed,
        f,
        cut,
        (regions, keys.rings, bumps, sockets),
        (volumes, drafts),
        checks,
    ))
}

/// The mold, with the construction solids another tool rebuilds the
/// halves from.
fn assemble(
    posed: PosedDevice,
    f: Features,
    cut: cut::Cut,
    (regions, rings, bumps, sockets): (Regions, Vec<parting::Bump>, Manifold, Manifold),
    (volumes, (draft_top, draft_bottom)): (Volumes, (Draft, Draft)),
    checks: Vec<CheckResult>,
) -> Mold {
    let Channels { all: channels, .. } = &cut.channels;
    let (vents, bolts, keys) = (
        f.vents.len() as u32,
        f.bolts.len() as u32,
        f.keys.len() as u32,
    );
    let construction = vec![
        ConstructionSolid {
            name: "above",
            mesh: regions.above,
            shells: 1,
        },
        ConstructionSolid {
            name: "below",
            mesh: regions.below,
            shells: 1,
        },
        ConstructionSolid {
            name: "channels",
            mesh: to_mesh(channels).mesh,
            shells: 1 + vents + bolts,
        },
        ConstructionSolid {
            name: "key-bumps",
            mesh: to_mesh(&bumps).mesh,
            shells: keys,
        },
        ConstructionSolid {
            name: "key-sockets",
            mesh: to_mesh(&sockets).mesh,
            shells: keys,
        },
    ];
    let parting_triangles = construction[0].mesh.triangles.len();
    let exact = ExactParts {
        footprint: features::block_rect(&f),
        channels: cut.channels.shapes,
        bumps: rings,
        top: TracedHalf {
            region: regions.top,
            cap_z: f.block_hi.z,
            surfaces: cut.top.surfaces,
        },
        bottom: TracedHalf {
            region: regions.bottom,
            cap_z: f.block_lo.z,
            surfaces: cut.bottom.surfaces,
        },
        posed,
    };
    let mut features = f;
    features.warnings.extend(cut.turned_note);
    Mold {
        top: cut.top.solid,
        bottom: cut.bottom.solid,
        features,
        volumes,
        draft_top,
        draft_bottom,
        genus_top: 1 + vents + bolts,
        genus_bottom: bolts,
        parting_triangles,
        checks,
        construction,
        exact,
    }
}
