// The Inspection page: inspect once, start and stop continuous operation (operator), with
// the policy and sort switches; the live result (the last image with its contour and label,
// every model's score as bars, the viewpoints visited); a filmstrip of the last results
// (images load lazily); counters per shift and the throughput over the last minute.
//
// The recipe line shows the cell's active recipe (GET /api/recipes): the controls start at
// its options, and only those the operator changes are sent (they override the recipe's,
// which the server applies, read again before each object of a run).
//
// The belt card shows the belt's state (GET /api/belt): a run waiting for a part says so in
// its job line, and an operator starts or stops the belt here; an engineer on the simulator
// can put a catalogue part at the station.
//
// Counters: the shift start is kept in this browser (localStorage, per cell), the counts are
// the server's (GET /api/inspections?since=<shift start>&decision=...): a reload or a second
// console shows the same numbers, and "New shift" needs no server state or role.

import { api, fetchBlob } from "../api.js";
import { $, applyRoles, el, lazyImage, releaseImages, setText } from "../dom.js";
import { bars } from "../charts.js";

const FILMSTRIP = 16;
const REFRESH_MS = 5000;
const SHIFT_KEY = "visioncell-shift-start";
const DECISIONS = ["recognized", "unknown", "failed"];

let root = null;
let ctx = null;
let listeners = [];
let timer = null;
let threshold = null;      // the global threshold
let perModel = {};         // model name -> the threshold that applies to it (every taught model)
let shownId = null;
let generation = 0;
let runJob = null;
let thresholdsRead = Promise.resolve();  // the models and thresholds, read at mount
let recipe = null;         // the active recipe (API form), null: none
let recipeSeen = "";       // id and update time of the recipe the controls were set from

const q = (sel) => (root ? $(sel, root) : null);

function listen(target, type, fn) {
  target.addEventListener(type, fn);
  listeners.push(() => target.removeEventListener(type, fn));
}

/** The shift start (ISO, UTC) of this console, set to now the first time. */
export function shiftStart() {
  let v = localStorage.getItem(SHIFT_KEY);
  if (!v || !Number.isFinite(Date.parse(v))) {
    v = new Date().toISOString();
    localStorage.setItem(SHIFT_KEY, v);
  }
  return v;
}

/**
 * The options to send: every control without an active recipe; with one, only the
 * controls set otherwise than the recipe (the server takes the recipe's for the rest).
 */
function options() {
  const body = { policy: q("#insp-policy").value, sort: q("#insp-sort").checked, max_views: Number(q("#insp-max-views").value) };
  if (!recipe) return body;
  for (const key of Object.keys(body)) if (body[key] === recipe[key]) delete body[key];
  return body;
}

async function loadRecipe() {
  const gen = generation;
  let page;
  try { page = await api("GET", "/recipes?limit=1"); } catch (e) { return; }
  if (gen !== generation || !root) return;
  recipe = page.active;
  const line = q("#insp-recipe");
  if (!recipe) {
    line.replaceChildren("Recipe: none active (", el("a", { href: "#recipes" }, "Recipes"), "): the options below apply.");
    recipeSeen = "";
    return;
  }
  line.replaceChildren("Recipe: ", el("strong", { id: "insp-recipe-name" }, `${recipe.name} (no. ${recipe.number})`),
    ` · ${recipe.models.length ? recipe.models.join(", ") : "every model"} · threshold ${recipe.threshold === null ? "automatic" : recipe.threshold.toFixed(2)}`
    + ` · belt ${recipe.belt_mode || "as it is"}; options changed below override it.`);
  const seen = `${recipe.id}@${recipe.updated_at}`;
  if (seen === recipeSeen) return;  // the operator's own changes stay until the recipe changes
  recipeSeen = seen;
  q("#insp-policy").value = recipe.policy;
  q("#insp-max-views").value = String(recipe.max_views);
  q("#insp-sort").checked = recipe.sort;
}

