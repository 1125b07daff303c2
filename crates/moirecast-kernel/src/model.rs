//! The exact device model (METHOD §2–§5.1): revealer lenses over f, base
//! surfaces, base creases and base lenses. Every function here is exact up
//! to floating-point round-off and the convergence of its root finder.

use crate::design::{BaseKind, Design};
use crate::error::{KernelError, Result};
use crate::lens::LensArc;
use crate::solve::bracketed_newton;
use glam::DVec3;

impl Design {
    /// Layout u of revealer crease i (centred layout): u_i = −W/2 + i·T.
    pub fn crease_u(&self, i: i64) -> f64 {
        -self.params.width / 2.0 + i as f64 * self.params.period
    }

    /// Revealer crease curve P_i(v) = f(u_i, v).
    pub fn crease_point(&self, i: i64, v: f64) -> DVec3 {
        self.surface().point(self.crease_u(i), v)
    }

    /// Revealer lens i at station v (METHOD §2): from P_i to P_{i+1},
    /// bulging along the normal at the lens middle.
    pub fn revealer_arc(&self, i: i64, v: f64) -> LensArc {
        let (p0, p1) = (self.crease_point(i, v), self.crease_point(i + 1, v));
        let mid_u = self.crease_u(i) + 0.5 * self.params.period;
        LensArc::new(p0, p1, self.surface().normal(mid_u, v), self.revealer_rule)
    }

    /// Local width factor λ = |f(u + T/2) − f(u − T/2)| / T (METHOD §3).
    pub fn width_factor(&self, u: f64, v: f64) -> f64 {
        let t = self.params.period;
        (self.surface().point(u + t / 2.0, v) - self.surface().point(u - t / 2.0, v)).length() / t
    }

    /// Offset of the interpolated base surface below f along n:
    /// (1 − a)·d + a·D_s·λ (METHOD §3, eq 8).
    pub fn base_offset(&self, u: f64, v: f64) -> f64 {
        let a = self.params.base.a;
        let focal = if a > 0.0 {
            self.standard.focal_depth * self.width_factor(u, v)
        } else {
            0.0
        };
        (1.0 - a) * self.d + a * focal
    }

    /// Base surface s(u, v) = f − ((1 − a)·d + a·D_s·λ)·n.
    pub fn base_surface(&self, u: f64, v: f64) -> DVec3 {
        let (p, n) = self.surface().point_and_normal(u, v);
        p - self.base_offset(u, v) * n
    }

    /// Unit normal of s, on the same side as n, from analytic derivatives:
    /// s = f − δ n with δ = (1 − a)·d + a·D_s·λ, so
    /// s_u = f_u − δ_u n − δ n_u (likewise in v), with n_u from the second
    /// derivatives of f. An offset surface (a = 0) shares f's normal exactly.
    pub fn base_normal(&self, u: f64, v: f64) -> DVec3 {
        if self.params.base.a == 0.0 {
            return self.surface().normal(u, v);
        }
        let (s_u, s_v) = self.base_tangents(u, v);
        s_u.cross(s_v).normalize()
    }

    /// The tangents (s_u, s_v) of the base surface s, from analytic
    /// derivatives as in [`Design::base_normal`].
    pub fn base_tangents(&self, u: f64, v: f64) -> (DVec3, DVec3) {
        let surface = self.surface();
        let jet = surface.jet(u, v);
        let (n, n_u, n_v) = jet.normal_derivatives();
        // λ = |c| / T with c = f(u + T/2) − f(u − T/2)
        let t = self.params.period;
        let (jp, jm) = (surface.jet(u + t / 2.0, v), surface.jet(u - t / 2.0, v));
        let c = jp.p - jm.p;
        let c_hat = c / c.length();
        let (lambda, lambda_u, lambda_v) = (
            c.length() / t,
            c_hat.dot(jp.du - jm.du) / t,
            c_hat.dot(jp.dv - jm.dv) / t,
        );
        let a = self.params.base.a;
        let focal = self.standard.focal_depth;
        let delta = (1.0 - a) * self.d + a * focal * lambda;
        let (delta_u, delta_v) = (a * focal * lambda_u, a * focal * lambda_v);
        let s_u = jet.du - delta_u * n - delta * n_u;
        let s_v = jet.dv - delta_v * n - delta * n_v;
        (s_u, s_v)
    }

