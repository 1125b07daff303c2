//! `moirecast studio` against hostile input (issue 44): formulas that
//! aborted the process, writes from another site, and the headers that
//! keep the page from being framed or running injected script. The browser
//! side (a file named like markup, another site's page) is
//! tests/node/studio-hostile.mjs.

mod common;

use common::http::{self, Response};
use common::{scratch, Scratch, SMALL};

struct Studio {
    port: u16,
    dir: Scratch,
}

impl Studio {
    fn start(name: &str) -> Studio {
        let dir = scratch("studio-hostile", name);
        std::fs::write(dir.join("design.toml"), SMALL).unwrap();
        let port = http::start_studio(dir.join("design.toml"), dir.join("out"));
        Studio { port, dir }
    }

    fn host(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }

    fn send(&self, method: &str, target: &str, headers: &[(&str, &str)], body: &[u8]) -> Response {
        http::request_with(self.port, &self.host(), method, target, headers, body)
    }
}

/// The formulas of issue 44 that overflowed the studio's stack: each is
/// refused at `surface.z` by its named rule (or parses), and the studio
/// answers the next request.
#[test]
fn formulas_that_aborted_the_studio_are_refused_by_name() {
    let studio = Studio::start("formulas");
    let sum = |n: usize| {
        (0..n)
            .map(|i| format!("x*y/{}", 1000 + i))
            .collect::<Vec<_>>()
            .join("+")
    };
    let nested = |d: usize| (0..d).fold("x".to_string(), |f, _| format!("sin({f})"));
    let cases = [
        (sum(18), "formula-operations"),
        (sum(200), "formula-length"),
        (nested(9), "formula-depth"),
        (
            (0..20)
                .map(|i| format!("sin(x/{})", i + 1))
                .collect::<Vec<_>>()
                .join("+"),
            "formula-operations",
        ),
        (
            (0..10)
                .map(|_| "(x+y)".to_string())
                .collect::<Vec<_>>()
                .join("*"),
            "formula-derivatives",
        ),
    ];
    for (z, rule) in cases {
        let spec = format!(
            "[surface]\nkind = \"formula\"\nz = \"{z}\"\n[profile]\nkind = \"bump\"\nsigma = 1.5\n"
        );
        let r = studio.send("PUT", "/api/spec", &[], spec.as_bytes());
        assert_eq!(r.status, 422, "{}", String::from_utf8_lossy(&r.body));
        let errors = r.json()["errors"].clone();
        assert_eq!(errors[0]["key"], "surface.z", "{errors}");
        assert!(
            errors[0]["message"].as_str().unwrap().contains(rule),
            "{rule}: {errors}"
        );
    }
    // a product within the budget parses, and the design is built
    let five = (0..5)
        .map(|i| format!("(x/30+{i})"))
        .collect::<Vec<_>>()
        .join("*");
    let spec = format!("[surface]\nkind = \"formula\"\nz = \"{five}/1000\"\n[layout]\nwidth = 4.0\nheight = 3.0\n[profile]\nkind = \"bump\"\nsigma = 1.5\n");
    let r = studio.send("PUT", "/api/spec", &[], spec.as_bytes());
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(studio.send("GET", "/api/state", &[], b"").status, 200);
}