/**
 * A refusal in the page's words: with nothing taught yet, the way to the Models page (and,
 * for a user who may not teach, the role it takes) rather than the API's own path.
 */
function refusal(code, detail) {
  if (code !== "nothing_trained") return detail;
  return el("span", {}, "Nothing to recognise yet: teach a model first on the ",
    el("a", { id: "insp-teach-link", href: "#models" }, "Models page"),
    ctx && ctx.can("engineer") ? "." : " (teaching needs the engineer role).");
}

function showRefusal(sel, code, detail) {
  const box = q(sel);
  if (!box) return;
  box.replaceChildren(refusal(code, detail) || "");
}

async function command(method, path, body) {
  setText(q("#insp-message"), "");
  try { return await api(method, path, body); }
  catch (e) { showRefusal("#insp-message", e.code, e.message); return null; }
}

async function inspectOnce() {
  const r = await command("POST", "/inspections", { ...options(), wait_s: 60 });
  if (r) setText(q("#insp-run-state"), `inspection job ${r.job.id} started`);
}

async function startRun() {
  const countText = q("#insp-count").value.trim();
  const body = { ...options(), wait_s: 300 };
  if (countText) {
    const n = Number(countText);
    if (!Number.isInteger(n) || n < 1 || n > 100000) { setText(q("#insp-message"), `count must be a whole number 1..100000 or empty, got ${countText}`); return; }
    body.count = n;
  }
  const r = await command("POST", "/inspection/run", body);
  if (r) onJob(r.job);
}

async function stopRun() {
  const r = await command("POST", "/inspection/stop");
  if (r) setText(q("#insp-run-state"), "stopping after the current object…");
}

// -- the belt ----------------------------------------------------------------------------------
async function loadBelt() {
  const gen = generation;
  let b;
  try { b = await api("GET", "/belt"); } catch (e) { return; }
  if (gen !== generation || !root) return;
  setText(q("#belt-state"), b.summary);
  const have = !!b.belt;
  q("#belt-start").disabled = !have || b.belt.running || b.belt.halted;
  q("#belt-stop").disabled = !have || !b.belt.running;
}

async function setBelt(running) {
  const r = await command("POST", "/belt", { running });
  if (r) setText(q("#belt-state"), r.summary);
  loadBelt();
}

async function loadCatalogue() {
  if (!ctx.can("engineer")) return;
  let cat;
  try { cat = await api("GET", "/sim/catalogue?limit=100"); } catch (e) { return; }  // not simulated
  if (!root) return;
  q("#belt-place-name").replaceChildren(...cat.data.map((c) => el("option", { value: c.name }, c.name)));
  q("#belt-place").hidden = false;
}

async function placePart() {
  const name = q("#belt-place-name").value;
  const r = await command("POST", "/sim/objects", { name, at: "station" });
  if (r) setText(q("#belt-state"), `${name} placed at the station (object ${r.object.id})`);
  setTimeout(loadBelt, 1000);
}

function onJob(job) {
  if (!root) return;
  if (job.kind === "inspection-run" || job.kind === "inspect") loadBelt();
  if (job.kind === "inspection-run") {
    runJob = job.state === "running" ? job : null;
    q("#insp-stop").disabled = !runJob;
    q("#insp-run").disabled = !!runJob;
    setText(q("#insp-run-state"), job.state === "running"
      ? `running (${job.params && job.params.policy}): ${job.message || "starting"}`
      : `run ${job.state}${job.result ? `: ${job.result.inspected} inspected` : ""}${job.error ? ` (${job.error.detail})` : ""}`);
  } else if (job.kind === "inspect") {
    setText(q("#insp-run-state"), job.state === "running" ? `inspecting: ${job.message || ""}`
      : `inspection ${job.state}${job.error ? ` (${job.error.detail})` : ""}`);
  }
  if (job.state === "failed" && job.error && job.error.error === "nothing_trained") {
    showRefusal("#insp-message", job.error.error, job.error.detail);
  }
}

