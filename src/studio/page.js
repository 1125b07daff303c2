"use strict";
const $ = (id) => document.getElementById(id);
const studio = { keys: [], values: {}, revision: 0, frames: 0, yaw: 0.6, pitch: 0.7, distance: 0, lastFrameMs: null };
window.studio = studio;

function setStatus(text) { $("status").textContent = text; }

async function api(path, options) {
  const response = await fetch(path, options);
  return response;
}

// ---- spec form -------------------------------------------------------------

function fieldValue(key) {
  const [t, k] = key.split(".");
  return studio.values[t] ? studio.values[t][k] : undefined;
}

function buildForm() {
  const form = $("form");
  form.replaceChildren();
  let fieldset = null, table = null;
  for (const doc of studio.keys) {
    const [t, k] = doc.key.split(".");
    if (t !== table) {
      table = t;
      fieldset = document.createElement("fieldset");
      const legend = document.createElement("legend");
      legend.textContent = `[${t}]`;
      fieldset.appendChild(legend);
      form.appendChild(fieldset);
    }
    const div = document.createElement("div");
    div.className = "field";
    div.dataset.key = doc.key;
    const id = "f-" + doc.key.replace(".", "-");
    const label = document.createElement("label");
    label.htmlFor = id; label.textContent = k + (doc.unit ? ` (${doc.unit})` : ""); label.title = doc.meaning;
    let input;
    const kind = doc.kind.type;
    if (kind === "choice" || kind === "bool") {
      input = document.createElement("select");
      const choices = kind === "bool" ? ["true", "false"] : doc.kind.choices;
      input.add(new Option("(default)", ""));
      for (const c of choices) input.add(new Option(c, c));
    } else {
      input = document.createElement("input");
      input.type = "text";
      input.placeholder = doc.default;
    }
    input.id = id; input.name = doc.key;
    input.addEventListener("change", () => edit(doc, input.value));
    const hint = document.createElement("div");
    hint.className = "hint";
    hint.textContent = `default ${doc.default} · ${doc.range}`;
    hint.title = doc.meaning;
    const error = document.createElement("div");
    error.className = "error";
    div.append(label, input, hint, error);
    fieldset.appendChild(div);
  }
}

// The images in the spec's folder, to pick as the profile or as the
// height map.
function setProfileChoices(images) {
  for (const key of ["profile.image", "surface.image"]) {
    const doc = studio.keys.find((d) => d.key === key);
    const old = document.querySelector(`[data-key="${key}"] input, [data-key="${key}"] select`);
    if (!doc || !old) continue;
    const select = document.createElement("select");
    select.id = old.id; select.name = old.name;
    // every name from the server is text, never markup
    select.add(new Option("(none)", ""));
    for (const p of images) select.add(new Option(p, p));
    select.value = old.value;
    select.addEventListener("change", () => edit(doc, select.value));
    old.replaceWith(select);
  }
}

// A PNG dropped anywhere on the page goes into the spec's folder
// (profiles/, named safely by the server) and becomes the profile; dropped
// on the height map's field, it goes into surfaces/ and becomes the
// surface.
document.addEventListener("dragover", (e) => { if (e.dataTransfer && [...e.dataTransfer.types].includes("Files")) e.preventDefault(); });
document.addEventListener("drop", async (e) => {
  const file = e.dataTransfer && e.dataTransfer.files[0];
  if (!file) return;
  e.preventDefault();
  if (file.type && file.type !== "image/png") { setStatus(`${file.name}: drop a PNG image`); return; }
  const surface = e.target instanceof Element && e.target.closest('[data-key="surface.image"]');
  const route = surface ? "surfaces" : "profiles";
  const response = await api(`/api/${route}?name=${encodeURIComponent(file.name)}`, { method: "POST", body: await file.arrayBuffer(), headers: { "content-type": "image/png" } });
  const body = await response.json().catch(() => ({}));
  if (!response.ok) { setStatus(`${file.name}: ${body.error || `HTTP ${response.status}`}`); return; }
  setProfileChoices(await (await api("/api/profiles")).json());
  if (surface) {
    await patchSpec([{ key: "surface.kind", value: "heightmap" }, { key: "surface.image", value: body.image },
      { key: "surface.z", value: null }, { key: "surface.radius", value: null }]);
    setStatus(`added ${body.image} and made it the height map`);
  } else {
    await patchSpec([{ key: "profile.kind", value: "image" }, { key: "profile.image", value: body.image }]);
    setStatus(`added ${body.image} and made it the profile`);
  }
});

// Which keys apply to the design as written: the others (printed keys on a
// dual-lens design, z on a saddle, …) hide unless "all keys" is ticked,
// the spec writes them, or the draft holds them.
function applies(key) {
  // the draft's value where it holds one: z shows once kind = formula is typed
  const v = (k) => {
    const draft = studio.refused.get(k);
    const doc = studio.keys.find((d) => d.key === k);
    return draft && doc ? parseField(doc, draft.text ?? "") : fieldValue(k);
  };
  const surface = v("surface.kind") ?? "saddle";
  const base = v("base.kind") ?? "dual-lens";
  const profile = v("profile.kind") ?? (v("profile.image") !== undefined ? "image" : "rings");
  const rules = {
    "surface.radius": !["plane", "formula", "heightmap"].includes(surface),
    "surface.z": surface === "formula",
    "surface.image": surface === "heightmap",
    "surface.z_min": surface === "heightmap",
    "surface.z_max": surface === "heightmap",
    "surface.size": surface === "heightmap",
    "surface.smoothing": surface === "heightmap",
    "base.afov": base === "dual-lens",
    "base.duty": base === "printed",
    "base.band_thickness": base === "printed",
    "base.backing": base === "printed",
    "profile.image": profile === "image",
    "profile.mode": profile === "image",
    "profile.blur": profile === "image",
    "profile.threshold": profile === "image",
    "profile.invert": profile === "image",
    "profile.wavelength": profile === "rings",
    "profile.angle": profile === "ramp",
    "profile.sigma": profile === "bump",
    "mold.bolt_diameter": v("mold.bolts") === true,
    "mold.bolt_spacing": v("mold.bolts") === true,
  };
  return rules[key] ?? true;
}

