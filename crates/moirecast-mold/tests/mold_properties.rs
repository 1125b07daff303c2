//! Property tests of the mold on random designs: every design either gets a
//! mold whose every check passes (METHOD §7: solids, volumes, the exact
//! tiling, no overlaps, the cavity on the device, demoulding and filling),
//! or is refused for a named misfit. Never a broken solid or a failed
//! boolean. The halves are the same whether a far patch of each is left
//! out of its boolean or not.

use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::progress::Silent;
use moirecast_kernel::strategies::design_strategy;
use moirecast_kernel::Design;
use moirecast_kernel::Mesh;
use moirecast_mold::{build_mold, build_mold_with, HalfCut, MoldError, MoldParams};
use proptest::prelude::*;

proptest! {
    #![proptest_config(moirecast_kernel::strategies::config(32))]

    #[test]
    fn random_designs_get_a_correct_mold_or_a_clear_refusal(
        design in design_strategy(),
        lenses in 12usize..20,
        height in 8.0..12.0f64,
        flip in any::<bool>(),
    ) {
        // devices large enough for the default gate and keys
        let Some(design) = design else { return Ok(()) };
        let mut p = design.params.clone();
        p.width = lenses as f64 * p.period;
        p.height = height;
        let Ok(design) = Design::new(p) else { return Ok(()) };
        let device = mesh_device(&design, &Silent).unwrap();
        let params = MoldParams { flip, ..MoldParams::default() };
        match build_mold(&design, &device, &params, &Silent) {
            Ok(mold) => {
                for c in &mold.checks {
                    prop_assert!(c.passed, "{}: {} against {} ({})", c.name, c.value, c.limit, c.detail);
                }
                prop_assert!(mold.checks.iter().any(|c| c.name == "mold-parts-tile-block"));
                // Cutting each half whole gives the very same triangles.
                let whole = build_mold_with(&design, &device, &params, &Silent, HalfCut::Whole).unwrap();
                prop_assert!(triangles(mold.top.mesh()) == triangles(whole.top.mesh()), "top halves differ");
                prop_assert!(triangles(mold.bottom.mesh()) == triangles(whole.bottom.mesh()), "bottom halves differ");
                for half in [mold.top.mesh(), mold.bottom.mesh()] {
                    let mut used = vec![false; half.positions.len()];
                    half.triangles.iter().flatten().for_each(|&v| used[v as usize] = true);
                    prop_assert!(used.iter().all(|&u| u), "a half has unused vertices");
                }
            }
            Err(e @ MoldError::DoesNotFit { .. }) => {
                prop_assert!(!e.to_string().is_empty());
            }
            Err(e) => prop_assert!(false, "{e}"),
        }
    }
}

/// A mesh's triangles by their corners' coordinates, each started at its
/// least corner (so winding counts), sorted.
fn triangles(m: &Mesh) -> Vec<[[u64; 3]; 3]> {
    let mut all: Vec<[[u64; 3]; 3]> = m
        .triangles
        .iter()
        .map(|t| {
            let c = t.map(|v| m.positions[v as usize].to_array().map(f64::to_bits));
            let first = (0..3).min_by_key(|&k| c[k]).unwrap();
            [c[first], c[(first + 1) % 3], c[(first + 2) % 3]]
        })
        .collect();
    all.sort_unstable();
    all
}
