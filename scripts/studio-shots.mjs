// The README's pictures of the studio: the reference design at 1400 px
// wide (the moiré at 4° tilt, the mold halves in 3D, the scored (a, d)
// grid and the checks by part) and at 390 px (a phone).
//
//   node scripts/studio-shots.mjs MOIRECAST_BIN WORKDIR   (after npm ci --prefix tests/node)
//
// Writes WORKDIR/studio.png and WORKDIR/studio-390.png; copy them to docs/.

import { join } from "node:path";
import { launchChromium, referenceInto, startStudio } from "../tests/node/launch.mjs";

const [bin, work] = process.argv.slice(2);
if (!bin || !work) {
  console.error("usage: node scripts/studio-shots.mjs MOIRECAST_BIN WORKDIR");
  process.exit(2);
}
referenceInto(work);
const { server, url } = await startStudio(bin, join(work, "design.toml"), join(work, "out"));
const browser = await launchChromium();
try {
  const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
  await page.goto(url);
  await page.waitForFunction(() => window.studio && window.studio.frames >= 1, null, { timeout: 60000 });
  await page.locator("#tilt").fill("4");
  await page.locator("#tilt").dispatchEvent("change");
  await page.waitForFunction(() => document.getElementById("frame").dataset.tilt === "4" && !document.getElementById("frame").classList.contains("pending"), null, { timeout: 60000 });
  await page.locator("#show-mold").click();
  await page.waitForFunction(() => [...document.querySelectorAll("#check-list li.part")].some((li) => li.textContent.startsWith("Cavity")), null, { timeout: 120000 });
  await page.locator("#run-explore").click();
  await page.waitForFunction(() => document.getElementById("grid").children.length === 25, null, { timeout: 300000 });
  await page.waitForTimeout(1500);
  await page.screenshot({ path: join(work, "studio.png"), fullPage: true });
  const phone = await browser.newPage({ viewport: { width: 390, height: 844 } });
  await phone.goto(url);
  await phone.waitForFunction(() => window.studio && window.studio.frames >= 1, null, { timeout: 60000 });
  await phone.waitForTimeout(1000);
  await phone.screenshot({ path: join(work, "studio-390.png") });
  console.log(`wrote ${join(work, "studio.png")} and ${join(work, "studio-390.png")}`);
} finally {
  await browser.close();
  server.kill();
}
