//! Benchmark of the reference design (molds/saddle-horse.toml: 120 lenses,
//! 2 µm): spec → mesh → validated STL on disk, plus the report's checks.
//! Prints per-stage medians over repeated runs; peak memory is measured
//! from outside with `/usr/bin/time -v` (see README).
//!
//! `cargo bench --bench device [-- SPEC [RUNS]]`

use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::progress::Silent;
use std::time::Instant;

mod common;
use common::median;

/// Medians of `Design::new` on the spec's parameters with the view
/// compensation and without it (ms): what tracing C costs.
fn view_compensation_cost(spec_path: &str, runs: usize) -> (f64, f64) {
    let spec = moirecast_spec::load(std::path::Path::new(spec_path)).unwrap();
    let time = |compensate: bool| {
        let mut params = spec.design.params.clone();
        params.view.compensate = compensate;
        let times = (0..runs)
            .map(|_| {
                let t = Instant::now();
                moirecast_kernel::Design::new(params.clone()).unwrap();
                t.elapsed().as_secs_f64()
            })
            .collect();
        median(times) * 1e3
    };
    (time(true), time(false))
}

fn main() {
    let (spec_path, runs) = common::spec_and_runs(9);
    let out = std::env::temp_dir().join(format!("moirecast-bench-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let (mut load, mut mesh_t, mut stl_t, mut checks_t, mut total) =
        (vec![], vec![], vec![], vec![], vec![]);
    let (mut validate_t, mut encode_t, mut write_t) = (vec![], vec![], vec![]);
    let mut triangles = (0, 0);
    for _ in 0..runs {
        let t0 = Instant::now();
        let spec = moirecast_spec::load(std::path::Path::new(&spec_path)).unwrap();
        let t1 = Instant::now();
        let dm = mesh_device(&spec.design, &Silent).unwrap();
        let t2 = Instant::now();
        let solid = moirecast_export::validate("device.stl", &dm.mesh).unwrap();
        let tv = Instant::now();
        let bytes = moirecast_export::stl_bytes("device.stl", solid).unwrap();
        let te = Instant::now();
        std::fs::write(out.join("device.stl"), &bytes).unwrap();
        let t3 = Instant::now();
        validate_t.push((tv - t2).as_secs_f64());
        encode_t.push((te - tv).as_secs_f64());
        write_t.push((t3 - te).as_secs_f64());
        let build = moirecast::build_device(&spec.design, &Silent).unwrap();
        let t4 = Instant::now();
        let failed: Vec<_> = build
            .validated()
            .0
            .into_iter()
            .filter(|c| !c.passed)
            .collect();
        assert!(failed.is_empty(), "{failed:?}");
        triangles = (dm.stats.triangles, dm.stats.uniform_triangles);
        load.push((t1 - t0).as_secs_f64());
        mesh_t.push((t2 - t1).as_secs_f64());
        stl_t.push((t3 - t2).as_secs_f64());
        checks_t.push((t4 - t3).as_secs_f64() - (t2 - t1).as_secs_f64());
        total.push((t3 - t1).as_secs_f64());
    }
    let ms = |v: Vec<f64>| median(v) * 1e3;
    common::print_header(&spec_path, runs);
    println!(
        "triangles         {} (a uniform grid needs {} for the same tolerance: {:.2}x)",
        triangles.0,
        triangles.1,
        triangles.1 as f64 / triangles.0 as f64
    );
    println!("spec + profile    {:8.1} ms", ms(load));
    println!("mesh              {:8.1} ms", ms(mesh_t));
    println!(
        "STL check+write   {:8.1} ms  (solid checks {:.1}, encode {:.1}, write {:.1})",
        ms(stl_t),
        ms(validate_t),
        ms(encode_t),
        ms(write_t)
    );
    println!("mesh + STL        {:8.1} ms   (goal < 300 ms)", ms(total));
    println!("report checks     {:8.1} ms", ms(checks_t));
    let (with_c, without_c) = view_compensation_cost(&spec_path, runs);
    println!(
        "view compensation {:8.1} ms   (Design::new {with_c:.1} ms with C, {without_c:.1} ms without)",
        with_c - without_c
    );
    let _ = std::fs::remove_dir_all(&out);
}
