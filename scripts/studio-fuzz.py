#!/usr/bin/env python3
"""Fuzzes `moirecast studio` over HTTP: random routes, methods, queries,
headers and bodies (random spec TOML among them, mutated from a small
valid one), and now and then a malformed request line or a connection
that hangs up halfway. Counts the answers by status; a crash, an abort, a
request unanswered within HANG_S, or the studio's RSS over 1 GB fails it.

    python3 scripts/studio-fuzz.py MOIRECAST_BIN REQUESTS [SEED]

Only the standard library. Prints the counts as JSON; exits non-zero on
the first failure."""
import json
import os
import pathlib
import random
import re
import socket
import subprocess
import sys
import tempfile
import time

HANG_S = 120.0
# requests in flight at once
WORKERS = 8
RSS_LIMIT_MB = 1024

SPEC = """[surface]
kind = "saddle"
radius = 40.0
[layout]
width = 4.0
height = 3.0
period = 0.5
[lens]
afov = 60.0
[base]
levels = 1.0
[profile]
kind = "bump"
sigma = 1.5
[mesh]
tolerance = 0.004
"""

ROUTES = ["/", "/studio.js", "/studio.css", "/api/keys", "/api/state", "/api/spec", "/api/save",
          "/api/profiles", "/api/frame.png", "/api/report", "/api/device.stl", "/api/mold/top.stl",
          "/api/mold/bottom.stl", "/api/mold/device.stl", "/api/explore", "/api/explore/3.png",
          "/api/write", "/api/events", "/../etc/passwd", "/api/explore/+1.png", "/api/mold/x",
          "/%2e%2e/", "/api//state", "/API/STATE", "/favicon.ico"]
# builds that take seconds are asked for rarely
HEAVY = {"/api/mold/top.stl", "/api/mold/bottom.stl", "/api/mold/device.stl", "/api/explore",
         "/api/explore/3.png", "/api/write"}
KEYS = ["surface.kind", "surface.radius", "surface.z", "layout.width", "layout.height",
        "layout.period", "lens.afov", "lens.index", "lens.material", "base.kind", "base.a",
        "base.d", "base.levels", "base.duty", "profile.kind", "profile.wavelength",
        "profile.sigma", "profile.image", "mesh.tolerance", "view.tilt", "view.tilt_along",
        "view.distance", "view.compensate", "mold.gate_diameter", "nope.nope"]


def value(rng):
    return rng.choice([
        lambda: str(rng.uniform(-1e3, 1e3)), lambda: str(rng.choice([0, -1, 1e300, 1e-300])),
        lambda: '"nan"', lambda: "nan", lambda: "inf", lambda: "true", lambda: '"focal"',
        lambda: '"' + rng.choice(["plane", "saddle", "formula", "rings", "image", "printed",
                                  "x*y/1000", "../../etc/passwd", "<script>", "infinite"]) + '"',
        lambda: '"' + "+".join(f"x*y/{1000 + i}" for i in range(rng.randint(1, 300))) + '"',
        lambda: '"' + "sin(" * rng.randint(1, 40) + "x" + ")" * rng.randint(0, 40) + '"',
        lambda: str(rng.uniform(0.01, 2.0)), lambda: str(rng.randint(-5, 5000)),
        lambda: "[1, 2]", lambda: '"' + "a" * rng.randint(0, 5000) + '"',
    ])()


def spec_body(rng):
    text = SPEC
    for _ in range(rng.randint(0, 4)):
        table, key = rng.choice(KEYS).split(".")
        line = f"{key} = {value(rng)}"
        text = text.replace(f"[{table}]\n", f"[{table}]\n{line}\n", 1) if f"[{table}]" in text \
            else text + f"\n[{table}]\n{line}\n"
        # a key already there twice is a TOML error: fine, it is fuzz
    roll = rng.random()
    if roll < 0.1:
        text = text[: rng.randint(0, len(text))]
    elif roll < 0.15:
        text = bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 300))).decode("latin-1")
    return text.encode("utf-8", "replace")


def query(rng):
    params = []
    for name in rng.sample(["tilt", "along", "size", "samples", "lights", "what", "token", "x"],
                           rng.randint(0, 5)):
        v = rng.choice([str(rng.uniform(-90, 90)), str(rng.randint(-10, 5000)), "nan", "",
                        "default", "white", "#ff0000,#00ff00", "device", "mold", "%00", "1e309"])
        params.append(f"{name}={v}")
    return ("?" + "&".join(params)) if params else ""


