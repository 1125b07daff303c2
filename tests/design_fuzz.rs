//! The design fuzzer: random spec files drawn across every key's whole
//! range and beyond, through the same pipelines as `moirecast device` and
//! `moirecast mold`. Every drawn spec must build (a device, and for a third
//! of the dual-lens ones a mold) with every check passing, or be refused by
//! a named rule (a spec key, or a mold check naming its key). A check that
//! fails on an accepted spec, a solver that does not converge, a panic or a
//! case that runs past its time is a bug: the spec is saved into
//! `tests/design-corpus/` (replayed first on every run) and the test fails.
//!
//! The test command draws from one fixed seed, so CI is reproducible and a
//! red run is a change's doing; exploring is the soak's job:
//! `MOIRECAST_SOAK=N` runs N times the cases from a new seed each run, and
//! `MOIRECAST_FUZZ_SEED=S` (printed on every run) replays one.
//! `MOIRECAST_FUZZ_CORPUS=DIR` replays and saves finds in DIR instead.
//! `MOIRECAST_FUZZ_FROM=N` runs from case N on (the cases before it are
//! still drawn, so case N is the seed's own), and `MOIRECAST_FUZZ_VERBOSE`
//! prints each case's spec before it runs and its outcome after: a case
//! that takes the process down (out of memory, say) is the last printed.

use moirecast::{RunError, Thoroughness};
use moirecast_kernel::progress::Silent;
use moirecast_kernel::MeshBudget;
use moirecast_spec::{ImageSource, SpecError};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Cases per run in CI.
const CASES: usize = 160;
/// Cases on a height map per run in CI, drawn from a stream of their own
/// (so the other cases stay the seed's).
const HEIGHTMAP_CASES: usize = 24;
/// Bytes a fuzzed design's mold run may hold (about 150,000 triangles):
/// larger draws are refused by the budget rule, which keeps a case under a
/// second.
const BUDGET_BYTES: f64 = 120e6;
/// The seed of the test command's cases.
const FIXED_SEED: u64 = 7;
/// A case running longer than this is a hang.
const CASE_TIMEOUT: Duration = Duration::from_secs(120);

/// SplitMix64: small and reproducible.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// Log-uniform between positive `lo` and `hi`.
    fn log(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.unit()).exp()
    }
    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[(self.next() % items.len() as u64) as usize]
    }
}

/// A number as TOML writes it, short.
fn num(v: f64) -> String {
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() || s == "-" {
        "0".into()
    } else {
        s.into()
    }
}

