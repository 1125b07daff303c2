//! Property test over random valid designs (every surface kind, every
//! profile kind, both lens rules): the B-rep builds, its shell is closed,
//! its faces are the lenses and the walls, every lens face lies within the
//! tolerance of its exact lens, and truck-stepio reads the STEP text back
//! with the same faces. `moirecast device` writes a B-rep for every design,
//! so a design the B-rep cannot take would be a regression.

use moirecast_brep::{build_brep, read_back_faces, step_text};
use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::progress::Silent;
use moirecast_kernel::strategies::design_strategy;
use proptest::prelude::*;
use truck_modeling::ShellCondition;

proptest! {
    #![proptest_config(moirecast_kernel::strategies::config(48))]

    #[test]
    fn random_designs_give_closed_breps_that_round_trip(design in design_strategy()) {
        prop_assume!(design.is_some());
        let d = design.unwrap();
        let dm = mesh_device(&d, &Silent).unwrap();
        let brep = build_brep(&d, &dm).unwrap();
        let s = &brep.stats;
        prop_assert_eq!(brep.solid.boundaries()[0].shell_condition(), ShellCondition::Closed);
        prop_assert_eq!(s.revealer_faces, d.lenses);
        prop_assert_eq!(s.wall_faces, 4);
        prop_assert!(s.base_faces >= s.base_lenses);
        prop_assert_eq!(s.vertices as i64 - s.edges as i64 + s.faces as i64, 2);
        prop_assert!(s.max_surface_deviation_mm <= d.tolerance.mm(), "{:?}", s);
        let text = step_text(&brep.solid, "device.step", "property test");
        prop_assert_eq!(read_back_faces(&text).unwrap(), vec![s.faces]);
        assert_truck_stepio_data(&text, std::slice::from_ref(&brep.solid))?;
    }
}

/// The printed bodies' B-rep on a design whose band edges touch the side
/// walls tangentially at rows (rings on a plane; touches the mesher finds
/// between rows get a row at the touch and need no repair): the repaired
/// band outlines follow the mesh's edges, and the solids still close.
#[test]
fn printed_bodies_with_repaired_wall_touches_give_closed_breps() {
    use moirecast_kernel::*;
    let mut p = DesignParams::with_defaults(PitchSurface::Plane, 24.0, 24.0, 0.5);
    p.profile = Profile::Rings { wavelength: 6.0 };
    p.base.kind = BaseKind::Printed(PrintedBase::default());
    let d = Design::new(p).unwrap();
    let dm = mesh_device(&d, &Silent).unwrap();
    let bodies = moirecast_kernel::printed::printed_bodies(&d, &dm).unwrap();
    assert!(bodies.wall_touches.touches >= 2);
    assert!(bodies
        .clear_faces
        .contains(&moirecast_kernel::printed::BodyFace::Repaired));
    assert_printed_brep(&d, &dm, &bodies).unwrap();
}

/// Every invariant of the printed bodies' B-rep that holds for any design.
fn assert_printed_brep(
    d: &moirecast_kernel::Design,
    dm: &moirecast_kernel::mesher::DeviceMesh,
    bodies: &moirecast_kernel::printed::PrintedBodies,
) -> Result<(), TestCaseError> {
    let brep = moirecast_brep::build_printed_brep(d, dm, bodies).unwrap();
    let s = &brep.stats;
    prop_assert_eq!(s.clear_genus, bodies.clear_genus as i64, "{:?}", s);
    prop_assert_eq!(s.black_solids, bodies.bands as usize, "{:?}", s);
    prop_assert!(s.max_surface_deviation_mm <= d.tolerance.mm(), "{:?}", s);
    for solid in std::iter::once(&brep.clear).chain(&brep.bands) {
        let shells = solid.boundaries();
        prop_assert_eq!(shells.len(), 1);
        prop_assert_eq!(shells[0].shell_condition(), ShellCondition::Closed);
    }
    let clear = step_text(&brep.clear, "device-clear.step", "property test");
    prop_assert_eq!(read_back_faces(&clear).unwrap(), vec![s.clear_faces]);
    let black = moirecast_brep::step_text_of(&brep.bands, "device-black.step", "property test");
    let faces = read_back_faces(&black).unwrap();
    prop_assert_eq!(faces.iter().sum::<usize>(), s.black_faces);
    assert_truck_stepio_data(&clear, std::slice::from_ref(&brep.clear))?;
    assert_truck_stepio_data(&black, &brep.bands)
}

/// Our STEP text (written in parallel, with zmij's floats) holds
/// truck-stepio's serial text of `solids` from `DATA;` on, under the same
/// schema: byte for byte but for numbers, which read back the same.
fn assert_truck_stepio_data(
    text: &str,
    solids: &[truck_modeling::Solid],
) -> Result<(), TestCaseError> {
    use truck_stepio::out::{CompleteStepDisplay, StepHeaderDescriptor, StepModels};
    let compressed: Vec<_> = solids.iter().map(|s| s.compress()).collect();
    let serial = CompleteStepDisplay::new(
        compressed.iter().collect::<StepModels<_, _, _>>(),
        StepHeaderDescriptor::default(),
    )
    .to_string();
    let data = |t: &str| t.find("DATA;\n").map(|i| same_numbers(&t[i..]));
    let schema = |t: &str| {
        t.lines()
            .find(|l| l.starts_with("FILE_SCHEMA("))
            .map(str::to_owned)
    };
    prop_assert!(data(text).is_some() && data(text) == data(&serial));
    prop_assert_eq!(schema(text), schema(&serial));
    Ok(())
}

proptest! {
    #![proptest_config(moirecast_kernel::strategies::config(24))]

    /// Random printed designs (every surface and profile kind, any duty and
    /// layer thickness): both bodies' B-reps close, with the meshes' genus
    /// and band count, every surface within the tolerance, and both STEP
    /// texts read back.
    #[test]
    fn random_printed_designs_give_closed_brep_bodies(
        design in moirecast_kernel::strategies::printed_design_strategy()
    ) {
        prop_assume!(design.is_some());
        let d = design.unwrap();
        let dm = mesh_device(&d, &Silent).unwrap();
        // a band that touches a wall beyond repair is refused by the mesh
        // already (its own property test)
        let Ok(bodies) = moirecast_kernel::printed::printed_bodies(&d, &dm) else {
            return Err(TestCaseError::reject("a band touches a wall"));
        };
        assert_printed_brep(&d, &dm, &bodies)?;
    }
}

/// `text` with every number written as `core::fmt` writes the f64 it reads as.
fn same_numbers(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut token = String::new();
    let flush = |token: &mut String, out: &mut String| {
        match token.parse::<f64>() {
            Ok(x) if token.contains('.') => out.push_str(&format!("{x:?}")),
            _ => out.push_str(token),
        }
        token.clear();
    };
    for c in text.chars() {
        if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '+' | '_') {
            token.push(c);
        } else {
            flush(&mut token, &mut out);
            out.push(c);
        }
    }
    flush(&mut token, &mut out);
    out
}
