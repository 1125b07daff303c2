//! Cubic B-spline interpolation (C², clamped): the curves through exact
//! points that the B-rep's faces and edges are made of.
//!
//! **Guarantee.** The spline passes through every data point exactly (up to
//! round-off of one tridiagonal solve). Between data points it is the C²
//! cubic with the given end slopes; callers measure its distance from the
//! exact geometry themselves (it is O(h⁴) for smooth data).

use truck_modeling::KnotVec;

/// Clamped cubic knot vector with one interior knot per interior parameter.
/// Chord-length parameters of a polyline's vertices (from 0).
pub fn chord_lengths(pts: &[glam::DVec3]) -> Vec<f64> {
    let mut s = vec![0.0];
    for w in pts.windows(2) {
        s.push(s.last().unwrap() + (w[1] - w[0]).length());
    }
    s
}

pub fn clamped_knots(params: &[f64]) -> KnotVec {
    let (first, last) = (params[0], params[params.len() - 1]);
    let mut knots = vec![first; 4];
    knots.extend_from_slice(&params[1..params.len() - 1]);
    knots.extend([last; 4]);
    KnotVec::from(knots)
}

/// Slope at the first parameter of the parabola through the first three
/// points (the line through two, if there are only two).
fn end_slope<const D: usize>(v: [f64; 3], q: [&[f64; D]; 3], points: usize) -> [f64; D] {
    let mut d = [0.0; D];
    let h1 = v[1] - v[0];
    if points == 2 {
        for c in 0..D {
            d[c] = (q[1][c] - q[0][c]) / h1;
        }
        return d;
    }
    let h2 = v[2] - v[1];
    let (a, b, e) = (
        -(2.0 * h1 + h2) / (h1 * (h1 + h2)),
        (h1 + h2) / (h1 * h2),
        -h1 / (h2 * (h1 + h2)),
    );
    for c in 0..D {
        d[c] = a * q[0][c] + b * q[1][c] + e * q[2][c];
    }
    d
}

/// Control points (n + 3 of them for n + 1 points) of the clamped C² cubic
/// through `data` at increasing `params` ([`clamped_knots`]), with end
/// slopes from the parabolas through the three end points.
pub fn interpolate<const D: usize>(params: &[f64], data: &[[f64; D]]) -> Vec<[f64; D]> {
    let m = params.len();
    assert!(m >= 2 && data.len() == m, "interpolation needs 2+ points");
    let n = m - 1;
    let take3 = |i: [usize; 3]| {
        (
            [params[i[0]], params[i[1]], params[i[2]]],
            [&data[i[0]], &data[i[1]], &data[i[2]]],
        )
    };
    let (v0, q0) = take3([0, 1.min(n), 2.min(n)]);
    let d0 = end_slope(v0, q0, m);
    // the last end, mirrored: parameters negated, so the slope flips sign
    let (vn, qn) = take3([n, n.saturating_sub(1), n.saturating_sub(2)]);
    let dn = end_slope(vn.map(|x| -x), qn, m).map(|x| -x);
    interpolate_with_slopes(params, data, d0, dn)
}

