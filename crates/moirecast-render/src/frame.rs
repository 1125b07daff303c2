//! One frame: an orthographic view of the device, tilted, lit by a lateral
//! area light below it (the dual-lens moiré selects the direction light
//! comes from) or, for a printed device, by a diffuse backlight behind its
//! black bands, with stratified supersampling. Deterministic for a seed.

use crate::scene::Scene;
use crate::trace::{radiance, SplitMix64};
use glam::{DMat3, DVec3};
use moirecast_kernel::mesher::DeviceMesh;
use moirecast_kernel::{BaseKind, Design, KernelError, Mesh, PitchSurface};
use rayon::prelude::*;
use std::borrow::Cow;

/// How to render one frame.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub width: usize,
    pub height: usize,
    /// Samples per pixel along each axis (n × n, stratified).
    pub samples: usize,
    /// Tilt about the lens axis (y), radians: the tilt that makes the moiré beat.
    pub tilt_across: f64,
    /// Tilt about the x axis, radians.
    pub tilt_along: f64,
    pub camera: Camera,
    pub seed: u64,
}

/// How rays leave the camera.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum Camera {
    /// Parallel rays: every point of the device seen at the same angle.
    #[default]
    Orthographic,
    /// Rays from an eye `distance` mm from the device's centre, along the
    /// view direction; the device fills the frame. Points towards the edges
    /// are seen at angles up to atan(extent / 2 / distance) off the axis,
    /// as a viewer at that distance sees them.
    Perspective { distance: f64 },
}

/// A rendered frame and, per pixel, the elevation phase frac(A·e) of the
/// layout point the pixel sees (NaN where it misses the device).
pub struct Frame {
    pub width: usize,
    pub height: usize,
    pub luminance: Vec<f64>,
    pub phase: Vec<f64>,
    /// Pixels per lens period.
    pub period_px: f64,
}

/// Half-width (as a direction's x component) of the ramp between dark and
/// lit: the area light fills the directions with x > 0 below the device.
const LIGHT_EDGE: f64 = 0.15;

/// The lateral light: directions leaving the device downwards and towards
/// +x are lit, those towards −x dark, with a soft edge; nothing above.
pub fn lateral_light(d: DVec3) -> f64 {
    if d.z >= 0.0 {
        return 0.0;
    }
    (0.5 + 0.5 * d.x / LIGHT_EDGE).clamp(0.0, 1.0)
}

/// The diffuse backlight of a printed device (METHOD §8): every direction
/// leaving the device downwards reaches it; nothing is lit above.
pub fn backlight(d: DVec3) -> f64 {
    if d.z < 0.0 {
        1.0
    } else {
        0.0
    }
}

/// The light a design is seen in: a backlight behind a printed device's
/// bands, the lateral light for a dual-lens device, whose moiré selects the
/// direction light comes from.
pub fn light_for(design: &Design) -> fn(DVec3) -> f64 {
    match design.params.base.kind {
        BaseKind::Printed(_) => backlight,
        BaseKind::DualLens => lateral_light,
    }
}

/// What the tracer sees of a device: its mesh and, per triangle, whether it
/// absorbs. A dual-lens device is its mesh, all dielectric. A printed device
/// is its clear body, whose faces shared with the black bands absorb (the
/// black material is opaque): the very clear body that is printed. The
/// dual-lens mesh is borrowed, not copied.
pub fn traced_mesh<'m>(
    design: &Design,
    dm: &'m DeviceMesh,
) -> Result<(Cow<'m, Mesh>, Vec<bool>), KernelError> {
    match design.params.base.kind {
        BaseKind::DualLens => Ok((
            Cow::Borrowed(&dm.mesh),
            vec![false; dm.mesh.triangles.len()],
        )),
        BaseKind::Printed(_) => {
            let bodies = moirecast_kernel::printed::printed_bodies(design, dm)?;
            Ok((Cow::Owned(bodies.clear), bodies.clear_on_band))
        }
    }
}

