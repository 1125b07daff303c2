//! One frame: an orthographic or perspective view of the device, tilted,
//! lit by two coloured lateral area lights below it (the dual-lens moiré
//! selects the direction light comes from, so its level lines take the
//! lights' colours) or, for a printed device, by a diffuse backlight behind
//! its black bands, with stratified supersampling. Deterministic for a seed.

use crate::scene::Scene;
use crate::trace::{trace_branches, trace_path, Pruning, SplitMix64};
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
    pub lighting: Lighting,
    pub integrator: Integrator,
    /// Seed of the sample jitter (and of the path tracer's choices).
    pub seed: u64,
}

/// How a pixel's light is integrated over the branches at each interface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Integrator {
    /// Every branch followed with its Fresnel weight: the exact expectation,
    /// no noise but the sample jitter's ([`trace_branches`]).
    Branching(Pruning),
    /// Monte Carlo path tracing, one branch at random ([`trace_path`]):
    /// the reference.
    Path,
}

/// The path tracer stays the default until the branching integrator's
/// pixel sampling is as clean as its branches (issue 19).
impl Default for Integrator {
    fn default() -> Self {
        Integrator::Path
    }
}

impl Integrator {
    /// What it is, for reports.
    pub fn describe(&self) -> String {
        match self {
            Integrator::Branching(p) => format!(
                "branching: both Fresnel branches followed at every interface, those under {} of a ray's weight or past {} interfaces dropped",
                p.min_weight, p.max_depth
            ),
            Integrator::Path => "path: Monte Carlo, one Fresnel branch chosen at random per interface".into(),
        }
    }
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

/// A rendered frame: per pixel its linear RGB colour, the scalar
/// [`Lighting::signal`] of it that fidelity scores, and the elevation phase
/// frac(A·e) of the layout point the pixel sees (NaN where it misses the
/// device's top).
pub struct Frame {
    pub width: usize,
    pub height: usize,
    /// Linear RGB, row-major; 1 is a light's full radiance in a channel.
    pub rgb: Vec<DVec3>,
    /// [`Lighting::signal`] of each pixel's colour.
    pub signal: Vec<f64>,
    pub phase: Vec<f64>,
    /// Pixels per lens period.
    pub period_px: f64,
    /// Mean weight per camera ray the branching integrator dropped
    /// (0 for the path tracer, whose dropped paths are its noise).
    pub dropped_weight: f64,
}

impl Frame {
    /// Mean Rec. 709 luminance of the linear colours.
    pub fn mean_luminance(&self) -> f64 {
        self.rgb.iter().map(|&c| luminance(c)).sum::<f64>() / self.rgb.len().max(1) as f64
    }

    /// The frame's [`crate::fidelity::local_fidelity`].
    pub fn local_fidelity(&self) -> f64 {
        crate::fidelity::local_fidelity(
            &self.signal,
            &self.phase,
            self.width,
            self.height,
            self.period_px,
        )
    }

    /// The frame's [`crate::fidelity()`].
    pub fn fidelity(&self) -> f64 {
        crate::fidelity(
            &self.signal,
            &self.phase,
            self.width,
            self.height,
            self.period_px,
        )
    }
}

/// Rec. 709 luminance of a linear RGB colour.
pub fn luminance(c: DVec3) -> f64 {
    c.dot(DVec3::new(0.2126, 0.7152, 0.0722))
}

/// Half-width (as a direction's x component) of the ramp between the two
/// lateral lights: each fills the directions below the device on its side.
pub const LIGHT_EDGE: f64 = 0.15;

/// Warm light from the +x side of the default dual-lens lighting.
pub const AMBER: DVec3 = DVec3::new(1.0, 0.6, 0.15);
/// Cool light from the −x side of the default dual-lens lighting.
pub const SKY_BLUE: DVec3 = DVec3::new(0.15, 0.45, 1.0);

/// The light a device is seen in (METHOD §8). Only the direction a path
/// leaves the device in matters: the lights are infinitely far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lighting {
    /// A printed device's diffuse backlight: every direction leaving
    /// downwards sees `colour`; nothing is lit above.
    Backlight { colour: DVec3 },
    /// The paper's lateral area lights, below a dual-lens device, one on
    /// each side: directions leaving downwards towards +x see `plus_x`,
    /// towards −x `minus_x`, blended over ±[`LIGHT_EDGE`] in direction x;
    /// nothing is lit above. The dual-lens moiré selects the direction light
    /// comes from, so its level lines take the two lights' colours.
    Lateral { plus_x: DVec3, minus_x: DVec3 },
}

