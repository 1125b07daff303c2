//! `moirecast studio`'s HTTP API on a server bound to port 0: every
//! endpoint, refusals by key with the last good design kept, traversal
//! attempts, a foreign Host, an oversized body, concurrent frames, and a
//! write that gives the command line's bytes.

mod common;

use common::http::{self, Response};
use common::{scratch, Scratch, SMALL};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::Command;

/// A studio serving `spec` from its own thread, writing into `dir/out`.
struct Studio {
    port: u16,
    dir: Scratch,
}

impl Studio {
    fn start(name: &str, spec_text: &str) -> Studio {
        let dir = scratch("studio", name);
        std::fs::write(dir.join("design.toml"), spec_text).unwrap();
        std::fs::create_dir_all(dir.join("profiles")).unwrap();
        std::fs::copy(
            concat!(env!("CARGO_MANIFEST_DIR"), "/molds/profiles/horse.png"),
            dir.join("profiles/horse.png"),
        )
        .unwrap();
        let port = http::start_studio(dir.join("design.toml"), dir.join("out"));
        Studio { port, dir }
    }

    /// `method target` with `body`, Host set to the studio's address.
    fn request(&self, method: &str, target: &str, body: &[u8]) -> Response {
        self.request_as(&format!("127.0.0.1:{}", self.port), method, target, body)
    }

    fn get(&self, target: &str) -> Response {
        self.request("GET", target, b"")
    }

    fn request_as(&self, host: &str, method: &str, target: &str, body: &[u8]) -> Response {
        http::request(self.port, host, method, target, body)
    }

    /// Reads `/api/events` until an event of `kind` `done` or `error`,
    /// after starting it with `start`.
    fn events_until_finished(&self, start: impl FnOnce()) -> String {
        let mut stream = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        write!(
            stream,
            "GET /api/events HTTP/1.1\r\nHost: 127.0.0.1:{}\r\n\r\n",
            self.port
        )
        .unwrap();
        let mut seen = Vec::new();
        let mut chunk = [0u8; 4096];
        // the stream's headers first: then the subscription exists
        while !String::from_utf8_lossy(&seen).contains("\r\n\r\n") {
            let n = stream.read(&mut chunk).unwrap();
            seen.extend_from_slice(&chunk[..n]);
        }
        start();
        stream
            .set_read_timeout(Some(std::time::Duration::from_secs(300)))
            .unwrap();
        loop {
            let text = String::from_utf8_lossy(&seen).into_owned();
            if text.contains(r#""kind":"done""#) || text.contains(r#""kind":"error""#) {
                return text;
            }
            let n = stream.read(&mut chunk).unwrap();
            assert!(n > 0, "the event stream ended: {text}");
            seen.extend_from_slice(&chunk[..n]);
        }
    }
}

fn is_png(bytes: &[u8]) -> bool {
    bytes.starts_with(b"\x89PNG\r\n\x1a\n")
}

/// A binary STL's triangle count, checked against its length.
fn stl_triangles(bytes: &[u8]) -> usize {
    let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap()) as usize;
    assert_eq!(bytes.len(), 84 + 50 * n, "a binary STL's length");
    n
}

