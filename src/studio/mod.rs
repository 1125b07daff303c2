//! `moirecast studio`: a local web page that designs a device live.
//!
//! One spec at a time, in revisions: every accepted edit (`PUT /api/spec`)
//! makes a new [`Revision`], and everything derived from it (frames, the
//! device mesh and report, the mold halves, the explore grid) is built on
//! first request and cached with it. A refused edit changes nothing: the
//! last good revision stays on screen.
//!
//! Frames are rendered by one worker thread per revision, which owns that
//! revision's scenes and sections; a frame request that a newer one
//! overtakes while it waits is answered `409` unrendered, so dragging a
//! slider never queues stale frames.
//!
//! Safety: the server binds the loopback address unless told otherwise,
//! refuses requests whose `Host` is not the address it serves (DNS
//! rebinding), refuses bodies over [`MAX_BODY_BYTES`], serves no file but
//! its embedded page, writes only into `-o DIR` and saves only the spec
//! file, and refuses profile images outside the spec's folder.

mod files;
mod frames;
mod upload;
mod views;

use crate::errors::RunError;
use crate::report::{derived, design_echo};
use axum::body::Body;
use axum::extract::{DefaultBodyLimit, Path as UrlPath, Query, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::middleware::{self, Next};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use frames::{FrameReply, FrameRequest, Frames};
use moirecast_kernel::progress::Progress;
use moirecast_spec::{ImageSource, Spec, SpecError};
use serde::Deserialize;
use serde_json::json;
use std::net::{IpAddr, SocketAddr};
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock, RwLock};
use tokio::sync::broadcast;
use views::{DeviceView, ExploreView, MoldView, Scoring};

/// Request bodies larger than this are refused with 413.
pub const MAX_BODY_BYTES: usize = 1_000_000;

/// The page: its markup, script and style, embedded in the binary (no CDN,
/// no build step). The script and style are files of their own so that the
/// Content-Security-Policy can forbid inline script.
const PAGE: &str = include_str!("page.html");
const SCRIPT: &str = include_str!("page.js");
const STYLE: &str = include_str!("page.css");

/// Every response's Content-Security-Policy: the page's own script and
/// style only, images from itself and the frames' blob URLs, requests to
/// itself, and no framing by any other page.
const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob:; connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// How `moirecast studio` was started.
pub struct StudioOptions {
    /// The spec file the page edits and saves; `None`: the reference
    /// design, saved as `DIR/spec.toml`.
    pub spec: Option<PathBuf>,
    /// Where "Write files" writes (`-o DIR`).
    pub out: PathBuf,
    pub host: IpAddr,
    pub port: u16,
    /// Build designs over the mesh budget (`--allow-large`).
    pub allow_large: bool,
}

/// Where the spec's text and its images live.
#[derive(Clone)]
enum Home {
    /// A spec file: it is saved in place, images resolve beside it.
    File { path: PathBuf, dir: PathBuf },
    /// The embedded reference design: saved into `-o DIR`.
    Embedded,
}

impl Home {
    /// The spec's name in messages, as the command line names it.
    fn file_name(&self) -> String {
        match self {
            Home::File { path, .. } => path.display().to_string(),
            Home::Embedded => "<default: molds/saddle-horse.toml>".into(),
        }
    }

    fn images(&self) -> ImageSource<'_> {
        match self {
            Home::File { dir, .. } => ImageSource::Dir(dir),
            Home::Embedded => ImageSource::Embedded,
        }
    }
}

/// Something built from a revision once: it, or the error as the command
/// line words it.
type Built<T> = OnceLock<Result<Arc<T>, String>>;

/// One accepted spec and everything derived from it, built on demand.
pub struct Revision {
    pub number: u64,
    pub text: String,
    pub spec: Arc<Spec>,
    frames: Frames,
    device: Built<DeviceView>,
    mold: Built<MoldView>,
    scoring: Scoring,
    /// Set once a newer revision replaces this one: its builds stop.
    replaced: AtomicBool,
}

impl Revision {
    fn new(number: u64, text: String, spec: Spec) -> Revision {
        let spec = Arc::new(spec);
        Revision {
            number,
            text,
            frames: Frames::start(spec.clone()),
            spec,
            device: OnceLock::new(),
            mold: OnceLock::new(),
            scoring: Scoring::default(),
            replaced: AtomicBool::new(false),
        }
    }

    /// The device's mesh, STL and report (built once, on a blocking thread).
    async fn device(self: &Arc<Self>) -> Result<Arc<DeviceView>, String> {
        self.cached(|rev| &rev.device, DeviceView::build).await
    }

    async fn mold(self: &Arc<Self>) -> Result<Arc<MoldView>, String> {
        self.cached(|rev| &rev.mold, MoldView::build).await
    }

    /// The explore grid, scored on the first request (see [`Scoring`]).
    async fn explore(self: &Arc<Self>) -> Result<Arc<ExploreView>, String> {
        let ticket = self.scoring.request();
        let rev = self.clone();
        blocking(move || rev.score(ticket)).await
    }

    /// The explore grid for a request's `ticket` (blocking).
    fn score(&self, ticket: u64) -> Result<Arc<ExploreView>, String> {
        let words = |e| page_words(e, &self.spec.origin);
        self.scoring.grid(ticket, &self.spec, &self.replaced, words)
    }

