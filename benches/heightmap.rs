//! Benchmark of `kind = "heightmap"`: the spline fit of a 1024 × 1024 map,
//! and the reference device (molds/saddle-horse.toml) on a height map
//! sampled from its own saddle (16 bit, 0.25 mm pixels over 64 mm) against
//! the closed-form saddle, run alternately: `run_device` writing STL, STEP
//! and report, medians and their ratio.
//!
//! `cargo bench --bench heightmap [-- SPEC [RUNS]]` (SPEC: a spec on the
//! reference's saddle, R = 60 mm; its `[surface]` is replaced)

use moirecast_kernel::heightmap::{HeightMap, HeightSamples};
use moirecast_kernel::progress::Silent;
use std::path::Path;
use std::time::Instant;

mod common;
use common::median;

/// Heights of the reference saddle (R = 60 mm) at pixel centres.
fn saddle_samples(pixels: usize, size: f64) -> HeightSamples {
    let step = size / pixels as f64;
    let z = (0..pixels * pixels)
        .map(|p| {
            let x = -size / 2.0 + ((p % pixels) as f64 + 0.5) * step;
            let y = size / 2.0 - ((p / pixels) as f64 + 0.5) * step;
            (x * x - y * y) / 120.0
        })
        .collect();
    HeightSamples {
        columns: pixels,
        rows: pixels,
        z,
        extent: (size, size),
    }
}

/// Writes the saddle as a 16-bit PNG into `dir`, and the reference spec on
/// it beside; returns the spec's path.
fn heightmap_spec(dir: &Path, reference: &str) -> std::path::PathBuf {
    let (pixels, size, range) = (256u32, 64.0, 8.6);
    let step = size / f64::from(pixels);
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(pixels, pixels, |i, j| {
        let x = -size / 2.0 + (f64::from(i) + 0.5) * step;
        let y = size / 2.0 - (f64::from(j) + 0.5) * step;
        let z = (x * x - y * y) / 120.0;
        image::Luma([((z + range) / (2.0 * range) * 65535.0).round() as u16])
    });
    std::fs::create_dir_all(dir.join("surfaces")).unwrap();
    std::fs::create_dir_all(dir.join("profiles")).unwrap();
    img.save(dir.join("surfaces/saddle.png")).unwrap();
    let molds = concat!(env!("CARGO_MANIFEST_DIR"), "/molds");
    std::fs::copy(
        format!("{molds}/profiles/horse.png"),
        dir.join("profiles/horse.png"),
    )
    .unwrap();
    let reference = std::fs::read_to_string(reference).unwrap();
    let surface = format!(
        "[surface]\nkind = \"heightmap\"\nimage = \"surfaces/saddle.png\"\nz_min = -{range}\nz_max = {range}\nsize = [{size}, {size}]\n"
    );
    let (_, rest) = reference.split_once("[layout]").unwrap();
    let spec = dir.join("heightmap.toml");
    std::fs::write(&spec, format!("{surface}\n[layout]{rest}")).unwrap();
    spec
}

fn main() {
    let (reference, runs) = common::spec_and_runs(7);
    common::print_header(&reference, runs);
    let samples = saddle_samples(1024, 64.0);
    let fits: Vec<f64> = (0..runs)
        .map(|_| {
            let t = Instant::now();
            HeightMap::fit(&samples, 0.5).unwrap();
            t.elapsed().as_secs_f64()
        })
        .collect();
    println!(
        "spline fit        1024 x 1024 samples: median {:.1} ms (goal < 500 ms)",
        median(fits) * 1e3
    );
    let dir =
        std::env::temp_dir().join(format!("moirecast-bench-heightmap-{}", std::process::id()));
    let specs: [std::path::PathBuf; 2] =
        [reference.clone().into(), heightmap_spec(&dir, &reference)];
    let mut times = [vec![], vec![]];
    for _ in 0..runs {
        for (k, path) in specs.iter().enumerate() {
            let t = Instant::now();
            let spec = moirecast_spec::load(path).unwrap();
            let out = dir.join(format!("out-{k}"));
            let _ = std::fs::remove_dir_all(&out);
            moirecast::run_device(
                &spec,
                &out,
                moirecast::Thoroughness::Sampled,
                moirecast::Mesher::Direct,
                &Silent,
            )
            .unwrap();
            times[k].push(t.elapsed().as_secs_f64());
        }
    }
    let [saddle, map] = times.map(median);
    println!(
        "device            closed-form saddle {:.0} ms, height map of it {:.0} ms: {:.2}x (goal <= 2x)",
        saddle * 1e3,
        map * 1e3,
        map / saddle
    );
    let _ = std::fs::remove_dir_all(&dir);
}
