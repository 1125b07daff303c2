//! Pitch surfaces f(u, v) (METHOD §1): the surface through the lens creases.
//!
//! Every built-in surface is *xy-separable*: `f(u, v).x` depends on `u` only
//! and `f(u, v).y == v` exactly. So revealer creases project to straight
//! lines `x = const`, and the outline is the rectangle
//! `[x(−W/2), x(W/2)] × [−H/2, H/2]`. The mesher relies on this.
//!
//! Derivatives are analytic for the closed forms and symbolic (exmex) for
//! `formula`.

use crate::formula::{self, FormulaError};
use crate::heightmap::HeightMap;
use exmex::prelude::*;
use glam::DVec3;
use std::sync::Arc;

/// Position and derivatives up to second order at one layout point.
#[derive(Clone, Copy, Debug)]
pub struct Jet {
    pub p: DVec3,
    pub du: DVec3,
    pub dv: DVec3,
    pub duu: DVec3,
    pub duv: DVec3,
    pub dvv: DVec3,
}

impl Jet {
    /// Outward unit normal `f_u × f_v / |f_u × f_v|` (points to the air side).
    pub fn normal(&self) -> DVec3 {
        self.du.cross(self.dv).normalize()
    }

    /// The unit normal n and its derivatives n_u and n_v, from the second
    /// derivatives: with N = f_u × f_v, n_u = (N_u − n (n·N_u)) / |N|.
    pub fn normal_derivatives(&self) -> (DVec3, DVec3, DVec3) {
        let big_n = self.du.cross(self.dv);
        let len = big_n.length();
        let n = big_n / len;
        let normal_derivative = |big_n_d: DVec3| (big_n_d - n * n.dot(big_n_d)) / len;
        let n_u = normal_derivative(self.duu.cross(self.dv) + self.du.cross(self.duv));
        let n_v = normal_derivative(self.duv.cross(self.dv) + self.du.cross(self.dvv));
        (n, n_u, n_v)
    }

    /// Largest absolute principal curvature (1/mm).
    pub fn max_abs_curvature(&self) -> f64 {
        let n = self.normal();
        let (e, f, g) = (
            self.du.dot(self.du),
            self.du.dot(self.dv),
            self.dv.dot(self.dv),
        );
        let (l, m, nn) = (self.duu.dot(n), self.duv.dot(n), self.dvv.dot(n));
        let det = e * g - f * f;
        let k = (l * nn - m * m) / det;
        let h = (e * nn - 2.0 * f * m + g * l) / (2.0 * det);
        let disc = (h * h - k).max(0.0).sqrt();
        (h + disc).abs().max((h - disc).abs())
    }
}

/// A user formula z = h(x, y), with its symbolic partial derivatives.
#[derive(Clone)]
pub struct FormulaSurface {
    pub source: String,
    // h, hx, hy, hxx, hxy, hyy
    terms: Arc<[NamedExpr; 6]>,
}

impl std::fmt::Debug for FormulaSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "FormulaSurface({:?})", self.source)
    }
}

/// An exmex expression with its variables resolved to x and y by name.
#[derive(Clone)]
struct NamedExpr {
    expr: Option<FlatEx<f64>>, // None: identically zero (derivative w.r.t. an absent variable)
    slots: Vec<bool>,          // per variable of `expr`: true = x, false = y
}