#[test]
fn every_endpoint_answers() {
    let studio = Studio::start("endpoints", SMALL);
    let page = studio.get("/");
    assert_eq!(page.status, 200);
    let html = String::from_utf8_lossy(&page.body);
    assert!(html.contains("<title>moirecast studio</title>"));
    // the page loads nothing from elsewhere
    assert!(!html.contains("http://") && !html.contains("https://"));

    let keys = studio.get("/api/keys").json();
    assert_eq!(keys.as_array().unwrap().len(), moirecast_spec::keys().len());
    assert_eq!(keys[0]["key"], "surface.kind");

    let state = studio.get("/api/state").json();
    assert_eq!(state["revision"], 1);
    assert_eq!(state["values"]["layout"]["width"], 4.0);
    assert_eq!(state["derived"]["N"], 8);
    assert_eq!(studio.get("/api/spec").body, SMALL.as_bytes());

    let profiles = studio.get("/api/profiles").json();
    assert_eq!(profiles, serde_json::json!(["profiles/horse.png"]));

    let frame = studio.get("/api/frame.png?tilt=2.5&size=64");
    assert_eq!(frame.status, 200);
    assert!(is_png(&frame.body));
    let contrast: f64 = frame.header("x-contrast").unwrap().parse().unwrap();
    assert!(contrast.is_finite() && contrast > 0.0, "{contrast}");
    // a tilt along is traced through the sections too (each ray slid along
    // the lenses it meets), within their budget of rays: this frame's 5.0 M
    // rays are past the mesh's 4.2 M
    let along = studio.get("/api/frame.png?along=10&size=320&samples=7&lights=white");
    assert_eq!(
        along.status,
        200,
        "{}",
        String::from_utf8_lossy(&along.body)
    );
    assert!(is_png(&along.body));
    for bad in [
        "tilt=91",
        "size=5000",
        "samples=0",
        "lights=purple",
        "tilt=x",
    ] {
        let r = studio.get(&format!("/api/frame.png?{bad}"));
        assert_eq!(r.status, 400, "{bad}");
    }

    let report = studio.get("/api/report").json();
    let checks = report["checks"].as_array().unwrap();
    assert!(checks.len() > 10);
    assert!(checks.iter().all(|c| c["passed"] == true), "{checks:?}");
    let device = studio.get("/api/device.stl");
    assert_eq!(device.status, 200);
    assert_eq!(
        stl_triangles(&device.body) as u64,
        report["mesh"]["triangles"].as_u64().unwrap()
    );

    for part in ["top.stl", "bottom.stl", "device.stl"] {
        let r = studio.get(&format!("/api/mold/{part}"));
        assert_eq!(r.status, 200, "{part}");
        assert!(stl_triangles(&r.body) > 100, "{part}");
    }
    // once built, the mold's checks are in the report
    let report = studio.get("/api/report").json();
    let mold_checks = report["mold"]["checks"].as_array().unwrap();
    assert!(mold_checks.iter().any(|c| c["name"] == "mold-volumes-sum"));
    assert!(mold_checks.iter().all(|c| c["passed"] == true));

    let grid = studio.get("/api/explore").json();
    let cells = grid["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 25);
    let best = grid["best"].as_u64().unwrap() as usize;
    assert!(cells[best]["contrast"].as_f64().unwrap() > 0.0);
    assert!(cells[best]["kept_contrast"].as_f64().unwrap() > 0.0);
    assert!(grid["flat_sheet"]["contrast"].as_f64().unwrap() > 0.0);
    let thumbnail = studio.get(grid["thumbnails"][best].as_str().unwrap());
    assert_eq!(thumbnail.status, 200);
    assert!(is_png(&thumbnail.body));
    assert_eq!(studio.get("/api/explore/25.png").status, 404);

    // an edit, then "Save spec" writes it back to the spec file
    let edited = SMALL.replace("levels = 1.0", "levels = 2.0");
    let put = studio.request("PUT", "/api/spec", edited.as_bytes());
    assert_eq!(put.status, 200);
    assert_eq!(put.json()["revision"], 2);
    assert_eq!(put.json()["values"]["base"]["levels"], 2.0);
    let saved = studio.request("POST", "/api/save", b"");
    assert_eq!(saved.status, 200);
    assert_eq!(
        std::fs::read_to_string(studio.dir.join("design.toml")).unwrap(),
        edited
    );
    assert_eq!(studio.get("/nothing-here").status, 404);
}

/// The form's edits (PATCH) change the spec's own text: a user's comment,
/// spacing and `40.0` survive an edit and a save, values that need each
/// other (a formula surface and its z) go in together, a refused edit
/// leaves the text as it was, and a non-number is refused at its key.
#[test]
fn form_edits_keep_the_users_text_and_take_linked_values() {
    let commented = SMALL
        .replace("radius = 40.0", "radius = 40.0   # mm, my saddle")
        .replace("[layout]", "# my notes\n[layout]");
    let studio = Studio::start("edits", &commented);
    let patch = |body: &str| {
        http::request_with(
            studio.port,
            &format!("127.0.0.1:{}", studio.port),
            "PATCH",
            "/api/spec",
            &[("Content-Type", "application/json")],
            body.as_bytes(),
        )
    };
    let r = patch(r#"{"edits": [{"key": "base.levels", "value": 2}]}"#);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["values"]["base"]["levels"], 2.0);
    assert_eq!(studio.request("POST", "/api/save", b"").status, 200);
    let saved = std::fs::read_to_string(studio.dir.join("design.toml")).unwrap();
    assert_eq!(saved, commented.replace("levels = 1.0", "levels = 2.0"));

    let formula = r#"{"edits": [{"key": "surface.kind", "value": "formula"},
        {"key": "surface.z", "value": "(x*x - y*y)/80"}, {"key": "surface.radius", "value": null}]}"#;
    let r = patch(formula);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let text = String::from_utf8(studio.get("/api/spec").body).unwrap();
    assert!(
        text.contains("kind = \"formula\"") && text.contains("# my notes"),
        "{text}"
    );

    let refused = patch(r#"{"edits": [{"key": "lens.afov", "value": 200}]}"#);
    assert_eq!(refused.status, 422);
    assert_eq!(studio.get("/api/spec").body, text.as_bytes());
    let not_a_value = patch(r#"{"edits": [{"key": "lens.afov", "value": [1]}]}"#);
    assert_eq!(not_a_value.status, 400);
    // a non-number is named at its key, not as a TOML line and column
    for typed in ["abc", "0,5"] {
        let r = patch(&format!(
            r#"{{"edits": [{{"key": "layout.period", "value": "{typed}"}}]}}"#
        ));
        assert_eq!(r.status, 422);
        let error = &r.json()["errors"][0];
        assert_eq!(error["key"], "layout.period");
        assert_eq!(error["value"], typed);
        assert!(
            error["fix"].as_str().unwrap().contains("0.5, not 0,5"),
            "{error}"
        );
    }
    assert_eq!(studio.get("/api/spec").body, text.as_bytes());
}

#[test]
fn a_bad_spec_is_refused_by_key_and_the_last_good_design_stays() {
    let studio = Studio::start("refusals", SMALL);
    let bad = SMALL.replace("afov = 60.0", "afov = 200");
    let r = studio.request("PUT", "/api/spec", bad.as_bytes());
    assert_eq!(r.status, 422);
    let error = &r.json()["errors"][0];
    assert_eq!(error["key"], "lens.afov");
    assert_eq!(error["value"], "200");
    assert!(error["fix"].as_str().unwrap().len() > 5);
    // worded as the command line words it
    std::fs::write(studio.dir.join("bad.toml"), &bad).unwrap();
    let cli = Command::new(env!("CARGO_BIN_EXE_moirecast"))
        .args(["device", "--quiet", "-o"])
        .arg(studio.dir.join("cli"))
        .arg(studio.dir.join("bad.toml"))
        .output()
        .unwrap();
    let cli_words = String::from_utf8_lossy(&cli.stderr);
    let ours = error["cli"]
        .as_str()
        .unwrap()
        .replace("design.toml", "bad.toml");
    assert!(cli_words.contains(&ours), "{cli_words} vs {ours}");

    // the last good design is kept
    let state = studio.get("/api/state").json();
    assert_eq!(state["revision"], 1);
    assert_eq!(state["values"]["lens"]["afov"], 60.0);
    assert_eq!(studio.get("/api/frame.png?size=32").status, 200);

    // TOML that does not parse: refused, no key
    let r = studio.request("PUT", "/api/spec", b"[layout\nwidth = ");
    assert_eq!(r.status, 422);
    assert!(r.json()["errors"][0]["key"].is_null());
    // an unknown key is named
    let r = studio.request(
        "PUT",
        "/api/spec",
        format!("{SMALL}\n[extra]\nx = 1\n").as_bytes(),
    );
    assert_eq!(r.status, 422);
    assert!(r.json()["errors"][0]["message"]
        .as_str()
        .unwrap()
        .contains("extra"));
}

#[test]
fn traversal_foreign_hosts_and_large_bodies_are_refused() {
    let studio = Studio::start("safety", SMALL);
    for path in [
        "/../../../etc/passwd",
        "/api/mold/..%2F..%2F..%2Fetc%2Fpasswd",
        "/api/mold/../../Cargo.toml",
        "/api/explore/..%2F0.png",
        "/%2e%2e/%2e%2e/etc/passwd",
        "/design.toml",
        "/profiles/horse.png",
    ] {
        let r = studio.get(path);
        assert!(r.status == 404 || r.status == 400, "{path}: {}", r.status);
        assert!(!String::from_utf8_lossy(&r.body).contains("root:"));
    }
    for image in [
        "../profiles/horse.png",
        "/etc/hosts.png",
        "profiles/../../x.png",
    ] {
        let text = SMALL.replace(
            "[profile]\nkind = \"bump\"\nsigma = 1.5",
            &format!("[profile]\nimage = {image:?}"),
        );
        let r = studio.request("PUT", "/api/spec", text.as_bytes());
        assert_eq!(r.status, 422, "{image}");
        assert_eq!(r.json()["errors"][0]["key"], "profile.image", "{image}");
    }
    // and a height map's, the same
    for image in ["../profiles/horse.png", "/etc/hosts.png"] {
        let text = SMALL.replace(
            "[surface]\nkind = \"saddle\"\nradius = 40.0",
            &format!(
                "[surface]\nkind = \"heightmap\"\nimage = {image:?}\nz_min = 0.0\nz_max = 1.0"
            ),
        );
        let r = studio.request("PUT", "/api/spec", text.as_bytes());
        assert_eq!(r.status, 422, "{image}");
        assert_eq!(r.json()["errors"][0]["key"], "surface.image", "{image}");
    }
    // an image inside the spec's folder is fine
    let text = SMALL.replace(
        "[profile]\nkind = \"bump\"\nsigma = 1.5",
        "[profile]\nimage = \"profiles/horse.png\"",
    );
    assert_eq!(
        studio.request("PUT", "/api/spec", text.as_bytes()).status,
        200
    );

    // DNS rebinding: another name for 127.0.0.1 is refused
    for host in [
        "evil.example",
        &format!("evil.example:{}", studio.port),
        "127.0.0.1:1",
    ] {
        let r = studio.request_as(host, "GET", "/api/state", b"");
        assert_eq!(r.status, 403, "{host}");
    }
    assert_eq!(
        studio
            .request_as(
                &format!("localhost:{}", studio.port),
                "GET",
                "/api/state",
                b""
            )
            .status,
        200
    );

    let big = vec![b'#'; moirecast::studio::MAX_BODY_BYTES + 1];
    assert_eq!(studio.request("PUT", "/api/spec", &big).status, 413);
    assert_eq!(studio.get("/api/state").json()["revision"], 2);
    assert_eq!(
        studio
            .request("POST", "/api/write?what=everything", b"")
            .status,
        400
    );
}

#[test]
fn concurrent_frames_are_rendered_or_superseded() {
    let studio = Studio::start("concurrent", SMALL);
    let replies: Vec<(u16, Vec<u8>)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..8)
            .map(|i| {
                let studio = &studio;
                s.spawn(move || {
                    let r = studio.get(&format!("/api/frame.png?size=96&tilt={}", i as f64 - 4.0));
                    (r.status, r.body)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let rendered = replies.iter().filter(|(s, _)| *s == 200).count();
    assert!(rendered >= 1);
    for (status, body) in &replies {
        match status {
            200 => assert!(is_png(body)),
            409 => assert!(String::from_utf8_lossy(body).contains("superseded")),
            other => panic!("status {other}"),
        }
    }
    // one at a time, every request is rendered; the same view again is
    // the revision's cached frame, the same bytes and scores
    let a = studio.get("/api/frame.png?size=48&tilt=1");
    let b = studio.get("/api/frame.png?size=48&tilt=1");
    assert_eq!((a.status, b.status), (200, 200));
    assert_eq!(
        (a.header("x-frame-cache"), b.header("x-frame-cache")),
        (Some("miss"), Some("hit"))
    );
    assert_eq!(a.body, b.body);
    assert_eq!(a.header("x-contrast"), b.header("x-contrast"));
    // another view is rendered, and the first is still cached
    let c = studio.get("/api/frame.png?size=48&tilt=1&samples=2");
    assert_eq!(c.header("x-frame-cache"), Some("miss"));
    assert_ne!(c.body, a.body);
    let again = studio.get("/api/frame.png?size=48&tilt=1");
    assert_eq!(again.header("x-frame-cache"), Some("hit"));
    assert_eq!(again.body, a.body);
}

/// The file's bytes, or a panic naming it.
fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn a_dropped_png_joins_the_specs_folder_under_a_safe_name() {
    let studio = Studio::start("add-image", SMALL);
    let horse = read(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/molds/profiles/horse.png"
    )));
    // a name that would climb out of the folder stays inside profiles/
    let r = studio.request(
        "POST",
        "/api/profiles?name=..%2F..%2Fmy%20horse.png",
        &horse,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["image"], "profiles/my-horse.png");
    assert_eq!(read(&studio.dir.join("profiles/my-horse.png")), horse);
    // the same bytes again: the same file; other bytes: a new name
    let again = studio.request("POST", "/api/profiles?name=my%20horse.png", &horse);
    assert_eq!(again.json()["image"], "profiles/my-horse.png");
    let coins = read(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/molds/profiles/coins.png"
    )));
    let other = studio.request("POST", "/api/profiles?name=my%20horse.png", &coins);
    assert_eq!(other.json()["image"], "profiles/my-horse-2.png");
    // the list offers it, and a spec can name it
    let listed = studio.get("/api/profiles").json();
    assert!(
        listed
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p == "profiles/my-horse.png"),
        "{listed}"
    );
    // not a PNG, or too many pixels: refused by name, nothing written
    let text = studio.request("POST", "/api/profiles?name=notes.png", b"not an image");
    assert_eq!(text.status, 400);
    assert!(String::from_utf8_lossy(&text.body).contains("not a readable PNG"));
    let mut wide = Vec::new();
    image::GrayImage::new(5000, 4000)
        .write_to(
            &mut std::io::Cursor::new(&mut wide),
            image::ImageFormat::Png,
        )
        .unwrap();
    let bomb = studio.request("POST", "/api/profiles?name=wide.png", &wide);
    assert_eq!(bomb.status, 400, "{}", String::from_utf8_lossy(&bomb.body));
    assert!(String::from_utf8_lossy(&bomb.body).contains("5000 × 4000"));
    assert!(
        !studio.dir.join("profiles/notes.png").exists()
            && !studio.dir.join("profiles/wide.png").exists()
    );
}