// -- the live result ---------------------------------------------------------------------------
function decisionText(r) {
  return r.decision === "recognized" ? `${r.model} (${(r.score ?? 0).toFixed(3)})` : r.decision;
}

// Where the object went: its bin, the reject bin and why, or why it was not placed.
function showPick(node, r) {
  const p = r.pick_outcome || { outcome: "not_sorted", bin: null, text: "not sorted" };
  node.className = `small pick pick-${p.outcome}${p.outcome === "not_placed" ? " error" : ""}`;
  node.dataset.outcome = p.outcome;
  node.dataset.bin = p.bin || "";
  setText(node, `Pick: ${p.text}`);
}

async function showInspection(id) {
  const gen = generation;
  let r;
  try { r = await api("GET", `/inspections/${id}`); } catch (e) { setText(q("#insp-message"), e.message); return; }
  await thresholdsRead;  // every taught model's bar and tick
  if (gen !== generation || !root) return;
  shownId = r.id;
  const title = q("#live-label");
  title.className = `decision decision-${r.decision}`;
  setText(title, `#${r.id} ${decisionText(r)}`);
  setText(q("#live-reason"), r.reason);
  showPick(q("#live-pick"), r);
  const pics = q("#live-images");
  releaseImages(pics);
  pics.replaceChildren(...r.images.map((url, k) => el("figure", {},
    lazyImage(url, fetchBlob, { alt: `inspection ${r.id} view ${k}`, className: "live-image" }),
    el("figcaption", { className: "small" }, `viewpoint ${r.viewpoints_visited[k] ?? "?"}`))));
  if (!r.images.length) pics.append(el("p", { className: "small" }, "No image kept for this inspection."));
  setText(q("#live-viewpoints"), `Viewpoints visited: ${r.viewpoints_visited.join(" → ") || "none"} · policy ${r.policy}`
    + `${r.recipe ? ` · recipe ${r.recipe}` : ""} · ${r.duration_s === null ? "" : `${r.duration_s.toFixed(2)} s`}`);
  const items = everyScore(r.scores, Object.keys(perModel))
    .map(([m, s]) => ({ label: m, value: s, color: m === r.model ? "#15803d" : "#9ca3af", mark: perModel[m] ?? threshold }));
  bars(q("#live-scores"), items, { max: 1 });
  const pose = r.pose && r.pose.T_base_obj;
  setText(q("#live-pose"), pose
    ? `pose: x ${(pose[0][3] * 1000).toFixed(1)} mm, y ${(pose[1][3] * 1000).toFixed(1)} mm, yaw ${(Math.atan2(pose[1][0], pose[0][0]) * 180 / Math.PI).toFixed(1)}°`
    : "");
  for (const f of root.querySelectorAll("#filmstrip figure")) f.classList.toggle("selected", Number(f.dataset.id) === r.id);
}

/**
 * Every model's score, best first: the inspection's scores plus each taught model it did not
 * score (0: none of its views matched well enough to be verified), so every model has a bar.
 */
export function everyScore(scores, models) {
  const all = { ...Object.fromEntries(models.map((m) => [m, 0])), ...scores };
  return Object.entries(all).sort((a, b) => b[1] - a[1] || a[0].localeCompare(b[0]));
}

// -- the filmstrip, counters, throughput -------------------------------------------------------
async function loadFilmstrip() {
  const gen = generation;
  let page;
  try { page = await api("GET", `/inspections?limit=${FILMSTRIP}`); } catch (e) { setText(q("#insp-message"), e.message); return; }
  if (gen !== generation || !root) return;
  const strip = q("#filmstrip");
  const have = new Map([...strip.children].map((f) => [Number(f.dataset.id), f]));
  const frames = page.data.map((r) => have.get(r.id) || el("figure", {
    className: `frame decision-${r.decision}`, dataset: { id: Number(r.id), decision: r.decision },
    on: { click: () => showInspection(r.id) },
  },
  r.images.length ? lazyImage(r.images[0], fetchBlob, { alt: `inspection ${r.id}` }) : el("div", { className: "noimage" }, "no image"),
  el("figcaption", {}, `#${r.id} ${decisionText(r)}`)));
  for (const [id, f] of have) if (!page.data.some((r) => r.id === id)) releaseImages(f);
  strip.replaceChildren(...frames);
  if (!page.count) strip.append(el("p", { className: "small" }, "No inspections yet."));
  if (shownId === null && page.data.length) showInspection(page.data[0].id);
}