impl NamedExpr {
    fn new(expr: FlatEx<f64>) -> Result<Self, String> {
        let slots = expr
            .var_names()
            .iter()
            .map(|n| match n.as_str() {
                "x" => Ok(true),
                "y" => Ok(false),
                other => Err(format!(
                    "unknown variable `{other}` (only x and y, in mm, are defined)"
                )),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(NamedExpr {
            expr: Some(expr),
            slots,
        })
    }

    fn partial(&self, by_x: bool) -> Result<Self, String> {
        let Some(expr) = &self.expr else {
            return Ok(self.clone());
        };
        match self.slots.iter().position(|&s| s == by_x) {
            None => Ok(NamedExpr {
                expr: None,
                slots: vec![],
            }),
            Some(idx) => NamedExpr::new(expr.clone().partial(idx).map_err(|e| e.to_string())?),
        }
    }

    /// The length of the expression written out (0 for an absent one).
    fn written_len(&self) -> usize {
        self.expr.as_ref().map_or(0, |e| e.unparse().len())
    }

    fn eval(&self, x: f64, y: f64) -> f64 {
        let Some(expr) = &self.expr else { return 0.0 };
        let mut vars = [0.0; 2];
        for (v, &s) in vars.iter_mut().zip(&self.slots) {
            *v = if s { x } else { y };
        }
        expr.eval(&vars[..self.slots.len()]).unwrap_or(f64::NAN)
    }
}

impl FormulaSurface {
    /// Parses `z = h(x, y)` and differentiates it twice, within the
    /// budget of [`crate::formula`]: a formula past it is refused by a
    /// named rule before exmex sees it, and exmex runs on a thread whose
    /// stack the budget cannot exhaust. The error says what is wrong.
    pub fn parse(source: &str) -> Result<Self, FormulaError> {
        formula::check_budget(source)?;
        let owned = source.to_owned();
        // an exmex expression holds 20 KB inline: the six cross back boxed
        let terms = formula::on_parse_thread(move || {
            let terms = Arc::new(Self::differentiate(&owned)?);
            let written: usize = terms[1..].iter().map(NamedExpr::written_len).sum();
            formula::check_derivatives(written).map(|()| terms)
        })??;
        Ok(FormulaSurface {
            source: source.to_owned(),
            terms,
        })
    }

    /// h and its first and second partial derivatives, by exmex.
    fn differentiate(source: &str) -> Result<[NamedExpr; 6], FormulaError> {
        let syntax = |e: String| FormulaError {
            rule: "formula-syntax",
            problem: format!("is not a formula in x and y: {e}"),
            fix: "use x, y, numbers, + - * / ^ and sin, cos, exp, sqrt…".into(),
        };
        let h = NamedExpr::new(exmex::parse::<f64>(source).map_err(|e| syntax(e.to_string()))?)
            .map_err(syntax)?;
        let hx = h.partial(true).map_err(syntax)?;
        let hy = h.partial(false).map_err(syntax)?;
        let hxx = hx.partial(true).map_err(syntax)?;
        let hxy = hx.partial(false).map_err(syntax)?;
        let hyy = hy.partial(false).map_err(syntax)?;
        Ok([h, hx, hy, hxx, hxy, hyy])
    }

    /// z = h(x, y) only.
    fn value(&self, x: f64, y: f64) -> f64 {
        self.terms[0].eval(x, y)
    }

    /// (h_x, h_y) only.
    fn gradient(&self, x: f64, y: f64) -> (f64, f64) {
        (self.terms[1].eval(x, y), self.terms[2].eval(x, y))
    }

    fn eval(&self, x: f64, y: f64) -> [f64; 6] {
        let t = &*self.terms;
        [
            t[0].eval(x, y),
            t[1].eval(x, y),
            t[2].eval(x, y),
            t[3].eval(x, y),
            t[4].eval(x, y),
            t[5].eval(x, y),
        ]
    }
}

/// The pitch surface. Radii are in mm; for `Paraboloid` and `Sphere` the
/// sign chooses a bowl (positive) or a dome (negative). For `Cylinder` a
/// positive radius bends the layout down (a dome along x), negative up.
#[derive(Clone, Debug)]
pub enum PitchSurface {
    Plane,
    Saddle {
        radius: f64,
    },
    Paraboloid {
        radius: f64,
    },
    Cylinder {
        radius: f64,
    },
    Sphere {
        radius: f64,
    },
    Formula(FormulaSurface),
    /// A height map's smoothing spline ([`crate::heightmap`]), shared.
    HeightMap(std::sync::Arc<HeightMap>),
}

impl PitchSurface {
    /// The x-coordinate of every point with layout coordinate `u`.
    pub fn x_of_u(&self, u: f64) -> f64 {
        match self {
            PitchSurface::Cylinder { radius: r } => r * (u / r).sin(),
            _ => u,
        }
    }

    /// Height and its derivatives for graph surfaces: [h, hx, hy, hxx, hxy, hyy].
    fn height(&self, x: f64, y: f64) -> [f64; 6] {
        match self {
            PitchSurface::Plane => [0.0; 6],
            PitchSurface::Saddle { radius: r } => [
                (x * x - y * y) / (2.0 * r),
                x / r,
                -y / r,
                1.0 / r,
                0.0,
                -1.0 / r,
            ],
            PitchSurface::Paraboloid { radius: r } => [
                (x * x + y * y) / (2.0 * r),
                x / r,
                y / r,
                1.0 / r,
                0.0,
                1.0 / r,
            ],
            PitchSurface::Sphere { radius: r } => {
                // bowl (r > 0): z = R − √(R² − ρ²); dome: the negative.
                let (s, a) = (r.signum(), r.abs());
                let q = a * a - x * x - y * y;
                let w = q.sqrt(); // NaN outside the sphere: caught by validation
                let w3 = w * w * w;
                [
                    s * (a - w),
                    s * x / w,
                    s * y / w,
                    s * (a * a - y * y) / w3,
                    s * x * y / w3,
                    s * (a * a - x * x) / w3,
                ]
            }
            PitchSurface::Formula(f) => f.eval(x, y),
            PitchSurface::HeightMap(m) => m.eval(x, y),
            PitchSurface::Cylinder { .. } => unreachable!("cylinder is not a graph in this form"),
        }
    }

    /// Position only; cheaper than [`jet`](Self::jet).
    pub fn point(&self, u: f64, v: f64) -> DVec3 {
        match self {
            PitchSurface::Cylinder { radius: r } => {
                let a = u / r;
                DVec3::new(r * a.sin(), v, r * a.cos() - r)
            }
            PitchSurface::Plane => DVec3::new(u, v, 0.0),
            PitchSurface::Formula(f) => DVec3::new(u, v, f.value(u, v)),
            PitchSurface::HeightMap(m) => DVec3::new(u, v, m.value(u, v)),
            _ => DVec3::new(u, v, self.height(u, v)[0]),
        }
    }

    /// Position with first and second derivatives.
    pub fn jet(&self, u: f64, v: f64) -> Jet {
        match self {
            PitchSurface::Cylinder { radius: r } => {
                let a = u / r;
                let (s, c) = a.sin_cos();
                Jet {
                    p: DVec3::new(r * s, v, r * c - r),
                    du: DVec3::new(c, 0.0, -s),
                    dv: DVec3::Y,
                    duu: DVec3::new(-s / r, 0.0, -c / r),
                    duv: DVec3::ZERO,
                    dvv: DVec3::ZERO,
                }
            }
            _ => {
                let [h, hx, hy, hxx, hxy, hyy] = self.height(u, v);
                Jet {
                    p: DVec3::new(u, v, h),
                    du: DVec3::new(1.0, 0.0, hx),
                    dv: DVec3::new(0.0, 1.0, hy),
                    duu: DVec3::new(0.0, 0.0, hxx),
                    duv: DVec3::new(0.0, 0.0, hxy),
                    dvv: DVec3::new(0.0, 0.0, hyy),
                }
            }
        }
    }

    /// Position and outward unit normal together: graph surfaces evaluate
    /// their height function once (this is on the base's hot path).
    pub fn point_and_normal(&self, u: f64, v: f64) -> (DVec3, DVec3) {
        match self {
            PitchSurface::Plane | PitchSurface::Cylinder { .. } => {
                (self.point(u, v), self.normal(u, v))
            }
            PitchSurface::Formula(f) => {
                let (hx, hy) = f.gradient(u, v);
                (
                    DVec3::new(u, v, f.value(u, v)),
                    DVec3::new(-hx, -hy, 1.0).normalize(),
                )
            }
            _ => {
                let [h, hx, hy, ..] = self.height(u, v);
                (DVec3::new(u, v, h), DVec3::new(-hx, -hy, 1.0).normalize())
            }
        }
    }

    /// Outward unit normal n(u, v).
    pub fn normal(&self, u: f64, v: f64) -> DVec3 {
        match self {
            PitchSurface::Plane => DVec3::Z,
            PitchSurface::Cylinder { radius: r } => {
                let (s, c) = (u / r).sin_cos();
                DVec3::new(s, 0.0, c)
            }
            _ => {
                let (hx, hy) = match self {
                    PitchSurface::Formula(f) => f.gradient(u, v),
                    _ => {
                        let [_, hx, hy, ..] = self.height(u, v);
                        (hx, hy)
                    }
                };
                DVec3::new(-hx, -hy, 1.0).normalize()
            }
        }
    }

    /// How to make this surface curve or slope less, as a fix says it.
    pub fn gentler(&self) -> &'static str {
        match self {
            PitchSurface::Formula(_) => "make surface.z gentler",
            PitchSurface::HeightMap(_) => {
                "lower surface.z_max − surface.z_min, or raise surface.smoothing"
            }
            _ => "use a larger radius",
        }
    }

    /// A short name for reports.
    pub fn kind(&self) -> &'static str {
        match self {
            PitchSurface::Plane => "plane",
            PitchSurface::Saddle { .. } => "saddle",
            PitchSurface::Paraboloid { .. } => "paraboloid",
            PitchSurface::Cylinder { .. } => "cylinder",
            PitchSurface::Sphere { .. } => "sphere",
            PitchSurface::Formula(_) => "formula",
            PitchSurface::HeightMap(_) => "heightmap",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd_check(s: &PitchSurface, u: f64, v: f64) {
        let h = 1e-5;
        let j = s.jet(u, v);
        let du = (s.point(u + h, v) - s.point(u - h, v)) / (2.0 * h);
        let dv = (s.point(u, v + h) - s.point(u, v - h)) / (2.0 * h);
        assert!((du - j.du).length() < 1e-7, "{s:?} du {du} vs {}", j.du);
        assert!((dv - j.dv).length() < 1e-7, "{s:?} dv");
        let duu = (s.jet(u + h, v).du - s.jet(u - h, v).du) / (2.0 * h);
        let duv = (s.jet(u, v + h).du - s.jet(u, v - h).du) / (2.0 * h);
        let dvv = (s.jet(u, v + h).dv - s.jet(u, v - h).dv) / (2.0 * h);
        assert!((duu - j.duu).length() < 1e-6, "{s:?} duu");
        assert!((duv - j.duv).length() < 1e-6, "{s:?} duv");
        assert!((dvv - j.dvv).length() < 1e-6, "{s:?} dvv");
        assert!((j.normal() - s.normal(u, v)).length() < 1e-12);
        assert_eq!(s.point(u, v).y, v, "xy-separable: y == v exactly");
        assert_eq!(s.point(u, v).x, s.x_of_u(u));
        assert_eq!(s.point_and_normal(u, v), (s.point(u, v), s.normal(u, v)));
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let surfaces = [
            PitchSurface::Plane,
            PitchSurface::Saddle { radius: 60.0 },
            PitchSurface::Paraboloid { radius: -80.0 },
            PitchSurface::Cylinder { radius: 40.0 },
            PitchSurface::Sphere { radius: 90.0 },
            PitchSurface::Sphere { radius: -90.0 },
            PitchSurface::Formula(
                FormulaSurface::parse("(x*x - y*y)/120 + 0.3*sin(x/7)*cos(y/5)").unwrap(),
            ),
            PitchSurface::Formula(FormulaSurface::parse("x/10").unwrap()),
        ];
        for s in &surfaces {
            for &(u, v) in &[(0.0, 0.0), (7.3, -4.1), (-12.0, 13.5)] {
                fd_check(s, u, v);
            }
        }
    }

    #[test]
    fn formula_equals_closed_form_saddle() {
        let f = PitchSurface::Formula(FormulaSurface::parse("(x*x - y*y)/120").unwrap());
        let s = PitchSurface::Saddle { radius: 60.0 };
        let (a, b) = (f.jet(3.0, -7.0), s.jet(3.0, -7.0));
        assert!((a.p - b.p).length() < 1e-12 && (a.duu - b.duu).length() < 1e-12);
    }

    #[test]
    fn formula_rejects_unknown_variable() {
        assert!(FormulaSurface::parse("x + q")
            .unwrap_err()
            .problem
            .contains("`q`"));
    }

    #[test]
    fn sphere_sign_is_bowl_or_dome() {
        assert!(PitchSurface::Sphere { radius: 50.0 }.point(10.0, 0.0).z > 0.0);
        assert!(PitchSurface::Sphere { radius: -50.0 }.point(10.0, 0.0).z < 0.0);
        assert!(PitchSurface::Paraboloid { radius: 50.0 }.point(10.0, 0.0).z > 0.0);
        // curvature of a sphere is 1/R
        let k = PitchSurface::Sphere { radius: 50.0 }
            .jet(3.0, 4.0)
            .max_abs_curvature();
        assert!((k - 1.0 / 50.0).abs() < 1e-12);
    }
}
