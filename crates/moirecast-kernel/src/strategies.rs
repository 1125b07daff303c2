//! proptest strategies for random valid designs, shared by the property
//! tests of every crate (feature `strategies`; not part of the library
//! proper).

use crate::*;
use proptest::prelude::*;

pub fn surface_strategy() -> impl Strategy<Value = PitchSurface> {
    prop_oneof![
        Just(PitchSurface::Plane),
        (30.0..120.0f64, prop::bool::ANY).prop_map(|(r, s)| PitchSurface::Saddle {
            radius: if s { r } else { -r }
        }),
        (30.0..120.0f64, prop::bool::ANY).prop_map(|(r, s)| PitchSurface::Paraboloid {
            radius: if s { r } else { -r }
        }),
        (20.0..120.0f64, prop::bool::ANY).prop_map(|(r, s)| PitchSurface::Cylinder {
            radius: if s { r } else { -r }
        }),
        (30.0..120.0f64, prop::bool::ANY).prop_map(|(r, s)| PitchSurface::Sphere {
            radius: if s { r } else { -r }
        }),
    ]
}

/// A 24 × 24 raster of random dark discs, as an image profile over an
/// 8 × 6 mm layout (gray or shape mode, blurred).
pub fn image_profile() -> impl Strategy<Value = Profile> {
    (
        prop::collection::vec((0.0..24.0f64, 0.0..24.0f64, 2.0..7.0f64), 1..4),
        prop::bool::ANY,
        0.6..2.0f64,
    )
        .prop_map(|(discs, shape, blur)| {
            let n = 24;
            let lum = (0..n * n)
                .map(|c| {
                    let (x, y) = ((c % n) as f64 + 0.5, (c / n) as f64 + 0.5);
                    if discs.iter().any(|&(cx, cy, r)| (x - cx).hypot(y - cy) < r) {
                        0.1
                    } else {
                        0.9
                    }
                })
                .collect();
            let raster = Raster {
                width: n,
                height: n,
                luminance: lum,
            };
            let mode = if shape {
                ProfileMode::Shape { threshold: 0.5 }
            } else {
                ProfileMode::Gray
            };
            Profile::Sampled(
                crate::profile::SampledProfile::from_raster(&raster, mode, false, blur, 8.0, 6.0)
                    .unwrap(),
            )
        })
}

pub fn profile_strategy() -> impl Strategy<Value = Profile> {
    prop_oneof![
        Just(Profile::Flat),
        image_profile(),
        (2.0..10.0f64).prop_map(|w| Profile::Rings { wavelength: w }),
        (0.0..3.2f64).prop_map(|a| Profile::ramp(a, 8.0, 6.0)),
        (1.0..4.0f64).prop_map(|s| Profile::Bump { sigma: s }),
    ]
}

prop_compose! {
    /// A random valid design (or `None` where validation refuses the draw):
    /// 3–13 lenses, every surface kind, every profile kind, both lens rules.
    pub fn design_strategy()(
        surface in surface_strategy(),
        profile in profile_strategy(),
        lenses in 3usize..14,
        period in 0.3..1.0f64,
        height in 1.5..5.0f64,
        afov in 30.0..90.0f64,
        index in 1.35..1.6f64,
        levels in 0.0..1.5f64,
        a in prop_oneof![Just(0.0), 0.0..1.0f64],
        d_scale in prop_oneof![Just(None), (0.3..1.5f64).prop_map(Some)],
        tol_scale in 0.02..0.2f64,
        equal_radius in proptest::bool::weighted(0.15),
        view in view_strategy(),
    ) -> Option<Design> {
        let std = StandardLens::new(period, afov.to_radians(), index);
        let p = DesignParams {
            surface,
            width: lenses as f64 * period,
            height,
            period,
            lens: LensParams { afov: afov.to_radians(), index, rule: if equal_radius { LensRule::EqualRadius } else { LensRule::ConstantAfov } },
            base: BaseParams { kind: BaseKind::DualLens, a, d: d_scale.map(|s| s * std.focal_depth), levels, afov: None },
            profile,
            tolerance: (tol_scale * std.sag).max(Tolerance::MIN_MM),
            view,
        };
        Design::new(p).ok()
    }
}

prop_compose! {
    /// A design view: mostly straight down and compensated (the default),
    /// else tilted up to 20° either way, from afar or from 100–1000 mm,
    /// and now and then uncompensated.
    pub fn view_strategy()(
        tilted in proptest::bool::weighted(0.3),
        tilt in -20.0..20.0f64,
        tilt_along in -20.0..20.0f64,
        distance in prop_oneof![3 => Just(None), 1 => (100.0..1000.0f64).prop_map(Some)],
        compensate in proptest::bool::weighted(0.9),
    ) -> crate::view::DesignView {
        crate::view::DesignView {
            tilt: if tilted { tilt.to_radians() } else { 0.0 },
            tilt_along: if tilted { tilt_along.to_radians() } else { 0.0 },
            distance,
            compensate,
        }
    }
}

prop_compose! {
    /// A random valid printed design (METHOD §5.2): a [`design_strategy`]
    /// draw with black bands instead of base lenses, any duty cycle and
    /// layer thicknesses.
    pub fn printed_design_strategy()(
        design in design_strategy(),
        duty in 0.1..0.9f64,
        band_thickness in 0.05..0.5f64,
        backing in 0.1..2.0f64,
    ) -> Option<Design> {
        let mut p = design?.params;
        p.base.kind = BaseKind::Printed(PrintedBase { duty, band_thickness, backing });
        Design::new(p).ok()
    }
}

/// A property test's configuration: `cases` random designs, times
/// `MOIRECAST_SOAK` when it is set. CI runs the counts as written (its
/// seeds are random, so every run explores anew); a soak before a change to
/// the geometry runs many more, e.g. `MOIRECAST_SOAK=30 cargo test -p
/// moirecast-mold`.
pub fn config(cases: u32) -> ProptestConfig {
    let soak = std::env::var("MOIRECAST_SOAK")
        .ok()
        .and_then(|v| v.parse::<u32>().ok())
        .unwrap_or(1)
        .max(1);
    ProptestConfig {
        cases: cases * soak,
        ..ProptestConfig::default()
    }
}