function showApplicableFields() {
  const all = $("all-keys").checked;
  for (const field of document.querySelectorAll("#form .field")) {
    const key = field.dataset.key;
    field.hidden = !(all || applies(key) || fieldValue(key) !== undefined || studio.refused.has(key));
  }
}

function fillForm() {
  for (const doc of studio.keys) {
    const input = $("f-" + doc.key.replace(".", "-"));
    if (!input) continue;
    const v = fieldValue(doc.key);
    const text = v === undefined ? "" : String(v);
    if (input.tagName === "SELECT" && text && ![...input.options].some((o) => o.value === text)) {
      input.add(new Option(text, text));
    }
    input.value = text;
  }
}

function parseField(doc, text) {
  const kind = doc.kind.type;
  if (text.trim() === "") return undefined;
  if (kind === "bool") return text === "true";
  if (kind === "number" || kind === "distance") {
    const n = Number(text);
    return text.trim() !== "" && Number.isFinite(n) ? n : text;
  }
  if (kind === "pair") {
    // "64, 64" or "[64, 64]"
    const parts = text.replace(/^\s*\[|\]\s*$/g, "").split(",").map((p) => p.trim());
    const numbers = parts.map(Number);
    return parts.length === 2 && parts.every((p) => p !== "") && numbers.every(Number.isFinite) ? numbers : text;
  }
  return text;
}

// The draft: values the user typed that the last good design does not
// take. Each stays in its field, marked, until an edit of that key builds;
// the banner says which revision is on screen and what differs from it.
studio.refused = new Map(); // key → { text, message }

function clearErrors() {
  for (const f of document.querySelectorAll(".field.invalid")) f.classList.remove("invalid");
  for (const e of document.querySelectorAll(".field .error")) e.textContent = "";
  $("spec-error").textContent = "";
}

function inputOf(key) { return $("f-" + key.replace(".", "-")); }

function showDraft() {
  clearErrors();
  for (const [key, { text, message }] of studio.refused) {
    const field = document.querySelector(`.field[data-key="${key}"]`);
    if (!field) continue;
    field.classList.add("invalid");
    const doc = studio.keys.find((d) => d.key === key);
    field.querySelector(".error").textContent = message + (doc ? `\nAllowed${doc.unit ? ` (${doc.unit})` : ""}: ${doc.range}` : "");
    const input = inputOf(key);
    if (input && text !== undefined) input.value = text;
  }
  const keys = [...studio.refused.keys()];
  $("draft").hidden = keys.length === 0;
  $("draft").textContent = keys.length
    ? `showing revision ${studio.revision}, the last design that built; not applied: ${keys.map((k) => `${k} = ${studio.refused.get(k).text}`).join(", ")}`
    : "";
}

// An error as the form shows it: the value, the problem and the fix, in
// the page's words; no command-line prefix, no file path. At its field the
// key is the field's label; elsewhere it leads.
function errorText(e, atField) {
  const value = e.value === null || e.value === undefined ? "" : `${e.value}: `;
  const lead = !atField && e.key ? `${e.key} = ${value}` : value;
  return `${lead}${e.message}${e.fix ? `.\nFix: ${e.fix}` : ""}`;
}

// `edited`: the keys the refused request set; those the errors do not name
// (kind = "formula", refused for its missing z) join the draft too.
function showErrors(errors, edited = []) {
  for (const e of errors) {
    if (e.key && document.querySelector(`.field[data-key="${e.key}"]`)) {
      const input = inputOf(e.key);
      studio.refused.set(e.key, { text: input ? input.value : undefined, message: errorText(e, true) });
    }
  }
  const named = errors.map((e) => e.key).filter(Boolean);
  for (const key of edited) {
    const input = inputOf(key);
    if (named.includes(key) || !input || !document.querySelector(`.field[data-key="${key}"]`)) continue;
    if (input.value === String(fieldValue(key) ?? "")) continue; // as the design has it
    studio.refused.set(key, { text: input.value, message: `not applied: it needs ${named.join(", ") || "a fix"} too` });
  }
  showDraft();
  showApplicableFields();
  const unplaced = errors.filter((e) => !e.key || !document.querySelector(`.field[data-key="${e.key}"]`));
  if (unplaced.length) $("spec-error").textContent = unplaced.map((e) => errorText(e, false)).join("\n");
  for (const e of errors) {
    const field = e.key && document.querySelector(`.field[data-key="${e.key}"]`);
    if (field) { field.scrollIntoView({ block: "nearest" }); break; }
  }
  setStatus(`refused: ${errors.map((e) => e.key || "TOML").join(", ")} (the last good design stays)`);
}

