//! The device as a B-rep (truck) and STEP, for every shipped spec: the
//! shell is closed, the faces are the lenses and the walls, every face lies
//! within the tolerance of its exact lens, and truck-stepio reads the STEP
//! text back with the same faces.

use moirecast_brep::{build_brep, read_back_faces, step_text};
use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::model::BaseSection;
use moirecast_kernel::progress::Silent;
use truck_modeling::ShellCondition;

mod common;
use common::shipped_specs;

#[test]
fn every_shipped_device_is_a_closed_brep_that_round_trips_through_step() {
    for path in shipped_specs() {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let spec = moirecast_spec::load(&path).unwrap();
        let design = &spec.design;
        let dm = mesh_device(design, &Silent).unwrap();
        let brep = build_brep(design, &dm).unwrap_or_else(|e| panic!("{name}: {e}"));
        let s = &brep.stats;

        let shells = brep.solid.boundaries();
        assert_eq!(shells.len(), 1, "{name}");
        assert_eq!(
            shells[0].shell_condition(),
            ShellCondition::Closed,
            "{name}"
        );
        assert_eq!(shells[0].len(), s.faces, "{name}");

        // faces: every revealer lens, every piece of a base lens, four walls
        assert_eq!(s.revealer_faces, design.lenses, "{name}");
        assert_eq!(s.wall_faces, 4, "{name}");
        assert!(
            s.base_faces >= s.base_lenses && s.base_lenses >= design.lenses - 2,
            "{name}: {s:?}"
        );
        assert_eq!(
            s.faces,
            s.revealer_faces + s.base_faces + s.wall_faces,
            "{name}"
        );
        // Euler: V − E + F = 2 for one closed shell of disc faces
        assert_eq!(
            s.vertices as i64 - s.edges as i64 + s.faces as i64,
            2,
            "{name}: {s:?}"
        );

        let tol = design.tolerance.mm();
        assert!(s.max_surface_deviation_mm <= tol, "{name}: {s:?}");

        // An independent, denser sample of every tenth base lens (or printed
        // band span), creases (t = 0, 1) included, against the exact
        // sections of the kernel, over each surface's own stations (a lens
        // ended in a wall ends there).
        let mut worst: f64 = 0.0;
        for (&k, surface) in brep.base.surfaces.iter().step_by(10) {
            let (_, (lo, hi)) = truck_modeling::BoundedSurface::range_tuple(surface);
            for j in 0..=400 {
                let v = lo + (hi - lo) * j as f64 / 400.0;
                for t in [0.0, 0.05, 0.3, 0.5, 0.7, 0.95, 1.0] {
                    worst = worst.max(distance_to_exact(design, k, surface, (t, v)));
                }
            }
        }
        assert!(
            worst <= tol,
            "{name}: base faces {worst} mm from the exact lenses"
        );

        let text = step_text(&brep.solid, "device.step", "moirecast device");
        assert_eq!(read_back_faces(&text).unwrap(), vec![s.faces], "{name}");
        // FILE_NAME's author and organization are lists of strings: one
        // pair of parentheses each (truck-stepio 0.3 writes two)
        let file_name = text.lines().find(|l| l.starts_with("FILE_NAME(")).unwrap();
        assert_eq!(
            file_name,
            format!(
                "FILE_NAME('device.step', '2000-01-01T00:00:00', ('moirecast'), ('moirecast'), \
                 'truck-stepio 0.3', 'moirecast {}', '');",
                env!("CARGO_PKG_VERSION")
            )
        );
        // deterministic: the same solid gives the same text
        assert_eq!(
            text,
            step_text(&brep.solid, "device.step", "moirecast device")
        );
    }
}

