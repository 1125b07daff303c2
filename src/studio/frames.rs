//! The studio's frames: one worker thread per revision renders them, and
//! drops a request that a newer one overtook while it waited.
//!
//! The worker owns what frames are traced through, built on first need and
//! kept: a dual-lens device's exact sections per frame size (a frame tilted
//! about the lens axis only needs nothing else), and the device's mesh and
//! its BVH for the other frames (a tilt along, a printed device).

use crate::render::{png, LightsChoice, Tracer};
use moirecast_kernel::mesher::DeviceMesh;
use moirecast_kernel::progress::Silent;
use moirecast_kernel::BaseKind;
use moirecast_render::frame::{render_traced, traced_mesh, Camera, Integrator, Sampling, View};
use moirecast_render::section::Sections;
use moirecast_render::sheet::to_rgb8;
use moirecast_render::Scene;
use moirecast_spec::Spec;
use std::cell::OnceCell;
use std::collections::HashMap;
use std::sync::mpsc;
use std::sync::Arc;
use tokio::sync::oneshot;

/// Largest tilt (degrees) a frame request may ask for, either axis.
pub const MAX_TILT_DEG: f64 = 45.0;
/// Frame sizes (pixels) a request may ask for.
pub const SIZES: (usize, usize) = (16, 1024);
/// Lens phases per pixel, N²: N in this range.
pub const SAMPLES: (usize, usize) = (1, 8);

/// What a frame shows.
pub struct FrameRequest {
    /// About the lens axis, degrees.
    pub tilt_deg: f64,
    /// About the other axis, degrees.
    pub along_deg: f64,
    pub size: usize,
    /// N: N² lens phases per pixel.
    pub samples: usize,
    pub lights: LightsChoice,
}

impl FrameRequest {
    /// Refuses values out of range, naming the parameter and the range.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [("tilt", self.tilt_deg), ("along", self.along_deg)] {
            if !v.is_finite() || v.abs() > MAX_TILT_DEG {
                return Err(format!(
                    "{name}={v}: a tilt in degrees from -{MAX_TILT_DEG} to {MAX_TILT_DEG}"
                ));
            }
        }
        if !(SIZES.0..=SIZES.1).contains(&self.size) {
            return Err(format!(
                "size={}: a frame size from {} to {} pixels",
                self.size, SIZES.0, SIZES.1
            ));
        }
        if !(SAMPLES.0..=SAMPLES.1).contains(&self.samples) {
            return Err(format!(
                "samples={}: N from {} to {} (N² lens phases per pixel)",
                self.samples, SAMPLES.0, SAMPLES.1
            ));
        }
        Ok(())
    }
}

/// A rendered frame and its scores.
pub struct FrameImage {
    pub png: Vec<u8>,
    pub fidelity: f64,
    pub local_fidelity: f64,
    pub contrast: f64,
    pub milliseconds: f64,
}

pub enum FrameReply {
    Done(FrameImage),
    /// A newer request arrived before this one was rendered.
    Superseded,
    /// The design could not be traced (the command line's words).
    Failed(String),
}

struct FrameJob {
    request: FrameRequest,
    reply: oneshot::Sender<FrameReply>,
}

/// The frame worker of one revision; it ends when this is dropped.
pub struct Frames {
    jobs: mpsc::Sender<FrameJob>,
}

impl Frames {
    pub fn start(spec: Arc<Spec>) -> Frames {
        let (jobs, queue) = mpsc::channel();
        std::thread::Builder::new()
            .name("studio-frames".into())
            .spawn(move || work(&spec, queue))
            .expect("a thread for frames");
        Frames { jobs }
    }

    /// Renders `request`, or answers that a newer one overtook it.
    pub async fn render(&self, request: FrameRequest) -> FrameReply {
        let (reply, answer) = oneshot::channel();
        if self.jobs.send(FrameJob { request, reply }).is_err() {
            return FrameReply::Failed("error: the frame worker stopped".into());
        }
        answer
            .await
            .unwrap_or_else(|_| FrameReply::Failed("error: the frame worker stopped".into()))
    }
}

