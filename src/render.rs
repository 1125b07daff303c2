//! `moirecast render`: the moiré of a design over a tilt sweep, before
//! anything is printed: `frame-NN.png`, `tilt.gif`, `sheet.png` and
//! `report.json` with the fidelity of every frame (METHOD §8).

use crate::{commit_with_report, refuse_failed};
use anyhow::{Context, Result};
use glam::DVec3;
use image::ImageEncoder;
use moirecast_export::OutputSet;
use moirecast_kernel::check::SolidMesh;
use moirecast_kernel::progress::Progress;
use moirecast_kernel::{BaseKind, Design};
use moirecast_render::frame::{
    render_scored, traced_mesh, Camera, Integrator, Lighting, Sampling, View,
};
use moirecast_render::section::Sections;
use moirecast_render::sheet::{contact_sheet, to_rgb8, Rgb8};
use moirecast_render::Scene;
use moirecast_spec::Spec;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// What to render (`moirecast render` and `moirecast explore`).
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Frame width and height (pixels).
    pub size: usize,
    /// Samples per pixel along each axis.
    pub samples: usize,
    /// Tilts about the lens axis (degrees), one frame each.
    pub tilts_deg: Vec<f64>,
    /// Tilt about the x axis (degrees), the same for every frame.
    pub tilt_along_deg: f64,
    /// Eye distance (mm) of a perspective camera; `None` is orthographic.
    pub camera_distance_mm: Option<f64>,
    pub lights: LightsChoice,
    pub integrator: Integrator,
    /// What the branching integrator traces where it can: a dual-lens
    /// device's exact cross-sections, or always the mesh.
    pub tracer: Tracer,
    pub seed: u64,
}

/// What is traced (`--tracer`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Tracer {
    /// The exact cross-sections of a dual-lens device
    /// ([`moirecast_render::section`]), where the view allows (orthographic,
    /// tilted about either axis); the mesh elsewhere.
    #[default]
    Sections,
    /// The mesh, as printed, everywhere.
    Mesh,
}

impl Tracer {
    /// What it is, for reports.
    pub fn describe(&self) -> &'static str {
        match self {
            Tracer::Sections => "sections: a dual-lens device's exact cross-sections where the view allows (orthographic, tilted about either axis), the mesh elsewhere",
            Tracer::Mesh => "mesh: the device's triangles, as printed",
        }
    }

    /// The sections of `design` to trace for frames of `size` pixels
    /// ([`Sections::for_frame`]). `None` for the mesh tracer or a printed device.
    pub fn sections<'d>(&self, design: &'d Design, size: usize) -> Option<Sections<'d>> {
        match self {
            Tracer::Sections => Sections::for_frame(design, size),
            Tracer::Mesh => None,
        }
    }
}

/// The lights asked for (`--lights`); [`LightsChoice::lighting`] makes them
/// a [`Lighting`] for a design.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum LightsChoice {
    /// The design's default: amber lateral light from +x and sky blue from
    /// −x (dual-lens), a white backlight (printed).
    #[default]
    Default,
    /// White from +x and none from −x (dual-lens), a white backlight
    /// (printed): luminance only, as in the Blender comparison.
    White,
    /// Colours given: +x and −x for dual-lens lateral lights; one for a
    /// printed device's backlight.
    Colours(Vec<DVec3>),
}

impl LightsChoice {
    /// Parses `default`, `white`, or comma-separated `#RRGGBB` colours.
    pub fn parse(text: &str) -> Result<Self, String> {
        match text.trim() {
            "default" => Ok(LightsChoice::Default),
            "white" => Ok(LightsChoice::White),
            list => list
                .split(',')
                .map(|c| {
                    let hex = c.trim().trim_start_matches('#');
                    let channel = |i: usize| {
                        hex.get(i..i + 2)
                            .and_then(|h| u8::from_str_radix(h, 16).ok())
                            .map(|v| v as f64 / 255.0)
                    };
                    match (hex.len(), channel(0), channel(2), channel(4)) {
                        (6, Some(r), Some(g), Some(b)) => Ok(DVec3::new(r, g, b)),
                        _ => Err(format!(
                            "{c:?} is not a colour: use #RRGGBB (hex), e.g. #FF9926,#2673FF, or `default` or `white`"
                        )),
                    }
                })
                .collect::<Result<_, _>>()
                .map(LightsChoice::Colours),
        }
    }

