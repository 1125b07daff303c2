//! Shared by the integration tests that run over every shipped design.

/// The specs in `molds/`, sorted (at least the four the README lists).
pub fn shipped_specs() -> Vec<std::path::PathBuf> {
    let mut specs: Vec<_> = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/molds"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    specs.sort();
    assert!(specs.len() >= 4, "the shipped specs are found");
    specs
}
