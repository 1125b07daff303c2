//! Moiré fidelity (METHOD §8): how much of a frame's variance the
//! elevation's level lines explain.
//!
//! 1. Low-pass the frame at the lens-period scale (a box average one period
//!    wide along each axis, which removes the lens carrier).
//! 2. Bin the pixels by the elevation phase frac(A·e(x, y)).
//! 3. Fidelity is R² = 1 − (variance within bins) / (total variance).

/// Bins of the elevation phase.
pub const PHASE_BINS: usize = 32;

/// Fidelity of a `width` × `height` frame (`values`, row-major) whose pixels
/// show the layout point of elevation phase `phase` (frac(A·e), NaN where a
/// pixel does not see the device), with the lens period `period_px` pixels
/// long. 0 for a frame without variance.
pub fn fidelity(values: &[f64], phase: &[f64], width: usize, height: usize, period_px: f64) -> f64 {
    let smooth = low_passed(values, phase, width, height, period_px);
    let (within, total) = variances(&smooth, phase, (0..width * height).collect(), PHASE_BINS);
    r_squared(within, total)
}

/// Windows per axis of [`local_fidelity`].
pub const LOCAL_WINDOWS: usize = 4;
/// Phase bins per window of [`local_fidelity`]: few, so that a window of a
/// few hundred pixels does not explain noise by chance (R² of pure noise is
/// about (bins − 1) / pixels).
pub const LOCAL_PHASE_BINS: usize = 8;

/// [`fidelity`] within each of [`LOCAL_WINDOWS`]² windows of the frame,
/// pooled: 1 − Σ within-bin variance / Σ variance about each window's mean.
/// On a curved device the view meets the surface at angles that change
/// across the frame, which shifts the level lines' brightness by an offset
/// that changes too; one set of bins over the whole frame mixes the
/// offsets, windows do not. Equal to [`fidelity`]'s idea where the offset
/// is constant (a plane); not part of METHOD §8, reported beside it.
pub fn local_fidelity(
    values: &[f64],
    phase: &[f64],
    width: usize,
    height: usize,
    period_px: f64,
) -> f64 {
    let (within, total, _) = windowed_variances(values, phase, width, height, period_px);
    r_squared(within, total)
}

/// How strongly a frame shows its level lines, in units of the signal's
/// full scale: 2 × the standard deviation of the part of the frame that the
/// elevation phase explains, within [`LOCAL_WINDOWS`]² windows (the
/// between-bin variance of [`local_fidelity`], per pixel). A signal that
/// swings between 0 and 1 in step with the level lines scores 1 (a square
/// wave; a full sine scores 0.71); none scores 0. [`local_fidelity`] is a
/// correlation, blind to contrast: a defocused base blurs the moiré into a
/// smooth, faint wave that correlates as well as a sharp one. A viewer sees
/// the contrast, so this ranks designs (`moirecast explore`).
pub fn level_line_contrast(
    values: &[f64],
    phase: &[f64],
    width: usize,
    height: usize,
    period_px: f64,
) -> f64 {
    let (within, total, seen) = windowed_variances(values, phase, width, height, period_px);
    if seen == 0 {
        return 0.0;
    }
    2.0 * ((total - within).max(0.0) / seen as f64).sqrt()
}

/// (Σ within-bin variance, Σ variance about each window's mean, pixels
/// that see the device) over [`LOCAL_WINDOWS`]² windows, as sums of squares.
fn windowed_variances(
    values: &[f64],
    phase: &[f64],
    width: usize,
    height: usize,
    period_px: f64,
) -> (f64, f64, usize) {
    let smooth = low_passed(values, phase, width, height, period_px);
    let (mut within, mut total) = (0.0, 0.0);
    for wy in 0..LOCAL_WINDOWS {
        for wx in 0..LOCAL_WINDOWS {
            let (x0, x1) = (wx * width / LOCAL_WINDOWS, (wx + 1) * width / LOCAL_WINDOWS);
            let (y0, y1) = (
                wy * height / LOCAL_WINDOWS,
                (wy + 1) * height / LOCAL_WINDOWS,
            );
            let pixels = (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| y * width + x))
                .collect();
            let (w, t) = variances(&smooth, phase, pixels, LOCAL_PHASE_BINS);
            within += w;
            total += t;
        }
    }
    let seen = phase.iter().filter(|p| p.is_finite()).count();
    (within, total, seen)
}

/// The frame low-passed over one lens period (a box one period wide along
/// each axis, which removes the lens carrier).
fn low_passed(
    values: &[f64],
    phase: &[f64],
    width: usize,
    height: usize,
    period_px: f64,
) -> Vec<f64> {
    assert_eq!(values.len(), width * height);
    assert_eq!(phase.len(), width * height);
    box_blur(values, width, height, (period_px / 2.0).round() as usize)
}

