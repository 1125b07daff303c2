//! Benchmark of the device as a B-rep (molds/saddle-horse.toml by default):
//! the B-rep build (topology from the mesh, lens surfaces refined against
//! the exact model) and the STEP write, as medians over repeated runs; then,
//! once, truck-stepio's read-back and truck-meshalgo's tessellation with the
//! cross-check against the direct mesh.
//!
//! `cargo bench --bench brep [-- SPEC [RUNS]]`

use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::progress::Silent;
use std::time::Instant;

mod common;
use common::median;

fn main() {
    let (spec_path, runs) = common::spec_and_runs(9);
    let spec = moirecast_spec::load(std::path::Path::new(&spec_path)).unwrap();
    let design = &spec.design;
    let dm = mesh_device(design, &Silent).unwrap();
    let (mut build_t, mut step_t, mut both_t) = (vec![], vec![], vec![]);
    let mut last = None;
    for _ in 0..runs {
        let t0 = Instant::now();
        let brep = moirecast_brep::build_brep(design, &dm).unwrap();
        let t1 = Instant::now();
        let text = moirecast_brep::step_text(&brep.solid, "device.step", "bench");
        let t2 = Instant::now();
        build_t.push((t1 - t0).as_secs_f64());
        step_t.push((t2 - t1).as_secs_f64());
        both_t.push((t2 - t0).as_secs_f64());
        last = Some((brep, text));
    }
    let (brep, text) = last.unwrap();
    let s = &brep.stats;
    let ms = |v: Vec<f64>| median(v) * 1e3;
    common::print_header(&spec_path, runs);
    println!(
        "B-rep             {} faces ({} revealer, {} base, {} walls), {} edges, {} vertices",
        s.faces, s.revealer_faces, s.base_faces, s.wall_faces, s.edges, s.vertices
    );
    println!(
        "lens surfaces     {} + {} stations, within {:.2e} mm of the exact lenses (fit {:.1e})",
        s.revealer_stations, s.base_stations, s.max_surface_deviation_mm, s.surface_fit_mm
    );
    println!("B-rep build       {:8.1} ms", ms(build_t));
    println!(
        "STEP write        {:8.1} ms  ({:.1} MB)",
        ms(step_t),
        text.len() as f64 / 1e6
    );
    println!("build + STEP      {:8.1} ms  (goal 200 ms)", ms(both_t));

    let t = Instant::now();
    let faces = moirecast_brep::read_back_faces(&text).unwrap();
    println!(
        "STEP read-back    {:8.1} ms  ({faces:?} faces)",
        t.elapsed().as_secs_f64() * 1e3
    );

    let t = Instant::now();
    match moirecast_brep::tessellate(&brep.solid, design.tolerance.mm()) {
        Ok(mesh) => {
            let tess = t.elapsed().as_secs_f64();
            let (checks, _) = moirecast_kernel::check::SolidMesh::validate(&mesh);
            let failed: Vec<String> = checks
                .iter()
                .filter(|c| !c.passed)
                .map(|c| format!("{} = {}", c.name, c.value))
                .collect();
            let c = moirecast_brep::compare(&mesh, &dm.mesh);
            println!(
                "meshalgo          {:8.1} ms  ({} triangles; direct mesh {}); failed checks: {failed:?}",
                tess * 1e3,
                c.brep_triangles,
                dm.mesh.triangles.len()
            );
            println!(
                "cross-check       volume {:.4} vs direct {:.4} mm³ ({:.2e} relative); Hausdorff {:.2e} mm at {:?}",
                c.brep_volume_mm3, c.direct_volume_mm3, c.volume_rel_diff, c.hausdorff_mm, c.hausdorff_at
            );
        }
        Err(e) => println!("meshalgo          failed: {e}"),
    }
}