/// A height map dropped on its field goes into surfaces/, and the surface
/// takes it with its keys, `size` as two numbers, in one edit.
#[test]
fn a_dropped_height_map_becomes_the_surface() {
    let studio = Studio::start("add-surface", SMALL);
    let hills = read(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/molds/surfaces/hills.png"
    )));
    let r = studio.request("POST", "/api/surfaces?name=my%20hills.png", &hills);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["image"], "surfaces/my-hills.png");
    assert_eq!(read(&studio.dir.join("surfaces/my-hills.png")), hills);
    let listed = studio.get("/api/profiles").json();
    assert!(
        listed
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p == "surfaces/my-hills.png"),
        "{listed}"
    );
    let patch = |body: &str| {
        http::request_with(
            studio.port,
            &format!("127.0.0.1:{}", studio.port),
            "PATCH",
            "/api/spec",
            &[("Content-Type", "application/json")],
            body.as_bytes(),
        )
    };
    let r = patch(
        r#"{"edits": [{"key": "surface.kind", "value": "heightmap"},
        {"key": "surface.image", "value": "surfaces/my-hills.png"},
        {"key": "surface.radius", "value": null},
        {"key": "surface.z_min", "value": 0}, {"key": "surface.z_max", "value": 0.5},
        {"key": "surface.size", "value": [64, 64]}]}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["design"]["surface"], "heightmap");
    let text = String::from_utf8(studio.get("/api/spec").body).unwrap();
    assert!(text.contains("size = [64.0, 64.0]"), "{text}");
    // two numbers or nothing; and no other key takes an array
    let r = patch(r#"{"edits": [{"key": "surface.size", "value": "64 by 64"}]}"#);
    assert_eq!(r.status, 422);
    assert_eq!(r.json()["errors"][0]["key"], "surface.size");
    let r = patch(r#"{"edits": [{"key": "surface.z_max", "value": [1, 2]}]}"#);
    assert_eq!(r.status, 400);
}

/// The first event of `kind` among the server-sent `events`.
fn event_of(events: &str, kind: &str) -> serde_json::Value {
    events
        .lines()
        .filter_map(|l| l.strip_prefix("data: "))
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|e| e["kind"] == kind)
        .unwrap_or_else(|| panic!("no {kind} event: {events}"))
}