/** The threshold of each model: its own, else the automatic per-model one, else the global. */
async function loadThresholds() {
  try {
    const [s, models] = await Promise.all([api("GET", "/recognition/settings"), api("GET", "/models?limit=1000")]);
    threshold = s.global_threshold;
    const auto = (s.chosen_by === "auto" && s.detail && s.detail.per_model) || {};
    perModel = Object.fromEntries(models.data.map((m) => [m.name, m.threshold ?? auto[m.name] ?? s.global_threshold]));
    setText(q("#live-threshold-note"), "every taught model; ticks: the threshold of each model");
  } catch (e) { /* the bars show without ticks */ }
}

async function countSince(since, decision) {
  const p = new URLSearchParams({ since, limit: "1" });
  if (decision) p.set("decision", decision);
  return (await api("GET", `/inspections?${p}`)).count;
}

async function loadCounters() {
  const gen = generation;
  const since = shiftStart();
  const minuteAgo = new Date(Date.now() - 60_000).toISOString();
  try {
    const [rec, unk, fail, minute] = await Promise.all([...DECISIONS.map((d) => countSince(since, d)), countSince(minuteAgo)]);
    if (gen !== generation || !root) return;
    setText(q("#count-recognized"), rec);
    setText(q("#count-unknown"), unk);
    setText(q("#count-failed"), fail);
    const total = rec + unk + fail;
    setText(q("#count-yield"), total ? `${((rec / total) * 100).toFixed(1)} %` : "-");
    setText(q("#throughput"), `${minute} /min`);
    setText(q("#shift-since"), `since ${new Date(since).toLocaleString()}`);
  } catch (e) { if (root) setText(q("#insp-message"), e.message); }
}

function newShift() {
  localStorage.setItem(SHIFT_KEY, new Date().toISOString());
  loadCounters();
}

async function refresh() {
  await Promise.all([loadFilmstrip(), loadCounters()]);
}