/// One spec file, drawn wide: most draws are plausible, some at the edges
/// of every range and some beyond.
fn draw(rng: &mut Rng, with_mold: bool) -> String {
    let mut t = String::new();
    let radius = |rng: &mut Rng| {
        let r = rng.log(4.0, 20_000.0);
        if rng.chance(0.5) {
            -r
        } else {
            r
        }
    };
    // [surface]
    let kind = *rng.pick(&[
        "plane",
        "saddle",
        "paraboloid",
        "cylinder",
        "sphere",
        "formula",
    ]);
    writeln!(t, "[surface]\nkind = \"{kind}\"").unwrap();
    match kind {
        "plane" => {}
        "formula" => {
            let (k, r, a, b) = (
                rng.uniform(-1.6, 1.6),
                radius(rng),
                rng.log(0.05, 5.0),
                rng.log(2.0, 40.0),
            );
            let z = match rng.next() % 8 {
                7 => heavy_formula(rng),
                0 => format!("{}*x", num(k)),
                1 => format!("{}*y", num(k)),
                2 => format!("{}*x + {}*y", num(k), num(rng.uniform(-1.0, 1.0))),
                3 => format!("(x*x - y*y)/{}", num(r)),
                4 => format!("(x*x + y*y)/{}", num(r)),
                5 => format!("{}*sin(x/{})*cos(y/{})", num(a), num(b), num(b * 1.3)),
                _ => format!("{}*exp(-(x*x + y*y)/{})", num(a), num(b * b)),
            };
            writeln!(t, "z = \"{z}\"").unwrap();
        }
        _ => writeln!(t, "radius = {}", num(radius(rng))).unwrap(),
    }
    // [layout]: whole numbers of periods mostly; extreme aspect ratios sometimes
    let period = if rng.chance(0.9) {
        rng.log(0.06, 3.0)
    } else {
        rng.log(0.02, 30.0)
    };
    // four decimals, so that whole numbers of periods print exactly
    let period = (period * 1e4).round().max(1.0) / 1e4;
    let lenses = if rng.chance(0.95) {
        rng.log(1.0, 160.0).round().max(1.0)
    } else {
        rng.uniform(0.5, 40.0)
    };
    let width = lenses * period;
    let height = match rng.next() % 20 {
        0 => width * rng.log(0.001, 0.05),
        1 | 2 => width * rng.log(5.0, 60.0),
        3 => period * rng.log(1.0, 3.0),
        _ => rng.log(1.0, 40.0),
    };
    writeln!(
        t,
        "[layout]\nwidth = {}\nheight = {}\nperiod = {}",
        num(width),
        num(height),
        num(period)
    )
    .unwrap();
    // [lens]
    writeln!(t, "[lens]\nafov = {}", num(rng.uniform(5.0, 125.0))).unwrap();
    match rng.next() % 4 {
        0 => writeln!(
            t,
            "material = \"{}\"",
            rng.pick(&[
                "sylgard-184",
                "polyjet-clear",
                "pmma",
                "polycarbonate",
                "epoxy"
            ])
        )
        .unwrap(),
        1 => writeln!(
            t,
            "index = {}",
            num(*rng.pick(&[1.0001, 1.01, 1.2, 1.41, 1.6, 2.2, 3.0, 3.3]))
        )
        .unwrap(),
        _ => {}
    }
    if rng.chance(0.15) {
        writeln!(t, "rule = \"equal-radius\"").unwrap();
    }
    // [base]
    let printed = !with_mold && rng.chance(0.25);
    writeln!(
        t,
        "[base]\nkind = \"{}\"",
        if printed { "printed" } else { "dual-lens" }
    )
    .unwrap();
    let a = match rng.next() % 4 {
        0 => 0.0,
        1 => 1.0,
        _ => rng.uniform(-0.1, 1.1),
    };
    writeln!(t, "a = {}", num(a)).unwrap();
    if rng.chance(0.4) {
        writeln!(t, "d = {}", num(rng.log(0.005, 20.0))).unwrap();
    }
    let levels = if rng.chance(0.1) {
        0.0
    } else {
        rng.log(0.05, 8.0)
    };
    writeln!(t, "levels = {}", num(levels)).unwrap();
    if printed {
        for (key, lo, hi) in [
            ("duty", 0.02, 0.98),
            ("band_thickness", 0.005, 12.0),
            ("backing", 0.005, 60.0),
        ] {
            if rng.chance(0.5) {
                writeln!(t, "{key} = {}", num(rng.log(lo, hi))).unwrap();
            }
        }
    } else if rng.chance(0.3) {
        writeln!(t, "afov = {}", num(rng.uniform(5.0, 125.0))).unwrap();
    }
    // [profile]
    writeln!(t, "[profile]").unwrap();
    match rng.next() % 6 {
        0 => writeln!(t, "kind = \"flat\"").unwrap(),
        1 => {
            writeln!(t, "kind = \"rings\"").unwrap();
            if rng.chance(0.5) {
                writeln!(t, "wavelength = {}", num(rng.log(0.2, 100.0))).unwrap();
            }
        }
        2 => writeln!(
            t,
            "kind = \"ramp\"\nangle = {}",
            num(rng.uniform(-360.0, 360.0))
        )
        .unwrap(),
        3 => {
            writeln!(t, "kind = \"bump\"").unwrap();
            if rng.chance(0.5) {
                writeln!(t, "sigma = {}", num(rng.log(0.1, 50.0))).unwrap();
            }
        }
        _ => {
            writeln!(
                t,
                "image = \"profiles/{}.png\"\nmode = \"{}\"\nthreshold = {}\ninvert = {}",
                rng.pick(&["horse", "camera", "coins"]),
                rng.pick(&["gray", "shape"]),
                num(rng.uniform(0.05, 1.0)),
                rng.chance(0.3)
            )
            .unwrap();
        }
    }
    writeln!(t, "blur = {}", num(rng.log(0.05, 8.0))).unwrap();
    if rng.chance(0.3) {
        draw_view(rng, &mut t);
    }
    // [mesh]
    let tolerance = if rng.chance(0.85) {
        rng.log(5e-4, 0.03)
    } else {
        rng.log(5e-5, 0.15)
    };
    writeln!(t, "[mesh]\ntolerance = {}", num(tolerance)).unwrap();
    if with_mold {
        writeln!(t, "[mold]").unwrap();
        for (key, lo, hi) in [
            ("wall_thickness", 0.8, 30.0),
            ("gate_diameter", 0.15, 4.0),
            ("vent_diameter", 0.15, 3.0),
            ("key_diameter", 0.4, 12.0),
            ("key_height", 0.15, 6.0),
            ("key_clearance", 0.01, 1.0),
            ("shrink_scale", 0.95, 1.05),
            ("min_draft", 0.05, 10.0),
        ] {
            if rng.chance(0.3) {
                writeln!(t, "{key} = {}", num(rng.log(lo, hi))).unwrap();
            }
        }
        if rng.chance(0.3) {
            writeln!(t, "flip = true").unwrap();
        }
        if rng.chance(0.3) {
            writeln!(
                t,
                "bolts = true\nbolt_spacing = {}",
                num(rng.log(6.0, 60.0))
            )
            .unwrap();
        }
    }
    t
}