    /// What `build` makes of the spec, built once into the revision's
    /// `cell`, on tokio's blocking pool; errors in the page's words.
    async fn cached<T: Send + Sync + 'static>(
        self: &Arc<Self>,
        cell: fn(&Revision) -> &Built<T>,
        build: fn(&Spec, &dyn Progress) -> anyhow::Result<T>,
    ) -> Result<Arc<T>, String> {
        let rev = self.clone();
        blocking(move || {
            let stop = Replaced(&rev.replaced);
            cell(&rev)
                .get_or_init(|| {
                    build(&rev.spec, &stop)
                        .map(Arc::new)
                        .map_err(|e| page_words(e, &rev.spec.origin))
                })
                .clone()
        })
        .await
    }
}

/// A build's progress that says it is no longer wanted once its revision
/// is replaced: the build stops at its next stage instead of running on
/// (a replaced revision's device of 11 GB had kept growing beside the new).
struct Replaced<'a>(&'a AtomicBool);

impl Progress for Replaced<'_> {
    fn cancelled(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// An error in the page's words: as the command line prints it, but
/// without its `error:` prefix and the spec file's path (the page shows
/// one spec); a refused value as its key, value, problem and fix.
fn page_words(e: anyhow::Error, origin: &str) -> String {
    if let Some(RunError::Spec(SpecError::Invalid {
        key,
        value,
        problem,
        fix,
        ..
    })) = e.downcast_ref::<RunError>()
    {
        return format!("{key} = {value}: {problem}.\nFix: {fix}");
    }
    format!("{e:#}")
        .replace(&format!("spec `{origin}`: "), "")
        .replace("\n  Fix: ", "\nFix: ")
}

/// Runs `f` on tokio's blocking pool.
async fn blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    tokio::task::spawn_blocking(f)
        .await
        .expect("a studio task panicked")
}

/// The server's state.
pub struct Studio {
    /// Changed by Open and Save as.
    home: RwLock<Home>,
    out: PathBuf,
    /// `Host` header values the server answers to; `None`: any (it
    /// listens on every address, and every request needs the token).
    hosts: Option<Vec<String>>,
    /// The session's token, for a listener beyond loopback: every request
    /// carries it (cookie, `x-studio-token` header or `?token=`).
    token: Option<String>,
    current: RwLock<Arc<Revision>>,
    revisions: AtomicU64,
    /// Progress and results of writes, as server-sent events.
    events: broadcast::Sender<String>,
    /// `--allow-large`: designs over the mesh budget are built.
    allow_large: bool,
    /// Permits for event streams ([`MAX_EVENT_STREAMS`]).
    streams: Arc<tokio::sync::Semaphore>,
    writing: AtomicBool,
}

impl Studio {
    fn current(&self) -> Arc<Revision> {
        self.current.read().expect("not poisoned").clone()
    }

    fn home(&self) -> Home {
        self.home.read().expect("not poisoned").clone()
    }

    /// Parses and validates `text` as the command line would, and refuses
    /// images (a profile's, a height map's) outside the spec's folder.
    fn parse(&self, text: &str) -> Result<Spec, Vec<serde_json::Value>> {
        self.parse_at(&self.home(), text)
    }

    /// [`parse`](Self::parse) for a spec that lives at `home`.
    fn parse_at(&self, home: &Home, text: &str) -> Result<Spec, Vec<serde_json::Value>> {
        let table = toml::from_str::<toml::Table>(text).ok();
        for (table_name, key) in [("profile", "profile.image"), ("surface", "surface.image")] {
            let Some(image) = table
                .as_ref()
                .and_then(|t| t.get(table_name)?.get("image")?.as_str().map(str::to_owned))
            else {
                continue;
            };
            let inside = match home {
                Home::File { dir, .. } => is_inside(dir, Path::new(&image)),
                Home::Embedded => is_plain_relative(Path::new(&image)),
            };
            if !inside {
                return Err(vec![json!({
                    "key": key,
                    "value": format!("{image:?}"),
                    "message": "is not an image file inside the spec's folder (the studio reads no other)",
                    "fix": "pick an image from the list, or give a path relative to the spec's folder without `..`",
                    "cli": format!("error: spec `{}`: `{key}` = {image:?}: is not an image file inside the spec's folder (the studio reads no other).\n  Fix: pick an image from the list, or give a path relative to the spec's folder without `..`", home.file_name()),
                })]);
            }
        }
        let mut spec = moirecast_spec::parse(text, &home.file_name(), home.images())
            .map_err(|e| vec![spec_error_json(&e)])?;
        if self.allow_large {
            spec.design.mesh_budget = moirecast_kernel::MeshBudget::UNLIMITED;
        }
        Ok(spec)
    }

    /// The state the page shows: the spec's text and values, and the design.
    fn state(&self, rev: &Revision) -> serde_json::Value {
        let values: serde_json::Value = toml::from_str::<toml::Table>(&rev.text)
            .ok()
            .and_then(|t| serde_json::to_value(t).ok())
            .unwrap_or_default();
        json!({
            "revision": rev.number,
            "spec": rev.text,
            "values": values,
            "design": design_echo(&rev.spec),
            "derived": derived(&rev.spec),
            "spec_file": match self.home() {
                Home::File { path, .. } => path.display().to_string(),
                Home::Embedded => self.out.join("spec.toml").display().to_string(),
            },
            "folder": files::folder(&self.home(), &self.out).display().to_string(),
            "out": self.out.display().to_string(),
        })
    }
}