/// [`interpolate`] with the end slopes given: reproduces any cubic exactly
/// when they are its slopes.
pub fn interpolate_with_slopes<const D: usize>(
    params: &[f64],
    data: &[[f64; D]],
    d0: [f64; D],
    dn: [f64; D],
) -> Vec<[f64; D]> {
    let n = params.len() - 1;
    let mut p = vec![[0.0; D]; n + 3];
    p[0] = data[0];
    p[n + 2] = data[n];
    for c in 0..D {
        p[1][c] = data[0][c] + (params[1] - params[0]) / 3.0 * d0[c];
        p[n + 1][c] = data[n][c] - (params[n] - params[n - 1]) / 3.0 * dn[c];
    }
    if n < 2 {
        return p;
    }
    // Knot u(i) of the clamped vector, for the closed-form basis values.
    let knot = |i: isize| -> f64 { params[(i - 3).clamp(0, n as isize) as usize] };
    // Interior rows j = 1..n−1: a·p[j] + b·p[j+1] + c·p[j+2] = data[j].
    let rows: Vec<(f64, f64, f64)> = (1..n)
        .map(|j| {
            let i = j as isize;
            let a = (knot(i + 4) - knot(i + 3)).powi(2)
                / ((knot(i + 4) - knot(i + 1)) * (knot(i + 4) - knot(i + 2)));
            let c = (knot(i + 3) - knot(i + 2)).powi(2)
                / ((knot(i + 5) - knot(i + 2)) * (knot(i + 4) - knot(i + 2)));
            (a, 1.0 - a - c, c)
        })
        .collect();
    // Thomas algorithm over unknowns p[2..=n]; p[1] and p[n+1] are known.
    let k = n - 1;
    let mut upper = vec![0.0; k];
    let mut rhs = vec![[0.0; D]; k];
    for r in 0..k {
        let (a, b, c) = rows[r];
        let mut y = data[r + 1];
        if r == 0 {
            for (yc, pc) in y.iter_mut().zip(p[1]) {
                *yc -= a * pc;
            }
        }
        if r == k - 1 {
            for (yc, pc) in y.iter_mut().zip(p[n + 1]) {
                *yc -= c * pc;
            }
        }
        let (lower, prev_upper, prev_rhs) = if r == 0 {
            (0.0, 0.0, [0.0; D])
        } else {
            (a, upper[r - 1], rhs[r - 1])
        };
        let pivot = b - lower * prev_upper;
        upper[r] = c / pivot;
        for cc in 0..D {
            rhs[r][cc] = (y[cc] - lower * prev_rhs[cc]) / pivot;
        }
    }
    for r in (0..k).rev() {
        let next = if r + 1 < k { rhs[r + 1] } else { [0.0; D] };
        let u = if r + 1 < k { upper[r] } else { 0.0 };
        for cc in 0..D {
            rhs[r][cc] -= u * next[cc];
        }
        p[r + 2] = rhs[r];
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use truck_modeling::{BSplineCurve, ParametricCurve, Point3};

    #[test]
    fn passes_through_the_data_and_reproduces_cubics() {
        let params = [0.0, 0.3, 1.0, 1.2, 2.5, 3.0, 4.1];
        let f = |t: f64| [t * t * t - 2.0 * t, 0.5 * t * t, 1.0 - t];
        let data: Vec<[f64; 3]> = params.iter().map(|&t| f(t)).collect();
        let ctrl = interpolate(&params, &data);
        let curve = BSplineCurve::new(
            clamped_knots(&params),
            ctrl.iter().map(|c| Point3::new(c[0], c[1], c[2])).collect(),
        );
        for &t in &params {
            let p = curve.subs(t);
            let q = f(t);
            assert!((p.x - q[0]).abs() + (p.y - q[1]).abs() + (p.z - q[2]).abs() < 1e-12);
        }
        // Quadratic data are reproduced exactly (the parabola end slopes are exact).
        for i in 0..40 {
            let t = 4.1 * i as f64 / 39.0;
            let (p, q) = (curve.subs(t), f(t));
            assert!(
                (p.y - q[1]).abs() < 1e-12 && (p.z - q[2]).abs() < 1e-12,
                "t = {t}"
            );
        }
        // With its own end slopes, the cubic is reproduced exactly.
        let slope = |t: f64| [3.0 * t * t - 2.0, t, -1.0];
        let ctrl = interpolate_with_slopes(&params, &data, slope(0.0), slope(4.1));
        let curve = BSplineCurve::new(
            clamped_knots(&params),
            ctrl.iter().map(|c| Point3::new(c[0], c[1], c[2])).collect(),
        );
        for i in 0..40 {
            let t = 4.1 * i as f64 / 39.0;
            let (p, q) = (curve.subs(t), f(t));
            assert!(
                (p.x - q[0]).abs() + (p.y - q[1]).abs() + (p.z - q[2]).abs() < 1e-11,
                "t = {t}"
            );
        }
    }

    #[test]
    fn two_and_three_points() {
        for params in [&[0.0, 2.0][..], &[0.0, 0.5, 2.0][..]] {
            let data: Vec<[f64; 1]> = params.iter().map(|t| [t * t]).collect();
            let ctrl = interpolate(params, &data);
            let curve = BSplineCurve::new(
                clamped_knots(params),
                ctrl.iter().map(|c| Point3::new(c[0], 0.0, 0.0)).collect(),
            );
            for &t in params.iter() {
                assert!((curve.subs(t).x - t * t).abs() < 1e-12);
            }
        }
    }
}
