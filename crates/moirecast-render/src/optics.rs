//! Dielectric interfaces: Snell's law, unpolarised Fresnel reflectance and
//! total internal reflection. Directions are unit vectors; `normal` faces
//! the side the ray comes from (`d · normal < 0`).

use glam::DVec3;

/// Mirror reflection of `d` about `normal`.
pub fn reflect(d: DVec3, normal: DVec3) -> DVec3 {
    d - 2.0 * d.dot(normal) * normal
}

/// The refracted direction going from index `n1` into `n2`, or `None` at
/// total internal reflection.
pub fn refract(d: DVec3, normal: DVec3, n1: f64, n2: f64) -> Option<DVec3> {
    split(d, normal, n1, n2).refracted
}

/// Unpolarised Fresnel reflectance (the mean of s and p) for a ray meeting
/// the interface from index `n1` into `n2` at `cos_i` (> 0); 1 at total
/// internal reflection.
pub fn fresnel(cos_i: f64, n1: f64, n2: f64) -> f64 {
    let sin2_t = snell(cos_i, n1 / n2);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    reflectance(cos_i, (1.0 - sin2_t).sqrt(), n1, n2)
}

/// sin² of the refracted angle, by Snell's law, for a ray meeting the
/// interface at `cos_i` with index ratio `eta` = n1 / n2 (over 1: total
/// internal reflection).
fn snell(cos_i: f64, eta: f64) -> f64 {
    eta * eta * (1.0 - cos_i * cos_i).max(0.0)
}

/// The mean of the s and p reflectances at `cos_i` in, `cos_t` out.
fn reflectance(cos_i: f64, cos_t: f64, n1: f64, n2: f64) -> f64 {
    let rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t);
    let rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i);
    0.5 * (rs * rs + rp * rp)
}

/// What a ray meets at an interface: its reflection, its refraction and
/// the Fresnel reflectance, each as [`reflect`], [`refract`] and
/// [`fresnel`] give it, with Snell's law solved once for the three.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Split {
    pub reflected: DVec3,
    pub refracted: Option<DVec3>,
    pub reflectance: f64,
}

/// The ray `d` meeting a surface of `normal` (facing it) from index `n1`
/// into `n2`.
pub fn split(d: DVec3, normal: DVec3, n1: f64, n2: f64) -> Split {
    let eta = n1 / n2;
    let cos_i = -d.dot(normal);
    let sin2_t = snell(cos_i, eta);
    let cos_t = (1.0 - sin2_t).sqrt();
    Split {
        reflected: reflect(d, normal),
        refracted: (sin2_t <= 1.0).then(|| (eta * d + (eta * cos_i - cos_t) * normal).normalize()),
        reflectance: if sin2_t >= 1.0 {
            1.0
        } else {
            reflectance(cos_i, cos_t, n1, n2)
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snell_fresnel_and_total_internal_reflection() {
        let n = DVec3::Z;
        // normal incidence: ((n1 − n2) / (n1 + n2))², straight through
        assert!((fresnel(1.0, 1.0, 1.5) - 0.04).abs() < 1e-15);
        assert_eq!(refract(-DVec3::Z, n, 1.0, 1.5).unwrap(), -DVec3::Z);
        // Snell: n1 sin θ1 = n2 sin θ2, in the plane of incidence
        let theta: f64 = 50f64.to_radians();
        let d = DVec3::new(theta.sin(), 0.0, -theta.cos());
        let t = refract(d, n, 1.0, 1.41).unwrap();
        assert!((t.x - theta.sin() / 1.41).abs() < 1e-15 && t.y == 0.0 && t.z < 0.0);
        // Brewster's angle: p reflectance vanishes, so R = Rs / 2
        let brewster = 1.5f64.atan();
        let cos_t = (1.0 - (brewster.sin() / 1.5).powi(2)).sqrt();
        let rs = (brewster.cos() - 1.5 * cos_t) / (brewster.cos() + 1.5 * cos_t);
        assert!((fresnel(brewster.cos(), 1.0, 1.5) - 0.5 * rs * rs).abs() < 1e-15);
        // from inside, beyond the critical angle asin(1/1.41): total reflection
        let critical = (1.0f64 / 1.41).asin();
        for (angle, tir) in [(critical - 1e-6, false), (critical + 1e-6, true)] {
            let d = DVec3::new(angle.sin(), 0.0, angle.cos());
            assert_eq!(refract(d, -DVec3::Z, 1.41, 1.0).is_none(), tir);
            assert_eq!(fresnel(angle.cos(), 1.41, 1.0) == 1.0, tir);
        }
        assert_eq!(reflect(d, n), DVec3::new(d.x, 0.0, -d.z));
    }
}
