//! Elevation profiles e(x, y) ∈ [0, 1] over the layout (METHOD §4).
//!
//! Profiles are evaluated in centred layout coordinates and must be C¹:
//! the base creases solve `u − E(u, v) = kT` with Newton, and the base lens
//! surfaces inherit e's smoothness. Sampled profiles use Catmull-Rom bicubic
//! interpolation, which is C¹.

use crate::grid::{catmull_rom, CubicGrid};
use glam::DVec2;

/// A grey image handed to the kernel: luminance in [0, 1], composited over
/// white where the source had alpha (so transparent = white), row 0 at the top.
#[derive(Clone, Debug)]
pub struct Raster {
    pub width: usize,
    pub height: usize,
    pub luminance: Vec<f32>,
}

/// How an image becomes an elevation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProfileMode {
    /// e = luminance (bright is high).
    Gray,
    /// Bilevel shape: dark pixels (luminance < threshold) are the shape.
    /// e = 0.5 on its outline, rising to 1 at its deepest point and falling to
    /// 0 at the same distance outside, so level lines run parallel to the outline.
    Shape { threshold: f64 },
}

/// The elevation profile.
#[derive(Clone, Debug)]
pub enum Profile {
    /// e ≡ 0: an unshifted base.
    Flat,
    /// Concentric rings: e = ½ − ½ cos(2πρ/λ), ρ from the layout centre.
    Rings { wavelength: f64 },
    /// Linear ramp along direction `angle` (rad from +x), 0 to 1 across the layout.
    Ramp { angle: f64, length: f64 },
    /// Gaussian bump e = exp(−ρ²/2σ²) at the layout centre.
    Bump { sigma: f64 },
    /// An image, fitted into the layout, blurred and resampled.
    Sampled(SampledProfile),
}

impl Profile {
    /// A ramp across a layout of size `width × height` along `angle`.
    pub fn ramp(angle: f64, width: f64, height: f64) -> Profile {
        let length = width * angle.cos().abs() + height * angle.sin().abs();
        Profile::Ramp { angle, length }
    }

    /// The smallest length (mm) over which the elevation can bend: a
    /// survey of the base must sample finer than this to see its
    /// curvature. `None` for a profile with no such scale (flat, ramp).
    pub fn detail_mm(&self) -> Option<f64> {
        match self {
            Profile::Flat | Profile::Ramp { .. } => None,
            Profile::Rings { wavelength } => Some(wavelength / 4.0),
            Profile::Bump { sigma } => Some(*sigma),
            // the grid is as fine as the image and half the blur; its
            // cubic interpolation bends over a few cells. A grid coarser
            // than that (a large layout's 1024 cells, or the cell budget)
            // leaves the blur no room: the image's edges bend within one
            // cell (found-a0544021cc9fde75: 0.22 mm cells, blur 0.07 mm,
            // creases bending over 0.4 mm)
            Profile::Sampled(s) if s.blur < 2.0 * s.spacing() => Some(0.5 * s.spacing()),
            Profile::Sampled(s) => Some(2.0 * s.spacing()),
        }
    }

    /// The longest survey cell (mm) whose second differences still see the
    /// profile's curvature (see the base survey in the mesher): half its
    /// detail for a procedural profile; for an image, twice its grid's
    /// detail (finer than its blur lets it bend), and where the grid
    /// resolves the blur, at most half the blur, over which a blurred edge
    /// bends as a bump of that σ does (found-f27b41facbe9d15f: σ = 0.135
    /// mm at two grid cells, survey cells of 0.126 mm saw too little of its
    /// creases' curvature, and the rows missed the tolerance by 3 %). A
    /// blur finer than the grid bends nothing the grid's own detail does
    /// not. `None` where [`Self::detail_mm`] is.
    pub fn coarsest_survey_cell_mm(&self) -> Option<f64> {
        let detail = self.detail_mm()?;
        Some(match self {
            Profile::Sampled(s) if s.blur >= 2.0 * s.spacing() => (2.0 * detail).min(0.5 * s.blur),
            Profile::Sampled(_) => 2.0 * detail,
            _ => 0.5 * detail,
        })
    }