// A field's edit goes to the server as an edit of the spec's own text,
// which keeps the user's comments, order and number formatting.
// With refused values in the draft, the edit first goes with them: values
// that need each other (kind = "formula" and its z) build together once
// the last one is typed. If that is refused, the edit goes alone, so an
// unrelated edit still builds and the draft stays marked.
async function edit(doc, text) {
  const v = parseField(doc, text);
  const edits = [{ key: doc.key, value: v === undefined ? null : v }];
  if (doc.key === "profile.image" && v !== undefined) edits.push({ key: "profile.kind", value: "image" });
  if (doc.key === "surface.image" && v !== undefined) edits.push({ key: "surface.kind", value: "heightmap" });
  if (doc.key === "profile.kind" && v !== undefined && v !== "image") edits.push({ key: "profile.image", value: null });
  const withDraft = [...edits];
  for (const [key, draft] of studio.refused) {
    const other = studio.keys.find((d) => d.key === key);
    if (!other || withDraft.some((e) => e.key === key)) continue;
    const value = parseField(other, draft.text ?? "");
    withDraft.push({ key, value: value === undefined ? null : value });
  }
  if (withDraft.length > edits.length && (await patchSpec(withDraft, { quiet: true }))) return;
  patchSpec(edits);
}

// `quiet`: a refusal leaves the page as it was (a first try).
function patchSpec(edits, { quiet = false } = {}) {
  const request = { method: "PATCH", body: JSON.stringify({ edits }), headers: { "content-type": "application/json" } };
  return sendSpec(request, edits.map((e) => e.key), quiet);
}

// The whole TOML replaces the draft. `how`: "undo" or "redo" when it
// steps through the history (see applyState).
function putSpec(text, how = "edit") {
  return sendSpec({ method: "PUT", body: text, headers: { "content-type": "application/toml" } }, null, false, how);
}

// Undo and redo step through the spec texts this page has built: each is
// put again as a new revision.
studio.history = []; studio.future = []; studio.text = undefined; studio.savedText = undefined;
async function undo() {
  if (!studio.history.length) return;
  if (!(await putSpec(studio.history.pop(), "undo"))) setStatus("undo refused");
}
async function redo() {
  if (!studio.future.length) return;
  if (!(await putSpec(studio.future.pop(), "redo"))) setStatus("redo refused");
}
function showSaved() {
  $("unsaved").hidden = studio.text === studio.savedText;
  $("undo").disabled = !studio.history.length;
  $("redo").disabled = !studio.future.length;
}

// `keys`: the keys the request edits (null: all of them), which leave the
// draft once it builds.
async function sendSpec(request, keys, quiet = false, how = "edit") {
  setStatus("checking the spec…");
  const response = await api("/api/spec", request);
  const body = await response.json().catch(() => ({}));
  if (response.status === 422 && quiet) return false;
  if (response.status === 422) { showErrors(body.errors || [], keys || []); return false; }
  if (!response.ok) { $("spec-error").textContent = body.error || `HTTP ${response.status}`; return false; }
  if (keys === null) studio.refused.clear(); else for (const k of keys) studio.refused.delete(k);
  applyState(body, how);
  return true;
}

// `how` "open": another spec file, whose history starts anew.
function applyState(state, how = "edit") {
  if (how === "open") { studio.history = []; studio.future = []; studio.savedText = state.spec; studio.refused.clear(); }
  else if (studio.text !== undefined && state.spec !== studio.text) {
    if (how === "undo") studio.future.push(studio.text);
    else { studio.history.push(studio.text); if (how !== "redo") studio.future = []; }
  }
  studio.text = state.spec;
  if (studio.savedText === undefined) studio.savedText = state.spec;
  showSaved();
  studio.values = state.values;
  studio.revision = state.revision;
  studio.design = state.design;
  studio.derived = state.derived;
  $("toml").value = state.spec;
  $("revision").textContent = `revision ${state.revision}`;
  $("spec-file").textContent = state.spec_file;
  $("out-dir").textContent = `into ${state.out}`;
  fillForm();
  showDraft();
  showApplicableFields();
  markGrid();
  showView();
  showLightPickers();
  const d = state.derived;
  setStatus(`${d.N} lenses on a ${state.design.surface}, ${state.design.width_mm} × ${state.design.height_mm} mm; D_s ${d.D_s.toFixed(4)} mm`);
  requestFrame();
  loadReport();
  if (view.showing === "mold") showMold(); else showDevice();
}

// ---- moiré -----------------------------------------------------------------

// The sliders tilt from the design view ([view]); tilt 0 is the view the
// base is compensated for. The checkbox is view.compensate.
function showView() {
  const compensate = fieldValue("view.compensate");
  $("compensate").checked = compensate === undefined ? true : compensate === true;
  const tilt = fieldValue("view.tilt") || 0, along = fieldValue("view.tilt_along") || 0;
  $("view-note").textContent = tilt || along ? `tilt 0 is the design view (${tilt}°, ${along}° along)` : "tilt 0 is the design view (straight down)";
}
$("compensate").addEventListener("change", () => {
  // ticked is the default: the key goes, and the spec reads as it did
  patchSpec([{ key: "view.compensate", value: $("compensate").checked ? null : false }]);
});

// While a slider moves, frames use 9 lens phases per pixel (samples=3,
// about half the time); when it is let go, the default 16 (samples=4).
let frameInFlight = false, framePending = null;

// a printed device has one backlight; a dual-lens device, lights from +x and −x
const printed = () => studio.design && studio.design.base_kind === "printed";

function lightsParam() {
  const choice = $("lights").value;
  if (choice !== "custom") return choice;
  return printed() ? $("light-a").value : `${$("light-a").value},${$("light-b").value}`;
}

function showLightPickers() {
  const custom = $("lights").value === "custom";
  $("light-a").hidden = !custom;
  $("light-b").hidden = !custom || printed();
}

const degrees = (x) => `${Number(x).toFixed(2)}°`;