impl Lighting {
    /// The default for a design: a white backlight behind a printed
    /// device's bands; amber from +x and sky blue from −x for a dual-lens one.
    pub fn default_for(design: &Design) -> Self {
        match design.params.base.kind {
            BaseKind::Printed(_) => Lighting::Backlight { colour: DVec3::ONE },
            BaseKind::DualLens => Lighting::Lateral {
                plus_x: AMBER,
                minus_x: SKY_BLUE,
            },
        }
    }

    /// The colour seen along a path that leaves the device in direction `d`.
    pub fn colour(&self, d: DVec3) -> DVec3 {
        if d.z >= 0.0 {
            return DVec3::ZERO;
        }
        match *self {
            Lighting::Backlight { colour } => colour,
            Lighting::Lateral { plus_x, minus_x } => {
                let w = (0.5 + 0.5 * d.x / LIGHT_EDGE).clamp(0.0, 1.0);
                w * plus_x + (1.0 - w) * minus_x
            }
        }
    }

    /// The scalar whose level lines fidelity scores. Under two lateral
    /// lights of different colours it is where the colour lies on the line
    /// from the −x light's colour (0) to the +x light's (1): the share of
    /// light from +x, whatever the colours. Otherwise it is the luminance,
    /// relative to the light's. Linear in the colour, so the signal of a
    /// pixel's mean colour is the mean of its samples' signals.
    pub fn signal(&self, rgb: DVec3) -> f64 {
        match *self {
            Lighting::Lateral { plus_x, minus_x } if plus_x.distance_squared(minus_x) > 1e-12 => {
                let axis = plus_x - minus_x;
                (rgb - minus_x).dot(axis) / axis.length_squared()
            }
            Lighting::Lateral { plus_x: c, .. } | Lighting::Backlight { colour: c } => {
                luminance(rgb) / luminance(c).max(1e-12)
            }
        }
    }

