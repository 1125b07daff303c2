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
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

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
    }
}