/// Layout (u, v) of a point on the device's top seen at (x, y).
fn layout_of(design: &Design, x: f64, y: f64) -> (f64, f64) {
    match design.params.surface {
        PitchSurface::Cylinder { radius } => (radius * (x / radius).clamp(-1.0, 1.0).asin(), y),
        _ => (x, y),
    }
}

/// One frame of `scene` (the device's mesh, built once and shared by every
/// frame of it); `design` gives the index and the elevation phase.
pub fn render(design: &Design, scene: &Scene, view: View) -> Frame {
    let (lo, hi) = scene.mesh().bounds();
    let rot = DMat3::from_rotation_y(view.tilt_across) * DMat3::from_rotation_x(view.tilt_along);
    let dir = rot * DVec3::NEG_Z;
    let (du, dv) = (rot * DVec3::X, rot * DVec3::Y);
    let centre = 0.5 * (lo + hi);
    let extent = (hi - lo).x.max((hi - lo).y);
    let pixel = extent / view.width.max(view.height) as f64;
    let back = (hi - lo).length() + 1.0;
    let levels = design.params.base.levels;
    let light = light_for(design);
    // the ray towards the image-plane point `target`
    let ray = |target: DVec3| match view.camera {
        Camera::Orthographic => (target - back * dir, dir),
        Camera::Perspective { distance } => {
            let eye = centre - distance * dir;
            (eye, (target - eye).normalize())
        }
    };
    let n = view.samples.max(1);
    let pixels: Vec<(f64, f64)> = (0..view.width * view.height)
        .into_par_iter()
        .map(|p| {
            let (px, py) = (p % view.width, p / view.width);
            let mut rng = SplitMix64(view.seed ^ (p as u64).wrapping_mul(0x2545_F491_4F6C_DD1D));
            let mut sum = 0.0;
            for s in 0..n * n {
                let (sx, sy) = (s % n, s / n);
                let fx =
                    (px as f64 + (sx as f64 + rng.next_f64()) / n as f64) / view.width as f64 - 0.5;
                let fy = 0.5
                    - (py as f64 + (sy as f64 + rng.next_f64()) / n as f64) / view.height as f64;
                let target = centre
                    + du * (fx * pixel * view.width as f64)
                    + dv * (fy * pixel * view.height as f64);
                let (origin, d) = ray(target);
                sum += radiance(scene, design.params.lens.index, origin, d, &light, &mut rng);
            }
            // the phase at the pixel centre, from where its central ray meets the device
            let fx = (px as f64 + 0.5) / view.width as f64 - 0.5;
            let fy = 0.5 - (py as f64 + 0.5) / view.height as f64;
            let target = centre
                + du * (fx * pixel * view.width as f64)
                + dv * (fy * pixel * view.height as f64);
            let (origin, d) = ray(target);
            let phase = match scene.intersect(origin, d, 0.0) {
                Some(hit) if hit.normal.z > 0.0 => {
                    let q = origin + hit.t * d;
                    let (u, v) = layout_of(design, q.x, q.y);
                    (levels * design.params.profile.value(u, v)).rem_euclid(1.0)
                }
                _ => f64::NAN,
            };
            (sum / (n * n) as f64, phase)
        })
        .collect();
    let (luminance, phase) = pixels.into_iter().unzip();
    Frame {
        width: view.width,
        height: view.height,
        luminance,
        phase,
        period_px: design.params.period / pixel,
    }
}

/// [`render`] and the frame's [`crate::fidelity`].
pub fn render_scored(design: &Design, scene: &Scene, view: View) -> (Frame, f64) {
    let frame = render(design, scene, view);
    let fidelity = crate::fidelity(
        &frame.luminance,
        &frame.phase,
        frame.width,
        frame.height,
        frame.period_px,
    );
    (frame, fidelity)
}