/// A long, deep or product-heavy formula (issue 44: such formulas
/// overflowed the parser's stack): sums of many terms, nested functions,
/// products and powers, mostly past the formula budget, some within it.
fn heavy_formula(rng: &mut Rng) -> String {
    let n = 1 + (rng.next() % 60) as usize;
    let terms = |term: &dyn Fn(usize) -> String, join: &str| {
        (0..n).map(term).collect::<Vec<_>>().join(join)
    };
    match rng.next() % 4 {
        0 => terms(&|i| format!("x*y/{}", 1000 + i), "+"),
        1 => (0..n.min(14)).fold("x/20".to_string(), |f, _| format!("sin({f})")),
        2 => format!("({})/1000", terms(&|i| format!("(x/30+{})", i % 7), "*")),
        _ => terms(&|_| "x/40".to_string(), "^"),
    }
}

/// A `[view]` table: mostly tilts a viewer takes, some past grazing the
/// lenses, eyes near and far (some nearer than allowed), and the
/// uncompensated base.
fn draw_view(rng: &mut Rng, t: &mut String) {
    writeln!(t, "[view]").unwrap();
    for key in ["tilt", "tilt_along"] {
        if rng.chance(0.5) {
            let reach = if rng.chance(0.8) { 25.0 } else { 70.0 };
            writeln!(t, "{key} = {}", num(rng.uniform(-reach, reach))).unwrap();
        }
    }
    if rng.chance(0.4) {
        writeln!(t, "distance = {}", num(rng.log(30.0, 5000.0))).unwrap();
    }
    if rng.chance(0.15) {
        writeln!(t, "compensate = false").unwrap();
    }
}

/// How one case ended.
#[derive(Debug)]
enum Outcome {
    /// Built (and its mold, if asked), every check passed.
    Built { mold: bool },
    /// Refused by a named rule: the spec key, or the mold check.
    Refused(String),
    /// A bug: the message.
    Bug(String),
}

/// The named rule behind a refusal, if the error is one.
fn refusal(e: &anyhow::Error) -> Option<String> {
    if let Some(SpecError::Invalid { key, .. }) = e.downcast_ref::<SpecError>() {
        return Some((*key).to_string());
    }
    match e.downcast_ref::<RunError>()? {
        RunError::Spec(SpecError::Invalid { key, .. }) => Some((*key).to_string()),
        RunError::MoldMisfit { error, .. } => Some(match error {
            moirecast_mold::MoldError::DoesNotFit { check, .. } => format!("mold: {check}"),
            other => format!("mold: {other:?}").chars().take(40).collect(),
        }),
        _ => None,
    }
}

