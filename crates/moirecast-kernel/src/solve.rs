//! Small root finders for exact points. Every solve converges to
//! [`SOLVE_RESIDUAL_MM`] or returns an error that names what it was solving.

use crate::error::{KernelError, Result};
use crate::tolerance::SOLVE_RESIDUAL_MM;
use glam::DVec2;

const MAX_ITER: usize = 60;
/// Steps [`bracketed_newton`] takes before it bisects where Newton stalls:
/// a well-behaved solve has converged long before.
const NEWTON_PATIENCE: usize = 20;

/// Solves g(x) = 0 for a g with g' > 0 on the bracket [lo, hi], where
/// g(lo) ≤ 0 ≤ g(hi). Newton steps with analytic derivative, falling back to
/// bisection when a step leaves the bracket: always converges. A bracket
/// that holds no root (g of one sign at every point tried, so the bracket
/// shrank onto one of its ends) is an error, not that end.
pub fn bracketed_newton(
    mut lo: f64,
    mut hi: f64,
    x0: f64,
    residual: f64,
    what: &dyn Fn() -> String,
    g: impl Fn(f64) -> (f64, f64),
) -> Result<f64> {
    let mut x = x0.clamp(lo, hi);
    let (mut below, mut above) = (false, false);
    let mut last_abs = f64::INFINITY;
    for i in 0..200 {
        let (gx, dg) = g(x);
        if gx.abs() <= residual {
            return Ok(x);
        }
        if gx < 0.0 {
            (lo, below) = (x, true);
        } else {
            (hi, above) = (x, true);
        }
        // Newton can fall into a cycle across a kink of g' (a shape
        // profile's ridge: found-3844ff35bfcd5d9c), each step moving one end of
        // the bracket a little. A solve still running after
        // NEWTON_PATIENCE steps whose |g| did not halve bisects.
        let stalled = i >= NEWTON_PATIENCE && gx.abs() > 0.5 * last_abs;
        last_abs = gx.abs();
        let step = x - gx / dg;
        x = if !stalled && dg > 0.0 && step > lo && step < hi {
            step
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo <= f64::EPSILON * x.abs().max(1.0) {
            if below && above {
                return Ok(x);
            }
            break;
        }
    }
    Err(KernelError::Solver(what()))
}

/// Solves g(x) = 0 from `x0` by the chord method: a central-difference
/// derivative taken at the start and refreshed only when progress stalls.
/// For the smooth, nearly linear maps of the device (g' ≈ 1, varying
/// slowly) this costs about one evaluation per step.
pub fn newton_1d(x0: f64, what: &dyn Fn() -> String, g: impl Fn(f64) -> f64) -> Result<f64> {
    chord_1d(x0, None, what, g)
}

/// [`newton_1d`] with a known estimate of g' to start from (saves the
/// initial finite difference).
pub fn chord_1d(
    x0: f64,
    slope_hint: Option<f64>,
    what: &dyn Fn() -> String,
    g: impl Fn(f64) -> f64,
) -> Result<f64> {
    let h = 1e-6;
    let mut x = x0;
    let mut gx = g(x);
    let mut slope: Option<f64> = slope_hint.filter(|d| d.is_finite() && *d != 0.0);
    for _ in 0..MAX_ITER {
        if !gx.is_finite() {
            break;
        }
        if gx.abs() <= SOLVE_RESIDUAL_MM {
            return Ok(x);
        }
        let d = match slope {
            Some(d) => d,
            None => {
                let d = (g(x + h) - g(x - h)) / (2.0 * h);
                if d == 0.0 || !d.is_finite() {
                    break;
                }
                slope = Some(d);
                d
            }
        };
        let next = x - gx / d;
        let g_next = g(next);
        if g_next.abs() > 0.5 * gx.abs() {
            slope = None; // stalled: refresh the derivative at the new point
        }
        x = next;
        gx = g_next;
    }
    Err(KernelError::Solver(what()))
}

/// Solves g(x) = 0 on [lo, hi], where g(lo) and g(hi) have opposite signs,
/// by the Illinois variant of regula falsi: never leaves the bracket, so it
/// finds the root that was bracketed, not another one.
pub fn bracketed_secant(
    mut lo: f64,
    mut hi: f64,
    what: &dyn Fn() -> String,
    g: impl Fn(f64) -> f64,
) -> Result<f64> {
    let (mut g_lo, mut g_hi) = (g(lo), g(hi));
    if !(g_lo.is_finite() && g_hi.is_finite()) || (g_lo > 0.0) == (g_hi > 0.0) {
        return Err(KernelError::Solver(what()));
    }
    let mut side = 0i8;
    for _ in 0..200 {
        let x = (lo * g_hi - hi * g_lo) / (g_hi - g_lo);
        let gx = g(x);
        if !gx.is_finite() {
            break;
        }
        if gx.abs() <= SOLVE_RESIDUAL_MM || (hi - lo).abs() <= f64::EPSILON * x.abs().max(1.0) {
            return Ok(x);
        }
        if (gx > 0.0) == (g_hi > 0.0) {
            hi = x;
            g_hi = gx;
            if side == 1 {
                g_lo *= 0.5;
            }
            side = 1;
        } else {
            lo = x;
            g_lo = gx;
            if side == -1 {
                g_hi *= 0.5;
            }
            side = -1;
        }
    }
    Err(KernelError::Solver(what()))
}

/// Solves G(p) = 0 for G: ℝ² → ℝ² by Newton's method with a central-difference
/// Jacobian, starting at `p0`.
pub fn newton_2d(
    p0: DVec2,
    what: &dyn Fn() -> String,
    g: impl Fn(DVec2) -> DVec2,
) -> Result<DVec2> {
    let mut p = p0;
    let h = 1e-6;
    for _ in 0..MAX_ITER {
        let gp = g(p);
        if !gp.is_finite() {
            break;
        }
        if gp.abs().max_element() <= SOLVE_RESIDUAL_MM {
            return Ok(p);
        }
        let ja = (g(p + DVec2::new(h, 0.0)) - g(p - DVec2::new(h, 0.0))) / (2.0 * h);
        let jb = (g(p + DVec2::new(0.0, h)) - g(p - DVec2::new(0.0, h))) / (2.0 * h);
        let det = ja.x * jb.y - jb.x * ja.y;
        if det == 0.0 || !det.is_finite() {
            break;
        }
        let step = DVec2::new(jb.y * gp.x - jb.x * gp.y, -ja.y * gp.x + ja.x * gp.y) / det;
        p -= step;
    }
    Err(KernelError::Solver(what()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solvers_reach_round_off() {
        let what = || "test".to_string();
        let x = newton_1d(1.0, &what, |x| x * x * x - 2.0).unwrap();
        assert!((x - 2f64.cbrt()).abs() < 1e-12);
        let x = bracketed_newton(0.0, 3.0, 0.1, 1e-14, &what, |x| {
            (x * x * x - 2.0, 3.0 * x * x)
        })
        .unwrap();
        assert!((x - 2f64.cbrt()).abs() < 1e-13);
        let x = bracketed_secant(0.0, 3.0, &what, |x| x * x * x - 2.0).unwrap();
        assert!((x - 2f64.cbrt()).abs() < 1e-11);
        // two roots (±1): the bracket picks the one inside it
        let x = bracketed_secant(0.2, 5.0, &what, |x| x * x - 1.0).unwrap();
        assert!((x - 1.0).abs() < 1e-11);
        let p = newton_2d(DVec2::new(1.0, 1.0), &what, |p| {
            DVec2::new(p.x * p.x + p.y - 3.0, p.x - p.y * p.y + 1.0)
        })
        .unwrap();
        assert!((p.x * p.x + p.y - 3.0).abs() < 1e-11 && (p.x - p.y * p.y + 1.0).abs() < 1e-11);
    }

    #[test]
    fn divergence_is_an_error() {
        let what = || "no root".to_string();
        assert!(newton_1d(1.0, &what, |x| x * x + 1.0).is_err());
    }
}
