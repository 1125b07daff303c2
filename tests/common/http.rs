//! A minimal HTTP/1.1 client for the studio's tests and benchmark: one
//! request per connection, the whole response read.

use std::io::{Read, Write};
use std::net::TcpStream;

/// An HTTP response: status, headers (lower-case names), body.
pub struct Response {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Response {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or_else(|e| {
            panic!(
                "{e}: {} {}",
                self.status,
                String::from_utf8_lossy(&self.body)
            )
        })
    }
}

/// Starts `moirecast studio` on a free loopback port, serving from its own
/// thread; returns the port.
pub fn start_studio(spec: std::path::PathBuf, out: std::path::PathBuf) -> u16 {
    let url = start_studio_at(spec, out, "127.0.0.1");
    url.trim_end_matches('/')
        .rsplit(':')
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// Starts `moirecast studio` listening on `host` (port 0), serving from its
/// own thread; returns the URL it prints.
pub fn start_studio_at(spec: std::path::PathBuf, out: std::path::PathBuf, host: &str) -> String {
    let (sender, receiver) = std::sync::mpsc::channel();
    let options = moirecast::studio::StudioOptions {
        spec: Some(spec),
        out,
        host: host.parse().unwrap(),
        port: 0,
        allow_large: false,
    };
    std::thread::spawn(move || {
        moirecast::studio::run(options, |url| sender.send(url.to_string()).unwrap()).unwrap()
    });
    receiver.recv().unwrap()
}

/// `method target` with `body` to 127.0.0.1:`port`, with `Host: host`.
pub fn request(port: u16, host: &str, method: &str, target: &str, body: &[u8]) -> Response {
    request_with(port, host, method, target, &[], body)
}

/// [`request`] with more `headers` (name, value).
pub fn request_with(
    port: u16,
    host: &str,
    method: &str,
    target: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Response {
    let mut stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
    let extra: String = headers
        .iter()
        .map(|(n, v)| format!("{n}: {v}\r\n"))
        .collect();
    write!(
        stream,
        "{method} {target} HTTP/1.1\r\nHost: {host}\r\n{extra}Content-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    )
    .unwrap();
    // a refused body may close the connection before it is all sent
    let _ = stream.write_all(body);
    let mut raw = Vec::new();
    stream.read_to_end(&mut raw).unwrap();
    parse_response(&raw)
}

pub fn parse_response(raw: &[u8]) -> Response {
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a header block");
    let head = String::from_utf8_lossy(&raw[..split]).into_owned();
    let mut lines = head.lines();
    let status = lines
        .next()
        .unwrap()
        .split(' ')
        .nth(1)
        .unwrap()
        .parse()
        .unwrap();
    let headers: Vec<(String, String)> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(n, v)| (n.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let mut body = raw[split + 4..].to_vec();
    if headers
        .iter()
        .any(|(n, v)| n == "transfer-encoding" && v.contains("chunked"))
    {
        body = dechunk(&body);
    }
    Response {
        status,
        headers,
        body,
    }
}

fn dechunk(mut raw: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    loop {
        let line_end = raw.windows(2).position(|w| w == b"\r\n").unwrap();
        let size = usize::from_str_radix(std::str::from_utf8(&raw[..line_end]).unwrap().trim(), 16)
            .unwrap();
        if size == 0 {
            return out;
        }
        out.extend_from_slice(&raw[line_end + 2..line_end + 2 + size]);
        raw = &raw[line_end + 2 + size + 2..];
    }
}
