//! A height map as the pitch surface: z = h(x, y), a smoothing bicubic
//! B-spline fitted to a grid of height samples (an image's pixels).
//!
//! The lenses and the focal surface need a C² surface with its first and
//! second derivatives (docs/method.md §1, §3); a uniform cubic B-spline is
//! C² everywhere and gives them in closed form. Its coefficients lie on
//! the sample grid, one beyond each edge, and are fitted axis by axis as a
//! P-spline (Eilers and Marx): least squares to the samples plus λ times
//! the sum of squared third differences of the coefficients. A third
//! difference vanishes on every quadratic, so any quadratic surface (a
//! saddle, a paraboloid, a plane) is reproduced exactly whatever the
//! smoothing; λ damps only what bends faster.
//!
//! Fitting rows, then columns, is the exact tensor-product interpolant
//! where λ is negligible, and a separable smoothing spline otherwise (its
//! penalty is along x on the rows and along y on the columns, not the
//! full two-dimensional one). Beyond the samples' extent the surface goes
//! on as the quadratic that meets it to the second order at the edge:
//! smooth, but invented, so a spec keeps its layout inside the extent.

use rayon::prelude::*;
use thiserror::Error;

/// A height map's samples: `columns` × `rows` heights (mm), row-major,
/// row 0 at the largest y (an image's top row), pixel centres spread
/// evenly over `extent` (mm, centred on the origin).
#[derive(Clone, Debug)]
pub struct HeightSamples {
    pub columns: usize,
    pub rows: usize,
    pub z: Vec<f64>,
    pub extent: (f64, f64),
}

/// Why samples could not be fitted.
#[derive(Debug, Error, PartialEq)]
pub enum HeightMapError {
    #[error("the height map is {columns} × {rows} samples: it needs at least {min} × {min}", min = HeightMap::MIN_SAMPLES)]
    TooFew { columns: usize, rows: usize },
    #[error("the height map has {got} samples for {columns} × {rows}")]
    Shape {
        columns: usize,
        rows: usize,
        got: usize,
    },
    #[error("the extent {0:?} mm is not positive and finite")]
    Extent((f64, f64)),
    #[error("the smoothing {0} mm is not zero or positive and finite")]
    Smoothing(f64),
    #[error("a height sample is not finite")]
    NotFinite,
}

/// The fitted surface.
#[derive(Clone, Debug)]
pub struct HeightMap {
    /// Coefficients, (rows + 2) × (columns + 2), row-major; coefficient
    /// (k, l) is centred on sample (k − 1, l − 1).
    coef: Vec<f64>,
    stride: usize,
    /// Sample (0, 0)'s position (its x, and its y, the largest), and the
    /// spacing of samples along x and y (mm).
    x0: f64,
    y0: f64,
    hx: f64,
    hy: f64,
    /// Cells along x and y (samples − 1): where the polynomial pieces are.
    cells: (usize, usize),
    extent: (f64, f64),
    smoothing: f64,
    max_deviation: f64,
}

impl HeightMap {
    /// Fewest samples along either axis: a cubic across three cells.
    pub const MIN_SAMPLES: usize = 4;

    /// The smallest λ (relative): the fit then interpolates the samples to
    /// within about 1e-6 of their range, and λ keeps its system definite.
    const MIN_LAMBDA: f64 = 1e-6;

    /// Fits `samples` with features shorter than about `smoothing` (mm; 0
    /// interpolates) damped: λ is set so that a sine of that wavelength
    /// keeps half its amplitude, (smoothing / 2πh)⁶ for spacing h.
    pub fn fit(samples: &HeightSamples, smoothing: f64) -> Result<HeightMap, HeightMapError> {
        let (nx, ny) = (samples.columns, samples.rows);
        if nx < Self::MIN_SAMPLES || ny < Self::MIN_SAMPLES {
            return Err(HeightMapError::TooFew {
                columns: nx,
                rows: ny,
            });
        }
        if samples.z.len() != nx * ny {
            return Err(HeightMapError::Shape {
                columns: nx,
                rows: ny,
                got: samples.z.len(),
            });
        }
        let (w, h) = samples.extent;
        if !(w > 0.0 && h > 0.0 && w.is_finite() && h.is_finite()) {
            return Err(HeightMapError::Extent(samples.extent));
        }
        if !(smoothing >= 0.0 && smoothing.is_finite()) {
            return Err(HeightMapError::Smoothing(smoothing));
        }
        if samples.z.iter().any(|z| !z.is_finite()) {
            return Err(HeightMapError::NotFinite);
        }
        let (hx, hy) = (w / nx as f64, h / ny as f64);
        let lambda = |spacing: f64| {
            let l = (smoothing / (std::f64::consts::TAU * spacing)).powi(6);
            l.max(Self::MIN_LAMBDA)
        };
        let coef = fit_grid(
            samples,
            Penalty {
                along_x: lambda(hx),
                along_y: lambda(hy),
            },
        );
        let mut map = HeightMap {
            coef,
            stride: nx + 2,
            x0: -w / 2.0 + hx / 2.0,
            y0: h / 2.0 - hy / 2.0,
            hx,
            hy,
            cells: (nx - 1, ny - 1),
            extent: samples.extent,
            smoothing,
            max_deviation: 0.0,
        };
        map.max_deviation = map.deviation_from(samples);
        Ok(map)
    }

