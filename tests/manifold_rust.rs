//! manifold-rust (a port of Manifold 3.5.4, the mesh-boolean engine chosen for
//! molds) as an in-Rust oracle: our device meshes are valid manifolds, with
//! our volume, and a block minus the device — the first step of a mold —
//! is exact and valid.

use manifold_rust::linalg::Vec3;
use manifold_rust::manifold::Manifold;
use manifold_rust::types::Error;
use moirecast_kernel::progress::Silent;
use moirecast_kernel::*;

fn to_manifold(mesh: &Mesh) -> Manifold {
    moirecast_mold::boolean::to_manifold("device", mesh).unwrap()
}

fn design(surface: PitchSurface, profile: Profile, a: f64) -> Design {
    let mut p = DesignParams::with_defaults(surface, 8.0, 5.0, 0.5);
    p.profile = profile;
    p.base.a = a;
    p.tolerance = 0.003;
    Design::new(p).unwrap()
}

#[test]
fn device_meshes_are_valid_manifolds_and_subtract_exactly() {
    let cases = [
        design(
            PitchSurface::Saddle { radius: 30.0 },
            Profile::Bump { sigma: 2.0 },
            0.0,
        ),
        design(
            PitchSurface::Cylinder { radius: -25.0 },
            Profile::Rings { wavelength: 3.0 },
            0.5,
        ),
        design(
            PitchSurface::Sphere { radius: 40.0 },
            Profile::ramp(1.0, 8.0, 5.0),
            1.0,
        ),
    ];
    for d in &cases {
        let dm = mesher::mesh_device(d, &Silent).unwrap();
        let device = to_manifold(&dm.mesh);
        assert_eq!(device.status(), Error::NoError, "{:?}", d.params.surface);
        assert_eq!(device.genus(), 0);
        assert_eq!(device.decompose().len(), 1);
        assert_eq!(
            device.num_tri(),
            dm.mesh.triangles.len(),
            "nothing merged or dropped"
        );
        let ours = dm.mesh.volume();
        assert!(
            (device.volume() - ours).abs() <= 1e-10 * ours,
            "volume {} vs ours {ours}",
            device.volume()
        );

        // a block around the device, minus the device
        let (lo, hi) = dm.mesh.bounds();
        let (blo, bhi) = (lo - glam::DVec3::splat(3.0), hi + glam::DVec3::splat(3.0));
        let size = bhi - blo;
        let block = Manifold::cube(Vec3::new(size.x, size.y, size.z), false)
            .translate(Vec3::new(blo.x, blo.y, blo.z));
        let mold = block.difference(&device);
        assert_eq!(mold.status(), Error::NoError);
        let expected = size.x * size.y * size.z - ours;
        assert!(
            (mold.volume() - expected).abs() <= 1e-9 * expected,
            "block − device {} vs {expected}",
            mold.volume()
        );
        // the block's shell plus the enclosed cavity's: Euler characteristic
        // 4, which Manifold reports as genus −1
        assert_eq!(mold.genus(), -1, "a closed cavity, no handles");
    }
}
