//! What the benchmarks share: arguments and medians.

/// `[SPEC [RUNS]]` from the command line (cargo's own `--bench` flags
/// skipped): the reference design and `default_runs` unless given.
pub fn spec_and_runs(default_runs: usize) -> (String, usize) {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let spec = args
        .first()
        .cloned()
        .unwrap_or_else(|| concat!(env!("CARGO_MANIFEST_DIR"), "/molds/saddle-horse.toml").into());
    let runs = args
        .get(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(default_runs);
    (spec, runs)
}

pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The first lines of every benchmark's output.
pub fn print_header(spec: &str, runs: usize) {
    println!("design            {spec}");
    println!(
        "runs              {runs} (medians; {} threads)",
        rayon::current_num_threads()
    );
}
