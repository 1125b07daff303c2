//! The moiré, rendered, on small designs (METHOD §8): a level-line moiré
//! of rings has high fidelity at some tilt; defocusing the base, scrambling
//! its shift, or flattening it takes the level lines away; and frames are
//! deterministic for a seed. A printed device shows the rings against its
//! backlight.

use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::profile::{Raster, SampledProfile};
use moirecast_kernel::progress::Silent;
use moirecast_kernel::{
    BaseKind, Design, DesignParams, PitchSurface, PrintedBase, Profile, ProfileMode,
};
use moirecast_render::frame::{render, traced_mesh, Camera, Frame, View};
use moirecast_render::{fidelity, Scene};

const SIZE: f64 = 16.0;
const TILTS: [f64; 5] = [-5.0, -2.5, 0.0, 2.5, 5.0];

fn rings(levels: f64, d_scale: Option<f64>) -> Design {
    let mut p = DesignParams::with_defaults(PitchSurface::Plane, SIZE, SIZE, 0.5);
    // the spec default: min(W, H) / 4
    p.profile = Profile::Rings {
        wavelength: SIZE / 4.0,
    };
    p.base.levels = levels;
    if let Some(s) = d_scale {
        let std = moirecast_kernel::StandardLens::new(0.5, p.lens.afov, p.lens.index);
        p.base.d = Some(s * std.focal_depth);
    }
    Design::new(p).unwrap()
}

/// A base shifted by a random field instead of the rings (blurred noise,
/// one period deep), on the same plane.
fn scrambled() -> Design {
    let n = 32;
    let mut state = 12345u64;
    let luminance = (0..n * n)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        })
        .collect();
    let raster = Raster {
        width: n,
        height: n,
        luminance,
    };
    let profile =
        SampledProfile::from_raster(&raster, ProfileMode::Gray, false, 0.8, SIZE, SIZE).unwrap();
    let mut p = DesignParams::with_defaults(PitchSurface::Plane, SIZE, SIZE, 0.5);
    p.profile = Profile::Sampled(profile);
    p.base.levels = 1.0;
    Design::new(p).unwrap()
}

fn frame(phase_of: &Design, device: &Design, tilt: f64, seed: u64) -> Frame {
    let dm = mesh_device(device, &Silent).unwrap();
    let (mesh, absorbing) = traced_mesh(device, &dm).unwrap();
    render(
        phase_of,
        &Scene::with_absorbing(&mesh, absorbing),
        View {
            width: 128,
            height: 128,
            samples: 2,
            tilt_across: tilt.to_radians(),
            tilt_along: 0.0,
            camera: Camera::Orthographic,
            seed,
        },
    )
}

/// The best fidelity over the tilts, measured against `phase_of`'s rings.
fn best_fidelity(phase_of: &Design, device: &Design) -> f64 {
    TILTS
        .iter()
        .map(|&t| {
            let f = frame(phase_of, device, t, 1);
            fidelity(&f.luminance, &f.phase, f.width, f.height, f.period_px)
        })
        .fold(0.0, f64::max)
}

#[test]
fn the_rings_moire_and_what_destroys_it() {
    let good = rings(1.0, None);
    let best = best_fidelity(&good, &good);
    let defocused = best_fidelity(&good, &rings(1.0, Some(0.3)));
    let scrambled = best_fidelity(&good, &scrambled());
    let flat = best_fidelity(&good, &rings(0.0, None));
    eprintln!("fidelity: rings {best:.3}, defocused {defocused:.3}, scrambled {scrambled:.3}, flat {flat:.3}");
    assert!(best >= 0.8, "rings {best}");
    // measured 0.48 against 0.82: clearly lower
    assert!(defocused < best - 0.2, "defocused {defocused} vs {best}");
    assert!(scrambled < 0.15, "scrambled {scrambled}");
    assert!(flat < 0.15, "flat {flat}");
}

/// The printed device (METHOD §5.2) under its backlight: the rings show
/// through the clear gaps between black bands; with no shift they do not.
#[test]
fn a_printed_device_shows_the_rings_against_a_backlight() {
    let printed = |levels: f64| {
        let mut p = rings(levels, None).params;
        p.base.kind = BaseKind::Printed(PrintedBase::default());
        Design::new(p).unwrap()
    };
    let (good, flat) = (printed(1.0), printed(0.0));
    let best = best_fidelity(&good, &good);
    let unshifted = best_fidelity(&good, &flat);
    let f = frame(&good, &good, 0.0, 1);
    let mean = f.luminance.iter().sum::<f64>() / f.luminance.len() as f64;
    eprintln!("printed fidelity: rings {best:.3}, flat {unshifted:.3}; mean luminance {mean:.3}");
    assert!(best >= 0.8, "printed rings {best}");
    assert!(unshifted < 0.15, "printed flat {unshifted}");
    // half the base is black: roughly half the backlight comes through
    assert!(mean > 0.2 && mean < 0.8, "mean luminance {mean}");
}

/// A perspective camera far away sees what the orthographic camera sees;
/// close up it sees the edges at other angles, so the frame changes.
#[test]
fn a_far_perspective_camera_approaches_the_orthographic_one() {
    let d = rings(1.0, None);
    let dm = mesh_device(&d, &Silent).unwrap();
    let scene = Scene::new(&dm.mesh);
    let view = |camera| View {
        width: 96,
        height: 96,
        samples: 2,
        tilt_across: 0.0,
        tilt_along: 0.0,
        camera,
        seed: 3,
    };
    let score = |f: &Frame| fidelity(&f.luminance, &f.phase, f.width, f.height, f.period_px);
    let ortho = render(&d, &scene, view(Camera::Orthographic));
    let far = render(&d, &scene, view(Camera::Perspective { distance: 1e5 }));
    let near = render(&d, &scene, view(Camera::Perspective { distance: 30.0 }));
    let differing = |a: &Frame, b: &Frame| {
        a.luminance
            .iter()
            .zip(&b.luminance)
            .filter(|(x, y)| (*x - *y).abs() > 0.25)
            .count() as f64
            / a.luminance.len() as f64
    };
    eprintln!(
        "fidelity ortho {:.3} far {:.3} near {:.3}; pixels differing: far {:.3}, near {:.3}",
        score(&ortho),
        score(&far),
        score(&near),
        differing(&ortho, &far),
        differing(&ortho, &near)
    );
    assert!((score(&ortho) - score(&far)).abs() < 0.02);
    assert!(differing(&ortho, &near) > 2.0 * differing(&ortho, &far));
}

#[test]
fn frames_are_deterministic_for_a_seed() {
    let d = rings(1.0, None);
    let (a, b, c) = (
        frame(&d, &d, 2.5, 7),
        frame(&d, &d, 2.5, 7),
        frame(&d, &d, 2.5, 8),
    );
    assert_eq!(a.luminance, b.luminance);
    assert_ne!(a.luminance, c.luminance);
}