    /// The largest |h − sample| over the samples (mm).
    fn deviation_from(&self, samples: &HeightSamples) -> f64 {
        (0..samples.rows)
            .into_par_iter()
            .map(|j| {
                let y = self.y0 - j as f64 * self.hy;
                (0..samples.columns)
                    .map(|i| {
                        let x = self.x0 + i as f64 * self.hx;
                        (self.value(x, y) - samples.z[j * samples.columns + i]).abs()
                    })
                    .fold(0.0, f64::max)
            })
            .reduce(|| 0.0, f64::max)
    }

    /// The samples' extent (mm), centred on the origin.
    pub fn extent(&self) -> (f64, f64) {
        self.extent
    }

    /// The smoothing it was fitted with (mm).
    pub fn smoothing(&self) -> f64 {
        self.smoothing
    }

    /// The fit's largest deviation from its samples (mm).
    pub fn max_deviation(&self) -> f64 {
        self.max_deviation
    }

    /// The spacing of its samples along x and y (mm).
    pub fn spacing(&self) -> (f64, f64) {
        (self.hx, self.hy)
    }

    /// The cell holding coordinate `s` (in samples from the first) and the
    /// fraction into it; outside the samples, the outermost cell and a
    /// fraction beyond [0, 1].
    fn cell(s: f64, cells: usize) -> (usize, f64) {
        let i = if s > 0.0 { s as usize } else { 0 }.min(cells - 1);
        (i, s - i as f64)
    }

    /// The four coefficients' weights at `t` and their first and second
    /// derivatives in t. Beyond the samples (t outside [0, 1] in an
    /// outermost cell) the weights go on as their second-order Taylor
    /// expansion at the edge: the surface is continued as a quadratic, C²
    /// at the edge, and a cubic's growth (of the samples' noise, say) is not
    /// extrapolated.
    fn basis(t: f64) -> [[f64; 4]; 3] {
        let edge = t.clamp(0.0, 1.0);
        let [b, db, ddb] = Self::cubic_basis(edge);
        if edge == t {
            return [b, db, ddb];
        }
        let dt = t - edge;
        [
            std::array::from_fn(|k| b[k] + db[k] * dt + 0.5 * ddb[k] * dt * dt),
            std::array::from_fn(|k| db[k] + ddb[k] * dt),
            ddb,
        ]
    }