    /// e(x, y).
    pub fn value(&self, x: f64, y: f64) -> f64 {
        match self {
            Profile::Flat => 0.0,
            Profile::Rings { wavelength } => {
                0.5 - 0.5 * (std::f64::consts::TAU * x.hypot(y) / wavelength).cos()
            }
            Profile::Ramp { angle, length } => 0.5 + (x * angle.cos() + y * angle.sin()) / length,
            Profile::Bump { sigma } => (-(x * x + y * y) / (2.0 * sigma * sigma)).exp(),
            Profile::Sampled(s) => s.value(x, y),
        }
    }

    /// (e, ∇e) at (x, y).
    pub fn value_grad(&self, x: f64, y: f64) -> (f64, DVec2) {
        match self {
            Profile::Flat => (0.0, DVec2::ZERO),
            Profile::Rings { wavelength } => {
                let rho = x.hypot(y);
                let k = std::f64::consts::TAU / wavelength;
                let e = 0.5 - 0.5 * (k * rho).cos();
                if rho == 0.0 {
                    return (e, DVec2::ZERO);
                }
                // d/dρ = ½ k sin(kρ); sin(kρ)/ρ is smooth at 0
                let g = 0.5 * k * (k * rho).sin() / rho;
                (e, DVec2::new(g * x, g * y))
            }
            Profile::Ramp { angle, length } => {
                let d = DVec2::new(angle.cos(), angle.sin()) / *length;
                (self.value(x, y), d)
            }
            Profile::Bump { sigma } => {
                let e = self.value(x, y);
                (e, DVec2::new(-x, -y) * (e / (sigma * sigma)))
            }
            Profile::Sampled(s) => s.eval(x, y),
        }
    }

    /// Largest |∂e/∂x| anywhere (1/mm) and where: it limits the base shift
    /// (METHOD §4, φ must increase with u).
    pub fn max_slope_x(&self, half_w: f64, half_h: f64) -> (f64, DVec2) {
        match self {
            Profile::Flat => (0.0, DVec2::ZERO),
            Profile::Rings { wavelength } => (
                std::f64::consts::PI / wavelength,
                DVec2::new(wavelength / 4.0, 0.0),
            ),
            Profile::Ramp { angle, length } => (angle.cos().abs() / length, DVec2::ZERO),
            Profile::Bump { sigma } => (
                1.0 / (sigma * std::f64::consts::E.sqrt()),
                DVec2::new(*sigma, 0.0),
            ),
            Profile::Sampled(s) => s.max_slope_x(half_w, half_h),
        }
    }
}

/// A regular grid of elevation values with Catmull-Rom interpolation.
#[derive(Clone, Debug)]
pub struct SampledProfile {
    grid: CubicGrid,
    /// The Gaussian blur's σ (mm) the values were smoothed with.
    blur: f64,
}

/// Most grid cells a sampled profile holds (4 M: 32 MB of values).
pub const MAX_PROFILE_CELLS: usize = 1 << 22;
/// Grid cells per blur σ, at most: the blurred field bends over σ, and on a
/// grid of σ/32 Catmull-Rom follows a blurred edge to about 1e-5 of its
/// height, so finer cells would only cost time.
const BLUR_CELLS_PER_SIGMA: f64 = 32.0;
/// Samples per side of a grid cell, at most, when a cell is wider than an
/// image pixel.
const MAX_SUBSAMPLES: usize = 8;

impl SampledProfile {
    /// Fits `raster` into the layout `width × height` (mm) keeping its aspect
    /// ratio (centred, "contain"), turns it into an elevation by `mode`,
    /// blurs it with a Gaussian of σ = `blur` mm and keeps a grid fine enough
    /// for both the image and the blur. Outside the image the border repeats.
    /// Errors are plain messages; the caller names the parameter. The grid
    /// holds at most [`MAX_PROFILE_CELLS`] cells.
    pub fn from_raster(
        raster: &Raster,
        mode: ProfileMode,
        invert: bool,
        blur: f64,
        width: f64,
        height: f64,
    ) -> Result<Self, String> {
        Self::reaching(raster, (mode, invert, blur), (width, height), 0.0)
    }

