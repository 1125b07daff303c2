//! The `moirecast` command line.

use anyhow::Result;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use moirecast_kernel::progress::Progress;
use std::path::PathBuf;
use std::sync::Mutex;

#[derive(Parser)]
#[command(name = "moirecast", version, about = "Curved-surface level-line moiré devices and their casting molds.", after_help = moirecast_spec::defaults_help())]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Build the device: DIR/device.stl, DIR/device.step (B-rep) and DIR/report.json.
    Device {
        #[command(flatten)]
        run: RunArgs,
        /// Measure every vertex and lens triangle against the exact model
        /// (the default samples a few thousand; slower, same checks).
        #[arg(long)]
        full_checks: bool,
        /// `direct`: our mesher, straight from the exact model. `brep`:
        /// truck-meshalgo's tessellation of the B-rep, welded and
        /// cross-checked against the direct mesh (closed, within 2 ×
        /// tolerance, volume within lens area × tolerance) before it is
        /// written; slow, and it fails on designs with trimmed faces.
        #[arg(long, value_enum, default_value = "direct")]
        mesher: MesherArg,
    },
    /// Render the moiré over a tilt sweep before printing: DIR/frame-NN.png,
    /// DIR/tilt.gif, DIR/sheet.png and DIR/report.json (fidelity per frame).
    Render {
        #[command(flatten)]
        run: RunArgs,
        /// Frame width and height in pixels.
        #[arg(long, default_value_t = 256)]
        size: usize,
        /// Rays per pixel, N²: `branching` traces them at N² fixed lens
        /// phases across one lens period (no noise, no seed), `path` at
        /// N × N jittered strata of the pixel.
        #[arg(long, default_value_t = 4)]
        samples: usize,
        /// Tilts about the lens axis, degrees, comma-separated.
        #[arg(
            long,
            value_delimiter = ',',
            allow_hyphen_values = true,
            default_value = "-10,-7.5,-5,-2.5,0,2.5,5,7.5,10"
        )]
        tilts: Vec<f64>,
        #[command(flatten)]
        view: ViewArgs,
    },
    /// Score the (a, d) design space (METHOD §3) by moiré fidelity, as in
    /// the paper's Fig. 7: a from 0 to 1, d from 0.6 to 1.4 D_s. Writes
    /// DIR/grid.png (cells labelled "a d/D_s"), DIR/report.json and
    /// DIR/best.toml (the spec of the best cell).
    Explore {
        #[command(flatten)]
        run: RunArgs,
        /// Cell width and height in pixels.
        #[arg(long, default_value_t = 96)]
        size: usize,
        /// Rays per pixel, N², as for `render`.
        #[arg(long, default_value_t = 2)]
        samples: usize,
        /// Tilts tried per cell (the best counts), degrees, comma-separated.
        #[arg(
            long,
            value_delimiter = ',',
            allow_hyphen_values = true,
            default_value = "-5,0,5"
        )]
        tilts: Vec<f64>,
        #[command(flatten)]
        view: ViewArgs,
    },
    /// Design live in the browser: a local page with the spec's every key,
    /// the moiré under tilt sliders, the (a, d) grid, the device and mold
    /// in 3D, the checks, and "Write files" into DIR. Prints its URL.
    Studio {
        /// The spec to edit ("Save spec" writes it back). Without it, the
        /// reference design, saved as DIR/spec.toml.
        spec: Option<PathBuf>,
        /// Where "Write files" writes.
        #[arg(short, long, default_value = "moirecast-out")]
        out: PathBuf,
        /// Port; 0 picks a free one.
        #[arg(long, default_value_t = 7878)]
        port: u16,
        /// Address to listen on. Anything but loopback lets other machines
        /// use the page, and write files here: a warning says so.
        #[arg(long, default_value = "127.0.0.1")]
        host: std::net::IpAddr,
        /// Build designs over the budget (about 4 GB at a mold run's peak):
        /// without it the studio refuses them, naming the estimate.
        #[arg(long)]
        allow_large: bool,
    },
    /// Build the device and its two-piece casting mold: DIR/mold-top.stl and
    /// DIR/mold-bottom.stl, the same halves as exact B-reps DIR/mold-top.step
    /// and DIR/mold-bottom.step, the cavity's shape as DIR/device.stl and
    /// DIR/device.step (mold frame), DIR/assembly.scad, the construction
    /// solids and DIR/report.json.
    Mold {
        #[command(flatten)]
        run: RunArgs,
        /// Write the files even if a mold check fails, and mark the failure
        /// in report.json. Meshes that are not solids are never written.
        #[arg(long)]
        force: bool,
    },
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum MesherArg {
    Direct,
    Brep,
}