    /// The lighting for `design`; colours that do not fit its kind of base
    /// are refused by name.
    pub fn lighting(&self, design: &Design) -> Result<Lighting> {
        let printed = matches!(design.params.base.kind, BaseKind::Printed(_));
        Ok(match (self, printed) {
            (LightsChoice::Default, _) => Lighting::default_for(design),
            (LightsChoice::White, true) => Lighting::Backlight { colour: DVec3::ONE },
            (LightsChoice::White, false) => Lighting::Lateral {
                plus_x: DVec3::ONE,
                minus_x: DVec3::ZERO,
            },
            (LightsChoice::Colours(c), true) => match c[..] {
                [colour] => Lighting::Backlight { colour },
                _ => anyhow::bail!(
                    "--lights: a printed device has one backlight; give one colour, not {}",
                    c.len()
                ),
            },
            (LightsChoice::Colours(c), false) => match c[..] {
                [plus_x, minus_x] => Lighting::Lateral { plus_x, minus_x },
                _ => anyhow::bail!(
                    "--lights: a dual-lens device has two lateral lights; give two colours (+x side, then -x side), not {}",
                    c.len()
                ),
            },
        })
    }
}

impl RenderOptions {
    /// The command line's defaults at `size` px, N = `samples`, over
    /// `tilts_deg`: the branching integrator through the sections where
    /// they apply, the default lights, the design view's camera.
    pub fn preview(size: usize, samples: usize, tilts_deg: Vec<f64>) -> RenderOptions {
        RenderOptions {
            size,
            samples,
            tilts_deg,
            tilt_along_deg: 0.0,
            camera_distance_mm: None,
            lights: LightsChoice::Default,
            integrator: Integrator::default(),
            tracer: Tracer::Sections,
            seed: 1,
        }
    }

    /// Whether the sections trace every pixel the device covers in these
    /// frames: the branching integrator through a dual-lens device's
    /// sections, an orthographic camera.
    pub fn sections_trace_every_frame(&self, design: &Design) -> bool {
        self.tracer == Tracer::Sections
            && matches!(self.integrator, Integrator::Branching(_))
            && self.camera_distance(design).is_none()
    }

    /// The eye's distance of a perspective camera (mm): `--camera-distance`,
    /// else the design view's (`[view] distance`); `None`: orthographic.
    pub fn camera_distance(&self, design: &Design) -> Option<f64> {
        self.camera_distance_mm.or(design.params.view.distance)
    }

    /// The tilt about x (rad): the design view's and `--tilt-along`.
    fn tilt_along(&self, design: &Design) -> f64 {
        design.params.view.tilt_along + self.tilt_along_deg.to_radians()
    }

    /// Where each pixel's rays go: `samples`² fixed lens phases for the
    /// branching integrator, `samples` × `samples` jittered strata for the
    /// path tracer.
    pub fn sampling(&self) -> Sampling {
        match self.integrator {
            Integrator::Branching(_) => Sampling::LensPeriod(self.samples * self.samples),
            Integrator::Path => Sampling::Strata(self.samples),
        }
    }

    /// The view at `tilt_deg` about the lens axis from the design view
    /// (`[view]`: tilt 0 is the view the base is compensated for), in
    /// `lighting`.
    pub fn view(&self, design: &Design, tilt_deg: f64, lighting: Lighting) -> View {
        View {
            width: self.size,
            height: self.size,
            sampling: self.sampling(),
            tilt_across: design.params.view.tilt + tilt_deg.to_radians(),
            tilt_along: self.tilt_along(design),
            camera: match self.camera_distance(design) {
                None => Camera::Orthographic,
                Some(distance) => Camera::Perspective { distance },
            },
            lighting,
            integrator: self.integrator,
            seed: self.seed,
        }
    }
}