// While a frame is wanted that is not on screen, the view says so; the
// labels by the sliders always name the frame on screen.
function showFrameState() {
  const wanted = frameInFlight || framePending;
  $("frame").classList.toggle("pending", Boolean(wanted));
  $("frame-state").textContent = wanted
    ? `rendering tilt ${degrees($("tilt").value)}, along ${degrees($("along").value)}…`
    : "";
}

// A frame of 256 px while a slider moves; at rest, as many pixels as the
// frame shows (a wide screen's), up to 512, where the frame is traced
// through the exact sections (a dual-lens device seen orthographically);
// through the mesh, slower, 256.
function frameSize(samples) {
  const shown = $("frame").getBoundingClientRect().width * (window.devicePixelRatio || 1);
  const printed = (fieldValue("base.kind") || "dual-lens") !== "dual-lens";
  const distance = fieldValue("view.distance");
  const sections = !printed && (distance === undefined || distance === "infinite");
  return String(sections && samples >= 4 && shown > 320 ? Math.min(512, Math.ceil(shown / 64) * 64) : 256);
}

async function requestFrame(samples = 4) {
  if (frameInFlight) { framePending = Math.max(framePending || 0, samples); showFrameState(); return; }
  frameInFlight = true; framePending = null;
  showFrameState();
  const tilt = $("tilt").value, along = $("along").value;
  const params = new URLSearchParams({ tilt, along, size: frameSize(samples), samples: String(samples), lights: lightsParam() });
  try {
    const response = await api("/api/frame.png?" + params);
    if (response.ok) {
      const blob = await response.blob();
      const old = $("frame").src;
      $("frame").src = URL.createObjectURL(blob);
      if (old.startsWith("blob:")) URL.revokeObjectURL(old);
      const h = (n) => Number(response.headers.get(n));
      studio.frames += 1;
      studio.lastFrameMs = h("x-render-ms");
      $("frame").dataset.tilt = tilt;
      $("frame").dataset.along = along;
      $("frame").dataset.samples = samples;
      $("tilt-value").textContent = degrees(tilt);
      $("along-value").textContent = degrees(along);
      $("scores").textContent = `contrast ${h("x-contrast").toFixed(3)} · fidelity ${h("x-fidelity").toFixed(3)} · local ${h("x-local-fidelity").toFixed(3)} · ${h("x-render-ms").toFixed(0)} ms, ${samples * samples} lens phases`;
    } else if (response.status !== 409) {
      const body = await response.json().catch(() => ({}));
      $("scores").textContent = body.error || `HTTP ${response.status}`;
    }
  } finally {
    frameInFlight = false;
    if (framePending) requestFrame(framePending);
    else showFrameState();
  }
}

for (const id of ["tilt", "along"]) {
  $(id).addEventListener("input", () => requestFrame(3));
  $(id).addEventListener("change", () => requestFrame(4));
}
$("lights").addEventListener("change", () => {
  showLightPickers();
  requestFrame();
});
for (const id of ["light-a", "light-b"]) $(id).addEventListener("change", () => requestFrame());

// ---- checks ----------------------------------------------------------------

async function loadReport() {
  const revision = studio.revision;
  $("checks-status").textContent = "building the device and measuring it…";
  const response = await api("/api/report");
  const report = await response.json().catch(() => ({}));
  if (revision !== studio.revision) return;
  const list = $("check-list");
  list.replaceChildren();
  if (!response.ok) {
    const fail = document.createElement("span");
    fail.className = "fail";
    fail.textContent = report.error;
    $("checks-status").replaceChildren(fail);
    return;
  }
  showChecks((report.checks || []).concat(report.mold ? report.mold.checks : []), report.mesh.triangles);
  const warnings = ((report.view && report.view.warnings) || []).concat(report.mold ? report.mold.warnings : []);
  $("warnings").replaceChildren();
  for (const w of warnings) { const p = document.createElement("div"); p.className = "warn"; p.textContent = "warning: " + w; $("warnings").appendChild(p); }
}

// The checks, grouped by the part they are about, each with its label from
// the registry and its limit as a maximum (≤) or a minimum (≥); a failed
// check turns the section red, and is named in a banner and in the header.
const BOUND_SIGN = { "at most": "≤", "at least": "≥", "exactly": "=", "more than": ">" };
function showChecks(checks, triangles) {
  const failed = checks.filter((c) => !c.passed);
  $("checks").classList.toggle("failed", failed.length > 0);
  const banner = $("checks-failed");
  banner.hidden = !failed.length;
  banner.textContent = failed.length ? `✗ ${failed.length} check${failed.length > 1 ? "s" : ""} failed: ${failed.map((c) => `${c.label} (${c.part})`).join(", ")}` : "";
  $("header-failed").hidden = !failed.length;
  $("header-failed").textContent = failed.length ? `✗ ${failed.length} failed check${failed.length > 1 ? "s" : ""}` : "";
  $("checks-status").textContent = `${checks.length} checks, ${failed.length ? `${failed.length} failed` : "all passed"}; ${triangles} triangles`;
  const list = $("check-list");
  list.replaceChildren();
  const parts = [...new Set(checks.map((c) => c.part))];
  for (const part of parts) {
    const mine = checks.filter((c) => c.part === part);
    const bad = mine.filter((c) => !c.passed).length;
    const head = document.createElement("li");
    head.className = "part";
    head.textContent = `${part[0].toUpperCase()}${part.slice(1)}: ${mine.length} checks${bad ? `, ${bad} failed` : ""}`;
    list.appendChild(head);
    for (const c of mine) {
      const li = document.createElement("li");
      li.className = c.passed ? "" : "failed";
      li.title = `${c.name}: ${c.detail}`;
      li.dataset.check = c.name;
      li.innerHTML = `<span></span><span></span><span class="scores"></span>`;
      li.children[0].className = c.passed ? "pass" : "fail";
      li.children[0].textContent = c.passed ? "✓" : "✗";
      li.children[1].textContent = c.label;
      const sign = BOUND_SIGN[c.bound] || "/";
      li.children[2].textContent = `${Number(c.value).toPrecision(3)} ${sign} ${Number(c.limit).toPrecision(3)} ${c.unit}`;
      li.children[2].title = `must be ${c.bound} ${c.limit} ${c.unit}`;
      list.appendChild(li);
    }
  }
}