    /// The base's shift E(u, v) − C(u, v) (mm): the elevation's
    /// E = A·T·e(u, v) less the view compensation C (zero where the base is
    /// not compensated), so that φ = (u + W/2 − shift)/T.
    pub fn shift(&self, u: f64, v: f64) -> f64 {
        if let Some(grid) = &self.shift_grid {
            return grid.value(u, v);
        }
        let elevation =
            self.params.base.levels * self.params.period * self.params.profile.value(u, v);
        match &self.view {
            None => elevation,
            Some(view) => elevation - view.value(u, v),
        }
    }

    /// The shift and its gradient in (u, v) (mm, and per mm).
    pub fn shift_and_gradient(&self, u: f64, v: f64) -> (f64, glam::DVec2) {
        if let Some(grid) = &self.shift_grid {
            return grid.eval(u, v);
        }
        let a_t = self.params.base.levels * self.params.period;
        let (e, grad) = self.params.profile.value_grad(u, v);
        match &self.view {
            None => (a_t * e, a_t * grad),
            Some(view) => {
                let (c, c_grad) = view.offset(u, v);
                (a_t * e - c, a_t * grad - c_grad)
            }
        }
    }

    /// The view compensation C(u, v) (mm; 0 where the base is not
    /// compensated).
    pub fn view_offset(&self, u: f64, v: f64) -> f64 {
        self.view.as_ref().map_or(0.0, |view| view.value(u, v))
    }

    /// Base phase φ(u, v) = (u + W/2 − E(u, v) + C(u, v)) / T (METHOD §4,
    /// with the view compensation).
    pub fn base_phase(&self, u: f64, v: f64) -> f64 {
        (u + self.params.width / 2.0 - self.shift(u, v)) / self.params.period
    }

    /// The phase of base crease k: k for a dual-lens base; for a printed
    /// base, whose creases are the band edges, ⌊k/2⌋ for even k (a band
    /// starts) and ⌊k/2⌋ + duty for odd k (it ends).
    pub fn crease_phase(&self, k: i64) -> f64 {
        match self.params.base.kind {
            BaseKind::DualLens => k as f64,
            BaseKind::Printed(pb) => {
                k.div_euclid(2) as f64 + if k.rem_euclid(2) == 1 { pb.duty } else { 0.0 }
            }
        }
    }

    /// Whether base section k is a black band (printed bases only).
    pub fn is_black_band(&self, k: i64) -> bool {
        matches!(self.params.base.kind, BaseKind::Printed(_)) && k.rem_euclid(2) == 0
    }

    /// Layout u of base crease k at station v: the root of φ(u, v) =
    /// [`crease_phase`](Self::crease_phase)(k). φ increases with u
    /// (validated), and on the layout E ∈ [0, A·T] brackets the root.
    /// Beyond it, where a deep base on a sloping surface reaches (METHOD
    /// §5: the arrays are built over an extended layout), a ramp profile
    /// runs on past [0, 1]; there the bracket is widened until it holds
    /// the root.
    pub fn base_crease_u(&self, k: i64, v: f64) -> Result<f64> {
        self.base_crease_u_near(k, v, None)
    }

    /// [`base_crease_u`](Self::base_crease_u) starting from `start` (a nearby
    /// solution), which saves most Newton steps.
    pub fn base_crease_u_near(&self, k: i64, v: f64, start: Option<f64>) -> Result<f64> {
        let (t, a_t) = (
            self.params.period,
            self.params.base.levels * self.params.period,
        );
        let u0 = self.crease_phase(k) * t - self.params.width / 2.0;
        // the shift lies in [−C_max, A·T + C_max]
        let c_max = self.view.as_ref().map_or(0.0, |view| view.max_abs_mm);
        if a_t == 0.0 && c_max == 0.0 {
            return Ok(u0);
        }
        let profile = &self.params.profile;
        let (x0, lo, hi) = match &self.view {
            None => (
                start.unwrap_or_else(|| u0 + a_t * profile.value(u0, v)),
                u0 - 0.5 * a_t,
                u0 + 1.5 * a_t,
            ),
            Some(_) => (
                start.unwrap_or_else(|| u0 + self.shift(u0, v)),
                u0 - 0.5 * a_t - 2.0 * c_max,
                u0 + 1.5 * a_t + 2.0 * c_max,
            ),
        };
        let g = |u: f64| match &self.view {
            None => {
                let (e, grad) = profile.value_grad(u, v);
                (u - u0 - a_t * e, 1.0 - a_t * grad.x)
            }
            Some(_) => {
                let (shift, grad) = self.shift_and_gradient(u, v);
                (u - u0 - shift, 1.0 - grad.x)
            }
        };
        let what = || format!("base crease {k} at v = {v}");
        bracketed_newton(lo, hi, x0, 1e-13, &what, g).or_else(|_| {
            // g increases with u: step each end outward, doubling, until
            // g changes sign between them
            let step0 = a_t.max(c_max);
            let widened = |mut end: f64, outward: f64, wrong_side: &dyn Fn(f64) -> bool| {
                let mut step = step0;
                for _ in 0..64 {
                    if !wrong_side(g(end).0) {
                        return Ok(end);
                    }
                    end += outward * step;
                    step *= 2.0;
                }
                Err(KernelError::Solver(what()))
            };
            let lo = widened(lo, -1.0, &|g| g > 0.0)?;
            let hi = widened(hi, 1.0, &|g| g < 0.0)?;
            bracketed_newton(lo, hi, x0, 1e-13, &what, g)
        })
    }