    /// [`Self::from_raster`], its grid reaching at least `reach` (mm) past
    /// the layout on every side: a design's base reads the elevation over
    /// its margin ([`crate::Design::margin`]), and past the grid the border
    /// value holds, a kink the base would bend over within a row
    /// (found-14a20941fd0557ea: a deep base under a 36° slope reading 4.6
    /// mm past a grid that held 4.8 mm of blur margin, 2.7 times the
    /// tolerance off).
    pub fn reaching(
        raster: &Raster,
        (mode, invert, blur): (ProfileMode, bool, f64),
        (width, height): (f64, f64),
        reach: f64,
    ) -> Result<Self, String> {
        Self::with_blur_cells(
            raster,
            (mode, invert, blur),
            (width, height, reach),
            BLUR_CELLS_PER_SIGMA,
        )
    }

    /// [`Self::reaching`] with at most `cells_per_sigma` grid cells per
    /// blur σ.
    fn with_blur_cells(
        raster: &Raster,
        (mode, invert, blur): (ProfileMode, bool, f64),
        (width, height, reach): (f64, f64, f64),
        cells_per_sigma: f64,
    ) -> Result<Self, String> {
        if raster.width == 0 || raster.height == 0 {
            return Err("the image is empty".into());
        }
        let px = (width / raster.width as f64).min(height / raster.height as f64); // mm per pixel
                                                                                   // as fine as the image and half the blur, but no finer than the
                                                                                   // blurred field needs (a blur far wider than the pixels would
                                                                                   // otherwise cost 6σ/spacing kernel taps per cell: seconds)
        let mut spacing = if blur > 0.0 {
            px.min(blur / 2.0).max(blur / cells_per_sigma)
        } else {
            px
        };
        spacing = spacing.max(width.max(height) / 1024.0);
        // the grid with its blur margin: a blur far wider than a small
        // layout would ask for billions of cells, so the spacing grows
        // until the grid holds at most MAX_PROFILE_CELLS
        let grid = |spacing: f64| {
            let margin = (3.0 * blur + 4.0 * spacing).max(reach + 2.0 * spacing);
            let nx = ((width + 2.0 * margin) / spacing).ceil() as usize + 1;
            let ny = ((height + 2.0 * margin) / spacing).ceil() as usize + 1;
            (margin, nx, ny)
        };
        let (mut margin, mut nx, mut ny) = grid(spacing);
        while nx.saturating_mul(ny) > MAX_PROFILE_CELLS {
            spacing *= (nx as f64 * ny as f64 / MAX_PROFILE_CELLS as f64).sqrt() * 1.01;
            (margin, nx, ny) = grid(spacing);
        }
        let origin = DVec2::new(-width / 2.0 - margin, -height / 2.0 - margin);
        // Bilinear samples in pixel-centre coordinates, border clamped. A
        // cell wider than a pixel takes the mean of m × m samples spread
        // over it (a box filter), so pixels between the cell centres still
        // count; a cell no wider than a pixel takes the one sample. The
        // grid of samples is a product of columns and rows, so each
        // column's and row's pixel pair and weight is worked out once.
        let m = ((spacing / px).ceil() as usize).clamp(1, MAX_SUBSAMPLES);
        let offset = |k: usize| ((k as f64 + 0.5) / m as f64 - 0.5) * spacing;
        let taps = |count: usize, start: f64, pixels: usize, to_pixel: &dyn Fn(f64) -> f64| {
            let mut taps = Vec::with_capacity(count * m);
            for c in 0..count {
                let centre = start + c as f64 * spacing;
                for k in 0..m {
                    let at = if m == 1 { centre } else { centre + offset(k) };
                    let f = to_pixel(at).clamp(0.0, (pixels - 1) as f64);
                    let lo = f.floor() as usize;
                    taps.push((lo, (lo + 1).min(pixels - 1), f - lo as f64));
                }
            }
            taps
        };
        let (w, h) = (raster.width, raster.height);
        let columns = taps(nx, origin.x, w, &|x| x / px + w as f64 / 2.0 - 0.5);
        let rows = taps(ny, origin.y, h, &|y| h as f64 / 2.0 - y / px - 0.5);
        let lum = &raster.luminance;
        let mut values = vec![0.0; nx * ny];
        {
            use rayon::prelude::*;
            values.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
                let row_taps = &rows[j * m..(j + 1) * m];
                for (i, v) in row.iter_mut().enumerate() {
                    let mut sum = 0.0;
                    for &(j0, j1, ty) in row_taps {
                        let (r0, r1) = (&lum[j0 * w..(j0 + 1) * w], &lum[j1 * w..(j1 + 1) * w]);
                        for &(i0, i1, tx) in &columns[i * m..(i + 1) * m] {
                            let top = r0[i0] as f64 * (1.0 - tx) + r0[i1] as f64 * tx;
                            let bot = r1[i0] as f64 * (1.0 - tx) + r1[i1] as f64 * tx;
                            let sample = top * (1.0 - ty) + bot * ty;
                            if m == 1 {
                                sum = sample;
                            } else {
                                sum += sample;
                            }
                        }
                    }
                    let l = if m == 1 { sum } else { sum / (m * m) as f64 };
                    *v = if invert { 1.0 - l } else { l };
                }
            });
        }
        if let ProfileMode::Shape { threshold } = mode {
            let inside: Vec<bool> = values.iter().map(|&l| l < threshold).collect();
            if !inside.iter().any(|&b| b) {
                return Err(format!(
                    "no pixel is darker than the threshold {threshold}: the shape is empty"
                ));
            }
            if inside.iter().all(|&b| b) {
                return Err(format!("every pixel is darker than the threshold {threshold}: the shape has no outline"));
            }
            let d_out = distance_transform(nx, ny, &inside); // distance of outside cells to the shape
            let not_inside: Vec<bool> = inside.iter().map(|b| !b).collect();
            let d_in = distance_transform(nx, ny, &not_inside);
            let signed: Vec<f64> = (0..nx * ny)
                .map(|c| if inside[c] { d_in[c] - 0.5 } else { 0.5 - d_out[c] } * spacing)
                .collect();
            let depth = signed.iter().cloned().fold(0.0, f64::max);
            for (v, s) in values.iter_mut().zip(&signed) {
                *v = (0.5 + s / (2.0 * depth)).clamp(0.0, 1.0);
            }
        }
        if blur > 0.0 {
            gaussian_blur(&mut values, nx, ny, blur / spacing);
        }
        Ok(SampledProfile {
            grid: CubicGrid::new(origin, spacing, nx, ny, values),
            blur,
        })
    }

    /// Grid spacing (mm).
    pub fn spacing(&self) -> f64 {
        self.grid.spacing
    }

    /// The grid of e.
    pub fn grid(&self) -> &CubicGrid {
        &self.grid
    }

    /// (e, ∇e) at (x, y) by Catmull-Rom interpolation (C¹).
    pub fn eval(&self, x: f64, y: f64) -> (f64, DVec2) {
        self.grid.eval(x, y)
    }

    /// e at (x, y), as [`SampledProfile::eval`] gives it, without the
    /// gradient (a frame's elevation phase per pixel).
    pub fn value(&self, x: f64, y: f64) -> f64 {
        self.grid.value(x, y)
    }

    fn max_slope_x(&self, half_w: f64, half_h: f64) -> (f64, DVec2) {
        use rayon::prelude::*;
        let g = &self.grid;
        // On a grid row the interpolant is a 1-D Catmull-Rom spline in x, whose
        // derivative is piecewise quadratic: sampling at nodes and half-cells
        // finds its maximum to within a few per cent for a blurred profile;
        // the steepness rule keeps a 10 % margin.
        let col = |x: f64| ((x - g.origin.x) / g.spacing).clamp(0.0, (g.nx - 1) as f64);
        let row = |y: f64| ((y - g.origin.y) / g.spacing).clamp(0.0, (g.ny - 1) as f64);
        let (i0, i1) = (col(-half_w).floor() as usize, col(half_w).ceil() as usize);
        let (j0, j1) = (row(-half_h).floor() as usize, row(half_h).ceil() as usize);
        let (_, d_half) = catmull_rom(0.5);
        (j0..=j1)
            .into_par_iter()
            .map(|j| {
                let mut best = (0.0, DVec2::ZERO);
                let y = g.origin.y + j as f64 * g.spacing;
                for i in i0..i1.min(g.nx - 1) {
                    let v = |a: isize| g.at(i as isize + a, j as isize);
                    let at_node = (v(1) - v(-1)) / (2.0 * g.spacing);
                    let at_half = (d_half[0] * v(-1)
                        + d_half[1] * v(0)
                        + d_half[2] * v(1)
                        + d_half[3] * v(2))
                        / g.spacing;
                    for (slope, off) in [(at_node.abs(), 0.0), (at_half.abs(), 0.5)] {
                        if slope > best.0 {
                            best = (
                                slope,
                                DVec2::new(g.origin.x + (i as f64 + off) * g.spacing, y),
                            );
                        }
                    }
                }
                best
            })
            .reduce(
                || (0.0, DVec2::ZERO),
                |a, b| {
                    if b.0 > a.0 || (b.0 == a.0 && (b.1.y, b.1.x) < (a.1.y, a.1.x)) {
                        b
                    } else {
                        a
                    }
                },
            )
    }
}