// ---- explore ---------------------------------------------------------------

// The grid is scored for one design; a change other than its own a and d
// makes it stale (marked, and said so), and a cell adopts its own ratio
// of the current D_s.
function designSignature(values) {
  const copy = JSON.parse(JSON.stringify(values || {}));
  if (copy.base) { delete copy.base.a; delete copy.base.d; }
  return JSON.stringify(copy);
}

// Scoring the grid: started with one short request, followed by polling
// its progress (cells done of 25), so no request is held open meanwhile
// (a browser has six connections per site, and a cancel must get
// through); Cancel stops it after the cells being scored.
function showScoring(scoring) {
  $("run-explore").disabled = scoring;
  $("cancel-explore").hidden = !scoring;
  $("cancel-explore").disabled = false;
  $("explore-progress").hidden = !scoring;
  studio.cancelling = false;
}
async function pollScoring() {
  const p = await (await api("/api/explore/progress")).json().catch(() => null);
  if (!p) { studio.scoringTimer = setTimeout(pollScoring, 250); return; }
  if (p.scored) { showScoring(false); showGrid(); return; }
  if (!p.running && p.pending === 0) {
    showScoring(false);
    $("explore-status").textContent = p.cancelled
      ? `cancelled after ${p.done} of ${p.total} cells; the grid was not scored`
      : "not scored: the design changed while it was scored; score it again";
    return;
  }
  if (!studio.cancelling) {
    $("explore-progress").max = p.total; $("explore-progress").value = p.done;
    $("explore-status").textContent = p.running ? `scoring: ${p.done} of ${p.total} cells` : "scoring: waiting to start…";
  }
  studio.scoringTimer = setTimeout(pollScoring, 250);
}
$("cancel-explore").addEventListener("click", async () => {
  $("cancel-explore").disabled = true;
  studio.cancelling = true;
  $("explore-status").textContent = "cancelling after the cells being scored…";
  await api("/api/explore/cancel", { method: "POST" });
});
$("run-explore").addEventListener("click", async () => {
  $("explore-status").textContent = "scoring 25 cells…";
  showScoring(true);
  const started = await api("/api/explore/start", { method: "POST" });
  if (!started.ok) { showScoring(false); $("explore-status").textContent = `HTTP ${started.status}`; return; }
  pollScoring();
});
async function showGrid() {
  const response = await api("/api/explore");
  const grid = await response.json().catch(() => ({ error: `HTTP ${response.status}` }));
  if (!response.ok) { $("explore-status").textContent = grid.error; return; }
  studio.grid = { signature: designSignature(studio.values), cells: grid.cells, best: grid.best };
  const box = $("grid");
  box.replaceChildren();
  grid.cells.forEach((cell, i) => {
    const fig = document.createElement("figure");
    if (i === grid.best) fig.classList.add("best");
    const contrast = cell.contrast == null ? "invalid"
      : cell.kept_contrast == null ? `contrast ${cell.contrast.toFixed(3)}`
      : `kept ${cell.kept_contrast.toFixed(2)}`;
    fig.innerHTML = `<img alt=""><figcaption></figcaption>`;
    fig.firstChild.src = grid.thumbnails[i];
    fig.lastChild.textContent = `a ${cell.a} · d ${cell.d_over_ds}·D_s · ${contrast}`;
    fig.title = cell.invalid || `d = ${cell.d_over_ds}·D_s; click to adopt a and d`;
    if (cell.contrast != null) fig.addEventListener("click", () => adopt(cell));
    box.appendChild(fig);
  });
  markGrid();
}

// The current design's cell, and whether the grid is stale.
function markGrid() {
  const grid = studio.grid;
  if (!grid) return;
  const stale = designSignature(studio.values) !== grid.signature;
  $("grid").classList.toggle("stale", stale);
  const base = studio.values.base || {};
  const a = base.a ?? 0;
  const ds = studio.derived ? studio.derived.D_s : NaN;
  const d = base.d === undefined || base.d === "focal" ? ds : base.d;
  [...$("grid").children].forEach((fig, i) => {
    const cell = grid.cells[i];
    fig.classList.toggle("current", !stale && Math.abs(cell.a - a) < 1e-9 && Math.abs(cell.d_over_ds * ds - d) < 1e-6 * ds);
  });
  const best = grid.cells[grid.best];
  $("explore-status").textContent = stale
    ? "stale: the design changed since this grid was scored; score it again"
    : `best: a ${best.a}, d ${best.d_over_ds}·D_s (outlined); the current design's cell is filled`;
}

function adopt(cell) {
  const ds = studio.derived.D_s;
  patchSpec([
    { key: "base.a", value: cell.a },
    { key: "base.d", value: Number((cell.d_over_ds * ds).toFixed(6)) },
  ]);
}

// ---- 3D view ---------------------------------------------------------------

const view = { gl: null, program: null, meshes: [], showing: "device", centre: [0, 0, 0], radius: 1, explode: 0.4 };
window.studio.view = view;

