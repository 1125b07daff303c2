// The studio in a real browser: Debian's chromium, headless, driven over
// the DevTools protocol by playwright-core (no browser download).
//
//   node tests/node/studio.mjs MOIRECAST_BIN WORKDIR SCREENSHOT
//
// Copies the reference spec and its image into WORKDIR, starts
// `moirecast studio` on a free port, and checks what a designer does:
// the first frame arrives; the tilt slider changes the frame; the view
// compensation toggles; afov = 200
// is refused at its field, naming `lens.afov`, and stays marked through
// the next edit, with a banner naming the revision shown; the 3D view orbits;
// "Write device files" writes device.stl into the output folder; "Write
// mold" writes the halves and shows the casting numbers; an edit
// saved keeps the spec's comments and changes only its line; a formula
// surface takes its kind and z together (z shows once the kind is
// formula; only the keys that apply show); undo and redo step through the
// revisions, with an unsaved mark; Save as and Open; the checks are
// grouped by part, labelled, and a failed one cannot be missed; scoring the explore grid shows its
// progress and can be cancelled; the grid marks the current design's cell, and goes stale when the design changes; at 390 px the
// page scrolls only down; at 1920 px the moiré grows past 512 px; a dropped PNG becomes the profile, or the height map when dropped on its field. Saves screenshots at 1400 and 390 px. Exits non-zero, saying why, on any failure.

import { existsSync, readFileSync } from "node:fs";
import { join } from "node:path";
import { launchChromium, referenceInto, startStudio } from "./launch.mjs";

const [bin, work, screenshot] = process.argv.slice(2);
if (!bin || !work || !screenshot) {
  console.error("usage: node studio.mjs MOIRECAST_BIN WORKDIR SCREENSHOT");
  process.exit(2);
}
referenceInto(work);
const out = join(work, "out");

const { server, url } = await startStudio(bin, join(work, "design.toml"), out);

