//! A regular grid of samples with Catmull-Rom bicubic interpolation (C¹):
//! the sampled elevation profile's grid and the view compensation's.

use glam::DVec2;

/// Values at the nodes `origin + (i, j)·spacing`, i < nx, j < ny, row-major,
/// read by Catmull-Rom interpolation. Beyond the border the interpolant runs
/// flat (the stencil's node past it is mirrored about it).
#[derive(Clone, Debug)]
pub struct CubicGrid {
    pub(crate) origin: DVec2,
    pub(crate) spacing: f64,
    pub(crate) nx: usize,
    pub(crate) ny: usize,
    pub(crate) values: Vec<f64>,
}

/// Where (x, y) falls in a [`CubicGrid`]: the stencil's
/// corner (i − 1, j − 1), whether it lies wholly inside the grid, and the
/// Catmull-Rom weights and their derivatives along x and y.
struct Stencil {
    i: usize,
    j: usize,
    interior: bool,
    wx: [f64; 4],
    dx: [f64; 4],
    wy: [f64; 4],
    dy: [f64; 4],
}

pub(crate) fn catmull_rom(t: f64) -> ([f64; 4], [f64; 4]) {
    let (t2, t3) = (t * t, t * t * t);
    let w = [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ];
    let d = [
        0.5 * (-3.0 * t2 + 4.0 * t - 1.0),
        0.5 * (9.0 * t2 - 10.0 * t),
        0.5 * (-9.0 * t2 + 8.0 * t + 1.0),
        0.5 * (3.0 * t2 - 2.0 * t),
    ];
    (w, d)
}

impl CubicGrid {
    /// The grid of `values` (row-major, `nx × ny`, at least 2 × 2) at
    /// nodes `origin + (i, j)·spacing`.
    pub fn new(origin: DVec2, spacing: f64, nx: usize, ny: usize, values: Vec<f64>) -> Self {
        assert!(
            nx >= 2 && ny >= 2 && values.len() == nx * ny,
            "a grid of at least 2 × 2 nodes"
        );
        CubicGrid {
            origin,
            spacing,
            nx,
            ny,
            values,
        }
    }

    /// Grid spacing (mm).
    pub fn spacing(&self) -> f64 {
        self.spacing
    }

    /// The node values, row-major.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The grid value at node (i, j), the stencil's one node beyond the
    /// border mirrored about it: the interpolant's slope across the border
    /// is then 0, as it is beyond, where the border value holds. A clamped
    /// node left a kink there, which a base reaching past the grid (a deep
    /// base under a steep slope: found-14a20941fd0557ea, 4.6 mm past the
    /// layout) bent over within one row: 2.7 times the tolerance.
    pub(crate) fn at(&self, i: isize, j: isize) -> f64 {
        let mirrored = |k: isize, n: usize| {
            let last = n as isize - 1;
            let k = if k < 0 {
                -k
            } else if k > last {
                2 * last - k
            } else {
                k
            };
            k.clamp(0, last) as usize
        };
        self.values[mirrored(j, self.ny) * self.nx + mirrored(i, self.nx)]
    }

    /// The value and its gradient at (x, y) by Catmull-Rom interpolation (C¹).
    pub fn eval(&self, x: f64, y: f64) -> (f64, DVec2) {
        let s = self.stencil(x, y);
        let (mut e, mut ex, mut ey) = (0.0, 0.0, 0.0);
        for b in 0..4 {
            let row = self.stencil_row(&s, b);
            let (mut r, mut rd) = (0.0, 0.0);
            for ((w, d), v) in s.wx.iter().zip(s.dx).zip(row) {
                r += w * v;
                rd += d * v;
            }
            e += s.wy[b] * r;
            ex += s.wy[b] * rd;
            ey += s.dy[b] * r;
        }
        (e, DVec2::new(ex, ey) / self.spacing)
    }

    /// The value at (x, y), as [`CubicGrid::eval`] gives it, without the
    /// gradient.
    pub fn value(&self, x: f64, y: f64) -> f64 {
        let s = self.stencil(x, y);
        let mut e = 0.0;
        for b in 0..4 {
            let row = self.stencil_row(&s, b);
            let mut r = 0.0;
            for (w, v) in s.wx.iter().zip(row) {
                r += w * v;
            }
            e += s.wy[b] * r;
        }
        e
    }

    /// The 4 × 4 Catmull-Rom stencil around (x, y). Inlined: it runs
    /// once per evaluation, millions of times a run (the base creases'
    /// Newton solves), and as a call it cost a third of the evaluation.
    #[inline(always)]
    fn stencil(&self, x: f64, y: f64) -> Stencil {
        let fx = ((x - self.origin.x) / self.spacing).clamp(0.0, (self.nx - 1) as f64);
        let fy = ((y - self.origin.y) / self.spacing).clamp(0.0, (self.ny - 1) as f64);
        // fx, fy ≥ 0, so truncation is floor (and avoids a libm call)
        let (i, j) = (
            (fx as usize).min(self.nx - 2),
            (fy as usize).min(self.ny - 2),
        );
        let (wx, dx) = catmull_rom(fx - i as f64);
        let (wy, dy) = catmull_rom(fy - j as f64);
        Stencil {
            i,
            j,
            interior: i >= 1 && j >= 1 && i + 2 < self.nx && j + 2 < self.ny,
            wx,
            dx,
            wy,
            dy,
        }
    }

    /// Row `b` of the stencil's values: in the interior a slice of the
    /// grid, at the border clamped to it.
    #[inline(always)]
    fn stencil_row(&self, s: &Stencil, b: usize) -> [f64; 4] {
        if s.interior {
            let start = (s.j - 1 + b) * self.nx + s.i - 1;
            return self.values[start..start + 4].try_into().unwrap();
        }
        std::array::from_fn(|a| {
            self.at(s.i as isize - 1 + a as isize, s.j as isize - 1 + b as isize)
        })
    }
}