/// A request that changes state from another origin is refused, whatever
/// its content type; the studio's own origin and tools that send no
/// Origin (curl) are not. Every answer refuses framing and carries the CSP.
#[test]
fn writes_from_another_site_are_refused() {
    let studio = Studio::start("cross-site");
    let own = format!("http://{}", studio.host());
    let spec = SMALL.replace("period = 0.5", "period = 1.0");
    let refused = [
        (
            "POST",
            "/api/write?what=device",
            vec![
                ("Origin", "http://evil.example"),
                ("Content-Type", "text/plain"),
            ],
        ),
        (
            "POST",
            "/api/save",
            vec![
                ("Origin", "http://evil.example"),
                ("Content-Type", "text/plain"),
            ],
        ),
        ("PUT", "/api/spec", vec![("Origin", "null")]),
        (
            "POST",
            "/api/profiles?name=evil.png",
            vec![
                ("Origin", "http://evil.example"),
                ("Content-Type", "image/png"),
            ],
        ),
        (
            "PATCH",
            "/api/spec",
            vec![
                ("Origin", "http://evil.example"),
                ("Content-Type", "application/json"),
            ],
        ),
        ("POST", "/api/save", vec![("Sec-Fetch-Site", "cross-site")]),
        (
            "POST",
            "/api/save",
            vec![("Origin", own.as_str()), ("Sec-Fetch-Site", "same-site")],
        ),
    ];
    for (method, target, headers) in &refused {
        let r = studio.send(method, target, headers, spec.as_bytes());
        assert_eq!(
            r.status,
            403,
            "{method} {target} {headers:?}: {}",
            String::from_utf8_lossy(&r.body)
        );
    }
    assert!(!studio.dir.join("out").exists(), "nothing was written");
    assert!(
        !studio.dir.join("profiles/evil.png").exists(),
        "no image was added"
    );
    assert_eq!(
        std::fs::read_to_string(studio.dir.join("design.toml")).unwrap(),
        SMALL
    );
    assert_eq!(
        studio.send("GET", "/api/state", &[], b"").json()["values"]["layout"]["period"],
        0.5
    );
    // the page itself, and curl
    let ours = [("Origin", own.as_str()), ("Sec-Fetch-Site", "same-origin")];
    assert_eq!(
        studio
            .send("PUT", "/api/spec", &ours, spec.as_bytes())
            .status,
        200
    );
    assert_eq!(studio.send("POST", "/api/save", &[], b"").status, 200);
    // reading is not refused, and every answer carries the headers
    let page = studio.send("GET", "/", &[("Origin", "http://evil.example")], b"");
    assert_eq!(page.status, 200);
    let csp = page.header("content-security-policy").unwrap_or_default();
    assert!(
        csp.contains("script-src 'self'") && csp.contains("frame-ancestors 'none'"),
        "{csp}"
    );
    assert_eq!(page.header("x-frame-options"), Some("DENY"));
    let script = studio.send("GET", "/studio.js", &[], b"");
    assert_eq!(script.status, 200);
    assert!(script
        .header("content-type")
        .unwrap()
        .starts_with("text/javascript"));
    let html = String::from_utf8_lossy(&page.body);
    assert!(!html.contains("<script>"), "no inline script on the page");
}

/// `/api/explore/+1.png` is no cell (it answered 200), and an image path
/// says the same whether it is missing, a folder, or a link leading out of
/// the spec's folder: nothing of what exists outside it.
#[test]
fn paths_tell_nothing_of_what_exists_outside() {
    let studio = Studio::start("paths");
    for target in [
        "/api/explore/+1.png",
        "/api/explore/-0.png",
        "/api/explore/.png",
    ] {
        assert_eq!(studio.send("GET", target, &[], b"").status, 404, "{target}");
    }
    let outside = studio
        .dir
        .join("..")
        .join(format!("outside-{}.png", std::process::id()));
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/molds/profiles/horse.png"),
        &outside,
    )
    .unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(&outside, studio.dir.join("link.png")).unwrap();
    std::fs::create_dir_all(studio.dir.join("folder.png")).unwrap();
    let message = |image: &str| {
        let spec = format!("{SMALL}\n").replace(
            "[profile]\nkind = \"bump\"\nsigma = 1.5",
            &format!("[profile]\nimage = \"{image}\""),
        );
        let r = studio.send("PUT", "/api/spec", &[], spec.as_bytes());
        assert_eq!(
            r.status,
            422,
            "{image}: {}",
            String::from_utf8_lossy(&r.body)
        );
        r.json()["errors"][0]["message"]
            .as_str()
            .unwrap()
            .to_string()
    };
    let missing = message("missing.png");
    assert_eq!(message("folder.png"), missing);
    #[cfg(unix)]
    assert_eq!(message("link.png"), missing);
    assert!(missing.contains("inside the spec's folder"), "{missing}");
    std::fs::remove_file(outside).unwrap();
}