/// Whether `image` names a file inside `dir`: a plain relative path whose
/// real path (symbolic links followed) lies within the folder's. One
/// answer for a missing file, a folder and a link leading out, so the
/// message tells nothing of what exists outside.
fn is_inside(dir: &Path, image: &Path) -> bool {
    if !is_plain_relative(image) {
        return false;
    }
    let (Ok(root), Ok(real)) = (dir.canonicalize(), dir.join(image).canonicalize()) else {
        return false;
    };
    real.starts_with(&root) && real.is_file()
}

/// A path with only normal components: no root, no `..`.
fn is_plain_relative(path: &Path) -> bool {
    path.components().all(|c| matches!(c, Component::Normal(_)))
        && path.components().next().is_some()
}

/// A spec error as JSON: the key, the value, the problem and the fix, and
/// the whole message as the command line prints it.
fn spec_error_json(e: &SpecError) -> serde_json::Value {
    let cli = format!("error: {e}");
    match e {
        SpecError::Invalid {
            key,
            value,
            problem,
            fix,
            ..
        } => json!({"key": key, "value": value, "message": problem, "fix": fix, "cli": cli}),
        SpecError::Syntax { message, .. } => {
            json!({"key": null, "value": null, "message": message, "fix": "correct the TOML", "cli": cli})
        }
        SpecError::Read { .. } => {
            json!({"key": null, "value": null, "message": e.to_string(), "fix": "", "cli": cli})
        }
    }
}

/// Starts the studio on `options.host:options.port` and serves until the
/// process ends. `announce` is told the URL once the port is bound.
pub fn run(options: StudioOptions, announce: impl FnOnce(&str)) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind((options.host, options.port)).await?;
        let (router, url) = router(&options, listener.local_addr()?)?;
        announce(&url);
        serve(listener, router).await;
        Ok(())
    })
}

/// Most connections served at once; past it a new one is closed at once.
pub const MAX_CONNECTIONS: usize = 256;
/// A connection that does not send a whole request head within this time
/// (waiting idle for its next request included) is closed.
pub const HEADER_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(5);

/// Serves `router` on `listener` until the process ends: HTTP/1.1, at most
/// [`MAX_CONNECTIONS`] at once, each closed after [`HEADER_TIMEOUT`]
/// without a request head, so idle sockets cannot hold the server (1,100
/// of them, with `ulimit -n 1024`, made every request time out). A failed
/// accept (out of file descriptors) waits a moment and goes on.
async fn serve(listener: tokio::net::TcpListener, router: Router) {
    use hyper_util::rt::{TokioIo, TokioTimer};
    let connections = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            Err(_) => {
                tokio::time::sleep(std::time::Duration::from_millis(50)).await;
                continue;
            }
        };
        let Ok(permit) = connections.clone().try_acquire_owned() else {
            continue; // dropped: closed
        };
        let service = hyper_util::service::TowerToHyperService::new(router.clone());
        tokio::spawn(async move {
            let connection = hyper::server::conn::http1::Builder::new()
                .timer(TokioTimer::new())
                .header_read_timeout(HEADER_TIMEOUT)
                // a client may close its side once its request is sent
                .half_close(true)
                .serve_connection(TokioIo::new(stream), service);
            let _ = connection.await;
            drop(permit);
        });
    }
}

/// The studio's routes for `options`, served at `addr`, and its URL.
pub fn router(options: &StudioOptions, addr: SocketAddr) -> anyhow::Result<(Router, String)> {
    let (home, text) = match &options.spec {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| anyhow::anyhow!("cannot read spec `{}`: {e}", path.display()))?;
            let dir = path
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(Path::new("."))
                .to_owned();
            let home = Home::File {
                path: path.clone(),
                dir,
            };
            (home, text)
        }
        None => (Home::Embedded, moirecast_spec::DEFAULT_SPEC.to_owned()),
    };
    let port = addr.port();
    let (hosts, token) = allowed_hosts(addr);
    let studio = Studio {
        home: RwLock::new(home),
        out: options.out.clone(),
        hosts,
        token: token.clone(),
        current: RwLock::new(Arc::new(Revision::new(
            0,
            String::new(),
            moirecast_spec::default_spec()?,
        ))),
        revisions: AtomicU64::new(1),
        events: broadcast::channel(1024).0,
        streams: Arc::new(tokio::sync::Semaphore::new(MAX_EVENT_STREAMS)),
        allow_large: options.allow_large,
        writing: AtomicBool::new(false),
    };
    // the spec given must itself be valid: a studio opens on a design
    let spec = studio.parse(&text).map_err(|errors| {
        anyhow::anyhow!(
            "{}",
            errors[0]["cli"]
                .as_str()
                .unwrap_or("invalid spec")
                .trim_start_matches("error: ")
        )
    })?;
    *studio.current.write().expect("not poisoned") = Arc::new(Revision::new(1, text, spec));
    let studio = Arc::new(studio);
    let url = match addr.ip() {
        IpAddr::V6(ip) => format!("http://[{ip}]:{port}/"),
        IpAddr::V4(ip) => format!("http://{ip}:{port}/"),
    } + &token.map(|t| format!("?token={t}")).unwrap_or_default();
    let router = Router::new()
        .route("/", get(page))
        .route("/studio.js", get(script))
        .route("/studio.css", get(style))
        .route("/api/keys", get(keys))
        .route("/api/state", get(state))
        .route("/api/spec", get(get_spec).put(put_spec).patch(patch_spec))
        .route("/api/save", post(files::save))
        .route("/api/save-as", post(files::save_as))
        .route("/api/specs", get(files::specs))
        .route("/api/open", post(files::open))
        .route("/api/profiles", get(files::profiles).post(add_profile))
        .route("/api/surfaces", post(add_surface))
        .route("/api/frame.png", get(frame))
        .route("/api/report", get(report))
        .route("/api/device.stl", get(device_stl))
        .route("/api/mold/{part}", get(mold_stl))
        .route("/api/explore", get(explore))
        .route("/api/explore/progress", get(explore_progress))
        .route("/api/explore/start", post(explore_start))
        .route("/api/explore/cancel", post(explore_cancel))
        .route("/api/explore/{cell}", get(explore_cell))
        .route("/api/write", post(write))
        .route("/api/events", get(events))
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .layer(middleware::from_fn_with_state(
            studio.clone(),
            loopback_only,
        ))
        .with_state(studio);
    Ok((router, url))
}