/// (variance within phase bins, variance about the mean), both as sums of
/// squares, over the `pixels` that see the device.
fn variances(smooth: &[f64], phase: &[f64], pixels: Vec<usize>, bins: usize) -> (f64, f64) {
    let mut sum = vec![0.0f64; bins];
    let mut sum2 = vec![0.0f64; bins];
    let mut count = vec![0usize; bins];
    for i in pixels {
        let (v, p) = (smooth[i], phase[i]);
        if !p.is_finite() {
            continue;
        }
        let b = ((p.rem_euclid(1.0) * bins as f64) as usize).min(bins - 1);
        sum[b] += v;
        sum2[b] += v * v;
        count[b] += 1;
    }
    let n: usize = count.iter().sum();
    if n == 0 {
        return (0.0, 0.0);
    }
    let mean = sum.iter().sum::<f64>() / n as f64;
    let total = sum2.iter().sum::<f64>() - n as f64 * mean * mean;
    let within: f64 = (0..bins)
        .filter(|&b| count[b] > 0)
        .map(|b| sum2[b] - sum[b] * sum[b] / count[b] as f64)
        .sum();
    (within, total.max(0.0))
}

/// 1 − within / total, in [0, 1]; 0 without variance.
fn r_squared(within: f64, total: f64) -> f64 {
    if total <= 0.0 {
        return 0.0;
    }
    (1.0 - within / total).clamp(0.0, 1.0)
}

/// Separable box average over (2r + 1) pixels per axis, clamped at edges.
fn box_blur(values: &[f64], width: usize, height: usize, r: usize) -> Vec<f64> {
    if r == 0 {
        return values.to_vec();
    }
    let pass = |src: &[f64], along_x: bool| -> Vec<f64> {
        let mut out = vec![0.0; src.len()];
        let (lines, len) = if along_x {
            (height, width)
        } else {
            (width, height)
        };
        for line in 0..lines {
            let at = |i: usize| {
                if along_x {
                    line * width + i
                } else {
                    i * width + line
                }
            };
            for i in 0..len {
                let (lo, hi) = (i.saturating_sub(r), (i + r).min(len - 1));
                out[at(i)] = (lo..=hi).map(|j| src[at(j)]).sum::<f64>() / (hi - lo + 1) as f64;
            }
        }
        out
    };
    pass(&pass(values, true), false)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(f: impl Fn(usize, usize) -> (f64, f64)) -> (Vec<f64>, Vec<f64>) {
        (0..64 * 48).map(|i| f(i % 64, i / 64)).unzip()
    }

    #[test]
    fn level_lines_explain_the_frame_and_noise_does_not() {
        // brightness a function of the phase alone (phase ramps slowly in x)
        let (v, p) = frame(|x, _| {
            let p = (x as f64 / 40.0).fract();
            ((2.0 * std::f64::consts::PI * p).cos(), p)
        });
        assert!(fidelity(&v, &p, 64, 48, 1.0) > 0.99);
        // a lens-period carrier on top is removed by the low-pass
        let (v2, _) = frame(|x, _| {
            let p = (x as f64 / 40.0).fract();
            (
                (2.0 * std::f64::consts::PI * p).cos() + if x % 4 < 2 { 0.5 } else { -0.5 },
                p,
            )
        });
        assert!(fidelity(&v2, &p, 64, 48, 4.0) > 0.9);
        // brightness unrelated to the phase (varies along y only)
        let (v3, _) = frame(|_, y| ((y as f64 / 7.0).sin(), 0.0));
        assert!(fidelity(&v3, &p, 64, 48, 1.0) < 0.05);
        // constant: no variance, no fidelity; unseen pixels are ignored
        let nan = vec![f64::NAN; 64 * 48];
        assert_eq!(fidelity(&vec![0.5; 64 * 48], &p, 64, 48, 1.0), 0.0);
        assert_eq!(fidelity(&v, &nan, 64, 48, 1.0), 0.0);
    }

    /// Level lines whose brightness offset drifts across the frame (as on a
    /// curved device, seen at changing angles): one set of bins over the
    /// frame mixes the offsets, windows recover the lines; noise stays low.
    #[test]
    fn local_fidelity_follows_level_lines_whose_offset_drifts() {
        let (w, h) = (128, 128);
        let phase = |x: usize, y: usize| ((x as f64 + 0.5 * y as f64) / 17.0).fract();
        let (v, p): (Vec<f64>, Vec<f64>) = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let offset = 0.5 * (x as f64 / w as f64 + y as f64 / h as f64); // up to 1 period
                let p = phase(x, y);
                ((2.0 * std::f64::consts::PI * (p + offset)).cos(), p)
            })
            .unzip();
        let (global, local) = (
            fidelity(&v, &p, w, h, 1.0),
            local_fidelity(&v, &p, w, h, 1.0),
        );
        eprintln!("global {global}, local {local}");
        assert!(global < 0.3, "global {global}");
        assert!(local > 0.8, "local {local}");
        // brightness unrelated to the phase: white noise
        let mut rng = crate::trace::SplitMix64(7);
        let noise: Vec<f64> = (0..w * h).map(|_| rng.next_f64()).collect();
        let by_chance = local_fidelity(&noise, &p, w, h, 1.0);
        eprintln!("noise {by_chance}");
        assert!(by_chance < 0.05, "noise {by_chance}");
        // where the offset is constant, both agree closely
        let (v2, _): (Vec<f64>, Vec<f64>) = (0..w * h)
            .map(|i| (((2.0 * std::f64::consts::PI * p[i]).cos()), 0.0))
            .unzip();
        let (g2, l2) = (
            fidelity(&v2, &p, w, h, 1.0),
            local_fidelity(&v2, &p, w, h, 1.0),
        );
        assert!(g2 > 0.99 && l2 > 0.95, "{g2} {l2}");
    }
}