    /// What the lighting is, for reports.
    pub fn describe(&self) -> String {
        let hex = |c: DVec3| {
            let [r, g, b] = c
                .to_array()
                .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
            format!("#{r:02X}{g:02X}{b:02X}")
        };
        match *self {
            Lighting::Backlight { colour } => format!(
                "diffuse backlight {} below the device; black bands absorb",
                hex(colour)
            ),
            Lighting::Lateral { plus_x, minus_x } => format!(
                "lateral area lights below the device: {} towards +x, {} towards -x (soft edge ±{LIGHT_EDGE} in direction x)",
                hex(plus_x),
                hex(minus_x)
            ),
        }
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

/// Pixels per side of the square tiles a frame is traced in: neighbouring
/// rays walk the same part of the BVH, so tiles keep it in cache.
const TILE: usize = 8;

/// One frame of `scene` (the device's mesh, built once and shared by every
/// frame of it); `design` gives the index and the elevation phase.
pub fn render(design: &Design, scene: &Scene, view: View) -> Frame {
    let (lo, hi) = scene.bounds();
    let rot = DMat3::from_rotation_y(view.tilt_across) * DMat3::from_rotation_x(view.tilt_along);
    let dir = rot * DVec3::NEG_Z;
    let (du, dv) = (rot * DVec3::X, rot * DVec3::Y);
    let centre = 0.5 * (lo + hi);
    let extent = (hi - lo).x.max((hi - lo).y);
    let pixel = extent / view.width.max(view.height) as f64;
    let back = (hi - lo).length() + 1.0;
    let levels = design.params.base.levels;
    let lighting = view.lighting;
    // the ray towards the image-plane point `target`
    let ray = |target: DVec3| match view.camera {
        Camera::Orthographic => (target - back * dir, dir),
        Camera::Perspective { distance } => {
            let eye = centre - distance * dir;
            (eye, (target - eye).normalize())
        }
    };
    let n = view.samples.max(1);
    // the stratum whose sample gives the pixel its phase: the central one
    let central = (n / 2) * n + n / 2;
    let (width, height) = (view.width, view.height);
    // the colour, phase and dropped weight of pixel (px, py)
    let index = design.params.lens.index;
    let colour_of = |d: DVec3| lighting.colour(d);
    let pixel_of = |px: usize, py: usize| -> (DVec3, f64, f64) {
        let p = py * width + px;
        let mut rng = SplitMix64(view.seed ^ (p as u64).wrapping_mul(0x2545_F491_4F6C_DD1D));
        let (mut sum, mut phase, mut dropped) = (DVec3::ZERO, f64::NAN, 0.0);
        for s in 0..n * n {
            let (sx, sy) = (s % n, s / n);
            let fx = (px as f64 + (sx as f64 + rng.next_f64()) / n as f64) / width as f64 - 0.5;
            let fy = 0.5 - (py as f64 + (sy as f64 + rng.next_f64()) / n as f64) / height as f64;
            let target =
                centre + du * (fx * pixel * width as f64) + dv * (fy * pixel * height as f64);
            let (origin, d) = ray(target);
            let first = match view.integrator {
                Integrator::Path => {
                    let end = trace_path(scene, index, origin, d, &mut rng);
                    sum += end.leaves.map_or(DVec3::ZERO, |l| lighting.colour(l));
                    end.first
                }
                Integrator::Branching(pruning) => {
                    let b = trace_branches(scene, index, origin, d, &colour_of, pruning);
                    sum += b.colour;
                    dropped += b.dropped;
                    b.first
                }
            };
            if s == central {
                // the layout point this sample sees first, if on the device's top
                if let Some((q, _)) = first.filter(|(_, nrm)| nrm.z > 0.0) {
                    let (u, v) = layout_of(design, q.x, q.y);
                    phase = (levels * design.params.profile.value(u, v)).rem_euclid(1.0);
                }
            }
        }
        let samples = (n * n) as f64;
        (sum / samples, phase, dropped / samples)
    };
    let mut rgb = vec![DVec3::ZERO; width * height];
    let mut phase = vec![f64::NAN; width * height];
    let mut dropped = vec![0.0; width * height];
    // bands of TILE rows in parallel, each traced tile by tile, written in place
    let band = (width * TILE).max(1);
    rgb.par_chunks_mut(band)
        .zip(phase.par_chunks_mut(band))
        .zip(dropped.par_chunks_mut(band))
        .enumerate()
        .for_each(|(b, ((rgb, phase), dropped))| {
            let rows = rgb.len() / width.max(1);
            for x0 in (0..width).step_by(TILE) {
                for y in 0..rows {
                    for px in x0..(x0 + TILE).min(width) {
                        let (c, ph, dr) = pixel_of(px, b * TILE + y);
                        rgb[y * width + px] = c;
                        phase[y * width + px] = ph;
                        dropped[y * width + px] = dr;
                    }
                }
            }
        });
    Frame {
        width,
        height,
        signal: rgb.iter().map(|&c| lighting.signal(c)).collect(),
        rgb,
        phase,
        period_px: design.params.period / pixel,
        dropped_weight: dropped.iter().sum::<f64>() / dropped.len().max(1) as f64,
    }
}

/// [`render`] and the frame's [`crate::fidelity()`].
pub fn render_scored(design: &Design, scene: &Scene, view: View) -> (Frame, f64) {
    let frame = render(design, scene, view);
    let fidelity = frame.fidelity();
    (frame, fidelity)
}
