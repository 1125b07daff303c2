//! A lens surface read directly: one rational quadratic across (three rows
//! of control points, Bézier knots), a clamped cubic B-spline along.
//! truck's general NURBS evaluation allocates its basis at every call; the
//! samples of the lens ends and the nearest-point presearch evaluate
//! thousands of points per lens.

use glam::{DVec3, DVec4};
use truck_modeling::{NurbsSurface, Vector4};

/// A surface's parameter ranges: across (t), along (v).
pub(crate) type Domain = ((f64, f64), (f64, f64));

/// A point of a lens surface and its tangents across (∂/∂t) and along
/// (∂/∂v).
pub(crate) struct Tangents {
    pub point: DVec3,
    pub across: DVec3,
    pub along: DVec3,
}

/// A lens surface (a rational quadratic across, a cubic B-spline along)
/// read directly: truck's general evaluation allocates at every call (the
/// samples of the reference's four wall ends took 80 ms with it).
pub(crate) struct LensPatch<'s> {
    knots: Vec<f64>,
    rows: &'s [Vec<Vector4>],
}

impl<'s> LensPatch<'s> {
    pub fn of(surface: &'s NurbsSurface<Vector4>) -> Self {
        LensPatch {
            knots: surface.vknot_vec().to_vec(),
            rows: surface.control_points(),
        }
    }

    /// Whether `surface` is one: three rows across on Bézier knots, cubic
    /// along.
    pub fn fits(surface: &NurbsSurface<Vector4>) -> bool {
        let (across, along) = (surface.uknot_vec(), surface.vknot_vec());
        surface.control_points().len() == 3
            && across.len() == 6
            && across[0] == 0.0
            && across[5] == 1.0
            && across[2] == 0.0
            && across[3] == 1.0
            && along.len() >= 8
    }

    /// The three homogeneous points of the section at station `v`.
    fn section(&self, v: f64) -> [DVec4; 3] {
        let (first, basis, _) = cubic_basis(&self.knots, v);
        self.weighted(first, &basis)
    }

    /// Each row's four control points from `first` on, weighed by `w`.
    fn weighted(&self, first: usize, w: &[f64; 4]) -> [DVec4; 3] {
        std::array::from_fn(|r| {
            let c = &self.rows[r][first..first + 4];
            (0..4).fold(DVec4::ZERO, |acc, j| {
                acc + DVec4::new(c[j].x, c[j].y, c[j].z, c[j].w) * w[j]
            })
        })
    }

    /// truck's presearch for the point nearest `target` (the nearest of a
    /// (division + 1)² grid over `range`, the first of equals in truck's
    /// order: u outer, v inner), each grid column's section computed once.
    pub fn presearch(&self, target: DVec3, domain: Domain, division: usize) -> (f64, f64) {
        let ((u0, u1), (v0, v1)) = domain;
        let at = |i: usize, lo: f64, hi: f64| {
            let p = i as f64 / division as f64;
            lo * (1.0 - p) + hi * p
        };
        let sections: Vec<[DVec4; 3]> = (0..=division)
            .map(|j| self.section(at(j, v0, v1)))
            .collect();
        let mut best = (f64::INFINITY, (0.0, 0.0));
        for i in 0..=division {
            let u = at(i, u0, u1);
            let s = 1.0 - u;
            let b = [s * s, 2.0 * s * u, u * u];
            for (j, h) in sections.iter().enumerate() {
                let h = h[0] * b[0] + h[1] * b[1] + h[2] * b[2];
                let d = (h.truncate() / h.w).distance_squared(target);
                if d < best.0 {
                    best = (d, (u, at(j, v0, v1)));
                }
            }
        }
        best.1
    }

    /// The point at (t, v) and its tangents (v is clamped into the knots'
    /// last span at the ends, where the cubic extrapolates).
    pub fn at(&self, t: f64, v: f64) -> Tangents {
        let (first, basis, slope) = cubic_basis(&self.knots, v);
        let (rows, slopes) = (self.weighted(first, &basis), self.weighted(first, &slope));
        let s = 1.0 - t;
        let (b, db) = (
            [s * s, 2.0 * s * t, t * t],
            [-2.0 * s, 2.0 - 4.0 * t, 2.0 * t],
        );
        let sum = |w: [f64; 3], h: &[DVec4; 3]| h[0] * w[0] + h[1] * w[1] + h[2] * w[2];
        let (h, h_t, h_v) = (sum(b, &rows), sum(db, &rows), sum(b, &slopes));
        let point = h.truncate() / h.w;
        let derivative = |d: DVec4| (d.truncate() - point * d.w) / h.w;
        Tangents {
            point,
            across: derivative(h_t),
            along: derivative(h_v),
        }
    }
}

/// The cubic B-spline basis at `v` over clamped `knots`: the first control
/// point it weighs, its four weights and their derivatives (the NURBS
/// Book, A2.2 and A2.3).
fn cubic_basis(knots: &[f64], v: f64) -> (usize, [f64; 4], [f64; 4]) {
    const P: usize = 3;
    let n = knots.len() - P - 1; // control points
    let span = (knots.partition_point(|&k| k <= v).max(P + 1) - 1).min(n - 1);
    let (mut left, mut right) = ([0.0; P + 1], [0.0; P + 1]);
    // ndu[j][r]: basis functions (upper triangle) and knot differences
    let mut ndu = [[0.0; P + 1]; P + 1];
    ndu[0][0] = 1.0;
    for j in 1..=P {
        left[j] = v - knots[span + 1 - j];
        right[j] = knots[span + j] - v;
        let mut saved = 0.0;
        for r in 0..j {
            ndu[j][r] = right[r + 1] + left[j - r];
            let temp = ndu[r][j - 1] / ndu[j][r];
            ndu[r][j] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        ndu[j][j] = saved;
    }
    let basis = std::array::from_fn(|j| ndu[j][P]);
    // first derivatives: p · (N_{j,p−1}/Δ_j − N_{j+1,p−1}/Δ_{j+1})
    let slope = std::array::from_fn(|r| {
        let below = if r >= 1 {
            ndu[r - 1][P - 1] / ndu[P][r - 1]
        } else {
            0.0
        };
        let above = if r < P {
            ndu[r][P - 1] / ndu[P][r]
        } else {
            0.0
        };
        P as f64 * (below - above)
    });
    (span - P, basis, slope)
}