def request(rng, port):
    route = rng.choice(ROUTES)
    while route in HEAVY and rng.random() < 0.98:
        route = rng.choice(ROUTES)
    if route == "/api/frame.png":
        # frames mostly small: the worker renders them one at a time
        q = f"?tilt={rng.uniform(-20, 20):.2f}&size={rng.choice([16, 32, 64, 96])}&samples={rng.randint(1, 3)}"
        q += rng.choice(["", f"&along={rng.uniform(-10, 10):.1f}", "&lights=white", "&size=100000"])
    else:
        q = query(rng)
    method = rng.choice(["GET"] * 6 + ["PUT", "POST", "DELETE", "HEAD", "OPTIONS", "PATCH", "BREW"])
    if route == "/api/spec" and rng.random() < 0.7:
        method = "PUT"
    body = spec_body(rng) if method in ("PUT", "POST") else b""
    host = rng.choice([f"127.0.0.1:{port}"] * 8 + ["evil.example", "", "localhost:1", f"[::1]:{port}"])
    headers = [f"Host: {host}"] if host else []
    for name, v in rng.sample([("Origin", "http://evil.example"), ("Origin", f"http://127.0.0.1:{port}"),
                               ("Sec-Fetch-Site", "cross-site"), ("Content-Type", "text/plain"),
                               ("Cookie", "moirecast_token=0"), ("X-Junk", "x" * 10000),
                               ("Content-Length", "99999999"), ("Transfer-Encoding", "chunked")],
                              rng.randint(0, 3)):
        headers.append(f"{name}: {v}")
    if not any(h.startswith("Content-Length") or h.startswith("Transfer-Encoding") for h in headers):
        headers.append(f"Content-Length: {len(body)}")
    head = f"{method} {route}{q} HTTP/1.1\r\n" + "\r\n".join(headers) + "\r\nConnection: close\r\n\r\n"
    if rng.random() < 0.01:
        head = rng.choice(["GARBAGE\r\n\r\n", "GET / HTTP/9.9\r\n\r\n", "GET " + "a" * 70000 + " HTTP/1.1\r\n\r\n"])
    return route, head.encode("latin-1", "replace") + body, rng.random() < 0.01


def exchange(port, route, raw, hang_up):
    """Sends `raw`; the answer's status, `hung-up`, `closed`, or `hang` if
    no whole answer came within HANG_S (an event stream: its head)."""
    deadline = time.monotonic() + HANG_S
    with socket.create_connection(("127.0.0.1", port), timeout=HANG_S) as s:
        try:
            s.sendall(raw)
            # all sent: a body shorter than declared ends here
            s.shutdown(socket.SHUT_WR)
        except OSError:
            pass  # refused mid-body: it may close early
        if hang_up:
            return "hung-up"
        reply = b""
        try:
            while time.monotonic() < deadline:
                s.settimeout(max(0.1, deadline - time.monotonic()))
                chunk = s.recv(65536)
                if not chunk:
                    break
                reply += chunk
                if route == "/api/events" and b"\r\n\r\n" in reply:
                    break
            else:
                return "hang"
        except socket.timeout:
            return "hang"
        except OSError:
            pass
        m = re.match(rb"HTTP/1\.1 (\d+)", reply)
        return m.group(1).decode() if m else "closed"


def rss_mb(pid):
    for line in pathlib.Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def main():
    binary, total = sys.argv[1], int(sys.argv[2])
    rng = random.Random(int(sys.argv[3]) if len(sys.argv) > 3 else 1)
    work = pathlib.Path(tempfile.mkdtemp(prefix="moirecast-studio-fuzz-"))
    (work / "design.toml").write_text(SPEC)
    studio = subprocess.Popen([binary, "studio", str(work / "design.toml"), "-o", str(work / "out"),
                               "--port", "0"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    url = studio.stdout.readline()
    port = int(re.search(r":(\d+)/", url).group(1))
    counts, peak, started = {}, 0.0, time.monotonic()
    requests = [request(rng, port) for _ in range(total)]
    failure = []

    def one(i):
        route, raw, hang_up = requests[i]
        status = exchange(port, route, raw, hang_up)
        if status == "hang":
            failure.append({"hang": i, "request": raw[:300].decode("latin-1")})
        return status

    try:
        from concurrent.futures import ThreadPoolExecutor
        with ThreadPoolExecutor(max_workers=WORKERS) as pool:
            for i, status in enumerate(pool.map(one, range(total))):
                counts[status] = counts.get(status, 0) + 1
                if studio.poll() is not None:
                    failure.append({"crash": i, "code": studio.returncode})
                if i % 200 == 0:
                    peak = max(peak, rss_mb(studio.pid))
                    if peak > RSS_LIMIT_MB:
                        failure.append({"rss_mb": peak, "at": i})
                if failure:
                    print(json.dumps({"failure": failure, "counts": counts}))
                    os._exit(1)
    finally:
        if studio.poll() is None:
            peak = max(peak, rss_mb(studio.pid))
            studio.kill()
    print(json.dumps({"requests": total, "seconds": round(time.monotonic() - started, 1),
                      "peak_rss_mb": round(peak), "crashes": 0, "hangs": 0, "statuses": counts}))


if __name__ == "__main__":
    main()
