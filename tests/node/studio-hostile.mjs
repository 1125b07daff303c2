// The studio against hostile pages and files, in a real browser: Debian's
// chromium, headless, driven by playwright-core.
//
//   node tests/node/studio-hostile.mjs MOIRECAST_BIN WORKDIR
//
// 1. A PNG in the spec's folder named like markup that runs script
//    (`<img src=x onerror=...>.png`) is listed as text: no script runs, and
//    the page carries a Content-Security-Policy that forbids inline script.
// 2. A page served from another origin (another port of 127.0.0.1) tries
//    what any web page the user visits could: POST /api/write, POST
//    /api/save, /api/save-as, /api/open and PUT /api/spec, with fetch (no-cors, text/plain, which
//    browsers send without a preflight) and with a form. The studio
//    refuses every one: nothing is written, the spec file and the design
//    are unchanged. The studio cannot be framed by it either.
// Exits non-zero, saying why, on any failure.

import { copyFileSync, existsSync, readFileSync, readdirSync } from "node:fs";
import { createServer } from "node:http";
import { join } from "node:path";
import { launchChromium, referenceInto, startStudio } from "./launch.mjs";

const [bin, work] = process.argv.slice(2);
if (!bin || !work) {
  console.error("usage: node studio-hostile.mjs MOIRECAST_BIN WORKDIR");
  process.exit(2);
}
const repo = referenceInto(work);
const evil = `<img src=x onerror="document.title='PWNED'">.png`;
copyFileSync(join(repo, "molds", "profiles", "horse.png"), join(work, evil));
const specBefore = readFileSync(join(work, "design.toml"), "utf8");
const out = join(work, "out");

const { server, url } = await startStudio(bin, join(work, "design.toml"), out);

// the other site: a page that tries the writes and frames the studio
const attack = `<!doctype html><html><body>
<iframe id="framed" src="${url}"></iframe>
<form id="form" method="POST" action="${url}api/save" enctype="text/plain"><input name="x" value="y"></form>
<script>
window.attempts = (async () => {
  const tries = [
    ["POST", "api/write?what=device", "x"],
    ["POST", "api/save", "x"],
    ["POST", "api/save-as?name=pwned", "x"],
    ["POST", "api/open?name=design.toml", "x"],
    ["PUT", "api/spec", "[layout]\\nperiod = 1.0\\n"],
  ];
  for (const [method, path, body] of tries) {
    try { await fetch("${url}" + path, { method, mode: "no-cors", body, headers: { "content-type": "text/plain" } }); } catch (e) {}
  }
  return "tried";
})();
</script></body></html>`;
const site = createServer((req, res) => {
  res.writeHead(200, { "content-type": "text/html" });
  res.end(attack);
});
await new Promise((resolve) => site.listen(0, "127.0.0.1", resolve));
const siteUrl = `http://127.0.0.1:${site.address().port}/`;

const browser = await launchChromium();
let failed = false;
const check = (ok, what) => {
  console.log(`${ok ? "ok  " : "FAIL"} ${what}`);
  if (!ok) failed = true;
};
try {
  // 1. the file name is text
  const page = await browser.newPage();
  const response = await page.goto(url);
  const csp = response.headers()["content-security-policy"] || "";
  check(csp.includes("script-src 'self'") && !csp.includes("unsafe-inline") && csp.includes("frame-ancestors 'none'"),
    `the page's Content-Security-Policy forbids inline script and framing: ${csp}`);
  await page.waitForFunction(
    (name) => [...document.querySelectorAll('[data-key="profile.image"] option')].some((o) => o.textContent === name),
    evil,
    { timeout: 60000 },
  );
  await page.waitForTimeout(500);
  check(await page.title() !== "PWNED", "a file named like markup is listed as text, and runs no script");
  const injected = await page.evaluate(() => document.querySelectorAll('img[src="x"]').length);
  check(injected === 0, "no element was made from the file's name");
  const stateBefore = await (await page.request.get(url + "api/state")).json();

  // 2. another site's page tries to write
  const other = await browser.newPage();
  await other.goto(siteUrl);
  await other.evaluate(() => window.attempts);
  await other.evaluate(() => document.getElementById("form").submit());
  await other.waitForTimeout(1000);
  const framed = other.frames().find((f) => f.url().startsWith(url));
  const framedLoaded = framed ? await framed.evaluate(() => !!document.getElementById("frame")).catch(() => false) : false;
  check(!framedLoaded, "the studio does not load in another site's frame");
  const written = existsSync(out) ? readdirSync(out) : [];
  check(written.length === 0, `another site's page wrote nothing (out: ${JSON.stringify(written)})`);
  check(readFileSync(join(work, "design.toml"), "utf8") === specBefore && !existsSync(join(work, "pwned.toml")),
    "another site's page did not rewrite the spec file, nor save it as another (pwned.toml)");
  const stateAfter = await (await page.request.get(url + "api/state")).json();
  check(stateAfter.revision === stateBefore.revision && stateAfter.values.layout.period === 0.5,
    `another site's page did not change the design (revision ${stateBefore.revision} → ${stateAfter.revision})`);

  // the studio's own page still writes
  const own = await page.evaluate(async () => (await fetch("/api/save", { method: "POST" })).status);
  check(own === 200, `the studio's own page still saves (${own})`);
} catch (e) {
  check(false, String(e));
} finally {
  await browser.close();
  site.close();
  server.kill();
}
process.exit(failed ? 1 : 0);