/// Idle sockets cannot hold the studio: 300 connections that send nothing
/// (more than it serves at once) are closed after the header timeout, and
/// a request then answers (1,100 of them made every request time out).
#[test]
fn idle_sockets_are_closed_and_the_studio_answers() {
    use std::io::Read;
    let studio = Studio::start("idle");
    let idle: Vec<std::net::TcpStream> = (0..300)
        .filter_map(|_| std::net::TcpStream::connect(("127.0.0.1", studio.port)).ok())
        .collect();
    assert!(
        idle.len() > moirecast::studio::MAX_CONNECTIONS,
        "{} connected",
        idle.len()
    );
    std::thread::sleep(moirecast::studio::HEADER_TIMEOUT + std::time::Duration::from_secs(1));
    let closed = idle
        .into_iter()
        .filter(|mut s| {
            s.set_read_timeout(Some(std::time::Duration::from_secs(2)))
                .unwrap();
            matches!(s.read(&mut [0u8; 16]), Ok(0) | Err(_))
        })
        .count();
    assert_eq!(closed, 300, "every idle socket is closed");
    assert_eq!(studio.send("GET", "/api/state", &[], b"").status, 200);
}

/// Beyond loopback (`--host 0.0.0.0`) the studio answers any Host a remote
/// browser sends (the loopback list refused a real one and let in a remote
/// client that sent `Host: 127.0.0.1`), and only with the session token
/// printed in its URL: the URL sets it as a same-site cookie.
#[test]
fn beyond_loopback_every_request_needs_the_session_token() {
    let dir = scratch("studio-hostile", "token");
    std::fs::write(dir.join("design.toml"), SMALL).unwrap();
    let url = http::start_studio_at(dir.join("design.toml"), dir.join("out"), "0.0.0.0");
    let (address, token) = url
        .split_once("/?token=")
        .expect("the URL carries the token");
    assert_eq!(token.len(), 32, "{url}");
    let port: u16 = address.rsplit(':').next().unwrap().parse().unwrap();
    let get = |host: &str, target: &str, headers: &[(&str, &str)]| {
        http::request_with(port, host, "GET", target, headers, b"")
    };
    for host in [format!("127.0.0.1:{port}"), format!("studio.lan:{port}")] {
        assert_eq!(
            get(&host, "/api/state", &[]).status,
            403,
            "{host} without the token"
        );
        let header = [("x-studio-token", token)];
        assert_eq!(
            get(&host, "/api/state", &header).status,
            200,
            "{host} with it"
        );
    }
    let wrong = [("x-studio-token", "00000000000000000000000000000000")];
    assert_eq!(get("studio.lan:1", "/api/state", &wrong).status, 403);
    let printed = get(
        &format!("studio.lan:{port}"),
        &format!("/?token={token}"),
        &[],
    );
    assert_eq!(printed.status, 303);
    let cookie = printed.header("set-cookie").unwrap().to_string();
    assert!(
        cookie.contains("HttpOnly") && cookie.contains("SameSite=Strict"),
        "{cookie}"
    );
    let pair = cookie.split(';').next().unwrap();
    assert_eq!(
        get(&format!("studio.lan:{port}"), "/", &[("cookie", pair)]).status,
        200
    );
}