/// `text` with its `[surface]` replaced by a drawn height map: smooth
/// fields, noise, steps and ramps, 1 to 256 pixels a side, 8 or 16 bit,
/// over extents from the layout's to a hundred times it (and short of it
/// sometimes), with reliefs from 0.1 µm to 60 mm (and upside down
/// sometimes), smoothed or not.
fn on_a_height_map(rng: &mut Rng, text: &str) -> String {
    let table: toml::Table = toml::from_str(text).expect("a drawn spec is TOML");
    let layout = |key: &str| table["layout"][key].as_float().unwrap_or(10.0);
    let (w, h) = (layout("width"), layout("height"));
    let family = *rng.pick(&["smooth", "noise", "step", "ramp"]);
    let sides = [1, 2, 4, 7, 16, 33, 64, 128, 256];
    let (cols, rows) = (*rng.pick(&sides), *rng.pick(&sides));
    let bits = *rng.pick(&[8, 16]);
    let image = format!(
        "surfaces/{family}-{cols}x{rows}-{bits}b-{}.png",
        rng.next() % 1000
    );
    let z_min = rng.uniform(-20.0, 20.0);
    let relief = rng.log(1e-4, 60.0);
    let z_max = if rng.chance(0.05) {
        z_min - relief
    } else {
        z_min + relief
    };
    let scale = match rng.next() % 20 {
        0 => rng.uniform(0.5, 1.0),
        1 => rng.log(10.0, 100.0),
        _ => rng.uniform(1.0, 3.0),
    };
    let mut surface = format!(
        "[surface]\nkind = \"heightmap\"\nimage = \"{image}\"\nz_min = {}\nz_max = {}\nsize = [{}, {}]\n",
        num(z_min),
        num(z_max),
        num(w * scale),
        num(h * scale)
    );
    if rng.chance(0.5) {
        writeln!(surface, "smoothing = {}", num(rng.log(1e-3, 100.0))).unwrap();
    }
    let rest = &text[text.find("[layout]").expect("a drawn spec has a layout")..];
    format!("{surface}{rest}")
}

/// The folder a case's images come from: the shipped profiles, and the
/// height maps its spec names, each written from its name (so a saved
/// case finds its map again): `surfaces/FAMILY-COLSxROWS-BITSb-SEED.png`.
fn fuzz_images(text: &str) -> std::io::Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("moirecast-fuzz-images-{}", std::process::id()));
    let profiles = Path::new(env!("CARGO_MANIFEST_DIR")).join("molds/profiles");
    std::fs::create_dir_all(dir.join("profiles"))?;
    std::fs::create_dir_all(dir.join("surfaces"))?;
    for entry in std::fs::read_dir(&profiles)? {
        let entry = entry?;
        let to = dir.join("profiles").join(entry.file_name());
        if !to.exists() {
            std::fs::copy(entry.path(), to)?;
        }
    }
    let named = text
        .lines()
        .filter_map(|l| l.strip_prefix("image = \"surfaces/"))
        .filter_map(|l| l.strip_suffix(".png\""));
    for name in named {
        let path = dir.join("surfaces").join(format!("{name}.png"));
        if !path.exists() {
            write_height_map(name, &path)?;
        }
    }
    Ok(dir)
}

/// Writes the height map `name` (FAMILY-COLSxROWS-BITSb-SEED) to `path`.
fn write_height_map(name: &str, path: &Path) -> std::io::Result<()> {
    let bad = || std::io::Error::other(format!("no height map is named {name}"));
    let parts: Vec<&str> = name.split('-').collect();
    let [family, size, bits, seed] = parts[..] else {
        return Err(bad());
    };
    let (cols, rows) = size.split_once('x').ok_or_else(bad)?;
    let (cols, rows): (u32, u32) = (
        cols.parse().map_err(|_| bad())?,
        rows.parse().map_err(|_| bad())?,
    );
    let seed: u64 = seed.parse().map_err(|_| bad())?;
    let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x5EED);
    let bumps: Vec<[f64; 4]> = (0..3)
        .map(|_| {
            [
                rng.unit(),
                rng.unit(),
                rng.log(0.05, 0.5),
                rng.uniform(-1.0, 1.0),
            ]
        })
        .collect();
    let value = |i: u32, j: u32, rng: &mut Rng| -> f64 {
        let (x, y) = (
            (f64::from(i) + 0.5) / f64::from(cols),
            (f64::from(j) + 0.5) / f64::from(rows),
        );
        match family {
            "noise" => rng.unit(),
            "step" => f64::from(u8::from(x > 0.5)),
            "ramp" => x,
            _ => {
                let sum: f64 = bumps
                    .iter()
                    .map(|[cx, cy, r, a]| {
                        a * (-((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * r * r)).exp()
                    })
                    .sum();
                (0.5 + 0.3 * sum).clamp(0.0, 1.0)
            }
        }
    };
    let saved = if bits == "16b" {
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(cols, rows, |i, j| {
            image::Luma([(value(i, j, &mut rng) * 65535.0).round() as u16])
        })
        .save(path)
    } else {
        image::ImageBuffer::<image::Luma<u8>, Vec<u8>>::from_fn(cols, rows, |i, j| {
            image::Luma([(value(i, j, &mut rng) * 255.0).round() as u8])
        })
        .save(path)
    };
    saved.map_err(std::io::Error::other)
}

