//! Benchmark of the printed (multi-material) device (METHOD §5.2): the
//! reference geometry (120 lenses on a saddle, 2 µm) with a printed base,
//! from spec to `device-clear.stl`, `device-black.stl`, `device.3mf`,
//! both STEP files and `report.json` on disk, with per-stage medians. Spec
//! to files is timed into an empty directory and again over the files it
//! just wrote (replacing 80 MB of files costs the file system time too).
//!
//! `cargo bench --bench printed [-- SPEC [RUNS]]`

use moirecast_kernel::printed::printed_bodies;
use moirecast_kernel::progress::Silent;
use std::time::Instant;

mod common;
use common::median;

fn main() {
    let (spec_path, runs) = common::spec_and_runs(7);
    let spec_path = if spec_path.ends_with("saddle-horse.toml") {
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/molds/saddle-camera-printed.toml"
        )
        .to_string()
    } else {
        spec_path
    };
    let out = std::env::temp_dir().join(format!("moirecast-bench-printed-{}", std::process::id()));
    let (mut total, mut load, mut build_t, mut bodies_t, mut printed_t, mut solid_t) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    let (mut stl_t, mut threemf_t) = (vec![], vec![]);
    let (mut brep_t, mut step_t) = (vec![], vec![]);
    let mut triangles = 0;
    let (mut over, mut after) = (vec![], vec![]);
    let device = |spec_path: &str| {
        let t0 = Instant::now();
        let spec = moirecast_spec::load(std::path::Path::new(spec_path)).unwrap();
        let t1 = Instant::now();
        let outcome = moirecast::run_device(
            &spec,
            &out,
            moirecast::Thoroughness::Sampled,
            moirecast::Mesher::Direct,
            &Silent,
        )
        .unwrap();
        let t2 = Instant::now();
        (spec, outcome.triangles, t1 - t0, t2 - t0)
    };
    for _ in 0..runs {
        // into an empty directory (the last run's files removed untimed),
        // then again over the files just written, as a re-run does
        let _ = std::fs::remove_dir_all(&out);
        let (_, _, spec_t, fresh_t) = device(&spec_path);
        let (spec, tris, _, over_t) = device(&spec_path);
        triangles = tris;
        total.push(fresh_t.as_secs_f64());
        over.push(over_t.as_secs_f64());
        load.push(spec_t.as_secs_f64());
        // the stages again, one by one
        let t3 = Instant::now();
        let build = moirecast::build_device(&spec.design, &Silent).unwrap();
        let t4 = Instant::now();
        let bodies = printed_bodies(&spec.design, &build.mesh).unwrap();
        let t5 = Instant::now();
        let printed = moirecast::printed::build_printed(&spec.design, &build.mesh).unwrap();
        let t6 = Instant::now();
        assert_eq!(bodies.bands, printed.report.bands);
        let (_, solids) = printed.solids();
        let t7 = Instant::now();
        let [clear, black] = solids.unwrap();
        for (name, solid) in [("clear", clear), ("black", black)] {
            std::hint::black_box(moirecast_export::stl_bytes(name, solid).unwrap());
        }
        let t8 = Instant::now();
        let objects = [
            moirecast_export::Object {
                name: "clear",
                solid: clear,
                material: moirecast::printed::CLEAR,
            },
            moirecast_export::Object {
                name: "black",
                solid: black,
                material: moirecast::printed::BLACK,
            },
        ];
        std::hint::black_box(moirecast_export::threemf_bytes("device.3mf", &objects).unwrap());
        let t9 = Instant::now();
        let brep =
            moirecast_brep::build_printed_brep(&spec.design, &build.mesh, &printed.bodies).unwrap();
        let t10 = Instant::now();
        std::hint::black_box(moirecast_brep::step_text(&brep.clear, "clear", ""));
        std::hint::black_box(moirecast_brep::step_text_of(&brep.bands, "black", ""));
        let t11 = Instant::now();
        // as earlier sessions' bench timed it: after the stages, over the
        // files of the run before
        drop((build, bodies, printed, brep));
        let (_, _, _, after_t) = device(&spec_path);
        after.push(after_t.as_secs_f64());
        brep_t.push((t10 - t9).as_secs_f64());
        step_t.push((t11 - t10).as_secs_f64());
        stl_t.push((t8 - t7).as_secs_f64());
        threemf_t.push((t9 - t8).as_secs_f64());
        build_t.push((t4 - t3).as_secs_f64());
        bodies_t.push((t5 - t4).as_secs_f64());
        printed_t.push((t6 - t5).as_secs_f64() - (t5 - t4).as_secs_f64());
        solid_t.push((t7 - t6).as_secs_f64());
    }
    let ms = |v: Vec<f64>| median(v) * 1e3;
    common::print_header(&spec_path, runs);
    println!("triangles         {triangles} (clear and black)");
    println!(
        "spec to files     {:8.1} ms   (goal < 500 ms; into an empty directory)",
        ms(total)
    );
    println!(
        "  over last files {:8.1} ms   (the same, replacing the files of the run before)",
        ms(over)
    );
    println!(
        "  after stages    {:8.1} ms   (the same, after the stages below ran; earlier benches' layout)",
        ms(after)
    );
    println!("  spec + profile  {:8.1} ms", ms(load));
    println!("  mesh + measure  {:8.1} ms", ms(build_t));
    println!("  bodies          {:8.1} ms", ms(bodies_t));
    println!("  volumes, duty   {:8.1} ms", ms(printed_t));
    println!("  solid checks    {:8.1} ms", ms(solid_t));
    println!("  STL encoding    {:8.1} ms", ms(stl_t));
    println!("  3MF encoding    {:8.1} ms", ms(threemf_t));
    println!("  B-rep           {:8.1} ms", ms(brep_t));
    println!("  STEP text       {:8.1} ms", ms(step_t));
    println!("  (the rest of spec to files: the device mesh's solid checks, the report, writing)");
    let _ = std::fs::remove_dir_all(&out);
}