function initGl() {
  const canvas = $("view3d");
  const gl = canvas.getContext("webgl", { antialias: true });
  if (!gl) { $("view-status").textContent = "WebGL is not available in this browser"; return; }
  const vs = `attribute vec3 p; attribute vec3 n; uniform mat4 m; uniform vec3 offset; varying vec3 vn;
    void main() { vn = n; gl_Position = m * vec4(p + offset, 1.0); }`;
  const fs = `precision mediump float; varying vec3 vn; uniform vec3 colour; uniform vec3 light; uniform float unlit;
    void main() { float l = unlit > 0.5 ? 1.0 : 0.25 + 0.75 * abs(dot(normalize(vn), light)); gl_FragColor = vec4(colour * l, 1.0); }`;
  const shader = (type, source) => { const s = gl.createShader(type); gl.shaderSource(s, source); gl.compileShader(s); return s; };
  const program = gl.createProgram();
  gl.attachShader(program, shader(gl.VERTEX_SHADER, vs));
  gl.attachShader(program, shader(gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(program);
  view.gl = gl; view.program = program;
  gl.enable(gl.DEPTH_TEST);
}

function parseStl(buffer) {
  const data = new DataView(buffer);
  const count = data.getUint32(80, true);
  const positions = new Float32Array(count * 9), normals = new Float32Array(count * 9);
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let t = 0; t < count; t++) {
    const base = 84 + t * 50;
    const nx = data.getFloat32(base, true), ny = data.getFloat32(base + 4, true), nz = data.getFloat32(base + 8, true);
    for (let v = 0; v < 3; v++) {
      for (let a = 0; a < 3; a++) {
        const x = data.getFloat32(base + 12 + v * 12 + a * 4, true);
        positions[t * 9 + v * 3 + a] = x;
        if (x < lo[a]) lo[a] = x; if (x > hi[a]) hi[a] = x;
      }
      normals[t * 9 + v * 3] = nx; normals[t * 9 + v * 3 + 1] = ny; normals[t * 9 + v * 3 + 2] = nz;
    }
  }
  return { positions, normals, count, lo, hi };
}

async function loadMeshes(parts) {
  const revision = studio.revision;
  $("view-status").textContent = "building…";
  const loaded = [];
  for (const [url, colour, lift] of parts) {
    const response = await api(url);
    if (!response.ok) {
      const body = await response.json().catch(() => ({}));
      $("view-status").textContent = body.error || `HTTP ${response.status}`;
      return;
    }
    loaded.push({ stl: parseStl(await response.arrayBuffer()), colour, lift });
  }
  if (revision !== studio.revision || !view.gl) return;
  const gl = view.gl;
  for (const m of view.meshes) { gl.deleteBuffer(m.pb); gl.deleteBuffer(m.nb); }
  view.meshes = loaded.map(({ stl, colour, lift }) => {
    const pb = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, pb); gl.bufferData(gl.ARRAY_BUFFER, stl.positions, gl.STATIC_DRAW);
    const nb = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, nb); gl.bufferData(gl.ARRAY_BUFFER, stl.normals, gl.STATIC_DRAW);
    return { pb, nb, count: stl.count * 3, colour, lift, lo: stl.lo, hi: stl.hi };
  });
  const lo = [0, 1, 2].map((a) => Math.min(...view.meshes.map((m) => m.lo[a])));
  const hi = [0, 1, 2].map((a) => Math.max(...view.meshes.map((m) => m.hi[a])));
  view.centre = [0, 1, 2].map((a) => (lo[a] + hi[a]) / 2);
  view.radius = Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2;
  view.height = hi[2] - lo[2];
  view.axes = axesFrom(gl, lo, hi);
  if (!studio.distance) studio.distance = 3 * view.radius;
  const triangles = loaded.reduce((s, m) => s + m.stl.count, 0);
  $("view-status").textContent = `${triangles.toLocaleString()} triangles · drag to orbit, wheel to zoom`;
  draw();
}

// Axes from the parts' lowest corner, each as long as the parts' extent
// along it (x red, y green, z blue; drawn unlit).
function axesFrom(gl, lo, hi) {
  if (view.axes) gl.deleteBuffer(view.axes.pb);
  const lines = [];
  for (let a = 0; a < 3; a++) {
    const end = lo.slice(); end[a] = hi[a];
    lines.push(...lo, ...end);
  }
  const pb = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, pb); gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(lines), gl.STATIC_DRAW);
  return { pb, colours: [[1, 0.42, 0.37], [0.42, 0.86, 0.42], [0.42, 0.66, 1]] };
}

// Which view the buttons show as active.
function markShowing() {
  $("show-device").setAttribute("aria-pressed", String(view.showing === "device"));
  $("show-mold").setAttribute("aria-pressed", String(view.showing === "mold"));
}

// The scale bar: a round length (1, 2 or 5 × 10^k mm) near a fifth of the
// pane's width at the distance of the parts' centre.
function drawScaleBar() {
  const canvas = $("view3d"), d = studio.distance || 3 * view.radius;
  if (!view.meshes.length || !canvas.clientHeight) { $("scale-bar").hidden = true; return; }
  const pxPerMm = (canvas.clientHeight / 2) / (d * Math.tan(Math.PI / 8));
  const want = canvas.clientWidth / 5 / pxPerMm;
  const power = 10 ** Math.floor(Math.log10(want));
  const mm = [5, 2, 1].map((m) => m * power).find((m) => m <= want) || power;
  $("scale-bar").hidden = false;
  $("scale-line").style.width = `${(mm * pxPerMm).toFixed(1)}px`;
  $("scale-label").textContent = `${Number(mm.toPrecision(3))} mm`;
  view.scaleMm = mm;
}