#[derive(Serialize)]
struct FrameReport {
    file: String,
    tilt_deg: f64,
    fidelity: f64,
    /// Fidelity within windows of the frame (beside METHOD §8; see
    /// `moirecast_render::fidelity::local_fidelity`).
    local_fidelity: f64,
    /// How strongly the frame shows the level lines, in units of the
    /// signal's full scale (`moirecast_render::fidelity::level_line_contrast`).
    contrast: f64,
    /// Mean Rec. 709 luminance of the frame's linear colours.
    mean_luminance: f64,
    /// Mean weight per camera ray that the branching integrator dropped
    /// (branches under its weight or past its depth).
    dropped_weight: f64,
}

#[derive(Serialize)]
struct RenderReport {
    moirecast: &'static str,
    spec: String,
    size_px: usize,
    samples_per_pixel: usize,
    sampling: String,
    seed: u64,
    pixels_per_period: f64,
    /// Tilt about the x axis of every frame (degrees).
    tilt_along_deg: f64,
    /// "orthographic", or the perspective eye's distance from the device's centre.
    camera: String,
    light: String,
    integrator: String,
    tracer: &'static str,
    frames: Vec<FrameReport>,
    /// The frame with the highest level-line contrast, and its scores.
    best_frame: usize,
    best_fidelity: f64,
    best_local_fidelity: f64,
    best_contrast: f64,
}

/// What `moirecast render` wrote.
pub struct RenderOutcome {
    pub written: Vec<PathBuf>,
    pub bytes: usize,
    /// (tilt in degrees, fidelity, local fidelity, level-line contrast) per frame.
    pub fidelity: Vec<(f64, f64, f64, f64)>,
}

/// PNG bytes of `image`: 8-bit grey where every pixel is grey (a printed
/// device's white backlight, `--lights white`), RGB otherwise.
pub(crate) fn png(image: &Rgb8) -> Result<Vec<u8>> {
    let grey: Option<Vec<u8>> = image
        .pixels
        .iter()
        .map(|&[r, g, b]| (r == g && g == b).then_some(r))
        .collect();
    let (bytes_in, colour) = match &grey {
        Some(grey) => (&grey[..], image::ExtendedColorType::L8),
        None => (image.bytes(), image::ExtendedColorType::Rgb8),
    };
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes).write_image(
        bytes_in,
        image.width as u32,
        image.height as u32,
        colour,
    )?;
    Ok(bytes)
}

fn gif(frames: &[Rgb8]) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    {
        let mut encoder = image::codecs::gif::GifEncoder::new_with_speed(&mut bytes, 10);
        encoder.set_repeat(image::codecs::gif::Repeat::Infinite)?;
        for g in frames {
            let rgba: Vec<u8> = g
                .pixels
                .iter()
                .flat_map(|&[r, g, b]| [r, g, b, 255])
                .collect();
            let buffer = image::RgbaImage::from_raw(g.width as u32, g.height as u32, rgba)
                .context("frame buffer")?;
            encoder.encode_frame(image::Frame::from_parts(
                buffer,
                0,
                0,
                image::Delay::from_numer_denom_ms(150, 1),
            ))?;
        }
    }
    Ok(bytes)
}

/// One rendered frame and its METHOD §8 fidelity.
pub struct RenderedFrame {
    pub tilt_deg: f64,
    pub frame: moirecast_render::frame::Frame,
    pub fidelity: f64,
}