    /// Base crease curve C_k(v) = s(u_k(v), v), with x at ±∞ where the
    /// crease lies beyond the extended layout (see
    /// [`beyond_extended_layout`](Self::beyond_extended_layout)).
    pub fn base_crease_point(&self, k: i64, v: f64) -> Result<DVec3> {
        let u = self.base_crease_u(k, v)?;
        let mut p = self.base_surface(u, v);
        if let Some(side) = self.beyond_extended_layout(u) {
            p.x = side;
        }
        Ok(p)
    }

    /// The side (−∞ or +∞ in x) of a base crease at layout `u` beyond the
    /// extended layout, the layout and its margin, where the surface is
    /// validated; `None` within it. The device's base comes from within it
    /// (the margin is settled so), and beyond it a surface may turn back
    /// over the outline (a cylinder past a quarter turn: a ramp that runs on
    /// past [0, 1] puts distant creases there), so a crease out there is
    /// outside the device on its side, wherever its point lands.
    pub fn beyond_extended_layout(&self, u: f64) -> Option<f64> {
        let reach = self.params.width / 2.0 + self.margin;
        (u.abs() > reach).then(|| f64::INFINITY.copysign(u))
    }

    /// Base lens k of a dual-lens design at station v (METHOD §5.1): from
    /// C_k to C_{k+1}, bulging along −n_s at the middle of its layout span,
    /// away from the body.
    pub fn base_arc(&self, k: i64, v: f64) -> Result<LensArc> {
        let (u0, u1) = (self.base_crease_u(k, v)?, self.base_crease_u(k + 1, v)?);
        Ok(self.base_arc_between(u0, u1, v))
    }

    /// Base section k at station v, with nearby crease solutions to start from.
    pub fn base_section_near(
        &self,
        k: i64,
        v: f64,
        near: (Option<f64>, Option<f64>),
    ) -> Result<BaseSection<'_>> {
        Ok(self.base_section_and_creases(k, v, near)?.0)
    }

    /// Base section k (a lens or a band span) at station v and the layout u
    /// of its two creases.
    pub fn base_section_and_creases(
        &self,
        k: i64,
        v: f64,
        near: (Option<f64>, Option<f64>),
    ) -> Result<(BaseSection<'_>, f64, f64)> {
        let (u0, u1) = (
            self.base_crease_u_near(k, v, near.0)?,
            self.base_crease_u_near(k + 1, v, near.1)?,
        );
        Ok((self.base_section_between(u0, u1, v), u0, u1))
    }

    /// The base section (a lens or a band span) whose creases lie at layout
    /// u0 and u1 (already solved) at station v.
    pub fn base_section_between(&self, u0: f64, u1: f64, v: f64) -> BaseSection<'_> {
        match self.params.base.kind {
            BaseKind::DualLens => BaseSection::Lens(self.base_arc_between(u0, u1, v)),
            BaseKind::Printed(_) => BaseSection::Band {
                design: self,
                u0,
                u1,
                v,
            },
        }
    }

    /// The base arc whose creases lie at layout u0 and u1 (already solved)
    /// at station v. Lets callers that share creases between neighbouring
    /// lenses compute each crease once.
    pub fn base_arc_between(&self, u0: f64, u1: f64, v: f64) -> LensArc {
        let (p0, p1) = (self.base_surface(u0, v), self.base_surface(u1, v));
        let toward = -self.base_normal(0.5 * (u0 + u1), v);
        LensArc::new(p0, p1, toward, self.base_rule)
    }

    /// A point of base section k: parameter t ∈ [0, 1] across, station v along.
    pub fn base_point(&self, k: i64, t: f64, v: f64) -> Result<DVec3> {
        Ok(self.base_section_near(k, v, (None, None))?.point(t))
    }

    /// A point of revealer lens i.
    pub fn revealer_point(&self, i: i64, t: f64, v: f64) -> DVec3 {
        self.revealer_arc(i, v).point(t)
    }

    /// Which lens surface of the device is meant.
    pub fn lens_point(&self, lens: LensRef, t: f64, v: f64) -> Result<DVec3> {
        match lens {
            LensRef::Revealer(i) => Ok(self.revealer_point(i, t, v)),
            LensRef::Base(k) => self.base_point(k, t, v),
        }
    }

    /// Solves the station v at which lens point (t, ·) has y = `y`.
    pub fn solve_station_for_y(&self, lens: LensRef, t: f64, y: f64, v0: f64) -> Result<f64> {
        crate::solve::newton_1d(v0, &|| format!("{lens:?} at t = {t}, y = {y}"), |v| {
            self.lens_point(lens, t, v)
                .map(|p| p.y - y)
                .unwrap_or(f64::NAN)
        })
    }
}