/// The `Host`s a studio listening at `addr` answers to, and its token. On
/// loopback: the loopback names, no token. On one other address: that
/// address, and a token. On every address (0.0.0.0, ::): any name a remote
/// browser may use, and a token, which is then what keeps other sites out.
fn allowed_hosts(addr: SocketAddr) -> (Option<Vec<String>>, Option<String>) {
    let port = addr.port();
    let named = |ip: IpAddr| match ip {
        IpAddr::V4(ip) => format!("{ip}:{port}"),
        IpAddr::V6(ip) => format!("[{ip}]:{port}"),
    };
    if addr.ip().is_loopback() {
        let mut hosts = vec![
            format!("127.0.0.1:{port}"),
            format!("localhost:{port}"),
            format!("[::1]:{port}"),
        ];
        hosts.push(named(addr.ip()));
        return (Some(hosts), None);
    }
    let hosts = (!addr.ip().is_unspecified()).then(|| vec![named(addr.ip())]);
    (hosts, Some(session_token()))
}

/// 128 random bits as hex, from the operating system.
fn session_token() -> String {
    let mut bytes = [0u8; 16];
    getrandom::getrandom(&mut bytes).expect("the operating system's random numbers");
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Whether `request` carries the session's `token`: as the
/// `moirecast_token` cookie (set by the printed URL), an `x-studio-token`
/// header, or a `token` query parameter.
fn carries_token(request: &Request, token: &str) -> bool {
    let headers = request.headers();
    let cookie = headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|c| c.to_str().ok())
        .flat_map(|c| c.split(';'))
        .any(|c| c.trim() == format!("moirecast_token={token}"));
    let header = headers
        .get("x-studio-token")
        .is_some_and(|h| h.as_bytes() == token.as_bytes());
    let query = request
        .uri()
        .query()
        .is_some_and(|q| q.split('&').any(|p| p == format!("token={token}")));
    cookie || header || query
}

/// Refuses requests whose `Host` is not an address this server answers
/// at (a page on another site that rebinds its name to 127.0.0.1 sends its
/// own name), those without the session's token where there is one, and
/// state-changing requests from another origin (browsers
/// send `Origin` on every cross-origin write, and `Sec-Fetch-Site`; local
/// tools such as curl send neither). Every answer carries the page's
/// Content-Security-Policy and refuses to be framed.
async fn loopback_only(
    State(studio): State<Arc<Studio>>,
    request: Request,
    next: Next,
) -> Response {
    let headers = request.headers();
    let text = |name: header::HeaderName| {
        headers
            .get(name)
            .map(|h| h.to_str().unwrap_or("(not text)").to_string())
    };
    let host = text(header::HOST).unwrap_or_default();
    let known = studio
        .hosts
        .as_ref()
        .is_none_or(|hosts| hosts.contains(&host));
    let token = studio.token.as_deref();
    let printed_url = request.uri().query().is_some_and(|q| q.contains("token="));
    let mut response = if !known {
        error(
            StatusCode::FORBIDDEN,
            format!(
                "Host `{host}` is not this studio's address ({})",
                studio.hosts.as_ref().map_or("", |h| h[0].as_str())
            ),
        )
    } else if token.is_some_and(|t| !carries_token(&request, t)) {
        error(
            StatusCode::FORBIDDEN,
            "this studio serves beyond this machine and needs its session token: open the URL it printed (with ?token=…)",
        )
    } else if let (Some(t), true, "/") = (token, printed_url, request.uri().path()) {
        // the printed URL: keep the token in a cookie of this site only,
        // and go on to the page without it in the address bar
        let mut to_page = StatusCode::SEE_OTHER.into_response();
        let headers = to_page.headers_mut();
        headers.insert(header::LOCATION, HeaderValue::from_static("/"));
        let cookie = format!("moirecast_token={t}; Path=/; HttpOnly; SameSite=Strict");
        headers.insert(
            header::SET_COOKIE,
            HeaderValue::from_str(&cookie).expect("hex"),
        );
        to_page
    } else if let Some(why) = cross_site_write(&request) {
        error(StatusCode::FORBIDDEN, why)
    } else {
        match whole_body(request).await {
            Ok(request) => next.run(request).await,
            Err(refused) => refused,
        }
    };
    let safety = response.headers_mut();
    safety.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    safety.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    safety.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    safety.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    response
}

