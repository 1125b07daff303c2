//! Benchmark of `moirecast render` on the reference design (or SPEC):
//! the scene (BVH) build, and then one frame of that scene at 256 × 256 and
//! 512 × 512, as medians over repeated runs: the default (the branching
//! integrator through 16 lens phases per pixel), the same through the
//! mesh, and the path tracer at one sample per pixel. The default traces
//! the device's exact cross-sections alone, with no BVH (built once per
//! design, row by row as frames need them); the others trace the mesh.
//!
//! `cargo bench --bench render [-- SPEC [RUNS]]`

use moirecast_kernel::mesher::mesh_device;
use moirecast_kernel::progress::Silent;
use moirecast_render::frame::{render_traced, Integrator, Lighting, Sampling, View};
use moirecast_render::section::Sections;
use moirecast_render::trace::Pruning;
use moirecast_render::Scene;
use rayon::prelude::*;
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
    // the default traces the sections alone, framed as the mesh is
    let no_mesh = Scene::framing(scene.bounds());
    let rows = Sections::for_frame(design, 256).unwrap().rows();
    let section_t: Vec<f64> = (0..runs)
        .map(|_| {
            let t = Instant::now();
            let sections = Sections::for_frame(design, 256).unwrap();
            (0..sections.rows()).into_par_iter().for_each(|r| {
                std::hint::black_box(sections.section(r));
            });
            t.elapsed().as_secs_f64()
        })
        .collect();
    println!(
        "sections ({rows} rows, 256 px) {:6.1} ms",
        median(section_t) * 1e3
    );
    let integrators = [
        (
            "default: branching, 16 lens phases, sections",
            Integrator::default(),
            Sampling::default(),
            true,
        ),
        (
            "branching, 16 lens phases, mesh",
            Integrator::Branching(Pruning::DEFAULT),
            Sampling::default(),
            false,
        ),
        (
            "path, 1 sample, mesh",
            Integrator::Path,
            Sampling::Strata(1),
            false,
        ),
    ];
    for (size, (name, integrator, sampling, by_sections)) in [256, 512]
        .into_iter()
        .flat_map(|s| integrators.map(|i| (s, i)))
    {
        let sections = Sections::for_frame(design, size);
        let mut fid = (0.0, 0.0);
        let times: Vec<f64> = (0..runs)
            .map(|_| {
                let t = Instant::now();
                let f = render_traced(
                    design,
                    if by_sections { &no_mesh } else { &scene },
                    sections.as_ref().filter(|_| by_sections),
                    View {
                        width: size,
                        height: size,
                        sampling,
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
            "frame {size} x {size}  {:8.1} ms  ({name}; scene built once, above; fidelity {:.3}, local {:.3})",
            median(times) * 1e3,
            fid.0,
            fid.1
        );
    }
}