/// One cross-section of the base between creases k and k + 1 at a station:
/// a base lens (dual-lens) or a span of s itself between two band edges
/// (printed), where t runs linearly in layout u.
#[derive(Clone, Copy, Debug)]
pub enum BaseSection<'a> {
    Lens(LensArc),
    Band {
        design: &'a Design,
        u0: f64,
        u1: f64,
        v: f64,
    },
}

impl BaseSection<'_> {
    /// The point at t ∈ [0, 1]; t = 0 and t = 1 are the creases bit for bit.
    pub fn point(&self, t: f64) -> DVec3 {
        match *self {
            BaseSection::Lens(arc) => arc.point(t),
            BaseSection::Band { design, u0, u1, v } => {
                let u = if t == 1.0 { u1 } else { u0 + t * (u1 - u0) };
                design.base_surface(u, v)
            }
        }
    }

    /// Segments across that keep the chordal error within `e` (mm): from the
    /// arc's radius for a lens, from the measured mid-span sag for a band
    /// (s is smooth on a period's scale, so the sag falls as 1/segments²).
    pub fn columns(&self, e: f64) -> usize {
        match *self {
            BaseSection::Lens(arc) => crate::lens::columns_for(arc.radius, 2.0 * arc.half_angle, e),
            BaseSection::Band { .. } => {
                let sag = (self.point(0.5) - 0.5 * (self.point(0.0) + self.point(1.0))).length();
                let by_sag = ((sag / e).sqrt().ceil() as usize).max(1);
                // The middle's sag is the chord error of a band of even
                // curvature; across an inflection (a band over a bump's
                // flank, found-1960f6721880b29e) its halves cancel. The largest
                // curvature along the band, from second differences, bounds
                // the error of every column.
                const STEPS: usize = 16;
                let pts: Vec<DVec3> = (0..=STEPS)
                    .map(|j| self.point(j as f64 / STEPS as f64))
                    .collect();
                let largest_sag = pts
                    .windows(3)
                    .map(|w| (w[1] - 0.5 * (w[0] + w[2])).length())
                    .fold(0.0, f64::max);
                // a sag over two steps scales as (2/STEPS)² of the band's
                let by_curvature = (STEPS as f64 / 2.0 * (largest_sag / e).sqrt()).ceil() as usize;
                by_sag.max(by_curvature)
            }
        }
    }
}

/// A lens of the device: revealer lens i or base lens k.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LensRef {
    Revealer(i64),
    Base(i64),
}

#[cfg(test)]
mod tests {
    use crate::*;

    #[test]
    fn base_normal_matches_finite_differences() {
        for a in [0.0, 0.3, 1.0] {
            let p = DesignParams {
                surface: PitchSurface::Sphere { radius: -60.0 },
                width: 20.0,
                height: 10.0,
                period: 0.5,
                lens: LensParams {
                    afov: 1.0,
                    index: 1.41,
                    rule: LensRule::ConstantAfov,
                },
                base: BaseParams {
                    kind: BaseKind::DualLens,
                    a,
                    d: None,
                    levels: 0.0,
                    afov: None,
                },
                profile: Profile::Flat,
                tolerance: 0.002,
                view: crate::DesignView::default(),
            };
            let d = Design::new(p).unwrap();
            for (u, v) in [(0.0, 0.0), (7.0, -3.0), (-9.5, 4.5)] {
                let h = 1e-5;
                let su = d.base_surface(u + h, v) - d.base_surface(u - h, v);
                let sv = d.base_surface(u, v + h) - d.base_surface(u, v - h);
                let fd = su.cross(sv).normalize();
                assert!(
                    (fd - d.base_normal(u, v)).length() < 1e-8,
                    "a = {a}: {fd} vs {}",
                    d.base_normal(u, v)
                );
            }
        }
    }
}