    /// The uniform cubic B-spline's four weights at `t` ∈ [0, 1], and their
    /// first and second derivatives.
    fn cubic_basis(t: f64) -> [[f64; 4]; 3] {
        let (t2, t3) = (t * t, t * t * t);
        let u = 1.0 - t;
        [
            [
                u * u * u / 6.0,
                (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
                (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
                t3 / 6.0,
            ],
            [
                -u * u / 2.0,
                (3.0 * t2 - 4.0 * t) / 2.0,
                (-3.0 * t2 + 2.0 * t + 1.0) / 2.0,
                t2 / 2.0,
            ],
            [u, 3.0 * t - 2.0, -3.0 * t + 1.0, t],
        ]
    }

    /// Where (x, y) falls: the first coefficient's index, and the x and y
    /// weights with their derivatives (per mm).
    fn weights(&self, x: f64, y: f64) -> (usize, [[f64; 4]; 3], [[f64; 4]; 3]) {
        let (i, tx) = Self::cell((x - self.x0) / self.hx, self.cells.0);
        // rows run down the image: y decreases with the row
        let (j, ty) = Self::cell((self.y0 - y) / self.hy, self.cells.1);
        let (mut bx, mut by) = (Self::basis(tx), Self::basis(ty));
        for (order, b) in bx.iter_mut().enumerate() {
            b.iter_mut().for_each(|w| *w /= self.hx.powi(order as i32));
        }
        for (order, b) in by.iter_mut().enumerate() {
            // d/dy = −d/dt / hy
            let scale = (-self.hy).powi(order as i32);
            b.iter_mut().for_each(|w| *w /= scale);
        }
        (j * self.stride + i, bx, by)
    }

    /// h(x, y).
    pub fn value(&self, x: f64, y: f64) -> f64 {
        let (first, bx, by) = self.weights(x, y);
        (0..4)
            .map(|r| {
                let row = &self.coef[first + r * self.stride..][..4];
                by[0][r] * (0..4).map(|c| bx[0][c] * row[c]).sum::<f64>()
            })
            .sum()
    }

    /// [h, hx, hy, hxx, hxy, hyy] at (x, y).
    pub fn eval(&self, x: f64, y: f64) -> [f64; 6] {
        let (first, bx, by) = self.weights(x, y);
        let mut out = [0.0; 6];
        for (r, ((w, dw), ddw)) in by[0].iter().zip(by[1]).zip(by[2]).enumerate() {
            let row = &self.coef[first + r * self.stride..][..4];
            // along x: the row's value and its first and second x-derivatives
            let along = |order: usize| (0..4).map(|c| bx[order][c] * row[c]).sum::<f64>();
            let (v, vx, vxx) = (along(0), along(1), along(2));
            out[0] += w * v;
            out[1] += w * vx;
            out[2] += dw * v;
            out[3] += w * vxx;
            out[4] += dw * vx;
            out[5] += ddw * v;
        }
        out
    }

    /// (hx, hy) at (x, y).
    pub fn gradient(&self, x: f64, y: f64) -> (f64, f64) {
        let [_, hx, hy, ..] = self.eval(x, y);
        (hx, hy)
    }
}

/// The P-spline's penalty weights λ along x (on the rows) and along y (on
/// the columns).
#[derive(Clone, Copy, Debug)]
struct Penalty {
    along_x: f64,
    along_y: f64,
}

/// The coefficients of `samples`' fit, rows first, then columns.
fn fit_grid(samples: &HeightSamples, penalty: Penalty) -> Vec<f64> {
    let (nx, ny) = (samples.columns, samples.rows);
    let along_x = Banded::p_spline(nx, penalty.along_x);
    // each row of samples → nx + 2 coefficients
    let rows: Vec<Vec<f64>> = samples
        .z
        .par_chunks(nx)
        .map(|row| along_x.fit(row))
        .collect();
    let along_y = Banded::p_spline(ny, penalty.along_y);
    // each column of those → ny + 2 coefficients
    let columns: Vec<Vec<f64>> = (0..nx + 2)
        .into_par_iter()
        .map(|c| {
            let column: Vec<f64> = rows.iter().map(|r| r[c]).collect();
            along_y.fit(&column)
        })
        .collect();
    let stride = nx + 2;
    let mut coef = vec![0.0; (ny + 2) * stride];
    for (c, column) in columns.iter().enumerate() {
        for (r, &v) in column.iter().enumerate() {
            coef[r * stride + c] = v;
        }
    }
    coef
}

/// The normal equations of a one-dimensional P-spline fit, factored:
/// (BᵀB + λ DᵀD) c = Bᵀ y for n samples, n + 2 coefficients, B the cubic
/// B-spline's values at the samples (1/6, 4/6, 1/6) and D the third
/// differences. Symmetric, positive definite (n ≥ 3, λ > 0) and banded
/// (three off the diagonal): a banded Cholesky factor, lower, row-major.
struct Banded {
    n: usize,
    /// `l[i][k]`: L(i, i − 3 + k), k = 0..4 (the diagonal last).
    l: Vec<[f64; 4]>,
}

impl Banded {
    const BAND: usize = 3;

    fn p_spline(samples: usize, lambda: f64) -> Banded {
        let n = samples + 2;
        // A(i, j) for |i − j| ≤ 3, stored as a[i][j − i + 3]
        let mut a = vec![[0.0f64; 7]; n];
        let b = [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0];
        for s in 0..samples {
            for p in 0..3 {
                for q in 0..3 {
                    a[s + p][q + 3 - p] += b[p] * b[q];
                }
            }
        }
        let d = [-1.0, 3.0, -3.0, 1.0];
        for s in 0..n.saturating_sub(3) {
            for p in 0..4 {
                for q in 0..4 {
                    a[s + p][q + 3 - p] += lambda * d[p] * d[q];
                }
            }
        }
        Banded::cholesky(&a)
    }

    fn cholesky(a: &[[f64; 7]]) -> Banded {
        let n = a.len();
        let mut l = vec![[0.0f64; 4]; n];
        for i in 0..n {
            for k in 0..=Self::BAND {
                // column j = i − 3 + k
                let Some(j) = (i + k).checked_sub(Self::BAND) else {
                    continue;
                };
                let mut sum = a[i][j + 3 - i];
                for m in j
                    .saturating_sub(Self::BAND)
                    .max(i.saturating_sub(Self::BAND))..j
                {
                    sum -= l[i][m + Self::BAND - i] * l[j][m + Self::BAND - j];
                }
                l[i][k] = if j == i {
                    sum.max(f64::MIN_POSITIVE).sqrt()
                } else {
                    sum / l[j][Self::BAND]
                };
            }
        }
        Banded { n, l }
    }

    /// The coefficients fitted to `y` (n − 2 samples).
    fn fit(&self, y: &[f64]) -> Vec<f64> {
        let n = self.n;
        let b = [1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0];
        let mut x = vec![0.0; n];
        for (s, &v) in y.iter().enumerate() {
            for p in 0..3 {
                x[s + p] += b[p] * v;
            }
        }
        // L z = Bᵀy, then Lᵀ c = z
        for i in 0..n {
            let first = i.saturating_sub(Self::BAND);
            let sum: f64 = (first..i)
                .map(|j| self.l[i][j + Self::BAND - i] * x[j])
                .sum();
            x[i] = (x[i] - sum) / self.l[i][Self::BAND];
        }
        for i in (0..n).rev() {
            let last = (i + Self::BAND + 1).min(n);
            let sum: f64 = (i + 1..last)
                .map(|j| self.l[j][i + Self::BAND - j] * x[j])
                .sum();
            x[i] = (x[i] - sum) / self.l[i][Self::BAND];
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples of `f` on a `columns` × `rows` grid of pixel centres over
    /// `extent`.
    fn sampled(
        f: impl Fn(f64, f64) -> f64,
        (columns, rows): (usize, usize),
        extent: (f64, f64),
    ) -> HeightSamples {
        let (hx, hy) = (extent.0 / columns as f64, extent.1 / rows as f64);
        let z = (0..rows)
            .flat_map(|j| {
                let y = extent.1 / 2.0 - (j as f64 + 0.5) * hy;
                (0..columns).map(move |i| (-extent.0 / 2.0 + (i as f64 + 0.5) * hx, y))
            })
            .map(|(x, y)| f(x, y))
            .collect();
        HeightSamples {
            columns,
            rows,
            z,
            extent,
        }
    }

    /// A quadratic is in the penalty's null space: fitted at any
    /// smoothing, the spline is the quadratic, with its derivatives,
    /// inside the extent and beyond it.
    #[test]
    fn a_saddle_is_reproduced_exactly_with_its_derivatives() {
        let r = 60.0;
        let saddle = |x: f64, y: f64| (x * x - y * y) / (2.0 * r);
        for smoothing in [0.0, 2.0, 20.0] {
            let map = HeightMap::fit(&sampled(saddle, (41, 33), (64.0, 48.0)), smoothing).unwrap();
            assert!(map.max_deviation() < 1e-7, "{}", map.max_deviation());
            for (x, y) in [(0.0, 0.0), (13.7, -8.2), (-31.0, 23.0), (35.0, -27.0)] {
                let [h, hx, hy, hxx, hxy, hyy] = map.eval(x, y);
                let want = [saddle(x, y), x / r, -y / r, 1.0 / r, 0.0, -1.0 / r];
                for (got, want) in [h, hx, hy, hxx, hxy, hyy].iter().zip(want) {
                    assert!(
                        (got - want).abs() < 1e-7,
                        "({x}, {y}) at {smoothing}: {got} vs {want}"
                    );
                }
                assert!((map.value(x, y) - h).abs() < 1e-12);
            }
        }
    }

    /// Interpolating, the fit meets every sample; smoothing damps a ripple
    /// of half the smoothing's wavelength and keeps one of twice it.
    #[test]
    fn smoothing_damps_short_ripples_and_keeps_long_ones() {
        let ripple = |wl: f64| move |x: f64, _y: f64| (std::f64::consts::TAU * x / wl).sin();
        let grid = (129, 8);
        let extent = (64.0, 4.0);
        let exact = HeightMap::fit(&sampled(ripple(3.0), grid, extent), 0.0).unwrap();
        assert!(exact.max_deviation() < 1e-5, "{}", exact.max_deviation());
        let amplitude = |map: &HeightMap| {
            (0..400)
                .map(|k| map.value(-20.0 + 0.1 * k as f64, 0.0).abs())
                .fold(0.0, f64::max)
        };
        let short = HeightMap::fit(&sampled(ripple(3.0), grid, extent), 6.0).unwrap();
        let long = HeightMap::fit(&sampled(ripple(12.0), grid, extent), 6.0).unwrap();
        assert!(
            amplitude(&short) < 0.1,
            "short ripple kept {}",
            amplitude(&short)
        );
        assert!(
            amplitude(&long) > 0.9,
            "long ripple damped to {}",
            amplitude(&long)
        );
        assert!(short.max_deviation() > 0.9);
    }

    /// The derivatives are those of the value (central differences).
    #[test]
    fn derivatives_agree_with_differences() {
        let f = |x: f64, y: f64| (x / 5.0).sin() * (y / 7.0).cos() + 0.01 * x * y;
        let map = HeightMap::fit(&sampled(f, (64, 48), (40.0, 30.0)), 0.0).unwrap();
        let e = 1e-4;
        for (x, y) in [(1.3, 2.1), (-12.0, 9.5), (15.2, -11.0)] {
            let [_, hx, hy, hxx, hxy, hyy] = map.eval(x, y);
            let d = |fx: &dyn Fn(f64, f64) -> f64, dx: f64, dy: f64| {
                (fx(x + dx, y + dy) - fx(x - dx, y - dy)) / (2.0 * e)
            };
            let v = |x: f64, y: f64| map.value(x, y);
            let gx = |x: f64, y: f64| map.eval(x, y)[1];
            let gy = |x: f64, y: f64| map.eval(x, y)[2];
            for (got, want) in [
                (hx, d(&v, e, 0.0)),
                (hy, d(&v, 0.0, e)),
                (hxx, d(&gx, e, 0.0)),
                (hxy, d(&gx, 0.0, e)),
                (hyy, d(&gy, 0.0, e)),
            ] {
                assert!((got - want).abs() < 1e-5, "({x}, {y}): {got} vs {want}");
            }
        }
    }

    #[test]
    fn too_few_or_bad_samples_are_refused() {
        let flat = |_: f64, _: f64| 0.0;
        assert!(matches!(
            HeightMap::fit(&sampled(flat, (1, 1), (10.0, 10.0)), 0.0),
            Err(HeightMapError::TooFew { .. })
        ));
        let mut s = sampled(flat, (8, 8), (10.0, 10.0));
        s.z[5] = f64::NAN;
        assert_eq!(
            HeightMap::fit(&s, 0.0).unwrap_err(),
            HeightMapError::NotFinite
        );
        let s = sampled(flat, (8, 8), (10.0, 10.0));
        assert!(matches!(
            HeightMap::fit(&s, -1.0),
            Err(HeightMapError::Smoothing(_))
        ));
    }

    /// Quantised heights are noise that an interpolating spline turns into
    /// curvature (0.018/mm on a 16-bit saddle at 0.25 mm spacing, against
    /// its 0.0167/mm): the defaults smooth 16-bit maps over 8 pixels and
    /// 8-bit ones over 24, which bring the curvature within a few percent.
    #[test]
    fn the_default_smoothing_quiets_quantised_heights() {
        let (n, s, r) = (257usize, 64.0, 60.0);
        let (z_min, z_max) = (-8.6, 8.6);
        for (bits, pixels, inside, beyond) in [(16, 8.0, 1e-3, 0.02), (8, 24.0, 5e-3, 0.06)] {
            let levels = if bits == 16 { 65535.0 } else { 255.0 };
            let quantised = |x: f64, y: f64| {
                let v = ((x * x - y * y) / (2.0 * r) - z_min) / (z_max - z_min);
                z_min + (z_max - z_min) * (v * levels).round() / levels
            };
            let samples = sampled(quantised, (n, n), (s, s));
            let map = HeightMap::fit(&samples, pixels * s / n as f64).unwrap();
            let mut worst = [0.0f64; 2];
            for k in 0..4000 {
                let x = -34.0 + 68.0 * ((k * 37) % 4000) as f64 / 4000.0;
                let y = -34.0 + 68.0 * k as f64 / 4000.0;
                let [_, _, _, hxx, hxy, hyy] = map.eval(x, y);
                let off = (hxx - 1.0 / r)
                    .abs()
                    .max(hxy.abs())
                    .max((hyy + 1.0 / r).abs());
                let slot = usize::from(x.abs().max(y.abs()) > 30.0);
                worst[slot] = worst[slot].max(off);
            }
            assert!(
                worst[0] < inside && worst[1] < beyond,
                "{bits} bit over {pixels} px: curvature off by {worst:?}/mm"
            );
        }
    }
}