/// What `render` and `explore` share, with the same defaults.
#[derive(clap::Args)]
struct ViewArgs {
    /// Tilt about the x axis (the other axis: the lens axes tip towards
    /// or away from the viewer), degrees, the same for every frame.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    tilt_along: f64,
    /// A perspective camera with its eye this far (mm) from the device's
    /// centre; left out, the camera is orthographic.
    #[arg(long)]
    camera_distance: Option<f64>,
    /// Light colours: `default` (dual-lens: amber lateral light from +x,
    /// sky blue from -x; printed: white backlight), `white` (white from +x
    /// only; white backlight), or #RRGGBB colours: two (+x, -x) for a
    /// dual-lens device, one for a printed device's backlight.
    #[arg(long, default_value = "default", value_parser = moirecast::render::LightsChoice::parse)]
    lights: moirecast::render::LightsChoice,
    /// Seed of the path tracer's sample jitter and choices: the same seed
    /// gives the same frames.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// `branching`: every Fresnel branch followed with its weight, through
    /// fixed lens phases: no noise, and the seed does not matter
    /// (report.json states the pruning and the weight dropped). `path`:
    /// Monte Carlo path tracing, one Fresnel branch chosen at random per
    /// interface, through jittered pixel strata: the reference.
    #[arg(long, value_enum, default_value = "branching")]
    integrator: IntegratorArg,
    /// `sections`: the branching integrator traces a dual-lens device's
    /// exact cross-sections where the view allows (orthographic), a
    /// preview many times faster than the mesh. `mesh`:
    /// the device's triangles, as printed, everywhere.
    #[arg(long, value_enum, default_value = "sections")]
    tracer: TracerArg,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum TracerArg {
    Sections,
    Mesh,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum IntegratorArg {
    Branching,
    Path,
}

/// The view options, refused when out of range before anything is built.
fn view_options(
    size: usize,
    samples: usize,
    tilts: Vec<f64>,
    view: ViewArgs,
) -> Result<moirecast::render::RenderOptions> {
    let ViewArgs {
        tilt_along,
        camera_distance,
        lights,
        seed,
        integrator,
        tracer,
    } = view;
    if let Some(d) = camera_distance.filter(|d| !d.is_finite() || *d <= 0.0) {
        anyhow::bail!("--camera-distance: {d} is not a distance in mm");
    }
    if size == 0 || size > 4096 || samples == 0 || samples > 16 || tilts.is_empty() {
        anyhow::bail!(
            "--size must be 1..=4096 (got {size}), --samples 1..=16 (got {samples}), and --tilts must name at least one angle"
        );
    }
    if let Some(t) = tilts.iter().find(|t| !t.is_finite() || t.abs() >= 60.0) {
        anyhow::bail!("--tilts: {t} is not a tilt in (-60, 60) degrees");
    }
    if !tilt_along.is_finite() || tilt_along.abs() >= 60.0 {
        anyhow::bail!("--tilt-along: {tilt_along} is not a tilt in (-60, 60) degrees");
    }
    Ok(moirecast::render::RenderOptions {
        size,
        samples,
        tilts_deg: tilts,
        tilt_along_deg: tilt_along,
        camera_distance_mm: camera_distance,
        lights,
        integrator: match integrator {
            IntegratorArg::Branching => moirecast_render::frame::Integrator::Branching(
                moirecast_render::trace::Pruning::DEFAULT,
            ),
            IntegratorArg::Path => moirecast_render::frame::Integrator::Path,
        },
        tracer: match tracer {
            TracerArg::Sections => moirecast::render::Tracer::Sections,
            TracerArg::Mesh => moirecast::render::Tracer::Mesh,
        },
        seed,
    })
}

/// What every command takes.
#[derive(clap::Args)]
struct RunArgs {
    /// The design spec (TOML; `moirecast mold` reads its optional [mold]
    /// table). Without it, the embedded reference design (saddle + horse).
    spec: Option<PathBuf>,
    /// Output directory.
    #[arg(short, long, default_value = "moirecast-out")]
    out: PathBuf,
    /// No progress bars.
    #[arg(short, long)]
    quiet: bool,
    /// Print how long each stage took.
    #[arg(short, long)]
    verbose: bool,
    /// Build designs over the run budget (about 4 GB at a mold run's peak,
    /// and a survey of 64 M cells): without it they are refused with the
    /// estimate before any meshing.
    #[arg(long)]
    allow_large: bool,
}

fn bars(quiet: bool, verbose: bool) -> Bars {
    Bars {
        quiet,
        verbose,
        bar: Mutex::new(None),
        stage_started: Mutex::new(None),
    }
}

/// The closing lines of a run: every file written, the size and the time.
fn print_written(written: &[PathBuf], bytes: usize, started: std::time::Instant) {
    for f in written {
        eprintln!("wrote {}", f.display());
    }
    eprintln!(
        "{:.1} MB in {:.2} s",
        bytes as f64 / 1e6,
        started.elapsed().as_secs_f64()
    );
}

/// Progress bars, the start time, and the loaded spec.
fn start(run: &RunArgs) -> Result<(Bars, std::time::Instant, moirecast_spec::Spec)> {
    let bars = bars(run.quiet, run.verbose);
    let started = std::time::Instant::now();
    bars.stage("reading spec", 1);
    let mut spec = load_spec(&run.spec)?;
    if run.allow_large {
        spec.design.mesh_budget = moirecast_kernel::MeshBudget::UNLIMITED;
    }
    for w in moirecast::report::view_warnings(spec.design.view.as_ref()) {
        eprintln!("warning: {w}");
    }
    Ok((bars, started, spec))
}

fn load_spec(spec: &Option<PathBuf>) -> Result<moirecast_spec::Spec> {
    Ok(match spec {
        Some(path) => moirecast_spec::load(path)?,
        None => {
            eprintln!("no spec given: building the reference design (molds/saddle-horse.toml)");
            moirecast_spec::default_spec()?
        }
    })
}

/// Draws the kernel's stages as indicatif bars on stderr (hidden when
/// stderr is not a terminal).
struct Bars {
    quiet: bool,
    verbose: bool,
    bar: Mutex<Option<ProgressBar>>,
    stage_started: Mutex<Option<(&'static str, std::time::Instant)>>,
}

impl Progress for Bars {
    fn stage(&self, name: &'static str, total: u64) {
        self.end_stage(Some(name));
        let mut bar = self.bar.lock().unwrap();
        if let Some(b) = bar.take() {
            b.finish_and_clear();
        }
        if !self.quiet {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(
                    "{spinner} {msg:<22} [{bar:30}] {pos}/{len} {elapsed}",
                )
                .unwrap()
                .progress_chars("=> "),
            );
            b.set_message(name);
            *bar = Some(b);
        }
    }
    fn tick(&self, n: u64) {
        if let Some(b) = self.bar.lock().unwrap().as_ref() {
            b.inc(n);
        }
    }
}

impl Bars {
    fn end_stage(&self, next: Option<&'static str>) {
        let mut started = self.stage_started.lock().unwrap();
        if let (true, Some((name, t))) = (self.verbose, started.as_ref()) {
            eprintln!("  {name:<22} {:8.1} ms", t.elapsed().as_secs_f64() * 1e3);
        }
        *started = next.map(|n| (n, std::time::Instant::now()));
    }

    fn done(&self) {
        self.end_stage(None);
        if let Some(b) = self.bar.lock().unwrap().take() {
            b.finish_and_clear();
        }
    }
}

fn main() -> std::process::ExitCode {
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    let command = cli.command.unwrap_or(Command::Device {
        run: RunArgs {
            spec: None,
            out: PathBuf::from("moirecast-out"),
            quiet: false,
            verbose: false,
            allow_large: false,
        },
        full_checks: false,
        mesher: MesherArg::Direct,
    });
    match command {
        Command::Device {
            run,
            full_checks,
            mesher,
        } => {
            let (bars, started, spec) = start(&run)?;
            let (out, quiet) = (run.out, run.quiet);
            let result = moirecast::run_device(
                &spec,
                &out,
                if full_checks {
                    moirecast::Thoroughness::Full
                } else {
                    moirecast::Thoroughness::Sampled
                },
                match mesher {
                    MesherArg::Direct => moirecast::Mesher::Direct,
                    MesherArg::Brep => moirecast::Mesher::Brep,
                },
                &bars,
            );
            bars.done();
            let done = result?;
            if !quiet {
                let d = &spec.design;
                eprintln!(
                    "{} lenses on a {} ({} × {} mm): {} triangles, {:.1} mm³, surface within {:.2} µm of exact (tolerance {} µm); {} checks passed",
                    d.lenses,
                    d.params.surface.kind(),
                    d.params.width,
                    d.params.height,
                    done.triangles,
                    done.volume_mm3,
                    done.worst_surface_error_mm * 1e3,
                    // the spec's own digits, without the mm → µm product's
                    // round-off (1.068, not 1.0679999999999998)
                    (d.tolerance.mm() * 1e9).round() / 1e6,
                    done.checks
                );
                print_written(&done.written, done.bytes, started);
            }
        }
        Command::Render {
            run,
            size,
            samples,
            tilts,
            view,
        } => {
            let options = view_options(size, samples, tilts, view)?;
            let (bars, started, spec) = start(&run)?;
            let result = moirecast::render::run_render(&spec, &run.out, &options, &bars);
            bars.done();
            let done = result?;
            if !run.quiet {
                for (tilt, f, local, contrast) in &done.fidelity {
                    eprintln!("tilt {tilt:+6.1}°: fidelity {f:.3}, local fidelity {local:.3}, level-line contrast {contrast:.3}");
                }
                print_written(&done.written, done.bytes, started);
            }
        }
        Command::Explore {
            run,
            size,
            samples,
            tilts,
            view,
        } => {
            let options = view_options(size, samples, tilts, view)?;
            let (bars, started, spec) = start(&run)?;
            let result = moirecast::explore::run_explore(&spec, &run.out, &options, &bars);
            bars.done();
            let done = result?;
            if !run.quiet {
                let (a, d, contrast) = done.best;
                let kept = done
                    .kept_contrast
                    .map(|k| format!(", {k:.3} of the flat sheet's"))
                    .unwrap_or_default();
                eprintln!(
                    "best cell: a = {a}, d = {d:.4} mm, level-line contrast {contrast:.3}{kept}"
                );
                print_written(&done.written, done.bytes, started);
            }
        }
        Command::Studio {
            spec,
            out,
            port,
            host,
            allow_large,
        } => {
            if !host.is_loopback() {
                eprintln!("warning: --host {host} serves the studio beyond this machine: anyone who reaches it with the session token in the URL below can edit the spec and write files into {}; keep the URL to yourself", out.display());
            }
            moirecast::studio::run(
                moirecast::studio::StudioOptions {
                    spec,
                    out,
                    host,
                    port,
                    allow_large,
                },
                |url| {
                    use std::io::Write;
                    println!("moirecast studio: {url}");
                    let _ = std::io::stdout().flush();
                },
            )?;
        }
        Command::Mold { run, force } => {
            let (bars, started, spec) = start(&run)?;
            let (out, quiet) = (run.out, run.quiet);
            let result = moirecast::run_mold(&spec, &out, force, &bars);
            bars.done();
            let done = result?;
            for w in &done.warnings {
                eprintln!("warning: {w}");
            }
            for f in &done.failed {
                eprintln!("warning: check `{f}` failed; written anyway (--force)");
            }
            if !quiet {
                let v = &done.volumes;
                eprintln!(
                    "mold: top {:.0} mm³, bottom {:.0} mm³, device {:.1} mm³ in a {:.0} mm³ block; {} / {} / {} triangles; {} checks, {} failed",
                    v.top, v.bottom, v.device, v.block,
                    done.triangles[1], done.triangles[2], done.triangles[0],
                    done.checks, done.failed.len()
                );
                eprintln!("{}", done.casting);
                print_written(&done.written, done.bytes, started);
            }
        }
    }
    Ok(())
}
