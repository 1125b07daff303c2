//! The exact circular lens arc of METHOD §2, shared by the revealer and the
//! base arrays.

use glam::DVec3;

/// How a lens's radius follows from its chord.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ArcRule {
    /// Constant angular field of view: the arc spans `2·half_angle` (rad).
    ConstantAfov { half_angle: f64 },
    /// A fixed radius (mm); the angle follows from the chord.
    EqualRadius { radius: f64 },
}

/// One lens cross-section: a circular arc from `p0` to `p1`, bulging along
/// `bulge`. Its ends are exactly `p0` and `p1`, so neighbours share creases.
#[derive(Clone, Copy, Debug)]
pub struct LensArc {
    pub p0: DVec3,
    pub p1: DVec3,
    /// Unit chord direction ĉ.
    pub chord_dir: DVec3,
    /// Unit bulge direction m, perpendicular to ĉ.
    pub bulge: DVec3,
    pub radius: f64,
    pub half_angle: f64,
}

impl LensArc {
    /// The arc between distinct points `p0` and `p1`, bulging towards
    /// `toward` (projected perpendicular to the chord). An equal radius
    /// smaller than half the chord is raised to a half circle; design
    /// validation rejects such designs before they get here. A crease
    /// beyond a sphere's rim (NaN, far outside the layout, where the
    /// mesher samples the extended layout) gives an arc of NaNs, which
    /// callers take as no lens there.
    pub fn new(p0: DVec3, p1: DVec3, toward: DVec3, rule: ArcRule) -> Self {
        let c = p1 - p0;
        let w = c.length();
        debug_assert!(w > 0.0 || w.is_nan(), "lens creases coincide");
        let chord_dir = c / w;
        let bulge = (toward - toward.dot(chord_dir) * chord_dir).normalize();
        let (radius, half_angle) = match rule {
            ArcRule::ConstantAfov { half_angle } => (w / (2.0 * half_angle.sin()), half_angle),
            ArcRule::EqualRadius { radius } => {
                let radius = radius.max(w / 2.0);
                (radius, (w / (2.0 * radius)).min(1.0).asin())
            }
        };
        LensArc {
            p0,
            p1,
            chord_dir,
            bulge,
            radius,
            half_angle,
        }
    }

    pub fn width(&self) -> f64 {
        (self.p1 - self.p0).length()
    }

    /// Sag s = r(1 − cos(half angle)): the apex height over the chord.
    pub fn sag(&self) -> f64 {
        self.radius * (1.0 - self.half_angle.cos())
    }

    /// The point at parameter `t ∈ [0, 1]` (uniform in angle). `t = 0` and
    /// `t = 1` return `p0` and `p1` bit for bit.
    pub fn point(&self, t: f64) -> DVec3 {
        if t == 0.0 {
            return self.p0;
        }
        if t == 1.0 {
            return self.p1;
        }
        self.point_by_formula(t)
    }

    /// The arc formula A(θ) = M + r(cos θ − cos α/2) m + r sin θ ĉ, without
    /// the exact-end shortcut (for tests that the formula meets the creases).
    pub fn point_by_formula(&self, t: f64) -> DVec3 {
        let theta = self.half_angle * (2.0 * t - 1.0);
        let mid = 0.5 * (self.p0 + self.p1);
        mid + self.radius * (theta.cos() - self.half_angle.cos()) * self.bulge
            + self.radius * theta.sin() * self.chord_dir
    }

    /// The centre of the circle.
    pub fn centre(&self) -> DVec3 {
        0.5 * (self.p0 + self.p1) - self.radius * self.half_angle.cos() * self.bulge
    }
}

/// Columns needed across an arc of radius `r` spanning `angle` (rad) for a
/// chordal error of at most `e`.
pub fn columns_for(r: f64, angle: f64, e: f64) -> usize {
    let step = if e >= r {
        std::f64::consts::PI
    } else {
        2.0 * (1.0 - e / r).acos()
    };
    ((angle / step).ceil() as usize).max(2)
}

/// Circle through three points: (centre, radius). `None` if collinear.
pub fn circumcircle(a: DVec3, b: DVec3, c: DVec3) -> Option<(DVec3, f64)> {
    let (ab, ac) = (b - a, c - a);
    let n = ab.cross(ac);
    let n2 = n.length_squared();
    if n2 == 0.0 {
        return None;
    }
    let centre =
        a + (ac.length_squared() * n.cross(ab) + ab.length_squared() * ac.cross(n)) / (2.0 * n2);
    Some((centre, (centre - a).length()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arc_ends_and_apex() {
        let (p0, p1) = (DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.5, 0.0, 0.0));
        let a = LensArc::new(
            p0,
            p1,
            DVec3::Z,
            ArcRule::ConstantAfov {
                half_angle: 30f64.to_radians(),
            },
        );
        assert!((a.radius - 0.5).abs() < 1e-15);
        assert!((a.point_by_formula(0.0) - p0).length() < 1e-15);
        assert!((a.point_by_formula(1.0) - p1).length() < 1e-15);
        let apex = a.point(0.5);
        assert!((apex.z - a.sag()).abs() < 1e-15 && (apex.x - 0.25).abs() < 1e-15);
        let (c, r) = circumcircle(a.point(0.0), a.point(0.3), a.point(1.0)).unwrap();
        assert!((r - 0.5).abs() < 1e-14 && (c - a.centre()).length() < 1e-14);
    }
}
