// What the browser tests share: a `moirecast studio` on a free port, and
// Debian's chromium, headless, with the flags this machine needs (no
// background networking: the closed network refuses it).

import { spawn } from "node:child_process";
import { copyFileSync, mkdirSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";

/// Starts `moirecast studio SPEC -o OUT --port 0`; resolves to the server
/// and the URL it prints.
export async function startStudio(bin, spec, out) {
  const server = spawn(bin, ["studio", spec, "-o", out, "--port", "0"], {
    stdio: ["ignore", "pipe", "inherit"],
  });
  const url = await new Promise((resolve, reject) => {
    let text = "";
    server.stdout.on("data", (chunk) => {
      text += chunk;
      const m = text.match(/moirecast studio: (http:\/\/\S+)/);
      if (m) resolve(m[1]);
    });
    server.on("exit", (code) => reject(new Error(`the studio exited (${code}) before printing its URL`)));
    setTimeout(() => reject(new Error("no URL after 30 s")), 30000);
  });
  return { server, url };
}

/// Debian's chromium, headless (WebGL by SwiftShader).
export function launchChromium() {
  return chromium.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    args: [
      "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
      "--disable-background-networking", "--disable-component-update", "--disable-sync",
      "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    ],
  });
}

/// Copies the reference spec (as design.toml) and its image into `work`;
/// returns the repository's folder.
export function referenceInto(work) {
  const repo = join(dirname(fileURLToPath(import.meta.url)), "..", "..");
  mkdirSync(join(work, "profiles"), { recursive: true });
  copyFileSync(join(repo, "molds", "saddle-horse.toml"), join(work, "design.toml"));
  copyFileSync(join(repo, "molds", "profiles", "horse.png"), join(work, "profiles", "horse.png"));
  return repo;
}
