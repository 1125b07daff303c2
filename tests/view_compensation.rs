//! The view-compensated base on the shipped curved designs (docs/decisions.md,
//! "The view-compensated base"): from the design view each shows its image
//! (METHOD §8's fidelity), the same picture as its spec on a plane, and
//! the level lines still move when it is tilted, as much as the plane's.
//!
//! Measured at 256 px (the render's default), the numbers are printed:
//! `cargo test --test view_compensation -- --nocapture`.

use moirecast::render::{render_frames, RenderOptions, RenderedFrame};
use moirecast_kernel::progress::Silent;
use moirecast_kernel::{Design, PitchSurface};
use moirecast_render::frame::Frame;
use moirecast_spec::Spec;

fn load(name: &str) -> Spec {
    let path = format!("{}/molds/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    moirecast_spec::load(std::path::Path::new(&path)).expect("a shipped spec")
}

/// The same spec on a plane: the layout, lenses, base and image unchanged.
fn on_a_plane(name: &str) -> Spec {
    let mut spec = load(name);
    let mut params = spec.design.params.clone();
    params.surface = PitchSurface::Plane;
    spec.design = Design::new(params).expect("the flat spec is valid");
    spec
}

fn frames(spec: &Spec, tilts: &[f64]) -> Vec<Frame> {
    let options = RenderOptions::preview(256, 4, tilts.to_vec());
    let mut out = Vec::new();
    render_frames(spec, &options, &Silent, &mut |r: RenderedFrame| {
        out.push(r.frame);
        Ok(())
    })
    .expect("rendered");
    out
}

/// The frame's signal box-blurred over `width` pixels (odd), averaging only
/// the pixels on the device; NaN off it.
fn blurred(frame: &Frame, width: usize) -> Vec<f64> {
    let (w, h, r) = (frame.width, frame.height, (width / 2) as isize);
    let on = |i: usize| !frame.phase[i].is_nan();
    (0..w * h)
        .map(|i| {
            if !on(i) {
                return f64::NAN;
            }
            let (x, y) = ((i % w) as isize, (i / w) as isize);
            let (mut sum, mut n) = (0.0, 0.0);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                        let j = yy as usize * w + xx as usize;
                        if on(j) {
                            sum += frame.signal[j];
                            n += 1.0;
                        }
                    }
                }
            }
            sum / n
        })
        .collect()
}

/// Pearson correlation over the pixels where both are defined.
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let pairs: Vec<(f64, f64)> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(&x, &y)| (x, y))
        .collect();
    let n = pairs.len() as f64;
    let (mx, my) = pairs
        .iter()
        .fold((0.0, 0.0), |(sx, sy), (x, y)| (sx + x / n, sy + y / n));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in pairs {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
        syy += (y - my) * (y - my);
    }
    sxy / (sxx * syy).sqrt()
}

const BINS: usize = 64;

/// The frame's mean signal in each of BINS bins of the elevation phase,
/// less its mean: how the colour follows the level lines.
fn transfer(frame: &Frame) -> [f64; BINS] {
    let (mut sum, mut n) = ([0.0; BINS], [0.0; BINS]);
    for (s, p) in frame.signal.iter().zip(&frame.phase) {
        if p.is_finite() {
            let b = ((p * BINS as f64) as usize).min(BINS - 1);
            sum[b] += s;
            n[b] += 1.0;
        }
    }
    let mut curve = [0.0; BINS];
    for b in 0..BINS {
        curve[b] = if n[b] > 0.0 { sum[b] / n[b] } else { 0.0 };
    }
    let mean = curve.iter().sum::<f64>() / BINS as f64;
    curve.map(|c| c - mean)
}

