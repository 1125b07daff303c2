//! The studio's frames: one worker thread per revision renders them, and
//! drops a request that a newer one overtook while it waited.
//!
//! The worker owns what frames are traced through, built on first need and
//! kept: a dual-lens device's exact sections per frame size (an
//! orthographic frame, tilted about either axis, needs nothing else), and
//! the device's mesh and its BVH for the other frames (a printed device, a
//! perspective view).

use crate::render::{png, LightsChoice, Tracer};
use moirecast_kernel::mesher::DeviceMesh;
use moirecast_kernel::progress::Silent;
use moirecast_kernel::BaseKind;
use moirecast_render::frame::{
    render_traced_while, traced_mesh, Camera, Integrator, Sampling, View,
};
use moirecast_render::section::Sections;
use moirecast_render::sheet::to_rgb8;
use moirecast_render::Scene;
use moirecast_spec::Spec;
use std::cell::OnceCell;
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use tokio::sync::oneshot;

/// Largest tilt (degrees) a frame request may ask for, either axis.
pub const MAX_TILT_DEG: f64 = 45.0;
/// Frame sizes (pixels) a request may ask for.
pub const SIZES: (usize, usize) = (16, 1024);
/// Lens phases per pixel, N²: N in this range.
pub const SAMPLES: (usize, usize) = (1, 8);
/// Most rays a frame may trace through the exact sections: a 1024 px
/// frame at 16 lens phases (the page's frames: 256 px at 9 or 16).
pub const SECTION_RAYS: usize = 1024 * 1024 * 16;
/// Most rays a frame may trace through the mesh (a printed device, a
/// perspective view), each several times a section ray's cost: four times the
/// page's 256 px at 16 phases. 1024 px at 64 phases, through the mesh at
/// a 30° tilt along, held the only frame worker for over 13 minutes.
pub const MESH_RAYS: usize = 4 * 256 * 256 * 16;

/// What a frame shows.
#[derive(Clone, Debug, PartialEq)]
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

    /// Refuses a frame past its budget of rays: [`SECTION_RAYS`] through
    /// a dual-lens device's sections, [`MESH_RAYS`] through the mesh.
    pub fn within_budget(&self, design: &moirecast_kernel::Design) -> Result<(), String> {
        let rays = self.size * self.size * self.samples * self.samples;
        let (budget, through) = if by_sections(design) {
            (SECTION_RAYS, "the exact sections")
        } else {
            (MESH_RAYS, "the mesh")
        };
        if rays > budget {
            return Err(format!(
                "size={} with samples={} traces {rays} rays through {through}, more than a frame's budget of {budget}: use a smaller size or fewer samples",
                self.size, self.samples
            ));
        }
        Ok(())
    }
}

/// Whether a frame is traced through a dual-lens device's exact sections
/// (an orthographic view, tilted about either axis; a tilt along follows
/// each ray's drift along the lenses, `moirecast_render::section::Drift`),
/// not through its mesh.
pub fn by_sections(design: &moirecast_kernel::Design) -> bool {
    design.params.base.kind == BaseKind::DualLens && design.params.view.distance.is_none()
}

/// A rendered frame and its scores.
pub struct FrameImage {
    pub png: Vec<u8>,
    pub fidelity: f64,
    pub local_fidelity: f64,
    pub contrast: f64,
    /// How long it took to render (when it was rendered, for a cached one).
    pub milliseconds: f64,
}

pub enum FrameReply {
    /// The frame, and whether it came from the revision's cache.
    Done(Arc<FrameImage>, bool),
    /// A newer request arrived before this one was rendered.
    Superseded,
    /// The design could not be traced (the command line's words).
    Failed(String),
}

struct FrameJob {
    /// The request's number: a job whose number is not the latest was
    /// overtaken.
    number: u64,
    request: FrameRequest,
    reply: oneshot::Sender<FrameReply>,
}

/// The frame worker of one revision; it ends when this is dropped.
pub struct Frames {
    jobs: mpsc::Sender<FrameJob>,
    /// The number of the latest request.
    latest: Arc<AtomicU64>,
    cache: Arc<Mutex<FrameCache>>,
}

/// Bytes of PNG the revision keeps: about 200 frames of 256 px.
const CACHE_BYTES: usize = 32 << 20;

/// The revision's frames already rendered, newest last, within
/// [`CACHE_BYTES`]: a request for a view it holds (a slider back at a tilt
/// it showed) is answered without tracing. A frame is a pure function of
/// the revision and its request, so a cached one is the frame itself.
#[derive(Default)]
struct FrameCache {
    frames: VecDeque<(FrameRequest, Arc<FrameImage>)>,
    bytes: usize,
}

impl FrameCache {
    fn get(&mut self, request: &FrameRequest) -> Option<Arc<FrameImage>> {
        let at = self.frames.iter().position(|(r, _)| r == request)?;
        let hit = self.frames.remove(at)?;
        let image = hit.1.clone();
        self.frames.push_back(hit);
        Some(image)
    }

    fn put(&mut self, request: FrameRequest, image: Arc<FrameImage>) {
        if self.get(&request).is_some() {
            return;
        }
        self.bytes += image.png.len();
        self.frames.push_back((request, image));
        while self.bytes > CACHE_BYTES {
            let Some((_, old)) = self.frames.pop_front() else {
                break;
            };
            self.bytes -= old.png.len();
        }
    }
}