/// Exact Euclidean distance (in cells) from every cell to the nearest cell
/// where `target` is true (Felzenszwalb & Huttenlocher 2012).
fn distance_transform(nx: usize, ny: usize, target: &[bool]) -> Vec<f64> {
    const INF: f64 = 1e20;
    let mut d: Vec<f64> = target.iter().map(|&t| if t { 0.0 } else { INF }).collect();
    let mut buf_f = vec![0.0; nx.max(ny)];
    let mut buf_d = vec![0.0; nx.max(ny)];
    for i in 0..nx {
        for j in 0..ny {
            buf_f[j] = d[j * nx + i];
        }
        dt_1d(&buf_f[..ny], &mut buf_d[..ny]);
        for j in 0..ny {
            d[j * nx + i] = buf_d[j];
        }
    }
    for j in 0..ny {
        buf_f[..nx].copy_from_slice(&d[j * nx..(j + 1) * nx]);
        dt_1d(&buf_f[..nx], &mut buf_d[..nx]);
        d[j * nx..(j + 1) * nx].copy_from_slice(&buf_d[..nx]);
    }
    d.iter().map(|v| v.sqrt()).collect()
}

/// 1-D squared distance transform of sampled function `f` (lower envelope of parabolas).
fn dt_1d(f: &[f64], out: &mut [f64]) {
    let n = f.len();
    let mut v = vec![0usize; n];
    let mut z = vec![0.0f64; n + 1];
    let mut k = 0usize;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    let meet = |q: usize, p: usize| {
        ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64))
    };
    for q in 1..n {
        let mut s = meet(q, v[k]);
        while s <= z[k] {
            k -= 1;
            s = meet(q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, o) in out.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let dq = q as f64 - v[k] as f64;
        *o = dq * dq + f[v[k]];
    }
}