const INITIAL_VIEW = { yaw: studio.yaw, pitch: studio.pitch };
function resetView() {
  studio.yaw = INITIAL_VIEW.yaw; studio.pitch = INITIAL_VIEW.pitch; studio.distance = 3 * view.radius;
  draw();
}

function showDevice() { view.showing = "device"; markShowing(); studio.distance = 0; loadMeshes([["/api/device.stl", [0.55, 0.75, 0.95], 0]]); }
async function showMold() {
  view.showing = "mold"; markShowing(); studio.distance = 0;
  await loadMeshes([["/api/mold/top.stl", [0.95, 0.6, 0.25], 1], ["/api/mold/bottom.stl", [0.35, 0.7, 0.65], -1], ["/api/mold/device.stl", [0.55, 0.75, 0.95], 0]]);
  loadReport(); // now with the mold's checks and warnings
}
$("show-device").addEventListener("click", showDevice);
$("show-mold").addEventListener("click", showMold);
$("reset-view").addEventListener("click", resetView);
$("explode").addEventListener("input", () => { view.explode = Number($("explode").value); draw(); });

function multiply(a, b) {
  const out = new Float32Array(16);
  for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) {
    let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + j] * b[i * 4 + k]; out[i * 4 + j] = s;
  }
  return out;
}

