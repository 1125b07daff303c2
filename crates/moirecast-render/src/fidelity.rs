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
    assert_eq!(values.len(), width * height);
    assert_eq!(phase.len(), width * height);
    let smooth = box_blur(values, width, height, (period_px / 2.0).round() as usize);
    let mut sum = [0.0f64; PHASE_BINS];
    let mut sum2 = [0.0f64; PHASE_BINS];
    let mut count = [0usize; PHASE_BINS];
    for (v, p) in smooth.iter().zip(phase) {
        if !p.is_finite() {
            continue;
        }
        let b = ((p.rem_euclid(1.0) * PHASE_BINS as f64) as usize).min(PHASE_BINS - 1);
        sum[b] += v;
        sum2[b] += v * v;
        count[b] += 1;
    }
    let n: usize = count.iter().sum();
    if n == 0 {
        return 0.0;
    }
    let mean = sum.iter().sum::<f64>() / n as f64;
    let total = sum2.iter().sum::<f64>() - n as f64 * mean * mean;
    if total <= 0.0 {
        return 0.0;
    }
    let within: f64 = (0..PHASE_BINS)
        .filter(|&b| count[b] > 0)
        .map(|b| sum2[b] - sum[b] * sum[b] / count[b] as f64)
        .sum();
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
}