fn gaussian_blur(values: &mut [f64], nx: usize, ny: usize, sigma_cells: f64) {
    let radius = (3.0 * sigma_cells).ceil() as isize;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|k| (-(k * k) as f64 / (2.0 * sigma_cells * sigma_cells)).exp())
        .collect();
    let sum: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / sum).collect();
    // rows in parallel; each value sums its kernel taps in the same order
    // as a serial loop would, so the result does not depend on the threads.
    // Tap by tap over the whole row (a border-padded copy of it), like the
    // vertical pass: the same sums in the same order per value, but the
    // values of a row no longer wait on each other's additions, so the
    // loop runs vectorised.
    use rayon::prelude::*;
    let mut tmp = vec![0.0; values.len()];
    let r = radius as usize;
    tmp.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
        let src = &values[j * nx..(j + 1) * nx];
        let padded: Vec<f64> = (0..nx + 2 * r)
            .map(|p| src[p.saturating_sub(r).min(nx - 1)])
            .collect();
        for (t, w) in kernel.iter().enumerate() {
            for (out, v) in row.iter_mut().zip(&padded[t..t + nx]) {
                *out += w * v;
            }
        }
    });
    // the vertical pass row by row: whole source rows, read contiguously
    values.par_chunks_mut(nx).enumerate().for_each(|(j, row)| {
        row.fill(0.0);
        for (t, w) in kernel.iter().enumerate() {
            let jj = (j as isize + t as isize - radius).clamp(0, ny as isize - 1) as usize;
            for (out, v) in row.iter_mut().zip(&tmp[jj * nx..(jj + 1) * nx]) {
                *out += w * v;
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn disc_raster(n: usize, radius_px: f64) -> Raster {
        let mut lum = vec![1.0f32; n * n];
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (
                    i as f64 + 0.5 - n as f64 / 2.0,
                    j as f64 + 0.5 - n as f64 / 2.0,
                );
                if x.hypot(y) < radius_px {
                    lum[j * n + i] = 0.0;
                }
            }
        }
        Raster {
            width: n,
            height: n,
            luminance: lum,
        }
    }

    /// Past the grid's border the border value holds with no gradient, and
    /// the interpolant runs into it flat: its slope across the border cell
    /// falls to 0 at the border (a node clamped there left a kink), and a
    /// grid asked to reach past the layout does.
    #[test]
    fn past_the_grid_the_value_holds_without_a_kink() {
        let p = SampledProfile::reaching(
            &disc_raster(64, 20.0),
            // inverted, the shape is all but the disc: its depth, and e,
            // still grow at the grid's border
            (ProfileMode::Shape { threshold: 0.5 }, true, 0.5),
            (40.0, 30.0),
            12.0,
        )
        .unwrap();
        let edge = p.grid.origin.y;
        assert!(edge <= -15.0 - 12.0, "the grid reaches {edge}");
        let x = 3.0;
        let (held, g) = p.eval(x, edge - 5.0);
        assert_eq!(g.y, 0.0);
        assert_eq!(held, p.eval(x, edge).0);
        // one-sided slope into the border: shrinking with the distance
        let slope = |h: f64| (p.eval(x, edge + h).0 - p.eval(x, edge).0) / h;
        let (near, far) = (slope(1e-4 * p.spacing()), slope(p.spacing()));
        assert!(far.abs() > 1e-3, "e is flat at the border: {far}");
        assert!(near.abs() <= 1e-3 * far.abs(), "{near} against {far}");
    }

    #[test]
    fn gradients_match_finite_differences() {
        let sampled = SampledProfile::from_raster(
            &disc_raster(64, 20.0),
            ProfileMode::Gray,
            false,
            2.0,
            40.0,
            30.0,
        )
        .unwrap();
        let profiles = [
            Profile::Rings { wavelength: 9.0 },
            Profile::ramp(0.4, 40.0, 30.0),
            Profile::Bump { sigma: 6.0 },
            Profile::Sampled(sampled),
        ];
        let h = 1e-6;
        for p in &profiles {
            for &(x, y) in &[(0.0, 0.0), (3.3, -2.2), (-11.0, 7.7)] {
                let (_, g) = p.value_grad(x, y);
                let gx = (p.value(x + h, y) - p.value(x - h, y)) / (2.0 * h);
                let gy = (p.value(x, y + h) - p.value(x, y - h)) / (2.0 * h);
                assert!(
                    (g.x - gx).abs() < 1e-6 && (g.y - gy).abs() < 1e-6,
                    "{p:?} at {x},{y}: {g} vs {gx},{gy}"
                );
            }
        }
    }

    /// A blur far wider than the pixels runs on a grid of σ/32 whose cells
    /// average their pixels. It agrees with the blur on the pixels' own
    /// grid, and the blurred disc's centre keeps its closed form
    /// 1 − exp(−r²/2σ²) (the Gaussian's mass in the disc) to within what
    /// cutting the kernel at 3σ costs (3.4e-3 at r = 1.25σ).
    #[test]
    fn a_wide_blur_runs_on_a_coarser_grid_with_the_same_values() {
        // a 512 px disc of radius 5 mm in a 40 mm square (px = 0.078 mm)
        let raster = disc_raster(512, 64.0);
        let r: f64 = 5.0;
        for blur in [4.0, 12.0] {
            let build = |cells| {
                SampledProfile::with_blur_cells(
                    &raster,
                    (ProfileMode::Gray, true, blur),
                    (40.0, 40.0, 0.0),
                    cells,
                )
                .unwrap()
            };
            let (coarse, fine) = (build(BLUR_CELLS_PER_SIGMA), build(f64::INFINITY));
            assert!(coarse.spacing() >= 1.5 * fine.spacing());
            for (x, y) in [(0.0, 0.0), (5.0, 0.0), (-3.0, 4.0), (12.0, -7.0)] {
                let (c, f) = (coarse.eval(x, y).0, fine.eval(x, y).0);
                assert!((c - f).abs() < 1e-4, "blur {blur} at {x},{y}: {c} vs {f}");
            }
            let exact = 1.0 - (-r * r / (2.0 * blur * blur)).exp();
            let centre = coarse.eval(0.0, 0.0).0;
            assert!(
                (centre - exact).abs() < 4e-3,
                "blur {blur}: centre {centre} vs {exact}"
            );
        }
    }

    #[test]
    fn shape_mode_levels_follow_the_outline() {
        // A disc of radius 20 px in a 64 px image fitted to 64 mm: outline at ρ = 20 mm.
        let p = SampledProfile::from_raster(
            &disc_raster(64, 20.0),
            ProfileMode::Shape { threshold: 0.5 },
            false,
            0.0,
            64.0,
            64.0,
        )
        .unwrap();
        for &a in &[0.0f64, 0.7, 2.0, 4.0] {
            let on_outline = p.eval(20.0 * a.cos(), 20.0 * a.sin()).0;
            assert!((on_outline - 0.5).abs() < 0.04, "e on outline {on_outline}");
            let centre = p.eval(0.0, 0.0).0;
            assert!(centre > 0.95, "deepest point {centre}");
            let out = p.eval(30.0 * a.cos(), 30.0 * a.sin()).0;
            assert!((out - 0.25).abs() < 0.04, "10 mm outside: {out}");
        }
    }

    #[test]
    fn distance_transform_is_exact_on_a_point() {
        let (nx, ny) = (7, 5);
        let mut t = vec![false; nx * ny];
        t[2 * nx + 3] = true;
        let d = distance_transform(nx, ny, &t);
        for j in 0..ny {
            for i in 0..nx {
                let e = ((i as f64 - 3.0).powi(2) + (j as f64 - 2.0).powi(2)).sqrt();
                assert!((d[j * nx + i] - e).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn gray_image_fits_keeping_aspect() {
        // 2:1 image into a square layout: the image spans the width, half the height.
        let mut lum = vec![0.0f32; 20 * 10];
        for j in 0..10 {
            for i in 10..20 {
                lum[j * 20 + i] = 1.0;
            }
        }
        let p = SampledProfile::from_raster(
            &Raster {
                width: 20,
                height: 10,
                luminance: lum,
            },
            ProfileMode::Gray,
            false,
            0.0,
            40.0,
            40.0,
        )
        .unwrap();
        assert!(p.eval(-10.0, 0.0).0 < 0.01 && p.eval(10.0, 0.0).0 > 0.99);
        assert!(
            p.eval(10.0, 15.0).0 > 0.99,
            "border repeats beyond the image"
        );
    }
}