/// Renders `spec` at every tilt of `options`, handing each frame to
/// `each` as it is done (a frame of 4096 px holds 670 MB): what `moirecast
/// render` writes, before it is encoded.
pub fn render_frames(
    spec: &Spec,
    options: &RenderOptions,
    progress: &dyn Progress,
    each: &mut dyn FnMut(RenderedFrame) -> Result<()>,
) -> Result<()> {
    let design = &spec.design;
    let lighting = options.lights.lighting(design)?;
    let dm = crate::mesh_spec(spec, progress)?;
    let (checks, _) = SolidMesh::validate(&dm.mesh);
    refuse_failed(&checks)?;
    progress.stage("rendering", options.tilts_deg.len() as u64);
    let (mesh, absorbing) = traced_mesh(design, &dm).context("building the traced bodies")?;
    let (lo, hi) = mesh.bounds();
    if let Some(d) = options.camera_distance(design) {
        let reach = 0.5 * (hi - lo).length();
        anyhow::ensure!(
            d > reach,
            "--camera-distance {d} mm puts the eye inside the device's bounding sphere ({reach:.1} mm around its centre); use more than {:.0} mm",
            reach.ceil()
        );
    }
    let sections = options.tracer.sections(design, options.size);
    // Frames the sections trace whole need no BVH: an empty scene frames
    // them as the mesh would.
    let scene = match sections.as_ref() {
        Some(_) if options.sections_trace_every_frame(design) => Scene::framing((lo, hi)),
        _ => Scene::with_absorbing(&mesh, absorbing),
    };
    for &tilt_deg in &options.tilts_deg {
        let view = options.view(design, tilt_deg, lighting);
        let (frame, fidelity) = render_scored(design, &scene, sections.as_ref(), view);
        progress.tick(1);
        each(RenderedFrame {
            tilt_deg,
            frame,
            fidelity,
        })?;
    }
    Ok(())
}

pub fn run_render(
    spec: &Spec,
    out: &Path,
    options: &RenderOptions,
    progress: &dyn Progress,
) -> Result<RenderOutcome> {
    let design = &spec.design;
    let lighting = options.lights.lighting(design)?;
    let mut files = OutputSet::new();
    let (mut images, mut reports) = (Vec::new(), Vec::new());
    let mut period_px = 0.0;
    render_frames(spec, options, progress, &mut |r| {
        let frame = &r.frame;
        period_px = frame.period_px;
        let image = to_rgb8(frame.width, frame.height, &frame.rgb);
        let name = format!("frame-{:02}.png", reports.len());
        files.add(&name, png(&image)?);
        reports.push(FrameReport {
            file: name,
            tilt_deg: r.tilt_deg,
            fidelity: r.fidelity,
            local_fidelity: frame.local_fidelity(),
            contrast: frame.level_line_contrast(),
            mean_luminance: frame.mean_luminance(),
            dropped_weight: frame.dropped_weight,
        });
        images.push(image);
        Ok(())
    })?;
    let labelled: Vec<(Rgb8, String)> = images
        .iter()
        .zip(&reports)
        .map(|(g, r)| (g.clone(), format!("{:+.1}°", r.tilt_deg)))
        .collect();
    let columns = (labelled.len() as f64).sqrt().ceil() as usize;
    files.add("sheet.png", png(&contact_sheet(&labelled, columns))?);
    files.add("tilt.gif", gif(&images)?);
    let best = reports.iter().enumerate().fold(0, |b, (i, r)| {
        if r.contrast > reports[b].contrast {
            i
        } else {
            b
        }
    });
    let fidelity = reports
        .iter()
        .map(|r| (r.tilt_deg, r.fidelity, r.local_fidelity, r.contrast))
        .collect();
    let report = RenderReport {
        moirecast: env!("CARGO_PKG_VERSION"),
        spec: crate::report::spec_name(spec),
        size_px: options.size,
        samples_per_pixel: options.samples * options.samples,
        sampling: options.sampling().describe(),
        seed: options.seed,
        pixels_per_period: period_px,
        tilt_along_deg: options.tilt_along_deg,
        camera: match options.camera_distance(design) {
            None => "orthographic".into(),
            Some(d) => format!("perspective, eye {d} mm from the device's centre"),
        },
        light: lighting.describe(),
        integrator: options.integrator.describe(),
        tracer: options.tracer.describe(),
        best_frame: best,
        best_fidelity: reports.get(best).map_or(0.0, |r| r.fidelity),
        best_local_fidelity: reports.get(best).map_or(0.0, |r| r.local_fidelity),
        best_contrast: reports.get(best).map_or(0.0, |r| r.contrast),
        frames: reports,
    };
    let (written, bytes) = commit_with_report(files, spec, &report, out)?;
    Ok(RenderOutcome {
        written,
        bytes,
        fidelity,
    })
}