function build() {
  const controls = el("div", { className: "card insp-controls" },
    el("h2", {}, "Operation"),
    el("p", { id: "insp-recipe", className: "small", role: "status" }, "Recipe: -"),
    el("div", { className: "row" },
      el("label", { className: "inline" }, "Policy ", el("select", { id: "insp-policy" },
        ...["two-views", "best-next", "top-only", "naive"].map((p) => el("option", { value: p }, p)))),
      el("label", { className: "inline" }, "Max views ", el("select", { id: "insp-max-views" },
        ...[3, 2, 1].map((v) => el("option", { value: v }, String(v))))),
      el("label", { className: "inline" }, el("input", { id: "insp-sort", type: "checkbox" }), " sort into bins")),
    el("div", { className: "row", dataset: { minRole: "operator", roleHint: "Inspecting and running the cell" } },
      el("button", { id: "insp-once", type: "button", on: { click: inspectOnce } }, "Inspect once"),
      el("button", { id: "insp-run", type: "button", className: "go", on: { click: startRun } }, "Start"),
      el("button", { id: "insp-stop", type: "button", disabled: "", on: { click: stopRun } }, "Stop"),
      el("label", { className: "inline" }, "count ", el("input", { id: "insp-count", type: "number", min: 1, max: 100000, placeholder: "∞", size: 5 }))),
    el("p", { id: "insp-run-state", className: "small", role: "status" }),
    el("div", { className: "counters" },
      el("div", { className: "counter ok" }, el("span", { id: "count-recognized" }, "-"), el("small", {}, "recognized")),
      el("div", { className: "counter unknown" }, el("span", { id: "count-unknown" }, "-"), el("small", {}, "unknown")),
      el("div", { className: "counter failed" }, el("span", { id: "count-failed" }, "-"), el("small", {}, "failed")),
      el("div", { className: "counter" }, el("span", { id: "count-yield" }, "-"), el("small", {}, "yield")),
      el("div", { className: "counter" }, el("span", { id: "throughput" }, "-"), el("small", {}, "last minute"))),
    el("p", { className: "small" }, el("span", { id: "shift-since" }), " ",
      el("button", { id: "new-shift", type: "button", className: "small-button", on: { click: newShift } }, "New shift")),
    el("p", { id: "insp-message", className: "error", role: "status" }));
  const belt = el("div", { className: "card insp-belt" },
    el("h2", {}, "Belt"),
    el("p", { id: "belt-state", className: "small", role: "status" }, "-"),
    el("div", { className: "row", dataset: { minRole: "operator" } },
      el("button", { id: "belt-start", type: "button", disabled: "", on: { click: () => setBelt(true) } }, "Start belt"),
      el("button", { id: "belt-stop", type: "button", disabled: "", on: { click: () => setBelt(false) } }, "Stop belt")),
    el("div", { id: "belt-place", className: "row", hidden: "" },  // engineers on the simulator (loadCatalogue)
      el("label", { className: "inline" }, "Part ", el("select", { id: "belt-place-name" })),
      el("button", { id: "belt-place-go", type: "button", on: { click: placePart } }, "Place at the station")));
  const live = el("div", { className: "card insp-live" },
    el("h2", {}, "Last result ", el("span", { id: "live-label", className: "decision" }, "-")),
    el("p", { id: "live-reason", className: "small" }),
    el("p", { id: "live-pick", className: "small pick" }),
    el("div", { id: "live-images", className: "live-images" }),
    el("p", { id: "live-viewpoints", className: "small" }),
    el("p", { id: "live-pose", className: "small" }),
    el("h3", {}, "Scores ", el("span", { id: "live-threshold-note", className: "small" })),
    el("canvas", { id: "live-scores", className: "chart bars" }));
  const strip = el("div", { className: "card insp-strip" }, el("h2", {}, "Recent results"), el("div", { id: "filmstrip", className: "filmstrip" }));
  return el("section", { id: "inspection-page", className: "page" }, el("div", { className: "insp-grid" }, controls, belt, live, strip));
}

export default {
  id: "inspection",
  title: "Inspection",
  minRole: "viewer",

  mount(target, context) {
    root = target;
    ctx = context;
    generation++;
    shownId = null;
    root.append(build());
    applyRoles(root, ctx.role, ctx.rank);
    listen(ctx.live, "job", (ev) => onJob(ev.detail));
    listen(ctx.live, "inspection", (ev) => { showInspection(ev.detail.id); refresh(); });
    listen(ctx.live, "open", (ev) => { if (ev.detail.reconnected) refresh(); });
    thresholdsRead = loadThresholds();
    api("GET", "/jobs").then((jobs) => {
      const run = jobs.data.find((j) => j.kind === "inspection-run" && j.state === "running");
      if (run) onJob(run);
    }).catch(() => {});
    refresh();
    loadBelt();
    loadRecipe();
    loadCatalogue();
    timer = setInterval(() => { if (document.visibilityState === "visible") { loadCounters(); loadBelt(); loadRecipe(); } }, REFRESH_MS);
  },

  unmount() {
    generation++;
    listeners.forEach((off) => off());
    listeners = [];
    clearInterval(timer);
    timer = null;
    if (root) releaseImages(root);
    root = null;
    ctx = null;
    runJob = null;
    recipe = null;
    recipeSeen = "";
  },
};