/// Runs one spec text: its device, and its mold if `with_mold`.
fn run_case(text: &str, with_mold: bool, out: &Path) -> Outcome {
    let images = match fuzz_images(text) {
        Ok(dir) => dir,
        Err(e) => return Outcome::Bug(format!("the drawn height map cannot be written: {e}")),
    };
    let mut spec = match moirecast_spec::parse(text, "fuzz.toml", ImageSource::Dir(&images)) {
        Ok(spec) => spec,
        Err(SpecError::Invalid { key, .. }) => return Outcome::Refused(key.to_string()),
        Err(e) => return Outcome::Bug(format!("the drawn spec does not parse: {e}")),
    };
    spec.design.mesh_budget = MeshBudget {
        max_bytes: Some(BUDGET_BYTES),
        ..MeshBudget::DEFAULT
    };
    let device = moirecast::run_device(
        &spec,
        &out.join("device"),
        Thoroughness::Sampled,
        moirecast::Mesher::Direct,
        &Silent,
    );
    if let Err(e) = device {
        return match refusal(&e) {
            Some(rule) => Outcome::Refused(rule),
            None => Outcome::Bug(format!("device: {e:#}")),
        };
    }
    if !with_mold {
        return Outcome::Built { mold: false };
    }
    match moirecast::run_mold(&spec, &out.join("mold"), false, &Silent) {
        Ok(_) => Outcome::Built { mold: true },
        Err(e) => match refusal(&e) {
            Some(rule) => Outcome::Refused(rule),
            None => Outcome::Bug(format!("mold: {e:#}")),
        },
    }
}

/// Runs a case on a thread of its own, so a panic is caught and a hang is
/// seen (the thread is then left behind, and the test fails).
fn guarded(text: String, with_mold: bool, out: PathBuf) -> Outcome {
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let outcome =
            std::panic::catch_unwind(|| run_case(&text, with_mold, &out)).unwrap_or_else(|p| {
                let what = p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                Outcome::Bug(format!("panic: {what}"))
            });
        let _ = send.send(outcome);
    });
    receive
        .recv_timeout(CASE_TIMEOUT)
        .unwrap_or_else(|_| Outcome::Bug(format!("no result after {CASE_TIMEOUT:?} (a hang)")))
}

/// The corpus: `tests/design-corpus/`, or `MOIRECAST_FUZZ_CORPUS`, so a
/// soak run beside a checkout replays and saves into a copy of its own.
fn corpus_dir() -> PathBuf {
    std::env::var_os("MOIRECAST_FUZZ_CORPUS").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/design-corpus"),
        PathBuf::from,
    )
}

/// Saves a failing spec into the corpus, so every later run replays it.
fn save(text: &str, why: &str) -> PathBuf {
    let mut h = Rng(text.len() as u64);
    for b in text.bytes() {
        h.0 ^= b as u64;
        h.next();
    }
    let path = corpus_dir().join(format!("found-{:016x}.toml", h.next()));
    let note: String = why.lines().next().unwrap_or("").chars().take(200).collect();
    let _ = std::fs::write(
        &path,
        format!("# found by tests/design_fuzz.rs: {note}\n{text}"),
    );
    path
}