/// A frame past its budget of rays is refused at once (1024 px at 64
/// phases through the mesh held the only frame worker for 13 minutes), and
/// frames whose clients hang up leave the worker to answer the next
/// (`render_traced_while` stops them: its own test).
#[test]
fn frames_have_a_budget_and_hung_up_frames_leave_the_worker() {
    use std::io::Write;
    let studio = Studio::start("frames");
    let r = studio.send(
        "GET",
        "/api/frame.png?size=1024&samples=8&along=30&tilt=30",
        &[],
        b"",
    );
    assert_eq!(r.status, 400, "{}", String::from_utf8_lossy(&r.body));
    assert!(String::from_utf8_lossy(&r.body).contains("budget"));
    // within the budget, and among the slowest frames: 1024 px at 4
    // phases, tilted about both axes
    let slow = "/api/frame.png?size=1024&samples=2&along=20&tilt=10";
    for _ in 0..3 {
        let mut hung = std::net::TcpStream::connect(("127.0.0.1", studio.port)).unwrap();
        write!(
            hung,
            "GET {slow} HTTP/1.1\r\nHost: {}\r\n\r\n",
            studio.host()
        )
        .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(300));
        drop(hung); // the client goes away
    }
    let r = studio.send("GET", "/api/frame.png?size=64&samples=2&tilt=0", &[], b"");
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
}

/// A body declared past the limit is refused at once (a Content-Length of
/// 100 MB kept the handler waiting), a body cut short ends its request,
/// and event streams past their number are refused instead of holding
/// connections.
#[test]
fn bodies_and_event_streams_cannot_hold_the_studio() {
    use std::io::{Read, Write};
    let studio = Studio::start("bodies");
    let raw = |head: &str, shut: bool| {
        let mut s = std::net::TcpStream::connect(("127.0.0.1", studio.port)).unwrap();
        s.write_all(head.as_bytes()).unwrap();
        if shut {
            s.shutdown(std::net::Shutdown::Write).unwrap();
        }
        let mut reply = String::new();
        let _ = s.read_to_string(&mut reply);
        reply
    };
    let huge = format!("PUT /api/spec HTTP/1.1\r\nHost: {}\r\nContent-Length: 99999999\r\nConnection: close\r\n\r\n[layout]\n", studio.host());
    let reply = raw(&huge, false);
    assert!(reply.starts_with("HTTP/1.1 413"), "{reply}");
    // declared 500 bytes, sent 9, then the client's side closes
    let short = format!(
        "PUT /api/spec HTTP/1.1\r\nHost: {}\r\nContent-Length: 500\r\n\r\n[layout]\n",
        studio.host()
    );
    let reply = raw(&short, true);
    assert!(reply.starts_with("HTTP/1.1 4"), "{reply}");
    let streams: Vec<std::net::TcpStream> = (0..moirecast::studio::MAX_EVENT_STREAMS)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(("127.0.0.1", studio.port)).unwrap();
            write!(
                s,
                "GET /api/events HTTP/1.1\r\nHost: {}\r\n\r\n",
                studio.host()
            )
            .unwrap();
            let mut head = [0u8; 12];
            s.read_exact(&mut head).unwrap();
            assert_eq!(&head, b"HTTP/1.1 200");
            s
        })
        .collect();
    assert_eq!(studio.send("GET", "/api/events", &[], b"").status, 503);
    drop(streams);
    assert_eq!(studio.send("GET", "/api/state", &[], b"").status, 200);
}

/// The spec that grew the studio past 24 GB (a metre-wide plane of 20,000
/// lenses) is refused when the device is asked for, before it is built,
/// and the studio goes on answering.
#[test]
fn a_design_past_the_budget_is_refused_not_built() {
    let studio = Studio::start("budget");
    let huge = "[surface]\nkind = \"plane\"\n[layout]\nwidth = 1000.0\nheight = 1000.0\nperiod = 0.05\n[profile]\nkind = \"rings\"\n";
    let r = studio.send("PUT", "/api/spec", &[], huge.as_bytes());
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let r = studio.send("GET", "/api/report", &[], b"");
    assert_eq!(r.status, 422);
    let error = r.json()["error"].as_str().unwrap().to_string();
    assert!(
        error.contains("layout.width") && error.contains("--allow-large"),
        "{error}"
    );
    assert_eq!(studio.send("GET", "/api/state", &[], b"").status, 200);
}