function matrix() {
  const canvas = $("view3d");
  const aspect = canvas.width / canvas.height, d = studio.distance || 3 * view.radius;
  const f = 1 / Math.tan(Math.PI / 8), near = Math.max(d - 2 * view.radius, d * 0.01), far = d + 2 * view.radius;
  const projection = new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0]);
  const cy = Math.cos(studio.yaw), sy = Math.sin(studio.yaw), cp = Math.cos(studio.pitch), sp = Math.sin(studio.pitch);
  // eye on a sphere around the centre, z up
  const eye = [view.centre[0] + d * cp * sy, view.centre[1] - d * cp * cy, view.centre[2] + d * sp];
  const fwd = [view.centre[0] - eye[0], view.centre[1] - eye[1], view.centre[2] - eye[2]].map((x) => x / d);
  let right = [fwd[1] * 1 - fwd[2] * 0, fwd[2] * 0 - fwd[0] * 1, 0];
  const rl = Math.hypot(...right) || 1; right = right.map((x) => x / rl);
  const up = [right[1] * fwd[2] - right[2] * fwd[1], right[2] * fwd[0] - right[0] * fwd[2], right[0] * fwd[1] - right[1] * fwd[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const viewMatrix = new Float32Array([right[0], up[0], -fwd[0], 0, right[1], up[1], -fwd[1], 0, right[2], up[2], -fwd[2], 0, -dot(right, eye), -dot(up, eye), dot(fwd, eye), 1]);
  view.light = fwd.map((x) => -x);
  return multiply(projection, viewMatrix);
}

function draw() {
  const gl = view.gl;
  if (!gl) return;
  gl.viewport(0, 0, gl.canvas.width, gl.canvas.height);
  gl.clearColor(0.125, 0.14, 0.16, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  if (!view.meshes.length) return;
  gl.useProgram(view.program);
  gl.uniformMatrix4fv(gl.getUniformLocation(view.program, "m"), false, matrix());
  gl.uniform3fv(gl.getUniformLocation(view.program, "light"), view.light);
  const p = gl.getAttribLocation(view.program, "p"), n = gl.getAttribLocation(view.program, "n");
  for (const m of view.meshes) {
    gl.uniform3fv(gl.getUniformLocation(view.program, "colour"), m.colour);
    gl.uniform3fv(gl.getUniformLocation(view.program, "offset"), [0, 0, m.lift * view.explode * (view.height || 1)]);
    gl.bindBuffer(gl.ARRAY_BUFFER, m.pb); gl.enableVertexAttribArray(p); gl.vertexAttribPointer(p, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, m.nb); gl.enableVertexAttribArray(n); gl.vertexAttribPointer(n, 3, gl.FLOAT, false, 0, 0);
    gl.drawArrays(gl.TRIANGLES, 0, m.count);
  }
  gl.disableVertexAttribArray(n);
  gl.vertexAttrib3f(n, 0, 0, 1);
  gl.uniform1f(gl.getUniformLocation(view.program, "unlit"), 1);
  gl.uniform3fv(gl.getUniformLocation(view.program, "offset"), [0, 0, 0]);
  gl.bindBuffer(gl.ARRAY_BUFFER, view.axes.pb); gl.enableVertexAttribArray(p); gl.vertexAttribPointer(p, 3, gl.FLOAT, false, 0, 0);
  view.axes.colours.forEach((c, a) => {
    gl.uniform3fv(gl.getUniformLocation(view.program, "colour"), c);
    gl.drawArrays(gl.LINES, 2 * a, 2);
  });
  gl.uniform1f(gl.getUniformLocation(view.program, "unlit"), 0);
  drawScaleBar();
}

(() => {
  const canvas = $("view3d");
  let dragging = null;
  canvas.addEventListener("pointerdown", (e) => { dragging = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { dragging = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!dragging) return;
    studio.yaw += (e.clientX - dragging[0]) * 0.01;
    studio.pitch = Math.max(-1.5, Math.min(1.5, studio.pitch + (e.clientY - dragging[1]) * 0.01));
    dragging = [e.clientX, e.clientY];
    draw();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    studio.distance = Math.max(view.radius * 0.2, (studio.distance || 3 * view.radius) * Math.exp(e.deltaY * 0.001));
    draw();
  }, { passive: false });
})();

// ---- write -----------------------------------------------------------------

let stageTotal = 1, stageDone = 0;
function listenForEvents() {
  const events = new EventSource("/api/events");
  events.onmessage = (message) => {
    const e = JSON.parse(message.data);
    if (e.kind === "start") { studio.writingRevision = e.revision; $("write-error").textContent = ""; $("written").textContent = ""; $("casting").textContent = ""; $("write-stage").textContent = `writing the ${e.what}…`; }
    if (e.kind === "stage") { stageTotal = Math.max(1, e.total); stageDone = 0; $("write-stage").textContent = e.name; $("write-progress").max = stageTotal; $("write-progress").value = 0; }
    if (e.kind === "tick") { stageDone += e.n; $("write-progress").value = stageDone; }
    if (e.kind === "done") {
      $("write-stage").textContent = `done: ${(e.bytes / 1e6).toFixed(1)} MB`;
      $("write-progress").value = $("write-progress").max;
      // a folder holds one run: say which earlier files this one replaced
      const replaced = e.replaces.length ? `replaced the earlier run in ${e.folder}: ${e.replaces.join(", ")}\n` : "";
      $("written").textContent = replaced + e.written.map((w) => "wrote " + w).join("\n") + e.warnings.map((w) => "\nwarning: " + w).join("");
      // the mold's casting numbers: fill (mL), grams, the mix and its parts
      if (e.casting) $("casting").textContent = e.casting.replace(/^casting: /, "To cast: ");
      setButtons(false);
      if (e.what === "mold") loadReport();
      // the run keeps its spec as spec.toml: where that is the spec file
      // (the built-in design's), the write saved it
      if (e.written.includes($("spec-file").textContent) && studio.writingRevision === studio.revision) { studio.savedText = studio.text; showSaved(); }
    }
    if (e.kind === "error") { $("write-stage").textContent = "failed"; $("write-error").textContent = e.message; setButtons(false); }
  };
}
function setButtons(busy) { $("write-device").disabled = busy; $("write-mold").disabled = busy; }
async function write(what) {
  setButtons(true);
  const response = await api(`/api/write?what=${what}`, { method: "POST" });
  if (response.status !== 202) {
    const body = await response.json().catch(() => ({}));
    $("write-error").textContent = body.error || `HTTP ${response.status}`;
    setButtons(false);
  }
}
$("write-device").addEventListener("click", () => write("device"));
$("write-mold").addEventListener("click", () => write("mold"));

// ---- start -----------------------------------------------------------------

$("apply-toml").addEventListener("click", () => putSpec($("toml").value));
$("all-keys").addEventListener("change", showApplicableFields);
$("save").addEventListener("click", async () => {
  const response = await api("/api/save", { method: "POST" });
  const body = await response.json().catch(() => ({}));
  setStatus(response.ok ? `saved ${body.saved}` : body.error || `HTTP ${response.status}`);
  if (response.ok) { studio.savedText = studio.text; showSaved(); }
});
// Save as: a name in the spec's folder, which becomes the spec file;
// another file of that name is replaced only once confirmed.
$("save-as").addEventListener("click", async () => {
  const name = encodeURIComponent($("save-as-name").value);
  let response = await api(`/api/save-as?name=${name}`, { method: "POST" });
  let body = await response.json().catch(() => ({}));
  if (response.status === 409 && body.exists) {
    if (!confirm(body.error)) { setStatus("not saved"); return; }
    response = await api(`/api/save-as?name=${name}&replace=true`, { method: "POST" });
    body = await response.json().catch(() => ({}));
  }
  if (!response.ok) { setStatus(body.error || `HTTP ${response.status}`); return; }
  setStatus(`saved ${body.saved}`);
  studio.savedText = studio.text;
  $("spec-file").textContent = body.state.spec_file;
  showSaved();
  listSpecs();
  setProfileChoices(await (await api("/api/profiles")).json());
});

// Open: another spec of the folder; unsaved changes are left only once
// confirmed, and a spec that does not build is refused with its errors.
async function listSpecs() {
  const body = await (await api("/api/specs")).json();
  const select = $("open-name");
  select.replaceChildren(...body.specs.map((n) => new Option(n, n)));
  const file = ($("spec-file").textContent || "").split("/").pop();
  if (body.specs.includes(file)) select.value = file;
  $("open").disabled = !body.specs.length;
}
$("open").addEventListener("click", async () => {
  const name = $("open-name").value;
  if (!name) return;
  if (studio.text !== studio.savedText && !confirm(`The spec has unsaved changes. Open ${name} and leave them?`)) return;
  const response = await api(`/api/open?name=${encodeURIComponent(name)}`, { method: "POST" });
  const body = await response.json().catch(() => ({}));
  if (!response.ok) {
    const why = body.errors ? body.errors.map((e) => errorText(e, false)).join("\n") : body.error || `HTTP ${response.status}`;
    $("spec-error").textContent = `${name} was not opened: ${why}`;
    return;
  }
  $("spec-error").textContent = "";
  setProfileChoices(await (await api("/api/profiles")).json());
  applyState(body, "open");
  setStatus(`opened ${body.spec_file}`);
});

$("undo").addEventListener("click", undo);
$("redo").addEventListener("click", redo);
document.addEventListener("keydown", (e) => {
  // in a text field the browser's own undo applies
  if (!(e.ctrlKey || e.metaKey) || e.key.toLowerCase() !== "z" || e.target.closest("input, textarea, select")) return;
  e.preventDefault();
  if (e.shiftKey) redo(); else undo();
});

(async () => {
  initGl();
  listenForEvents();
  studio.keys = await (await api("/api/keys")).json();
  buildForm();
  setProfileChoices(await (await api("/api/profiles")).json());
  applyState(await (await api("/api/state")).json());
  listSpecs();
})();