#[test]
fn every_accepted_design_builds_or_is_refused_by_name() {
    let soak: usize = std::env::var("MOIRECAST_SOAK")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let seed: u64 = std::env::var("MOIRECAST_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| {
            if soak == 1 {
                return FIXED_SEED;
            }
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(1, |d| d.as_nanos() as u64)
        });
    println!(
        "design fuzz: seed {seed}, {} cases ({} on height maps)",
        (CASES + HEIGHTMAP_CASES) * soak,
        HEIGHTMAP_CASES * soak
    );
    let out = std::env::temp_dir().join(format!("moirecast-fuzz-{}", std::process::id()));
    // past failures first, each with its mold if it has a [mold] table
    let mut corpus: Vec<PathBuf> = std::fs::read_dir(corpus_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    corpus.sort();
    let mut cases: Vec<(String, bool, Option<PathBuf>)> = corpus
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p).unwrap();
            let castable = !text.contains("\"printed\"");
            (text, castable, Some(p))
        })
        .collect();
    let mut rng = Rng(seed);
    for i in 0..CASES * soak {
        let with_mold = i % 3 == 0;
        cases.push((draw(&mut rng, with_mold), with_mold, None));
    }
    let mut maps = Rng(seed ^ 0x4845_4947_4854);
    for i in 0..HEIGHTMAP_CASES * soak {
        let with_mold = i % 3 == 0;
        let text = draw(&mut maps, with_mold);
        cases.push((on_a_height_map(&mut maps, &text), with_mold, None));
    }
    const SLOW_CASE: Duration = Duration::from_secs(5);
    let (mut built, mut molds) = (0, 0);
    let mut refused: BTreeMap<String, usize> = BTreeMap::new();
    let mut bugs = Vec::new();
    let (mut slowest, started) = ((Duration::ZERO, String::new()), Instant::now());
    let verbose = std::env::var_os("MOIRECAST_FUZZ_VERBOSE").is_some();
    let first: usize = std::env::var("MOIRECAST_FUZZ_FROM")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    for (n, (text, with_mold, from)) in cases.into_iter().enumerate().skip(first) {
        if verbose {
            println!("case {n} (mold: {with_mold}):\n{text}");
        }
        let t = Instant::now();
        let outcome = guarded(text.clone(), with_mold, out.join(n.to_string()));
        if verbose {
            println!("case {n}: {:.2} s {outcome:?}", t.elapsed().as_secs_f64());
        }
        match outcome {
            Outcome::Built { mold } => {
                built += 1;
                molds += mold as usize;
            }
            Outcome::Refused(rule) => *refused.entry(rule).or_default() += 1,
            Outcome::Bug(why) => {
                let saved = from.unwrap_or_else(|| save(&text, &why));
                bugs.push(format!("{}: {why}", saved.display()));
            }
        }
        if t.elapsed() > slowest.0 {
            slowest = (t.elapsed(), text);
        }
        let _ = std::fs::remove_dir_all(out.join(n.to_string()));
        // a soak's counts so far, by rule: it may be stopped at any time
        if soak > 1 && (n + 1) % 1000 == 0 {
            let by_rule: Vec<String> = refused.iter().map(|(r, c)| format!("{r} {c}")).collect();
            println!(
                "  {} cases: {built} built ({molds} molds), {} refused, {} bugs, {:.0} s; refused by {}",
                n + 1,
                refused.values().sum::<usize>(),
                bugs.len(),
                started.elapsed().as_secs_f64(),
                by_rule.join(", ")
            );
        }
    }
    println!(
        "built {built} (with {molds} molds), refused {}, bugs {}; slowest case {:.2} s, all {:.1} s",
        refused.values().sum::<usize>(),
        bugs.len(),
        slowest.0.as_secs_f64(),
        started.elapsed().as_secs_f64()
    );
    // a slow case is not a failure, but worth a look: print it to rerun
    if slowest.0 > SLOW_CASE {
        println!("  the slowest case's spec:\n{}", slowest.1);
    }
    for (rule, count) in &refused {
        println!("  refused by {rule}: {count}");
    }
    assert!(
        bugs.is_empty(),
        "accepted specs that did not build (saved in tests/design-corpus/):\n{}",
        bugs.join("\n")
    );
    assert!(
        built > 0,
        "no drawn design built: the fuzzer draws nothing useful"
    );
}