#[test]
fn a_write_gives_the_command_lines_bytes() {
    let studio = Studio::start("write", SMALL);
    let events = studio.events_until_finished(|| {
        let r = studio.request("POST", "/api/write?what=device", b"");
        assert_eq!(r.status, 202);
    });
    assert!(events.contains(r#""kind":"stage""#), "{events}");
    assert!(events.contains(r#""kind":"done""#), "{events}");
    let cli_out = studio.dir.join("cli");
    let cli = Command::new(env!("CARGO_BIN_EXE_moirecast"))
        .args(["device", "--quiet", "-o"])
        .arg(&cli_out)
        .arg(studio.dir.join("design.toml"))
        .status()
        .unwrap();
    assert!(cli.success());
    for file in ["device.stl", "device.step"] {
        assert!(
            read(&studio.dir.join("out").join(file)) == read(&cli_out.join(file)),
            "{file} differs from the command line's"
        );
    }
    // the mold, too, which says what of the device run it replaces
    let events = studio.events_until_finished(|| {
        assert_eq!(
            studio.request("POST", "/api/write?what=mold", b"").status,
            202
        );
    });
    let done = event_of(&events, "done");
    assert_eq!(
        done["replaces"],
        serde_json::json!(["device.step", "device.stl", "report.json"]),
        "{done}"
    );
    let cli = Command::new(env!("CARGO_BIN_EXE_moirecast"))
        .args(["mold", "--quiet", "-o"])
        .arg(&cli_out)
        .arg(studio.dir.join("design.toml"))
        .status()
        .unwrap();
    assert!(cli.success());
    for file in ["mold-top.stl", "mold-bottom.stl", "assembly.scad"] {
        assert!(
            read(&studio.dir.join("out").join(file)) == read(&cli_out.join(file)),
            "{file} differs from the command line's"
        );
    }
}

#[test]
fn a_refused_write_is_worded_for_the_page() {
    // a printed device cannot be cast: the mold is refused by a named rule
    let printed = SMALL.replace(
        "kind = \"dual-lens\"\na = 0.0\nd = \"focal\"",
        "kind = \"printed\"\na = 0.0",
    );
    let studio = Studio::start("refused-write", &printed);
    let events = studio.events_until_finished(|| {
        let r = studio.request("POST", "/api/write?what=mold", b"");
        assert_eq!(r.status, 202);
    });
    let error = event_of(&events, "error");
    assert_eq!(error["refusal"], true, "{error}");
    let message = error["message"].as_str().unwrap();
    // no command-line prefix, no spec path; the key and the rule stay
    assert!(!message.starts_with("error:"), "{message}");
    assert!(
        !message.contains("design.toml") && !message.contains("spec `"),
        "{message}"
    );
    assert!(message.contains("base.kind"), "{message}");
}

#[test]
fn save_as_and_open_stay_in_the_specs_folder() {
    let studio = Studio::start("files", SMALL);
    let dir = &studio.dir;
    // Save as: a new name becomes the spec file
    let r = studio.request("POST", "/api/save-as?name=copy", b"");
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(read(&dir.join("copy.toml")), SMALL.as_bytes());
    let spec_file = |studio: &Studio| studio.get("/api/state").json()["spec_file"].clone();
    assert!(spec_file(&studio).as_str().unwrap().ends_with("copy.toml"));
    // another existing file is replaced only when asked
    let r = studio.request("POST", "/api/save-as?name=design.toml", b"");
    assert_eq!(r.status, 409);
    assert_eq!(r.json()["exists"], true);
    let r = studio.request("POST", "/api/save-as?name=design.toml&replace=true", b"");
    assert_eq!(r.status, 200);
    // names that leave the folder, hide, or are no spec are refused
    for bad in [
        "../up.toml",
        "sub%2Fx.toml",
        ".hidden.toml",
        "x.txt",
        "",
        "a%00b.toml",
    ] {
        let r = studio.request("POST", &format!("/api/save-as?name={bad}"), b"");
        assert_eq!(r.status, 400, "save as {bad:?}");
        let r = studio.request("POST", &format!("/api/open?name={bad}"), b"");
        assert_eq!(r.status, 400, "open {bad:?}");
    }
    assert!(!dir.parent().unwrap().join("up.toml").exists());
    assert_eq!(
        studio.get("/api/specs").json()["specs"],
        serde_json::json!(["copy.toml", "design.toml"])
    );

    // Open: a spec that does not build is refused by key, nothing changes
    let bad = SMALL.replace("afov = 60.0", "afov = 200");
    std::fs::write(dir.join("bad.toml"), &bad).unwrap();
    let before = studio.get("/api/state").json();
    let r = studio.request("POST", "/api/open?name=bad.toml", b"");
    assert_eq!(r.status, 422);
    assert_eq!(r.json()["errors"][0]["key"], "lens.afov");
    assert_eq!(studio.get("/api/state").json(), before);
    assert_eq!(
        studio
            .request("POST", "/api/open?name=missing.toml", b"")
            .status,
        404
    );

    // a valid one becomes the design and the file that Save writes
    let other = SMALL.replace("afov = 60.0", "afov = 50.0   # mine");
    std::fs::write(dir.join("other.toml"), &other).unwrap();
    let r = studio.request("POST", "/api/open?name=other.toml", b"");
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let state = r.json();
    assert_eq!(state["spec"], other.as_str());
    assert_eq!(state["values"]["lens"]["afov"], 50.0);
    assert!(state["revision"].as_u64() > before["revision"].as_u64());
    assert!(state["spec_file"].as_str().unwrap().ends_with("other.toml"));
    let r = http::request_with(
        studio.port,
        &format!("127.0.0.1:{}", studio.port),
        "PATCH",
        "/api/spec",
        &[("Content-Type", "application/json")],
        br#"{"edits": [{"key": "lens.afov", "value": 45}]}"#,
    );
    assert_eq!(r.status, 200);
    assert_eq!(studio.request("POST", "/api/save", b"").status, 200);
    assert_eq!(
        std::fs::read_to_string(dir.join("other.toml")).unwrap(),
        other.replace("afov = 50.0", "afov = 45.0")
    );
    assert_eq!(read(&dir.join("design.toml")), SMALL.as_bytes());
}

/// The reference spec, whose grid takes long enough to cancel.
const REFERENCE: &str = include_str!("../molds/saddle-horse.toml");

#[test]
fn scoring_the_grid_shows_its_progress_and_can_be_cancelled() {
    let studio = Studio::start("scoring", REFERENCE);
    let progress = |studio: &Studio| studio.get("/api/explore/progress").json();
    let idle = progress(&studio);
    assert_eq!(
        (idle["done"].as_u64(), idle["total"].as_u64()),
        (Some(0), Some(25))
    );
    assert_eq!(
        (idle["running"].as_bool(), idle["scored"].as_bool()),
        (Some(false), Some(false))
    );
    // nothing to cancel
    let r = studio.request("POST", "/api/explore/cancel", b"");
    assert_eq!(r.json()["cancelled"], false);

    let port = studio.port;
    let scoring = std::thread::spawn(move || {
        http::request(
            port,
            &format!("127.0.0.1:{port}"),
            "GET",
            "/api/explore",
            b"",
        )
    });
    // once a cell is done, cancel: the request answers "cancelled" after
    // the cells being scored, short of the whole grid
    let started = std::time::Instant::now();
    while progress(&studio)["done"].as_u64() < Some(1) {
        assert!(started.elapsed().as_secs() < 120, "no cell was scored");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert_eq!(
        studio.request("POST", "/api/explore/cancel", b"").json()["cancelled"],
        true
    );
    let r = scoring.join().unwrap();
    assert_eq!(r.status, 422, "{}", String::from_utf8_lossy(&r.body));
    assert!(r.json()["error"].as_str().unwrap().starts_with("cancelled"));
    let stopped = progress(&studio);
    assert!(stopped["done"].as_u64().unwrap() < 25, "{stopped}");
    assert_eq!(
        (stopped["running"].as_bool(), stopped["scored"].as_bool()),
        (Some(false), Some(false))
    );

    // a cancelled grid is not kept: the next request scores it whole (on
    // a small design, a revision of its own), here started without
    // waiting, as the page does, and followed until it is scored
    assert_eq!(
        studio.request("PUT", "/api/spec", SMALL.as_bytes()).status,
        200
    );
    assert_eq!(
        studio.request("POST", "/api/explore/start", b"").status,
        202
    );
    let started = std::time::Instant::now();
    while progress(&studio)["scored"] != true {
        assert!(started.elapsed().as_secs() < 120, "the grid was not scored");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let r = studio.get("/api/explore");
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["cells"].as_array().unwrap().len(), 25);
    let whole = progress(&studio);
    assert_eq!(
        (whole["done"].as_u64(), whole["scored"].as_bool()),
        (Some(25), Some(true))
    );
}
