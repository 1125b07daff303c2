//! Benchmark of `moirecast render` on the reference design (or SPEC):
//! the scene (BVH) build, and then one frame of that scene at 256 × 256 and 512 × 512 with
//! one sample per pixel, as medians over repeated runs, with each
//! integrator (the path tracer, the default, and the branching one).
//!
//! `cargo bench --bench render [-- SPEC [RUNS]]`

use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::progress::Silent;
use moirecast_render::frame::{render, Integrator, Lighting, View};
use moirecast_render::trace::Pruning;
use moirecast_render::Scene;
use std::time::Instant;

mod common;
use common::median;

fn main() {
    let (spec_path, runs) = common::spec_and_runs(5);
    let spec = moirecast_spec::load(std::path::Path::new(&spec_path)).unwrap();
    let design = &spec.design;
    let dm = mesh_device(design, &Silent).unwrap();
    common::print_header(&spec_path, runs);
    println!("triangles         {}", dm.mesh.triangles.len());
    let scene_t: Vec<f64> = (0..runs)
        .map(|_| {
            let t = Instant::now();
            let scene = Scene::new(&dm.mesh);
            std::hint::black_box(&scene);
            t.elapsed().as_secs_f64()
        })
        .collect();
    println!("scene (BVH)       {:8.1} ms", median(scene_t) * 1e3);
    let scene = Scene::new(&dm.mesh);
    let integrators = [
        ("path", Integrator::Path),
        ("branching", Integrator::Branching(Pruning::DEFAULT)),
    ];
    for (size, (name, integrator)) in [256, 512]
        .into_iter()
        .flat_map(|s| integrators.map(|i| (s, i)))
    {
        let mut fid = (0.0, 0.0);
        let times: Vec<f64> = (0..runs)
            .map(|_| {
                let t = Instant::now();
                let f = render(
                    design,
                    &scene,
                    View {
                        width: size,
                        height: size,
                        samples: 1,
                        tilt_across: 0.0,
                        tilt_along: 0.0,
                        camera: Default::default(),
                        lighting: Lighting::default_for(design),
                        integrator,
                        seed: 1,
                    },
                );
                let e = t.elapsed().as_secs_f64();
                fid = (f.fidelity(), f.local_fidelity());
                e
            })
            .collect();
        println!(
            "frame {size} x {size}  {:8.1} ms  ({name}; scene built once, above; 1 sample per pixel; fidelity {:.3}, local {:.3})",
            median(times) * 1e3,
            fid.0,
            fid.1
        );
    }
}