impl Frames {
    pub fn start(spec: Arc<Spec>) -> Frames {
        let (jobs, queue) = mpsc::channel();
        let latest = Arc::new(AtomicU64::new(0));
        let cache = Arc::new(Mutex::new(FrameCache::default()));
        let (newest, kept) = (latest.clone(), cache.clone());
        std::thread::Builder::new()
            .name("studio-frames".into())
            .spawn(move || work(&spec, queue, (&newest, &kept)))
            .expect("a thread for frames");
        Frames {
            jobs,
            latest,
            cache,
        }
    }

    /// Renders `request`, or answers that a newer one overtook it (while it
    /// waited, or while it was traced: then it stops). A frame the revision
    /// rendered before is answered from its cache, and overtakes nothing.
    pub async fn render(&self, request: FrameRequest) -> FrameReply {
        let cached = self.cache.lock().expect("the frame cache").get(&request);
        if let Some(image) = cached {
            return FrameReply::Done(image, true);
        }
        let (reply, answer) = oneshot::channel();
        let number = self.latest.fetch_add(1, Ordering::SeqCst) + 1;
        let job = FrameJob {
            number,
            request,
            reply,
        };
        if self.jobs.send(job).is_err() {
            return FrameReply::Failed("error: the frame worker stopped".into());
        }
        answer
            .await
            .unwrap_or_else(|_| FrameReply::Failed("error: the frame worker stopped".into()))
    }
}

/// The device's mesh, its traced bodies and their BVH, each built once
/// on first need by a worker (locals of [`work`], which they borrow).
type MeshCell = OnceCell<Result<DeviceMesh, String>>;
type BodiesCell<'m> =
    OnceCell<Result<(std::borrow::Cow<'m, moirecast_kernel::Mesh>, Vec<bool>), String>>;

/// The mesh's scene (built once into the cells), or the error in the
/// command line's words.
fn mesh_scene<'m>(
    spec: &Spec,
    mesh: &'m MeshCell,
    bodies: &'m BodiesCell<'m>,
    scene: &'m OnceCell<Scene<'m>>,
) -> Result<&'m Scene<'m>, String> {
    let dm = mesh
        .get_or_init(|| {
            crate::mesh_spec(spec, &Silent)
                .map_err(|e| format!("error: {:#}", anyhow::Error::from(e)))
        })
        .as_ref()
        .map_err(Clone::clone)?;
    let (traced, absorbing) = bodies
        .get_or_init(|| {
            traced_mesh(&spec.design, dm)
                .map_err(|e| format!("error: building the traced bodies: {e}"))
        })
        .as_ref()
        .map_err(Clone::clone)?;
    Ok(scene.get_or_init(|| Scene::with_absorbing(traced, absorbing.clone())))
}

/// The view of `request`: its tilts count from the design view, tilt 0
/// being the view the base is compensated for.
fn view_of(
    design: &moirecast_kernel::Design,
    r: &FrameRequest,
    lighting: moirecast_render::frame::Lighting,
) -> View {
    let design_view = &design.params.view;
    View {
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
    }
}

/// The frame's PNG and its three scores, side by side.
fn encoded(frame: &moirecast_render::frame::Frame, started: std::time::Instant) -> FrameReply {
    let (encoded, (fidelity, (local_fidelity, contrast))) = rayon::join(
        || png(&to_rgb8(frame.width, frame.height, &frame.rgb)),
        || {
            rayon::join(
                || frame.fidelity(),
                || rayon::join(|| frame.local_fidelity(), || frame.level_line_contrast()),
            )
        },
    );
    match encoded {
        Err(e) => FrameReply::Failed(format!("error: encoding the frame: {e:#}")),
        Ok(bytes) => FrameReply::Done(
            Arc::new(FrameImage {
                png: bytes,
                fidelity,
                local_fidelity,
                contrast,
                milliseconds: started.elapsed().as_secs_f64() * 1e3,
            }),
            false,
        ),
    }
}

/// Serves frame jobs until every sender is gone, newest first. A frame
/// stops as soon as its client goes away or a newer request arrives.
fn work(
    spec: &Spec,
    queue: mpsc::Receiver<FrameJob>,
    (latest, cache): (&AtomicU64, &Mutex<FrameCache>),
) {
    let design = &spec.design;
    let (mesh, bodies, scene) = (OnceCell::new(), OnceCell::new(), OnceCell::new());
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
        let view = view_of(design, r, lighting);
        let keep_going = || !job.reply.is_closed() && latest.load(Ordering::SeqCst) == job.number;
        let through = by_sections(design)
            .then(|| {
                sections
                    .entry(r.size)
                    .or_insert_with(|| Tracer::Sections.sections(design, r.size))
                    .as_ref()
            })
            .flatten();
        // a frame the sections trace whole needs no mesh
        let frame = match through.and_then(|s| s.bounds()) {
            Some(bounds) => Ok(render_traced_while(
                design,
                &Scene::framing(bounds),
                through,
                view,
                &keep_going,
            )),
            None => mesh_scene(spec, &mesh, &bodies, &scene)
                .map(|scene| render_traced_while(design, scene, through, view, &keep_going)),
        };
        let reply = match frame {
            Err(e) => FrameReply::Failed(e),
            Ok(None) => FrameReply::Superseded,
            Ok(Some(frame)) => encoded(&frame, started),
        };
        if let FrameReply::Done(image, _) = &reply {
            let mut cache = cache.lock().expect("the frame cache");
            cache.put(job.request.clone(), image.clone());
        }
        let _ = job.reply.send(reply);
    }
}