/// Serves frame jobs until every sender is gone, newest first.
fn work(spec: &Spec, queue: mpsc::Receiver<FrameJob>) {
    let design = &spec.design;
    let mesh: OnceCell<Result<DeviceMesh, String>> = OnceCell::new();
    let traced = OnceCell::new();
    let scene = OnceCell::new();
    let mut sections: HashMap<usize, Option<Sections>> = HashMap::new();
    while let Ok(mut job) = queue.recv() {
        while let Ok(newer) = queue.try_recv() {
            let _ = job.reply.send(FrameReply::Superseded);
            job = newer;
        }
        if job.reply.is_closed() {
            continue;
        }
        let started = std::time::Instant::now();
        let r = &job.request;
        let lighting = match r.lights.lighting(design) {
            Ok(l) => l,
            Err(e) => {
                let _ = job.reply.send(FrameReply::Failed(format!("error: {e:#}")));
                continue;
            }
        };
        // the sliders tilt from the design view: tilt 0 is the view the
        // base is compensated for
        let design_view = &design.params.view;
        let view = View {
            width: r.size,
            height: r.size,
            sampling: Sampling::LensPeriod(r.samples * r.samples),
            tilt_across: design_view.tilt + r.tilt_deg.to_radians(),
            tilt_along: design_view.tilt_along + r.along_deg.to_radians(),
            camera: design_view
                .distance
                .map_or(Camera::Orthographic, |distance| Camera::Perspective {
                    distance,
                }),
            lighting,
            integrator: Integrator::default(),
            seed: 1,
        };
        let dual_lens = design.params.base.kind == BaseKind::DualLens;
        let by_sections =
            dual_lens && view.tilt_along == 0.0 && view.camera == Camera::Orthographic;
        let section_set = if by_sections {
            sections
                .entry(r.size)
                .or_insert_with(|| Tracer::Sections.sections(design, r.size))
                .as_ref()
        } else {
            None
        };
        // A frame the sections trace whole needs no mesh.
        let frame = match section_set.and_then(|s| s.bounds()) {
            Some(bounds) => Ok(render_traced(
                design,
                &Scene::framing(bounds),
                section_set,
                view,
            )),
            None => {
                let mesh_scene = mesh
                    .get_or_init(|| {
                        crate::mesh_spec(spec, &Silent)
                            .map_err(|e| format!("error: {:#}", anyhow::Error::from(e)))
                    })
                    .as_ref()
                    .map_err(Clone::clone)
                    .and_then(|dm| {
                        traced
                            .get_or_init(|| {
                                traced_mesh(design, dm)
                                    .map_err(|e| format!("error: building the traced bodies: {e}"))
                            })
                            .as_ref()
                            .map_err(Clone::clone)
                    })
                    .map(|(m, absorbing)| {
                        scene.get_or_init(|| Scene::with_absorbing(m, absorbing.clone()))
                    });
                mesh_scene.map(|scene| render_traced(design, scene, section_set, view))
            }
        };
        let reply = match frame {
            Err(e) => FrameReply::Failed(e),
            Ok(frame) => {
                // the image and its three scores, side by side
                let (encoded, (fidelity, (local_fidelity, contrast))) = rayon::join(
                    || png(&to_rgb8(frame.width, frame.height, &frame.rgb)),
                    || {
                        rayon::join(
                            || frame.fidelity(),
                            || {
                                rayon::join(
                                    || frame.local_fidelity(),
                                    || frame.level_line_contrast(),
                                )
                            },
                        )
                    },
                );
                match encoded {
                    Err(e) => FrameReply::Failed(format!("error: encoding the frame: {e:#}")),
                    Ok(bytes) => FrameReply::Done(FrameImage {
                        png: bytes,
                        fidelity,
                        local_fidelity,
                        contrast,
                        milliseconds: started.elapsed().as_secs_f64() * 1e3,
                    }),
                }
            }
        };
        let _ = job.reply.send(reply);
    }
}