const browser = await launchChromium();
let failed = false;
const check = (ok, what) => {
  console.log(`${ok ? "ok  " : "FAIL"} ${what}`);
  if (!ok) failed = true;
};
try {
  const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
  page.on("pageerror", (e) => check(false, `no script error on the page: ${e.message}`));
  await page.goto(url);

  // the first frame
  await page.waitForFunction(() => window.studio && window.studio.frames >= 1, null, { timeout: 60000 });
  const before = await page.locator("#frame").screenshot();
  check(before.length > 1000, "the first frame arrives");

  // the tilt slider changes the frame
  const frames = await page.evaluate(() => window.studio.frames);
  await page.locator("#tilt").fill("6");
  await page.waitForFunction(
    ([n]) => window.studio.frames > n && document.getElementById("frame").dataset.tilt === "6",
    [frames],
    { timeout: 60000 },
  );
  await page.waitForTimeout(200);
  const after = await page.locator("#frame").screenshot();
  check(!before.equals(after), "moving the tilt slider changes the frame");

  // while a frame is pending the view says so, and the labels keep naming
  // the frame on screen until the new one shows (frames held back 700 ms)
  await page.route("**/api/frame.png*", async (route) => { await new Promise((r) => setTimeout(r, 700)); await route.continue(); });
  const beforeSlow = await page.evaluate(() => window.studio.frames);
  await page.locator("#along").fill("5");
  await page.locator("#along").dispatchEvent("change");
  await page.waitForFunction(() => document.getElementById("frame").classList.contains("pending"), null, { timeout: 5000 });
  const pending = await page.evaluate(() => ({ state: document.getElementById("frame-state").textContent, label: document.getElementById("along-value").textContent }));
  await page.waitForFunction(([n]) => window.studio.frames > n && !document.getElementById("frame").classList.contains("pending"), [beforeSlow], { timeout: 60000 });
  const shownSlow = await page.evaluate(() => ({ label: document.getElementById("along-value").textContent, along: document.getElementById("frame").dataset.along, state: document.getElementById("frame-state").textContent }));
  check(pending.state.includes("along 5.00°") && pending.label === "0.00°" && shownSlow.label === "5.00°" && shownSlow.along === "5" && shownSlow.state === "",
    `a pending frame is marked and named; the label follows the frame on screen: ${JSON.stringify([pending, shownSlow])}`);
  await page.unroute("**/api/frame.png*");
  await page.locator("#along").fill("0");
  await page.locator("#along").dispatchEvent("change");
  await page.waitForFunction(() => document.getElementById("frame").dataset.along === "0", null, { timeout: 60000 });

  // the compensation toggle: off, the design is today's uncompensated base
  // and the frame changes; on again, back to the design view's picture
  const compensated = await page.locator("#frame").screenshot();
  const revision = await page.evaluate(() => window.studio.revision);
  const shown = await page.evaluate(() => window.studio.frames);
  await page.locator("#compensate").uncheck();
  await page.waitForFunction(
    ([r, n]) => window.studio.revision > r && window.studio.frames > n,
    [revision, shown],
    { timeout: 60000 },
  );
  await page.waitForTimeout(200);
  const uncompensated = await page.locator("#frame").screenshot();
  const off = await (await page.request.get(url + "api/state")).json();
  check(off.values.view && off.values.view.compensate === false && !compensated.equals(uncompensated),
    "unticking the compensation builds the uncompensated base, and the frame changes");
  await page.locator("#compensate").check();
  await page.waitForFunction(() => document.getElementById("compensate").checked && (window.studio.values.view || {}).compensate === undefined, null, { timeout: 60000 });
  check(true, "ticking it again compensates the base (the default: the key goes)");

  // afov = 200 is refused at its field, naming the key
  await page.locator("#f-lens-afov").fill("200");
  await page.locator("#f-lens-afov").press("Tab");
  await page.waitForFunction(
    () => document.querySelector('.field[data-key="lens.afov"] .error').textContent.length > 0,
    null,
    { timeout: 30000 },
  );
  const error = await page.locator('.field[data-key="lens.afov"] .error').textContent();
  // in the page's words: the value, the problem, the fix and the range with
  // its unit in front; no command-line prefix, no file path
  check(error.startsWith("200: ") && error.includes("\nFix: ") && /\nAllowed \(.+\): /.test(error)
    && !error.includes("error:") && !error.includes(".toml") && !error.includes("`"),
    `afov = 200 is refused at the field, in the page's words: ${JSON.stringify(error)}`);
  const state = await (await page.request.get(url + "api/state")).json();
  check(state.values.lens.afov === 60, "the last good design stays (lens.afov = 60)");

  // the refused value stays in its field, marked, through the next edit
  // that builds, and the banner names the revision on screen and the key
  const refusedAt = await page.evaluate(() => window.studio.revision);
  await page.locator("#f-base-levels").fill("1.00");
  await page.locator("#f-base-levels").press("Tab");
  await page.waitForFunction(([r]) => window.studio.revision > r, [refusedAt], { timeout: 60000 });
  const marked = await page.evaluate(() => ({
    value: document.getElementById("f-lens-afov").value,
    invalid: document.querySelector('.field[data-key="lens.afov"]').classList.contains("invalid"),
    banner: document.getElementById("draft").hidden ? "" : document.getElementById("draft").textContent,
  }));
  check(marked.value === "200" && marked.invalid && marked.banner.includes("lens.afov = 200") && marked.banner.includes(`revision ${refusedAt + 1}`),
    `after another edit the refused afov stays marked, and the banner says so: ${JSON.stringify(marked.banner)}`);

  // the 3D view: the device loads, and dragging orbits it
  await page.waitForFunction(() => window.studio.view.meshes.length > 0, null, { timeout: 60000 });
  const canvas = page.locator("#view3d");
  const still = await canvas.screenshot();
  const yaw = await page.evaluate(() => window.studio.yaw);
  const box = await canvas.boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 120, box.y + box.height / 2 + 30, { steps: 8 });
  await page.mouse.up();
  const orbited = await canvas.screenshot();
  const yawAfter = await page.evaluate(() => window.studio.yaw);
  check(yawAfter !== yaw && !still.equals(orbited), `dragging orbits the 3D view (yaw ${yaw.toFixed(2)} → ${yawAfter.toFixed(2)})`);

  // the 3D pane's axes, scale bar, active view and reset
  const pane = await page.evaluate(() => ({
    label: document.getElementById("scale-label").textContent,
    bar: document.getElementById("scale-line").getBoundingClientRect().width,
    canvas: document.getElementById("view3d").getBoundingClientRect().width,
    axes: Boolean(window.studio.view.axes),
    device: document.getElementById("show-device").getAttribute("aria-pressed"),
    mold: document.getElementById("show-mold").getAttribute("aria-pressed"),
  }));
  check(/^[0-9.]+ mm$/.test(pane.label) && pane.bar > 0.08 * pane.canvas && pane.bar <= 0.2 * pane.canvas + 1 && pane.axes
    && pane.device === "true" && pane.mold === "false",
    `the 3D pane has axes, a scale bar (${pane.label}, ${pane.bar.toFixed(0)} of ${pane.canvas.toFixed(0)} px) and marks the device view active`);
  await page.locator("#reset-view").click();
  // (the state, not the pixels: the software GL's antialiasing differs in
  // about 1 % of the pixels between two draws of one view)
  const reset = await page.evaluate(() => [window.studio.yaw, window.studio.pitch, window.studio.distance / window.studio.view.radius]);
  check(reset[0] === 0.6 && reset[1] === 0.7 && Math.abs(reset[2] - 3) < 1e-12,
    `"Reset view" brings back the first view (yaw ${reset[0]}, pitch ${reset[1]}, distance ${reset[2]} radii)`);

  // readable checks: grouped by part (the mold's once it is built), each
  // with its registry label and its limit as a maximum or a minimum
  await page.locator("#show-mold").click();
  await page.waitForFunction(() => [...document.querySelectorAll("#check-list li.part")].some((li) => li.textContent.startsWith("Cavity")), null, { timeout: 120000 });
  const readable = await page.evaluate(() => ({
    parts: [...document.querySelectorAll("#check-list li.part")].map((li) => li.textContent.split(":")[0].toLowerCase()),
    thickness: [...document.querySelectorAll('#check-list li[data-check="min-thickness"] span')].map((e) => e.textContent),
    surface: [...document.querySelectorAll('#check-list li[data-check="surface-to-mesh"] span')].map((e) => e.textContent),
  }));
  check(JSON.stringify(readable.parts) === JSON.stringify(["device", "mold top", "mold bottom", "mold", "cavity"])
    && readable.thickness[1] === "Thickness" && readable.thickness[2].includes(" ≥ ")
    && readable.surface[1] === "Mesh within tolerance" && readable.surface[2].includes(" ≤ "),
    `checks are grouped by part (${readable.parts.join(", ")}), labelled, with ≤ for a maximum and ≥ for a minimum: ${JSON.stringify([readable.thickness, readable.surface])}`);
  // a failed check cannot be missed (a failure injected into the report)
  await page.route("**/api/report", async (route) => {
    const report = await (await route.fetch()).json();
    const c = report.checks.find((c) => c.name === "min-thickness");
    c.passed = false; c.value = 0.001;
    await route.fulfill({ json: report });
  });
  await page.evaluate(() => loadReport());
  await page.waitForFunction(() => !document.getElementById("checks-failed").hidden, null, { timeout: 60000 });
  const failure = await page.evaluate(() => ({
    banner: document.getElementById("checks-failed").textContent,
    header: document.getElementById("header-failed").hidden ? "" : document.getElementById("header-failed").textContent,
    red: document.getElementById("checks").classList.contains("failed"),
    row: document.querySelector('#check-list li[data-check="min-thickness"]').className,
  }));
  await page.unroute("**/api/report");
  check(failure.banner === "✗ 1 check failed: Thickness (device)" && failure.header === "✗ 1 failed check" && failure.red && failure.row === "failed",
    `a failed check is named in a banner and in the header, and marked red: ${JSON.stringify(failure)}`);
  await page.locator("#show-device").click();
  await page.evaluate(() => loadReport());
  await page.waitForFunction(() => document.getElementById("checks-failed").hidden, null, { timeout: 60000 });

  // "Write device files" writes device.stl
  await page.locator("#write-device").click();
  await page.waitForFunction(() => document.getElementById("written").textContent.includes("device.stl"), null, { timeout: 120000 });
  check(existsSync(join(out, "device.stl")), `device.stl is written into ${out}`);

  // "Write mold" writes the halves and shows what to weigh out
  await page.locator("#write-mold").click();
  await page.waitForFunction(() => document.getElementById("casting").textContent.length > 0, null, { timeout: 300000 });
  const casting = await page.locator("#casting").textContent();
  check(existsSync(join(out, "mold-top.stl")) && /fill [0-9.]+ mL/.test(casting) && /mix [0-9.]+ g/.test(casting) && casting.includes("sylgard"),
    `the mold is written and its casting numbers show: ${JSON.stringify(casting)}`);
  const replaced = await page.locator("#written").textContent();
  check(/replaced the earlier run in .*: device\.step, device\.stl, report\.json/.test(replaced),
    `the mold's write says which device files it replaced: ${JSON.stringify(replaced.split("\n")[0])}`);

  // an edit, then "Save spec": the spec file keeps its comments, spacing
  // and number formatting, and only the edited line changes
  const written = readFileSync(join(work, "design.toml"), "utf8");
  const before55 = await page.evaluate(() => window.studio.revision);
  await page.locator("#f-lens-afov").fill("55");
  await page.locator("#f-lens-afov").press("Tab");
  await page.waitForFunction(([r]) => window.studio.revision > r, [before55], { timeout: 60000 });
  await page.locator("#save").click();
  await page.waitForFunction(() => document.getElementById("status").textContent.startsWith("saved"), null, { timeout: 30000 });
  const saved = readFileSync(join(work, "design.toml"), "utf8");
  check(await page.evaluate(() => document.getElementById("draft").hidden && !document.querySelector(".field.invalid")),
    "once afov builds, its mark and the banner go");
  const expected = written.replace(/^afov = 60\.0( +# degrees)$/m, "afov = 55.0$1");
  check(expected !== written && saved === expected,
    `a saved edit keeps the spec's comments and changes one line (${saved.split("\n").find((l) => l.startsWith("afov"))})`);

  // undo and redo (Ctrl+Z, Ctrl+Shift+Z) step through the revisions; the
  // unsaved mark follows the saved text
  const afovIs = (x) => page.waitForFunction(([x]) => window.studio.values.lens.afov === x, [x], { timeout: 60000 });
  await page.locator("#f-lens-afov").fill("50");
  await page.locator("#f-lens-afov").press("Tab");
  await afovIs(50);
  const unsavedAfterEdit = await page.locator("#unsaved").isVisible();
  await page.locator("header h1").click();
  await page.keyboard.press("Control+z");
  await afovIs(55);
  const unsavedAfterUndo = await page.locator("#unsaved").isVisible();
  const fieldAfterUndo = await page.locator("#f-lens-afov").inputValue();
  await page.keyboard.press("Control+Shift+z");
  await afovIs(50);
  await page.keyboard.press("Control+z");
  await afovIs(55);
  check(unsavedAfterEdit && !unsavedAfterUndo && fieldAfterUndo === "55",
    "an edit marks the spec unsaved; Ctrl+Z undoes it (afov 50 -> 55, the saved text again), Ctrl+Shift+Z redoes it");

  // Save as: a new name in the spec's folder becomes the spec file; Open
  // brings back another spec of the folder, asking first about unsaved
  // changes, and its history starts anew
  await page.locator("#save-as-name").fill("copy");
  await page.locator("#save-as").click();
  await page.waitForFunction(() => document.getElementById("spec-file").textContent.endsWith("copy.toml"), null, { timeout: 30000 });
  const copied = existsSync(join(work, "copy.toml")) ? readFileSync(join(work, "copy.toml"), "utf8") : "";
  await page.locator("#f-lens-afov").fill("52");
  await page.locator("#f-lens-afov").press("Tab");
  await afovIs(52);
  await page.waitForFunction(() => [...document.getElementById("open-name").options].map((o) => o.value).join() === "copy.toml,design.toml", null, { timeout: 30000 });
  await page.locator("#open-name").selectOption("design.toml");
  let asked = "";
  page.once("dialog", (d) => { asked = d.message(); d.accept(); });
  await page.locator("#open").click();
  await page.waitForFunction(() => document.getElementById("spec-file").textContent.endsWith("design.toml"), null, { timeout: 30000 });
  await afovIs(55);
  const opened = await page.evaluate(() => ({ unsaved: !document.getElementById("unsaved").hidden, undo: document.getElementById("undo").disabled }));
  check(copied === saved && asked.includes("unsaved") && !opened.unsaved && opened.undo,
    `Save as writes copy.toml and makes it the spec file; Open asks about unsaved changes (${JSON.stringify(asked)}) and opens design.toml, its history anew`);

  // scoring the grid shows its progress and can be cancelled
  // (the status as it changes: a small grid is scored within a second)
  await page.evaluate(() => {
    window.statuses = [];
    new MutationObserver(() => window.statuses.push(document.getElementById("explore-status").textContent))
      .observe(document.getElementById("explore-status"), { childList: true, characterData: true, subtree: true });
  });
  await page.locator("#run-explore").click();
  await page.waitForFunction(() => window.statuses.some((s) => /^scoring: /.test(s)), null, { timeout: 120000 });
  const scoringShown = await page.evaluate(() => ({ status: window.statuses.find((s) => /^scoring: /.test(s)), bar: !document.getElementById("explore-progress").hidden }));
  await page.locator("#cancel-explore").click();
  await page.waitForFunction(() => document.getElementById("explore-status").textContent.startsWith("cancelled"), null, { timeout: 120000 });
  const cancelled = await page.evaluate(() => ({ status: document.getElementById("explore-status").textContent, cells: document.getElementById("grid").children.length, again: !document.getElementById("run-explore").disabled }));
  const counted = await page.evaluate(() => window.statuses.filter((s) => /^scoring: [0-9]+ of 25 cells$/.test(s)));
  check(scoringShown.bar && /^cancelled after [0-9]+ of 25 cells/.test(cancelled.status) && cancelled.cells === 0 && cancelled.again,
    `scoring shows its progress (${JSON.stringify(counted.length ? counted : scoringShown.status)}) and Cancel stops it: ${JSON.stringify(cancelled.status)}`);

  // the explore grid marks the current design's cell
  await page.locator("#run-explore").click();
  await page.waitForFunction(() => document.getElementById("grid").children.length === 25, null, { timeout: 300000 });
  const current = await page.evaluate(() => [...document.querySelectorAll("#grid figure.current figcaption")].map((c) => c.textContent));
  check(current.length === 1 && current[0].startsWith("a 0 · d 1·D_s"), `the current design's cell is marked: ${JSON.stringify(current)}`);

  // only the keys that apply show: no z on a saddle, no printed keys on a
  // dual-lens device; "all keys" shows them
  const applicable = await page.evaluate(() => ["surface.z", "base.duty", "surface.radius"].map((k) => !document.querySelector(`.field[data-key="${k}"]`).hidden));
  await page.locator("#all-keys").check();
  const all = await page.evaluate(() => [...document.querySelectorAll("#form .field")].every((f) => !f.hidden));
  await page.locator("#all-keys").uncheck();
  check(!applicable[0] && !applicable[1] && applicable[2] && all, `z and duty hide on a dual-lens saddle, radius shows, "all keys" shows every key (${applicable})`);

  // a linked edit: kind = "formula" is refused for its missing z and stays
  // in the draft; typing z builds both together
  const beforeFormula = await page.evaluate(() => window.studio.revision);
  await page.locator("#f-surface-kind").selectOption("formula");
  await page.waitForFunction(() => document.querySelector('.field[data-key="surface.kind"]').classList.contains("invalid"), null, { timeout: 30000 });
  await page.locator("#f-surface-z").fill("(x*x - y*y)/120");
  await page.locator("#f-surface-z").press("Tab");
  await page.waitForFunction(([r]) => window.studio.revision > r, [beforeFormula], { timeout: 60000 });
  const linked = await page.evaluate(() => ({ surface: window.studio.values.surface, marked: document.querySelectorAll(".field.invalid").length }));
  check(linked.surface.kind === "formula" && linked.surface.z === "(x*x - y*y)/120" && linked.marked === 0,
    `kind = formula, refused alone, builds with z typed after it: ${JSON.stringify(linked)}`);
  const stale = await page.evaluate(() => [document.getElementById("grid").classList.contains("stale"), document.getElementById("explore-status").textContent]);
  check(stale[0] && stale[1].startsWith("stale"), `the grid scored for the saddle is marked stale: ${JSON.stringify(stale[1])}`);

  // a PNG dropped on the page joins the spec's folder and becomes the profile
  const png = readFileSync(new URL("../../molds/profiles/coins.png", import.meta.url)).toString("base64");
  const beforeDrop = await page.evaluate(() => window.studio.revision);
  await page.evaluate((b64) => {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const transfer = new DataTransfer();
    transfer.items.add(new File([bytes], "my coins.png", { type: "image/png" }));
    document.body.dispatchEvent(new DragEvent("drop", { dataTransfer: transfer, bubbles: true, cancelable: true }));
  }, png);
  await page.waitForFunction(([r]) => window.studio.revision > r, [beforeDrop], { timeout: 60000 });
  const dropped = await page.evaluate(() => ({ profile: window.studio.values.profile, chosen: document.getElementById("f-profile-image").value }));
  check(dropped.profile.kind === "image" && dropped.profile.image === "profiles/my-coins.png" && dropped.chosen === "profiles/my-coins.png"
    && existsSync(join(work, "profiles", "my-coins.png")),
    `a dropped PNG is added to the spec's folder and made the profile: ${JSON.stringify(dropped)}`);

  await page.screenshot({ path: screenshot, fullPage: true });
  console.log(`screenshot: ${screenshot}`);

  // a phone, 390 px wide: the page scrolls only down, the moiré first
  const phone = await browser.newPage({ viewport: { width: 390, height: 844 } });
  await phone.goto(url);
  await phone.waitForFunction(() => window.studio && window.studio.frames >= 1, null, { timeout: 60000 });
  const widths = await phone.evaluate(() => [document.documentElement.scrollWidth, document.documentElement.clientWidth]);
  check(widths[0] <= widths[1], `no sideways scrolling at 390 px (content ${widths[0]} px in ${widths[1]})`);
  const narrow = screenshot.replace(/\.png$/, "-390.png");
  await phone.screenshot({ path: narrow, fullPage: false });
  console.log(`screenshot: ${narrow}`);

  // a wide screen: the moiré grows beyond 512 px, sharper at rest
  const wide = await browser.newPage({ viewport: { width: 1920, height: 1080 } });
  await wide.goto(url);
  await wide.waitForFunction(() => window.studio && window.studio.frames >= 1 && document.getElementById("frame").naturalWidth > 256, null, { timeout: 60000 });
  const big = await wide.evaluate(() => ({ shown: document.getElementById("frame").getBoundingClientRect().width, pixels: document.getElementById("frame").naturalWidth, scroll: document.documentElement.scrollWidth <= document.documentElement.clientWidth }));
  check(big.shown > 600 && big.pixels >= 512 && big.scroll, `at 1920 px the moiré is ${big.shown.toFixed(0)} px wide, from a ${big.pixels} px frame, with no sideways scrolling`);

  // last (the other pages render the design before it): a height map dropped on its field joins surfaces/ and becomes the surface
  const hills = readFileSync(new URL("../../molds/surfaces/hills.png", import.meta.url)).toString("base64");
  const beforeHills = await page.evaluate(() => window.studio.revision);
  await page.evaluate((b64) => {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const transfer = new DataTransfer();
    transfer.items.add(new File([bytes], "hills.png", { type: "image/png" }));
    const field = document.querySelector('[data-key="surface.image"]');
    field.dispatchEvent(new DragEvent("drop", { dataTransfer: transfer, bubbles: true, cancelable: true }));
  }, hills);
  await page.waitForFunction(([r]) => window.studio.revision > r, [beforeHills], { timeout: 60000 });
  const surfaced = await page.evaluate(() => ({
    surface: window.studio.values.surface,
    chosen: document.getElementById("f-surface-image").value,
    shown: !document.querySelector('[data-key="surface.z_max"]').hidden,
    radius: document.querySelector('[data-key="surface.radius"]').hidden,
  }));
  check(surfaced.surface.kind === "heightmap" && surfaced.surface.image === "surfaces/hills.png" && surfaced.chosen === "surfaces/hills.png"
    && surfaced.shown && surfaced.radius && existsSync(join(work, "surfaces", "hills.png")),
    `a PNG dropped on the height map's field becomes the surface, with its keys shown: ${JSON.stringify(surfaced)}`);
} catch (e) {
  check(false, String(e));
} finally {
  await browser.close();
  server.kill();
}
process.exit(failed ? 1 : 0);