/// How long a request's body may take to arrive.
pub const BODY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// `request` with its body read whole, within [`MAX_BODY_BYTES`] and
/// [`BODY_TIMEOUT`]: a body declared or sent larger is refused with 413 at
/// once (a Content-Length of 100 MB kept the handler waiting for it), and
/// one that stalls with 408, so no client holds a handler.
async fn whole_body(request: Request) -> Result<Request, Response> {
    let declared = request
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > MAX_BODY_BYTES as u64) {
        return Err(error(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("a body of at most {MAX_BODY_BYTES} bytes"),
        ));
    }
    let (parts, body) = request.into_parts();
    match tokio::time::timeout(BODY_TIMEOUT, axum::body::to_bytes(body, MAX_BODY_BYTES)).await {
        Ok(Ok(bytes)) => Ok(Request::from_parts(parts, Body::from(bytes))),
        Ok(Err(_)) => Err(error(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("a body of at most {MAX_BODY_BYTES} bytes, whole"),
        )),
        Err(_) => Err(error(
            StatusCode::REQUEST_TIMEOUT,
            format!(
                "the body did not arrive within {} s",
                BODY_TIMEOUT.as_secs()
            ),
        )),
    }
}

/// Why a request that changes state comes from another site, if it does:
/// an `Origin` other than the studio's own, or a `Sec-Fetch-Site` other
/// than `same-origin` or `none` (typed into the address bar).
fn cross_site_write(request: &Request) -> Option<String> {
    use axum::http::Method;
    if matches!(
        *request.method(),
        Method::GET | Method::HEAD | Method::OPTIONS
    ) {
        return None;
    }
    let headers = request.headers();
    if let Some(origin) = headers.get(header::ORIGIN) {
        let origin = origin.to_str().unwrap_or("(not text)");
        // same origin: the page was served by the host this request names
        // (the Host itself was checked against the allowed ones)
        let host = headers
            .get(header::HOST)
            .and_then(|h| h.to_str().ok())
            .unwrap_or("");
        let ours = origin == format!("http://{host}");
        if !ours {
            return Some(format!(
                "a {} from origin `{origin}` is refused: only the studio's own page may change the design or write files",
                request.method()
            ));
        }
    }
    match headers.get("sec-fetch-site").map(|v| v.to_str().unwrap_or("")) {
        None | Some("same-origin") | Some("none") => None,
        Some(site) => Some(format!(
            "a {} from a {site} page is refused: only the studio's own page may change the design or write files",
            request.method()
        )),
    }
}

/// A JSON error body `{"error": message}`.
fn error(status: StatusCode, message: impl Into<String>) -> Response {
    (status, Json(json!({"error": message.into()}))).into_response()
}

/// A body of `content_type`.
fn bytes(content_type: &'static str, body: Vec<u8>) -> Response {
    let mut response = Response::new(Body::from(body));
    response
        .headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    response
}

async fn page() -> Html<&'static str> {
    Html(PAGE)
}

async fn script() -> Response {
    bytes("text/javascript; charset=utf-8", SCRIPT.as_bytes().to_vec())
}

async fn style() -> Response {
    bytes("text/css; charset=utf-8", STYLE.as_bytes().to_vec())
}

async fn keys() -> Json<Vec<moirecast_spec::KeyDoc>> {
    Json(moirecast_spec::keys())
}

async fn state(State(studio): State<Arc<Studio>>) -> Json<serde_json::Value> {
    Json(studio.state(&studio.current()))
}

async fn get_spec(State(studio): State<Arc<Studio>>) -> Response {
    bytes(
        "application/toml",
        studio.current().text.clone().into_bytes(),
    )
}

/// A new spec: 200 with the new state, or 422 with the errors (and the
/// last good revision kept).
async fn put_spec(State(studio): State<Arc<Studio>>, text: String) -> Response {
    install(studio, text).await
}

/// The form's edits: `{"edits": [{"key": "table.name", "value": v}]}`, v a
/// boolean, number or string, or null to remove the key.
#[derive(Deserialize)]
struct SpecEdits {
    edits: Vec<KeyEdit>,
}

#[derive(Deserialize)]
struct KeyEdit {
    key: String,
    value: Option<serde_json::Value>,
}

/// Edits applied together to the current spec's text, which keeps its
/// comments, order and number formatting ([`moirecast_spec::apply_edits`]),
/// then installed as [`put_spec`] does: 200 with the new state, 422 with
/// the errors, 400 for a value that is no boolean, number or string.
async fn patch_spec(State(studio): State<Arc<Studio>>, Json(body): Json<SpecEdits>) -> Response {
    use moirecast_spec::{EditValue, SpecEdit};
    let mut edits = Vec::with_capacity(body.edits.len());
    for KeyEdit { key, value } in body.edits {
        let value = match value {
            None | Some(serde_json::Value::Null) => None,
            Some(serde_json::Value::Bool(b)) => Some(EditValue::Bool(b)),
            Some(serde_json::Value::String(t)) => Some(EditValue::Text(t)),
            Some(serde_json::Value::Array(items)) => {
                let pair = moirecast_spec::keys()
                    .iter()
                    .any(|d| d.key == key && d.kind == moirecast_spec::ValueKind::Pair);
                match items.iter().map(serde_json::Value::as_f64).collect() {
                    Some(numbers) if pair => Some(EditValue::Numbers(numbers)),
                    _ => {
                        return error(
                            StatusCode::BAD_REQUEST,
                            format!("`{key}`: takes no array (only [X, Y] keys take numbers)"),
                        )
                    }
                }
            }
            Some(serde_json::Value::Number(n)) => match n.as_f64() {
                Some(x) => Some(EditValue::Number(x)),
                None => {
                    return error(
                        StatusCode::BAD_REQUEST,
                        format!("`{key}`: {n} is no number"),
                    )
                }
            },
            Some(other) => {
                return error(
                    StatusCode::BAD_REQUEST,
                    format!("`{key}`: a boolean, number, string, numbers or null, not {other}"),
                )
            }
        };
        edits.push(SpecEdit { key, value });
    }
    let misfits: Vec<serde_json::Value> = edits.iter().filter_map(edit_misfit).collect();
    if !misfits.is_empty() {
        return (
            StatusCode::UNPROCESSABLE_ENTITY,
            Json(json!({"errors": misfits, "revision": studio.current().number})),
        )
            .into_response();
    }
    match moirecast_spec::apply_edits(&studio.current().text, &edits) {
        Ok(text) => install(studio, text).await,
        Err(e) => error(StatusCode::BAD_REQUEST, e.to_string()),
    }
}

