#!/usr/bin/env node
// The README's picture of `moirecast studio`: the reference design with
// its moiré tilted, the explore grid scored, and the mold halves in 3D.
// Uses the test command's playwright-core (tests/node) and Debian's chromium.
//
//   node scripts/studio-picture.mjs target/release/moirecast docs/studio.png

import { spawn } from "node:child_process";
import { mkdtempSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { chromium } from "../tests/node/node_modules/playwright-core/index.mjs";

const [bin, picture] = process.argv.slice(2);
const out = mkdtempSync(join(tmpdir(), "moirecast-studio-picture-"));
const server = spawn(bin, ["studio", "molds/saddle-horse.toml", "-o", out, "--port", "0"], { stdio: ["ignore", "pipe", "inherit"] });
const url = await new Promise((resolve) => {
  let text = "";
  server.stdout.on("data", (c) => { text += c; const m = text.match(/(http:\/\/\S+)/); if (m) resolve(m[1]); });
});
const browser = await chromium.launch({
  executablePath: "/usr/bin/chromium",
  args: ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
});
try {
  const page = await browser.newPage({ viewport: { width: 1400, height: 1020 } });
  await page.goto(url);
  await page.waitForFunction(() => window.studio && window.studio.frames >= 1, null, { timeout: 60000 });
  await page.locator("#tilt").fill("4");
  await page.waitForFunction(() => document.getElementById("frame").dataset.tilt === "4", null, { timeout: 60000 });
  await page.locator("#run-explore").click();
  await page.waitForFunction(() => document.querySelectorAll("#grid figure").length === 25, null, { timeout: 120000 });
  await page.locator("#show-mold").click();
  await page.waitForFunction(() => window.studio.view.meshes.length === 3, null, { timeout: 120000 });
  await page.waitForFunction(() => document.getElementById("check-list").children.length > 20, null, { timeout: 120000 });
  await page.waitForTimeout(500);
  await page.screenshot({ path: picture });
  console.log(`wrote ${picture}`);
} finally {
  await browser.close();
  server.kill();
}
