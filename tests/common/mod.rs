//! Shared by the integration tests: the shipped designs, a small design,
//! scratch directories. (Each test crate uses some of it.)
#![allow(dead_code)]

use std::path::{Path, PathBuf};

pub mod http;

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

/// A small valid design: fast in debug builds.
pub const SMALL: &str = r#"
[surface]
kind = "saddle"
radius = 40.0
[layout]
width = 4.0
height = 3.0
period = 0.5
[lens]
afov = 60.0
index = 1.41
[base]
kind = "dual-lens"
a = 0.0
d = "focal"
levels = 1.0
[profile]
kind = "bump"
sigma = 1.5
[mesh]
tolerance = 0.004
"#;

/// A fresh directory for one test, removed when the test passes (kept for
/// a look when it fails).
pub struct Scratch(pub PathBuf);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

pub fn scratch(kind: &str, name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("moirecast-{kind}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    Scratch(dir)
}