/// The printed bodies as B-rep solids, for every shipped printed spec: the
/// clear body is one closed shell whose genus (by Euler's formula) is the
/// mesh's, every band is a closed solid of its own, every surface lies
/// within the tolerance of its exact section, and truck-stepio reads both
/// STEP texts back with the same faces.
#[test]
fn every_shipped_printed_device_gives_closed_brep_bodies_that_round_trip() {
    let mut printed = 0;
    for path in shipped_specs() {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let spec = moirecast_spec::load(&path).unwrap();
        let design = &spec.design;
        if !matches!(
            design.params.base.kind,
            moirecast_kernel::BaseKind::Printed(_)
        ) {
            continue;
        }
        printed += 1;
        let dm = mesh_device(design, &Silent).unwrap();
        let bodies = moirecast_kernel::printed::printed_bodies(design, &dm).unwrap();
        let brep = moirecast_brep::build_printed_brep(design, &dm, &bodies)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let s = &brep.stats;
        assert_eq!(s.clear_genus, bodies.clear_genus as i64, "{name}: {s:?}");
        assert_eq!(s.black_solids, bodies.bands as usize, "{name}: {s:?}");
        assert!(
            s.max_surface_deviation_mm <= design.tolerance.mm(),
            "{name}: {s:?}"
        );
        let mut band_faces = 0;
        for band in &brep.bands {
            let shells = band.boundaries();
            assert_eq!(shells.len(), 1, "{name}");
            assert_eq!(
                shells[0].shell_condition(),
                ShellCondition::Closed,
                "{name}"
            );
            // a top, a bottom, sides and end caps (a ring band: no caps)
            assert!(shells[0].len() >= 4, "{name}");
            band_faces += shells[0].len();
        }
        assert_eq!(band_faces, s.black_faces, "{name}");
        let clear = step_text(&brep.clear, "device-clear.step", "clear body");
        assert_eq!(
            read_back_faces(&clear).unwrap(),
            vec![s.clear_faces],
            "{name}"
        );
        let black = moirecast_brep::step_text_of(&brep.bands, "device-black.step", "bands");
        let shells = read_back_faces(&black).unwrap();
        assert_eq!(shells.len(), s.black_solids, "{name}");
        assert_eq!(shells.iter().sum::<usize>(), s.black_faces, "{name}");
    }
    assert!(printed >= 1, "a printed spec is shipped");
}

/// The distance (mm) of `surface`'s point at (t, v) from base lens `k`'s
/// exact section: at the station whose plane holds the point (a lens
/// ended in a wall slides along its axis near the wall: found from v by
/// Newton steps on the distance off the section's plane, the station
/// moving the plane along the surface's v-tangent); for a printed band
/// span, the point of s at the same t and station.
fn distance_to_exact(
    design: &moirecast_kernel::Design,
    k: i64,
    surface: &truck_modeling::NurbsSurface<truck_modeling::Vector4>,
    (t, v): (f64, f64),
) -> f64 {
    let p = surface.subs(t, v);
    let q = glam::DVec3::new(p.x, p.y, p.z);
    // the station whose section's plane holds q, by secants on the exact
    // sections alone (the surface's own parameter is no station where a
    // lens ends in a wall: its last span is stretched into the wall)
    let off = |station: f64| match design.base_section_near(k, station, (None, None)).unwrap() {
        BaseSection::Lens(arc) => {
            Some((q - arc.centre()).dot(arc.chord_dir.cross(arc.bulge).normalize()))
        }
        _ => None,
    };
    let (mut a, mut b) = (v, v + 1e-3);
    let (Some(mut fa), Some(mut fb)) = (off(a), off(b)) else {
        // a band span of a printed base: no arc, no plane
        let section = design.base_section_near(k, v, (None, None)).unwrap();
        return (q - section.point(t)).length();
    };
    {
        for _ in 0..8 {
            if fb.abs() < 1e-12 || fb == fa {
                break;
            }
            let next = b - fb * (b - a) / (fb - fa);
            (a, fa) = (b, fb);
            b = next;
            fb = off(b).unwrap_or(0.0);
        }
    }
    match design.base_section_near(k, b, (None, None)).unwrap() {
        BaseSection::Lens(arc) => moirecast_brep::lenses::distance_to_arc(&arc, q),
        section => (q - section.point(t)).length(),
    }
}