/// An edit whose value is not of its key's kind, as an error at that key:
/// text for a number ("abc", "0,5"), a number for a boolean. Named at the
/// field, where the spec's own parser would only point at a TOML line.
fn edit_misfit(edit: &moirecast_spec::SpecEdit) -> Option<serde_json::Value> {
    use moirecast_spec::{EditValue, ValueKind};
    let doc = moirecast_spec::keys()
        .into_iter()
        .find(|d| d.key == edit.key)?;
    let unit = if doc.unit.is_empty() {
        String::new()
    } else {
        format!(" in {}", doc.unit)
    };
    let (value, problem, fix) = match (&doc.kind, edit.value.as_ref()?) {
        (ValueKind::Number, EditValue::Text(t)) => (
            t.clone(),
            "is not a number".to_string(),
            format!("write a number{unit}, with a decimal point (0.5, not 0,5)"),
        ),
        (ValueKind::Distance, EditValue::Text(t)) if t != "focal" => (
            t.clone(),
            "is neither a number nor \"focal\"".to_string(),
            format!("write a number{unit}, or focal"),
        ),
        (ValueKind::Bool, EditValue::Number(x)) => (
            x.to_string(),
            "is not true or false".to_string(),
            "tick or untick it".to_string(),
        ),
        (ValueKind::Pair, EditValue::Text(t)) => (
            t.clone(),
            "is not two numbers".to_string(),
            format!("write two numbers{unit}, as 64, 64"),
        ),
        _ => return None,
    };
    let cli = format!("`{}` = {value:?}: {problem}.\n  Fix: {fix}", edit.key);
    Some(json!({"key": edit.key, "value": value, "message": problem, "fix": fix, "cli": cli}))
}

/// Parses `text` and, if it is a design, makes it the current revision.
async fn install(studio: Arc<Studio>, text: String) -> Response {
    let parsed = {
        let (studio, text) = (studio.clone(), text.clone());
        blocking(move || studio.parse(&text)).await
    };
    match parsed {
        Err(errors) => refused(&studio, errors),
        Ok(spec) => make_current(&studio, text, spec),
    }
}

/// 422 with a refused spec's errors and the revision that stays.
fn refused(studio: &Studio, errors: Vec<serde_json::Value>) -> Response {
    (
        StatusCode::UNPROCESSABLE_ENTITY,
        Json(json!({"errors": errors, "revision": studio.current().number})),
    )
        .into_response()
}

/// Makes the valid `spec` (of `text`) the current revision, which stops
/// the builds of the one it replaces; 200 with the new state.
fn make_current(studio: &Studio, text: String, spec: Spec) -> Response {
    let number = studio.revisions.fetch_add(1, Ordering::Relaxed) + 1;
    let rev = Arc::new(Revision::new(number, text, spec));
    let old = std::mem::replace(
        &mut *studio.current.write().expect("not poisoned"),
        rev.clone(),
    );
    old.replaced.store(true, Ordering::SeqCst);
    Json(studio.state(&rev)).into_response()
}

/// `?name=` of an image added to the spec's folder.
#[derive(Deserialize)]
struct AddImage {
    name: String,
}

/// Adds the PNG in the body (a file dropped on the page, named `name`) to
/// the spec's folder under `profiles/` ([`upload::add_image`]), and answers
/// with its path as the spec names it.
async fn add_profile(
    State(studio): State<Arc<Studio>>,
    Query(q): Query<AddImage>,
    body: axum::body::Bytes,
) -> Response {
    add_image_to(studio, upload::ImageFolder::Profiles, q, body).await
}

/// `POST /api/surfaces?name=NAME`: a height map's PNG, into `surfaces/`.
async fn add_surface(
    State(studio): State<Arc<Studio>>,
    Query(q): Query<AddImage>,
    body: axum::body::Bytes,
) -> Response {
    add_image_to(studio, upload::ImageFolder::Surfaces, q, body).await
}

