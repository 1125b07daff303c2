//! Benchmark of `moirecast studio` over HTTP, end to end, on the reference
//! design (or SPEC): the latency of a 256 px frame (median and p95 over
//! RUNS requests at tilts across ±10°, after one frame has built the
//! sections) with the default 16 lens phases and with the 9 the page asks
//! for while a slider moves, of a 512 px frame, of a 256 px frame tilted
//! along the lenses too (5°, 10° and 20°, at the same tilts across) beside
//! the one tilted about their axis alone, and the time from a spec edit
//! (`PUT /api/spec`) to its first 256 px frame.
//!
//! `cargo bench --bench studio [-- SPEC [RUNS]]`

mod common;
#[path = "../tests/common/http.rs"]
#[allow(dead_code)] // the tests use all of it
mod http;

use common::median;
use std::time::Instant;

/// The value below which `q` of `v` lie.
fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let (spec_path, runs) = common::spec_and_runs(40);
    common::print_header(&spec_path, runs);
    let out = std::env::temp_dir().join(format!("moirecast-bench-studio-{}", std::process::id()));
    let port = http::start_studio(spec_path.clone().into(), out);
    let host = format!("127.0.0.1:{port}");
    let get = |target: &str| {
        let t = Instant::now();
        let r = http::request(port, &host, "GET", target, b"");
        assert_eq!(
            r.status,
            200,
            "{target}: {}",
            String::from_utf8_lossy(&r.body)
        );
        (t.elapsed().as_secs_f64() * 1e3, r)
    };
    // RUNS frames at tilts across ±10°, each `query(tilt)`: their latencies
    // over HTTP and their render times (ms)
    let frames = |query: &dyn Fn(f64) -> String| {
        let (mut latency, mut render) = (Vec::new(), Vec::new());
        for i in 0..runs {
            let tilt = -10.0 + 20.0 * i as f64 / runs as f64;
            let (ms, r) = get(&query(tilt));
            latency.push(ms);
            render.push(r.header("x-render-ms").unwrap().parse::<f64>().unwrap());
        }
        (latency, render)
    };
    // the default (16 lens phases), and what the page asks for while a
    // slider moves (9)
    for (size, samples) in [(256, 4), (256, 3), (512, 4)] {
        // builds the sections, at a tilt the runs do not ask for (a view
        // asked for again is served from the revision's cache)
        get(&format!("/api/frame.png?size={size}&tilt=0.123"));
        let (latency, render) =
            frames(&|tilt| format!("/api/frame.png?size={size}&samples={samples}&tilt={tilt}"));
        println!(
            "frame {size} px, {:2} phases  median {:6.1} ms, p95 {:6.1} ms over HTTP (render alone: median {:.1} ms)",
            samples * samples,
            median(latency.clone()),
            quantile(latency, 0.95),
            median(render.clone())
        );
    }
    // tilted along the lenses as well, at the same tilts across: each ray
    // follows its drift along the lenses through the sections. Each frame
    // alternates with one at the same tilt about the axis alone (a tilt
    // off by 1e-3°, so that neither is served from the cache), and the
    // ratio is the median of the pairs': the machine's load drifts less
    // within a pair than over the run.
    for along in [5.0, 10.0, 20.0] {
        let (mut latency, mut render, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..runs {
            let tilt = -10.0 + 20.0 * i as f64 / runs as f64;
            let across_only = tilt + 1e-3 * (1.0 + along);
            let (_, r) = get(&format!(
                "/api/frame.png?size=256&samples=4&tilt={across_only}"
            ));
            let across_ms = r.header("x-render-ms").unwrap().parse::<f64>().unwrap();
            let (ms, r) = get(&format!(
                "/api/frame.png?size=256&samples=4&tilt={tilt}&along={along}"
            ));
            let along_ms = r.header("x-render-ms").unwrap().parse::<f64>().unwrap();
            latency.push(ms);
            render.push(along_ms);
            ratios.push(along_ms / across_ms);
        }
        println!(
            "frame 256 px, 16 phases, {along:2}° along  median {:6.1} ms over HTTP (render alone: median {:.1} ms, {:.2}x the frame at the same tilt about the axis alone: median of {runs} alternating pairs)",
            median(latency),
            median(render),
            median(ratios)
        );
    }
    // the same views again: each served from the cache
    let cached: Vec<f64> = (0..runs)
        .map(|i| {
            let tilt = -10.0 + 20.0 * i as f64 / runs as f64;
            let (ms, r) = get(&format!("/api/frame.png?size=256&samples=4&tilt={tilt}"));
            assert_eq!(r.header("x-frame-cache"), Some("hit"));
            ms
        })
        .collect();
    println!(
        "frame 256 px again  median {:6.1} ms over HTTP (from the revision's cache)",
        median(cached)
    );
    let original = String::from_utf8(get("/api/spec").1.body).unwrap();
    let edits: Vec<f64> = (0..5)
        .map(|i| {
            // a new elevation amplitude: a new profile, sections and frame
            let text = format!("{original}\n# edit {i}\n");
            let text = text.replacen("levels = ", &format!("levels = 1.{i}{i} # was "), 1);
            let t = Instant::now();
            let put = http::request(port, &host, "PUT", "/api/spec", text.as_bytes());
            assert_eq!(put.status, 200, "{}", String::from_utf8_lossy(&put.body));
            get("/api/frame.png?size=256&tilt=2.5");
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    println!(
        "edit to first frame  median {:6.1} ms over {} edits (PUT /api/spec, then a 256 px frame)",
        median(edits),
        5
    );
}