/// How far (in levels, within ±½) the level lines moved from `a` to `b`:
/// the circular shift of the phase that best maps one transfer curve onto
/// the other, refined between bins by a parabola.
fn level_shift(a: &Frame, b: &Frame) -> f64 {
    let (ta, tb) = (transfer(a), transfer(b));
    let score = |s: usize| (0..BINS).map(|k| ta[k] * tb[(k + s) % BINS]).sum::<f64>();
    let scores: Vec<f64> = (0..BINS).map(score).collect();
    let best = (0..BINS)
        .max_by(|&i, &j| scores[i].total_cmp(&scores[j]))
        .unwrap();
    let (l, c, r) = (
        scores[(best + BINS - 1) % BINS],
        scores[best],
        scores[(best + 1) % BINS],
    );
    let peak = best as f64 + 0.5 * (l - r) / (l - 2.0 * c + r);
    let shift = peak / BINS as f64;
    shift - shift.round()
}

/// The RMS change of the blurred signal between two frames.
fn change(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(x, y)| (x - y) * (x - y))
        .collect();
    (d.iter().sum::<f64>() / d.len() as f64).sqrt()
}

/// What a design shows from its design view, and how its level lines move
/// from −5° to +5°.
struct Shown {
    fidelity: f64,
    /// Correlation with the flat spec's frame, both blurred over two periods
    /// (graph surfaces, whose pixels are the plane's one for one).
    against_flat: Option<f64>,
    /// How far the level lines move (levels), the design's and the flat
    /// spec's: read off the colour against the elevation phase, which a
    /// two-level image (coins) leaves undefined.
    shift: f64,
    flat_shift: f64,
    /// The RMS change of the blurred frame, the design's and the flat spec's.
    beat: f64,
    flat_beat: f64,
}

fn shown(name: &str, graph: bool) -> Shown {
    let spec = load(name);
    let curved = frames(&spec, &[-5.0, 0.0, 5.0]);
    let flat = frames(&on_a_plane(name), &[-5.0, 0.0, 5.0]);
    let blur = ((2.0 * curved[1].period_px).round() as usize) | 1;
    let [c, f] =
        [&curved, &flat].map(|frames| frames.iter().map(|f| blurred(f, blur)).collect::<Vec<_>>());
    Shown {
        fidelity: curved[1].fidelity(),
        against_flat: graph.then(|| correlation(&c[1], &f[1])),
        shift: level_shift(&curved[0], &curved[2]),
        flat_shift: level_shift(&flat[0], &flat[2]),
        beat: change(&c[0], &c[2]),
        flat_beat: change(&f[0], &f[2]),
    }
}

fn check(name: &str, graph: bool) {
    let s = shown(name, graph);
    eprintln!(
        "{name}: fidelity {:.3}, against the flat spec {}; from -5° to +5° the level lines move {:+.3} levels (flat: {:+.3}) and the frame changes by {:.3} RMS (flat: {:.3}, ratio {:.2})",
        s.fidelity,
        s.against_flat.map_or("-".into(), |c| format!("{c:.3}")),
        s.shift,
        s.flat_shift,
        s.beat,
        s.flat_beat,
        s.beat / s.flat_beat
    );
    assert!(s.fidelity >= 0.8, "{name}: fidelity {}", s.fidelity);
    if let Some(c) = s.against_flat {
        assert!(c >= 0.8, "{name}: correlates {c} with its flat spec");
    }
    assert!(
        s.beat >= 0.8 * s.flat_beat,
        "{name}: the frame changes by {} RMS from -5° to +5°, the flat spec's by {}",
        s.beat,
        s.flat_beat
    );
}

#[test]
fn saddle_horse_shows_its_horse() {
    check("saddle-horse", true);
}

#[test]
fn paraboloid_camera_shows_its_camera() {
    check("paraboloid-camera", true);
}

#[test]
fn cylinder_coins_shows_its_coins() {
    // the cylinder maps u by arc length: its pixels are not the plane's
    check("cylinder-coins", false);
}

#[test]
fn saddle_camera_printed_shows_its_camera() {
    check("saddle-camera-printed", true);
}