/// Adds a dropped PNG to the spec's folder `to`: `{"image": PATH}`.
async fn add_image_to(
    studio: Arc<Studio>,
    to: upload::ImageFolder,
    q: AddImage,
    body: axum::body::Bytes,
) -> Response {
    let Home::File { dir, .. } = studio.home() else {
        return error(
            StatusCode::CONFLICT,
            "the built-in design has no folder for images: start the studio on a spec file (moirecast studio SPEC) and drop the image there",
        );
    };
    let dir = dir.clone();
    let added =
        tokio::task::spawn_blocking(move || upload::add_image(&dir, to, &q.name, &body)).await;
    match added {
        Ok(Ok(image)) => Json(json!({"image": image})).into_response(),
        Ok(Err(why)) => error(StatusCode::BAD_REQUEST, why),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

#[derive(Deserialize)]
struct FrameQuery {
    #[serde(default)]
    tilt: f64,
    #[serde(default)]
    along: f64,
    #[serde(default = "default_size")]
    size: usize,
    #[serde(default = "default_samples")]
    samples: usize,
    #[serde(default = "default_lights")]
    lights: String,
}

fn default_size() -> usize {
    256
}
fn default_samples() -> usize {
    4
}
fn default_lights() -> String {
    "default".into()
}

/// One frame of the current design as PNG; its scores in `x-*` headers.
async fn frame(State(studio): State<Arc<Studio>>, Query(q): Query<FrameQuery>) -> Response {
    let lights = match crate::render::LightsChoice::parse(&q.lights) {
        Ok(l) => l,
        Err(e) => return error(StatusCode::BAD_REQUEST, format!("lights: {e}")),
    };
    let request = FrameRequest {
        tilt_deg: q.tilt,
        along_deg: q.along,
        size: q.size,
        samples: q.samples,
        lights,
    };
    let rev = studio.current();
    if let Err(e) = request
        .validate()
        .and_then(|()| request.within_budget(&rev.spec.design))
    {
        return error(StatusCode::BAD_REQUEST, e);
    }
    match rev.frames.render(request).await {
        FrameReply::Done(f, cached) => {
            let mut response = bytes("image/png", f.png.clone());
            let h = response.headers_mut();
            h.insert(
                "x-frame-cache",
                HeaderValue::from_static(if cached { "hit" } else { "miss" }),
            );
            for (name, value) in [
                ("x-revision", rev.number as f64),
                ("x-fidelity", f.fidelity),
                ("x-local-fidelity", f.local_fidelity),
                ("x-contrast", f.contrast),
                ("x-render-ms", f.milliseconds),
            ] {
                h.insert(
                    name,
                    HeaderValue::from_str(&format!("{value}")).expect("a number"),
                );
            }
            h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
            response
        }
        FrameReply::Superseded => error(
            StatusCode::CONFLICT,
            "superseded: a newer frame request arrived before this one was rendered",
        ),
        FrameReply::Failed(e) => error(StatusCode::UNPROCESSABLE_ENTITY, e),
    }
}

/// The device's report (checks and measurements), and the mold's checks
/// and warnings once the mold has been built.
async fn report(State(studio): State<Arc<Studio>>) -> Response {
    let rev = studio.current();
    let device = match rev.device().await {
        Ok(d) => d,
        Err(e) => return error(StatusCode::UNPROCESSABLE_ENTITY, e),
    };
    let mut report = device.report.clone();
    report["revision"] = json!(rev.number);
    if let Some(Ok(mold)) = rev.mold.get() {
        report["mold"] = json!({"checks": mold.checks, "warnings": mold.warnings});
    }
    Json(report).into_response()
}

async fn device_stl(State(studio): State<Arc<Studio>>) -> Response {
    match studio.current().device().await {
        Ok(d) => bytes("model/stl", d.stl.clone()),
        Err(e) => error(StatusCode::UNPROCESSABLE_ENTITY, e),
    }
}

/// `top.stl`, `bottom.stl`, or `device.stl` (the cavity: the device in the
/// mold's frame).
async fn mold_stl(State(studio): State<Arc<Studio>>, UrlPath(part): UrlPath<String>) -> Response {
    if !["top.stl", "bottom.stl", "device.stl"].contains(&part.as_str()) {
        return error(StatusCode::NOT_FOUND, format!("no mold part `{part}`"));
    }
    match studio.current().mold().await {
        Ok(m) => bytes(
            "model/stl",
            match part.as_str() {
                "top.stl" => m.top.clone(),
                "bottom.stl" => m.bottom.clone(),
                _ => m.device.clone(),
            },
        ),
        Err(e) => error(StatusCode::UNPROCESSABLE_ENTITY, e),
    }
}

async fn explore(State(studio): State<Arc<Studio>>) -> Response {
    let rev = studio.current();
    match rev.explore().await {
        Ok(grid) => Json(json!({
            "revision": rev.number,
            "flat_sheet": grid.flat_sheet,
            "cells": grid.cells,
            "best": grid.best,
            "columns": crate::explore::A_VALUES.len(),
            "thumbnails": (0..grid.cells.len()).map(|i| format!("/api/explore/{i}.png")).collect::<Vec<_>>(),
        }))
        .into_response(),
        Err(e) => error(StatusCode::UNPROCESSABLE_ENTITY, e),
    }
}

/// How far the current revision's grid is scored: cells done of all.
async fn explore_progress(State(studio): State<Arc<Studio>>) -> Json<serde_json::Value> {
    let rev = studio.current();
    let mut progress = json!(rev.scoring.progress());
    progress["revision"] = json!(rev.number);
    Json(progress)
}

/// Starts scoring the current revision's grid, unless it is scored, and
/// answers at once (202): the page follows it on `/api/explore/progress`
/// and fetches it from `/api/explore` once scored, holding no connection
/// meanwhile (a browser has six per site).
async fn explore_start(State(studio): State<Arc<Studio>>) -> Response {
    let rev = studio.current();
    let ticket = rev.scoring.request();
    let number = rev.number;
    tokio::task::spawn_blocking(move || rev.score(ticket));
    (StatusCode::ACCEPTED, Json(json!({"revision": number}))).into_response()
}

/// Stops the current revision's scoring after the cells being scored;
/// its request then answers "cancelled", and the next one scores afresh.
async fn explore_cancel(State(studio): State<Arc<Studio>>) -> Json<serde_json::Value> {
    Json(json!({"cancelled": studio.current().scoring.cancel()}))
}

async fn explore_cell(
    State(studio): State<Arc<Studio>>,
    UrlPath(cell): UrlPath<String>,
) -> Response {
    let rev = studio.current();
    // digits only: `parse` would take `+1` too
    let Some(i) = cell
        .strip_suffix(".png")
        .filter(|i| !i.is_empty() && i.bytes().all(|b| b.is_ascii_digit()))
        .and_then(|i| i.parse::<usize>().ok())
    else {
        return error(StatusCode::NOT_FOUND, format!("no cell `{cell}`"));
    };
    match rev.explore().await {
        Ok(grid) => match grid.thumbnails.get(i) {
            Some(png) => bytes("image/png", png.clone()),
            None => error(StatusCode::NOT_FOUND, format!("no cell {i}")),
        },
        Err(e) => error(StatusCode::UNPROCESSABLE_ENTITY, e),
    }
}

#[derive(Deserialize)]
struct WriteQuery {
    what: String,
}

/// Progress of a write, as server-sent events.
struct EventProgress(broadcast::Sender<String>);

impl Progress for EventProgress {
    fn stage(&self, name: &'static str, total: u64) {
        let _ = self
            .0
            .send(json!({"kind": "stage", "name": name, "total": total}).to_string());
    }
    fn tick(&self, n: u64) {
        let _ = self.0.send(json!({"kind": "tick", "n": n}).to_string());
    }
}

/// Starts writing the device's files or the whole mold into `-o DIR`, by
/// the command line's own pipeline; progress and the result arrive on
/// `/api/events`.
async fn write(State(studio): State<Arc<Studio>>, Query(q): Query<WriteQuery>) -> Response {
    let mold = match q.what.as_str() {
        "device" => false,
        "mold" => true,
        other => {
            return error(
                StatusCode::BAD_REQUEST,
                format!("what={other}: write `device` or `mold`"),
            )
        }
    };
    if studio.writing.swap(true, Ordering::AcqRel) {
        return error(StatusCode::CONFLICT, "a write is already running");
    }
    let rev = studio.current();
    let number = rev.number;
    let task_studio = studio.clone();
    tokio::task::spawn_blocking(move || {
        let studio = task_studio;
        let progress = EventProgress(studio.events.clone());
        let what = if mold { "mold" } else { "device" };
        // what the run replaces: the folder holds one run at a time
        let replaces = moirecast_export::run_folder::earlier_run(&studio.out);
        let _ = studio
            .events
            .send(json!({"kind": "start", "what": what, "revision": rev.number}).to_string());
        let result = if mold {
            crate::run_mold(&rev.spec, &studio.out, false, &progress)
                .map(|o| (o.written, o.bytes, o.warnings, Some(o.casting)))
        } else {
            crate::run_device(
                &rev.spec,
                &studio.out,
                crate::Thoroughness::Sampled,
                crate::Mesher::Direct,
                &progress,
            )
            .map(|o| (o.written, o.bytes, Vec::new(), None))
        };
        let event = match result {
            Ok((written, bytes, warnings, casting)) => json!({
                "kind": "done",
                "what": what,
                "written": written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                "folder": studio.out.display().to_string(),
                // the earlier run's files (the folder's whole run is replaced)
                "replaces": replaces,
                "bytes": bytes,
                "warnings": warnings,
                // what to weigh out, as `moirecast mold` prints it
                "casting": casting,
            }),
            Err(e) => json!({
                "kind": "error",
                "what": what,
                "refusal": e.downcast_ref::<RunError>().is_some_and(RunError::is_refusal),
                "message": page_words(e, &rev.spec.origin),
            }),
        };
        studio.writing.store(false, Ordering::Release);
        let _ = studio.events.send(event.to_string());
    });
    (
        StatusCode::ACCEPTED,
        Json(json!({"started": q.what, "revision": number, "events": "/api/events"})),
    )
        .into_response()
}

/// Server-sent events: one JSON object per event (`start`, `stage`,
/// `tick`, `done`, `error`).
async fn events(State(studio): State<Arc<Studio>>) -> Response {
    // a stream holds its permit until it ends, which for a client gone
    // away is the next keep-alive that finds the socket closed
    let Ok(permit) = studio.streams.clone().try_acquire_owned() else {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            format!("at most {MAX_EVENT_STREAMS} event streams at once"),
        );
    };
    let receiver = studio.events.subscribe();
    let stream = futures_util::stream::unfold((receiver, permit), |(mut rx, permit)| async move {
        loop {
            match rx.recv().await {
                Ok(message) => {
                    return Some((
                        Ok::<_, std::convert::Infallible>(Event::default().data(message)),
                        (rx, permit),
                    ))
                }
                Err(broadcast::error::RecvError::Lagged(_)) => continue,
                Err(broadcast::error::RecvError::Closed) => return None,
            }
        }
    });
    let mut headers = HeaderMap::new();
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    let keep_alive = KeepAlive::default().interval(EVENTS_KEEP_ALIVE);
    (headers, Sse::new(stream).keep_alive(keep_alive)).into_response()
}

/// Most event streams at once (the page opens one).
pub const MAX_EVENT_STREAMS: usize = 16;
/// How often an idle event stream writes a comment: a client gone away is
/// found, and its stream and connection ended, within this.
pub const EVENTS_KEEP_ALIVE: std::time::Duration = std::time::Duration::from_secs(2);
