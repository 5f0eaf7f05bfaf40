// The Models page: object models with their trained views (thumbnails and masks), the teach
// wizard (empty the station, start teaching, place the object, watch the live camera and the
// views arrive through the job's progress), uploads of views, the thresholds (automatic: the
// score distributions and the ROC from GET /api/recognition/settings; by hand: engineer) and
// the confusability warnings.  Viewers read; engineers change (the server enforces it too).

import { api, ApiError, checkRefused, fetchBlob, getToken } from "../api.js";
import { $, applyRoles, el, lazyImage, releaseBlob, releaseImages, setText, showBlob } from "../dom.js";
import { binCounts, bars, histogram, lines, rocPoints } from "../charts.js";

const CAMERA_PERIOD_MS = 600;
const SCORE_EDGES = Array.from({ length: 21 }, (_, k) => k / 20);

let root = null;
let ctx = null;
let listeners = [];
let selected = null;       // the selected model (API form)
let models = [];
let teachJob = null;       // id of the teach job followed
let sim = null;            // {station_s_m, catalogue: [names]} when the cell is simulated
let camTimer = null;
let generation = 0;
// Teach rounds of the selected model: the object is turned by 360/N degrees between rounds,
// so the model is recognised at any yaw.  N is what the model's kind needs (the server's
// `rounds.recommended`: a 3d model is decided by side views, which need the object shown at
// many yaws; a 2d one by its rotation-invariant top view); the wizard resumes after the
// rounds the model has (`rounds.taught`: the distinct yaws the server counts).
let rounds = { model: null, n: 1, k: 0, baseYawDeg: 0 };

const q = (sel) => (root ? $(sel, root) : null);

function listen(target, type, fn) {
  target.addEventListener(type, fn);
  listeners.push(() => target.removeEventListener(type, fn));
}

/** Show `text` in the message line `sel`: in red, or in green when `ok` (a success). */
function say(sel, text, ok = false) {
  const node = q(sel);
  if (!node) return;
  setText(node, text || "");
  node.classList.toggle("ok", ok);
}

async function call(msgSel, method, path, body) {
  say(msgSel, "");
  try { return await api(method, path, body); }
  catch (e) { say(msgSel, e.message); return null; }
}

// -- the model list ---------------------------------------------------------------------------
// Each load is numbered: only the latest one's answer is shown, so a slow earlier load
// (e.g. after a teach) cannot bring back a list without the model just created.
let loads = 0;

async function loadModels() {
  const gen = generation;
  const seq = ++loads;
  const page = await call("#models-message", "GET", "/models?limit=1000");
  if (!page || gen !== generation || seq !== loads) return;
  models = page.data;
  const body = q("#models-table tbody");
  body.replaceChildren(...models.map((m) => el("tr", {
    dataset: { id: Number(m.id), name: m.name }, className: selected && selected.id === m.id ? "selected" : "",
    on: { click: () => selectModel(m.id) },
  },
  el("td", {}, m.name), el("td", {}, m.kind), el("td", {}, m.part),
  el("td", {}, `${m.views}${m.stale_views ? ` (${m.stale_views} stale)` : ""}`),
  el("td", {}, m.threshold === null ? "auto" : m.threshold.toFixed(3)))));
  if (!models.length) body.append(el("tr", {}, el("td", { colSpan: 5, className: "small" }, "No models yet.")));
  if (selected) {
    const again = models.find((m) => m.id === selected.id);
    if (again) await selectModel(again.id); else { selected = null; q("#model-detail").hidden = true; }
  }
}

async function createModel(ev) {
  ev.preventDefault();
  const body = {
    name: q("#new-model-name").value.trim(),
    kind: q("#new-model-kind").value,
  };
  const part = q("#new-model-part").value.trim();
  if (part) body.part = part;
  const m = await call("#models-message", "POST", "/models", body);
  if (!m) return;
  q("#new-model-form").reset();
  selected = m;
  await loadModels();
}

// -- one model: views, threshold, teach, upload ----------------------------------------------
function viewCard(v) {
  const card = el("figure", { className: "view-card", dataset: { view: Number(v.id), viewpoint: v.viewpoint } },
    el("div", { className: "view-pair" },
      lazyImage(v.thumbnail_url, fetchBlob, { alt: `view ${v.id}` }),
      lazyImage(v.mask_url, fetchBlob, { alt: `mask of view ${v.id}`, className: "mask", fallback: "no mask: the whole image" })),
    el("figcaption", {}, `#${v.id} vp ${v.viewpoint} · ${v.keypoints} kp · ${v.source}`,
      v.stale ? el("span", { className: "alarm" }, ` stale: ${v.stale}`) : ""));
  if (ctx.can("engineer")) {
    card.append(el("button", { type: "button", className: "small-button delete-view", on: { click: async () => {
      if (!window.confirm(`Delete view ${v.id}?`)) return;
      const r = await call("#model-message", "DELETE", `/models/${selected.id}/views/${v.id}?reason=console`);
      if (r) loadModels();
    } } }, "Delete"));
  }
  return card;
}

async function selectModel(id) {
  const gen = generation;
  const [m, views] = await Promise.all([
    call("#models-message", "GET", `/models/${id}`),
    call("#models-message", "GET", `/models/${id}/views?limit=500`),
  ]);
  if (!m || !views || gen !== generation) return;
  selected = m;
  for (const tr of root.querySelectorAll("#models-table tbody tr")) tr.classList.toggle("selected", Number(tr.dataset.id) === id);
  q("#model-detail").hidden = false;
  setText(q("#model-title"), `${m.name} (${m.kind}, part ${m.part}, base ${m.sitting_base})`);
  const per = Object.entries(m.views_per_viewpoint).map(([vp, n]) => `viewpoint ${vp}: ${n}`).join(", ");
  setText(q("#model-summary"), `${m.views} trained views${per ? ` (${per})` : ""}; ${m.indexed_views} in the live index`
    + `${m.stale_views ? `, ${m.stale_views} stale` : ""}. Threshold: ${m.threshold === null ? "automatic" : m.threshold.toFixed(3)}.`
    + ` Height: ${m.height_m === null ? "not known (teach it, or enter it below)" : `${(m.height_m * 1000).toFixed(1)} mm (${m.geometry_source || "stored"})`}.`);
  q("#model-height").value = m.height_m === null ? "" : (m.height_m * 1000).toFixed(1);
  if (rounds.model !== m.id) {
    const need = m.rounds.recommended;
    q("#teach-rounds").value = String(need);
    setText(q("#teach-rounds-why"), `(a ${m.kind} model needs ${need} round${need > 1 ? `s, ${Math.round(360 / need)}° apart,` : ""}`
      + ` to be recognised at any yaw; ${m.name} has ${m.rounds.taught})`);
    resetRounds(m.id, Math.min(m.rounds.taught, need));
  }
  q("#model-threshold").value = m.threshold === null ? "" : String(m.threshold);
  const grid = q("#views-grid");
  releaseImages(grid);
  grid.replaceChildren(...views.data.map(viewCard));
  if (!views.count) grid.append(el("p", { className: "small" }, "No trained views: teach the model or upload views."));
  q("#teach-kind").textContent = m.kind === "3d" ? "top and side views (viewpoints 1-3)" : "top views (viewpoint 1)";
}

async function saveModelThreshold(clear) {
  if (!selected) return;
  const text = q("#model-threshold").value.trim();
  const value = clear ? null : Number(text);
  if (!clear && (text === "" || !Number.isFinite(value) || value < 0 || value > 1)) {
    say("#model-message", `threshold must be a number in [0, 1], got ${JSON.stringify(text)}`);
    return;
  }
  const r = await call("#model-message", "PATCH", `/models/${selected.id}`, { threshold: value, reason: "set in the console" });
  if (r) { await loadModels(); await loadThresholds(); }
}

async function uploadViews(ev) {
  ev.preventDefault();
  if (!selected) return;
  const files = q("#upload-images").files;
  const masks = q("#upload-masks").files;
  if (!files.length) { say("#upload-message", "choose one or more images"); return; }
  if (masks.length && masks.length !== files.length) { say("#upload-message", `give one mask per image (${files.length}) or none`); return; }
  const form = new FormData();
  for (const f of files) form.append("images", f, f.name);
  for (const f of masks) form.append("masks", f, f.name);
  form.append("viewpoints", q("#upload-viewpoint").value);
  form.append("reason", "uploaded in the console");
  say("#upload-message", "uploading…");
  try {
    const sent = getToken();
    const res = await fetch(`/api/models/${selected.id}/views`, { method: "POST", body: form, headers: authHeader() });
    checkRefused(res, sent);
    const text = await res.text();
    const body = text ? JSON.parse(text) : {};
    if (!res.ok) throw new ApiError(res.status, body.error, typeof body.detail === "string" ? body.detail : JSON.stringify(body.detail));
    say("#upload-message", `${body.count} view(s) stored`);
    q("#upload-form").reset();
    await loadModels();
  } catch (e) { say("#upload-message", e.message); }
}

function authHeader() {
  const t = getToken();
  return t ? { Authorization: `Bearer ${t}` } : {};
}

// The part's height (mm): measured by the teach, or entered here when it could not be.
async function saveHeight(sel) {
  if (!selected) return;
  const text = q(sel).value.trim();
  const mm = Number(text);
  if (text === "" || !Number.isFinite(mm) || mm <= 0 || mm > 500) {
    say("#model-message", `height must be a number of millimetres in (0, 500], got ${JSON.stringify(text)}`);
    return;
  }
  const r = await call("#model-message", "PATCH", `/models/${selected.id}`, { height_mm: mm, reason: "height entered in the console" });
  if (r) { say("#teach-message", ""); q("#teach-height-ask").hidden = true; await loadModels(); }
}

// -- the teach wizard -------------------------------------------------------------------------
// Yaw of round k of n (0-based), degrees in (-180, 180]: as backend.recognition.teach_yaws_rad.
function roundYawDeg(k, n) {
  const d = (360 * k) / n;
  return d > 180 ? d - 360 : d;
}

// Start the rounds of `modelId` over (or resume them after `k` taught ones) with the number
// of rounds in the field.
function resetRounds(modelId, k = 0) {
  const n = Math.min(12, Math.max(1, Math.round(Number(q("#teach-rounds").value) || 1)));
  rounds = { model: modelId, n, k: Math.min(k, n), baseYawDeg: Number(q("#place-yaw").value) || 0 };
  showRound();
}

function showRound() {
  if (!root) return;
  const { n, k } = rounds;
  const bar = q("#teach-rounds-progress");
  bar.max = n;
  bar.value = Math.min(k, n);
  const done = k >= n;
  setText(q("#teach-round"), done
    ? `All ${n} round${n > 1 ? `s taught: the model is taught at ${n} yaws, ${Math.round(360 / n)}° apart` : " taught"}.`
    : `Round ${k + 1} of ${n}: the object turned ${roundYawDeg(k, n).toFixed(0)}° from its first round's pose`
      + (k > 0 ? " (turn it, keep it at the station; the stored backgrounds are used)." : "."));
  q("#teach-start").textContent = done ? "Teach again" : `Teach round ${k + 1} of ${n}`;
  if (k > 0 && !done) q("#teach-background").value = "stored";
}

function changeRounds() {
  const n = Number(q("#teach-rounds").value);
  if (!Number.isInteger(n) || n < 1 || n > 12) { say("#teach-message", `rounds must be a whole number in 1..12, got ${q("#teach-rounds").value}`); return; }
  rounds.n = n;
  showRound();
}

async function detectSim() {
  if (!ctx.can("engineer")) return;
  try {
    const [conv, cat] = await Promise.all([api("GET", "/sim/conveyor"), api("GET", "/sim/catalogue?limit=100")]);
    sim = { station_s_m: conv.conveyor.station_s_m, catalogue: cat.data.map((c) => c.name) };
  } catch (e) {
    sim = null;  // 409 not_simulated: the object is placed by hand
  }
  if (!root) return;
  q("#sim-place").hidden = !sim;
  q("#sim-clear").hidden = !sim;
  q("#hand-place").hidden = !!sim;
  if (sim) {
    const select = q("#place-name");
    select.replaceChildren(...sim.catalogue.map((n) => el("option", { value: n }, n)));
    const match = selected && sim.catalogue.find((n) => n === selected.name);
    if (match) select.value = match;
  }
}

async function clearStation() {
  if (!sim) return;
  say("#teach-message", "");
  try {
    await api("POST", "/sim/conveyor", { running: false, mode: "index", dwell_s: null });
    const objs = await api("GET", "/sim/objects?limit=100");
    for (const o of objs.data) await api("DELETE", `/sim/objects/${o.id}`);
    say("#teach-message", `station cleared (${objs.count} object(s) taken off the belt, belt stopped)`, true);
  } catch (e) { say("#teach-message", e.message); }
}

async function placeObject() {
  if (!sim) return;
  if (rounds.k > 0) {
    // a later round: the object at the station is turned, not a second one added
    const objs = await call("#teach-message", "GET", "/sim/objects?limit=100");
    if (!objs) return;
    for (const o of objs.data) await call("#teach-message", "DELETE", `/sim/objects/${o.id}`);
  } else {
    rounds.baseYawDeg = Number(q("#place-yaw").value) || 0;
  }
  const name = q("#place-name").value;
  const yawDeg = Number(q("#place-yaw").value || 0);
  if (!Number.isFinite(yawDeg) || Math.abs(yawDeg) > 180) { say("#teach-message", `yaw must be within ±180°, got ${q("#place-yaw").value}`); return; }
  const r = await call("#teach-message", "POST", "/sim/objects",
    { name, position_along_belt_m: sim.station_s_m, lateral_m: 0, yaw_rad: (yawDeg * Math.PI) / 180 });
  if (r) say("#teach-message", `${name} placed at the station (object ${r.object.id})`, true);
}

async function startTeach(ev) {
  ev.preventDefault();
  if (!selected) return;
  if (rounds.model !== selected.id || rounds.k >= rounds.n) resetRounds(selected.id);
  const yawDeg = roundYawDeg(rounds.k, rounds.n);
  const body = {
    background: rounds.k > 0 ? "stored" : q("#teach-background").value,
    replace: rounds.k === 0 && q("#teach-replace").checked,
    yaw_rad: (yawDeg * Math.PI) / 180,
    wait_s: 120,
    // The threshold is chosen once, at the end of the last round (the cell's threshold
    // keeper chooses it after every change anyway once the teach is over).
    threshold: rounds.k + 1 >= rounds.n,
    ...(q("#teach-rolls").value === "one" ? { top_rolls_rad: [0] } : {}),
    reason: "taught in the console",
  };
  setText(q("#teach-state"), `starting round ${rounds.k + 1} of ${rounds.n}…`);
  const r = await call("#teach-message", "POST", `/models/${selected.id}/teach`, body);
  if (!r) { setText(q("#teach-state"), ""); return; }
  teachJob = r.job.id;
  q("#teach-steps").replaceChildren();
  q("#teach-result").replaceChildren();
  q("#teach-progress").hidden = false;
  startCamera();
  onTeachJob(r.job);
}

function onTeachJob(job) {
  if (!root || job.id !== teachJob) return;
  const bar = q("#teach-progress");
  bar.value = job.progress || 0;
  const steps = q("#teach-steps");
  const last = steps.lastElementChild;
  if (job.message && (!last || last.dataset.msg !== job.message)) {
    steps.append(el("li", { dataset: { msg: job.message } }, job.message));
  }
  const waiting = job.state === "running" && /waiting for an object/.test(job.message || "");
  q("#teach-place").classList.toggle("attention", waiting);
  setText(q("#teach-state"), `teach job ${job.id}: ${job.state}${job.state === "running" ? ` ${Math.round((job.progress || 0) * 100)}%` : ""}`);
  if (job.state === "running") return;
  teachJob = null;
  stopCamera();
  bar.hidden = true;
  if (job.state !== "done") {
    say("#teach-message", job.error ? job.error.detail : `the teach ended ${job.state}`);
    return;
  }
  say("#teach-message", "");
  const res = job.result || {};
  const shots = (res.shots || []).filter((s) => !s.geometry_only);
  const out = q("#teach-result");
  if (res.model && rounds.model === res.model.id) { rounds.k += 1; showRound(); }
  if (sim && rounds.k < rounds.n) {
    let next = rounds.baseYawDeg + roundYawDeg(rounds.k, rounds.n);
    if (next > 180) next -= 360;
    q("#place-yaw").value = String(Math.round(next));
  }
  const thr = res.threshold || {};
  const geo = res.geometry || {};
  const measured = geo.measured || {};
  out.replaceChildren(
    el("p", {}, `${(res.views || []).length} view(s) stored for ${res.model ? res.model.name : "the model"}. `
      + `Threshold in force: ${Number.isFinite(thr.in_force) ? thr.in_force.toFixed(3) : "-"}`
      + `${thr.floor ? ` (the floor: the views cannot support a lower one yet)` : ""}. ${thr.reason || ""}`),
    el("p", { id: "teach-height", className: "small" }, geo.height_m
      ? `Part height ${(geo.height_m * 1000).toFixed(1)} mm (${geo.source}${geo.source === "measured" && measured.note ? `: ${measured.note}` : ""}).`
      : `Part height not known: ${measured.note || "not measured"}.`),
    ...(thr.advice && thr.advice.length
      ? [el("div", { id: "teach-advice", className: "warning" }, el("strong", {}, "To make recognition reliable: "),
        el("ul", {}, ...thr.advice.map((a) => el("li", {}, a))))]
      : []),
    el("div", { className: "views-grid" }, ...(res.views || []).map((v, i) => el("figure", { className: "view-card new-view" },
      el("div", { className: "view-pair" },
        lazyImage(v.thumbnail_url, fetchBlob, { alt: `new view ${v.id}` }),
        lazyImage(v.mask_url, fetchBlob, { alt: `mask of new view ${v.id}`, className: "mask", fallback: "no mask: the whole image" })),
      el("figcaption", {}, `vp ${v.viewpoint}${shots[i] ? ` · ${shots[i].mask_px} px mask · ${shots[i].segmentation}` : ""}`)))));
  const conf = res.confusable_from_top || [];
  if (conf.length) out.append(confusableList(conf));
  const ask = q("#teach-height-ask");
  ask.hidden = !geo.needed;
  setText(q("#teach-height-why"), geo.ask || "");
  loadModels();
  loadThresholds();
}

function confusableList(pairs) {
  return el("div", { className: "warning" },
    el("strong", {}, "Confusable from the top: "),
    el("ul", {}, ...pairs.map((p) => el("li", {},
      `${p.confused_with} passes its threshold on ${(p.rate * 100).toFixed(1)} % of ${p.model}'s top views`))),
    el("p", { className: "small" }, "Inspect these with a side view (policy two-views or best-next), or teach more top rolls."));
}

// -- the live camera while teaching -----------------------------------------------------------
function startCamera() {
  stopCamera();
  const img = q("#teach-camera");
  const tick = async () => {
    camTimer = null;
    if (!root || document.visibilityState !== "visible") { camTimer = setTimeout(tick, CAMERA_PERIOD_MS); return; }
    try { showBlob(img, await fetchBlob("/api/camera/frame.jpg")); img.hidden = false; setText(q("#teach-camera-status"), ""); }
    catch (e) { setText(q("#teach-camera-status"), e.detail || "unavailable"); }
    if (root && camTimer === null && teachJob !== null) camTimer = setTimeout(tick, CAMERA_PERIOD_MS);
  };
  camTimer = setTimeout(tick, 0);
}

function stopCamera() {
  if (camTimer !== null) clearTimeout(camTimer);
  camTimer = null;
}

// -- thresholds ------------------------------------------------------------------------------
async function loadThresholds() {
  const gen = generation;
  const s = await call("#threshold-message", "GET", "/recognition/settings");
  if (!s || gen !== generation || !root) return;
  const d = s.detail || {};
  const t = s.global_threshold;
  const rule = d.rule ? ` — ${d.rule}` : "";
  const rates = Number.isFinite(d.far) && Number.isFinite(d.frr)
    ? ` FAR ${(d.far * 100).toFixed(2)} %, FRR ${(d.frr * 100).toFixed(2)} % on held-out views.` : "";
  setText(q("#threshold-summary"), `Global threshold ${t.toFixed(3)} (${s.chosen_by}${rule}).${rates}`);
  const advice = d.advice || [];
  q("#threshold-advice").replaceChildren(...(advice.length
    ? [el("strong", {}, "To make recognition reliable: "), el("ul", {}, ...advice.map((a) => el("li", {}, a)))] : []));
  q("#threshold-advice").hidden = !advice.length;
  // A refresh that lands after the engineer began typing a threshold keeps what was typed
  // (it replaces the field only while the field still shows the last value loaded).
  const field = q("#global-threshold");
  if (field.value === "" || field.value === field.dataset.loaded) field.value = t.toFixed(3);
  field.dataset.loaded = t.toFixed(3);
  const genuine = d.genuine || [];
  const impostor = d.impostor || [];
  const hasScores = genuine.length + impostor.length > 0;
  q("#threshold-plots").hidden = !hasScores;
  setText(q("#threshold-none"), hasScores ? "" : "No score distributions yet: they are computed after every change of the trained views (two models, or one model and negative images; see the Recognise page).");
  if (hasScores) {
    histogram(q("#score-hist"), SCORE_EDGES, [
      { label: `genuine (${genuine.length})`, counts: binCounts(genuine, SCORE_EDGES), color: "#15803d" },
      { label: `impostor (${impostor.length})`, counts: binCounts(impostor, SCORE_EDGES), color: "#c81e1e" },
    ], { mark: t, density: true });
    const roc = rocPoints(genuine, impostor);
    const at = roc.reduce((best, p) => (Math.abs(p[2] - t) < Math.abs(best[2] - t) ? p : best), roc[0]);
    lines(q("#roc"), [{ label: "ROC", points: roc.map((p) => [p[0], p[1]]), color: "#2563eb" }],
      { x0: 0, x1: 1, y0: 0, y1: 1, xLabel: "false accept rate", yLabel: "true accept rate", mark: [at[0], at[1]] });
  }
  const per = Object.entries(d.per_model || {}).sort();
  const own = new Map(models.filter((m) => m.threshold !== null).map((m) => [m.name, m.threshold]));
  const items = [...new Set([...per.map(([m]) => m), ...own.keys()])].sort().map((m) => ({
    label: own.has(m) ? `${m} (own)` : m,
    value: own.has(m) ? own.get(m) : (d.per_model || {})[m],
    color: own.has(m) ? "#7c3aed" : "#e07a1e",
  }));
  bars(q("#per-model-thresholds"), items, { max: 1, mark: t });
  const conf = d.confusable_from_top || [];
  const box = q("#threshold-confusable");
  box.replaceChildren();
  if (conf.length) box.append(confusableList(conf));
}

async function saveGlobal(ev) {
  ev.preventDefault();
  const text = q("#global-threshold").value.trim();
  const v = Number(text);
  if (text === "" || !Number.isFinite(v) || v < 0 || v > 1) { say("#threshold-message", `threshold must be in [0, 1], got ${JSON.stringify(text)}`); return; }
  const note = q("#global-note").value.trim().slice(0, 500);
  const r = await call("#threshold-message", "PUT", "/recognition/settings", { global_threshold: v, note, reason: note || "set in the console" });
  if (r) { q("#global-threshold").dataset.loaded = text; loadThresholds(); }
}

// -- the page ----------------------------------------------------------------------------------
function build() {
  const engineer = (...kids) => el("div", { dataset: { minRole: "engineer" } }, ...kids);
  const list = el("div", { className: "card models-list" },
    el("h2", {}, "Models ", el("button", { type: "button", className: "small-button", on: { click: loadModels } }, "Refresh")),
    el("table", { id: "models-table" },
      el("thead", {}, el("tr", {}, ...["Name", "Kind", "Part", "Views", "Threshold"].map((h) => el("th", {}, h)))),
      el("tbody")),
    el("div", { dataset: { minRole: "engineer", roleHint: "Creating, teaching and changing models" } },
      el("form", { id: "new-model-form", className: "row", on: { submit: createModel } },
      el("input", { id: "new-model-name", type: "text", placeholder: "new model name", required: "", maxlength: 64 }),
      el("select", { id: "new-model-kind" }, el("option", { value: "2d" }, "2d"), el("option", { value: "3d" }, "3d")),
      el("input", { id: "new-model-part", type: "text", placeholder: "part (default: name)", maxlength: 64 }),
      el("button", { id: "new-model", type: "submit", className: "small-button" }, "Create"))),
    el("p", { id: "models-message", className: "error", role: "status" }));

  const detail = el("div", { id: "model-detail", className: "card model-detail", hidden: true },
    el("h2", { id: "model-title" }, "Model"),
    el("p", { id: "model-summary", className: "small" }),
    el("div", { id: "views-grid", className: "views-grid" }),
    engineer(
      el("div", { className: "row" },
        el("label", {}, "Own threshold ", el("input", { id: "model-threshold", type: "number", min: 0, max: 1, step: 0.01, placeholder: "auto" })),
        el("button", { id: "model-threshold-save", type: "button", className: "small-button", on: { click: () => saveModelThreshold(false) } }, "Set"),
        el("button", { id: "model-threshold-clear", type: "button", className: "small-button", on: { click: () => saveModelThreshold(true) } }, "Automatic")),
      el("div", { className: "row" },
        el("label", {}, "Height (mm) ", el("input", { id: "model-height", type: "number", min: 0.1, max: 500, step: 0.1, placeholder: "teach measures it" })),
        el("button", { id: "model-height-save", type: "button", className: "small-button", on: { click: () => saveHeight("#model-height") } }, "Set height")),
      el("form", { id: "upload-form", className: "row", on: { submit: uploadViews } },
        el("label", {}, "Images ", el("input", { id: "upload-images", type: "file", multiple: "", accept: "image/png,image/jpeg" })),
        el("label", {}, "Masks ", el("input", { id: "upload-masks", type: "file", multiple: "", accept: "image/png,image/jpeg" })),
        el("label", {}, "Viewpoint ", el("select", { id: "upload-viewpoint" }, ...[1, 2, 3].map((v) => el("option", { value: v }, String(v))))),
        el("button", { id: "upload-start", type: "submit", className: "small-button" }, "Upload views")),
      el("p", { id: "upload-message", className: "small", role: "status" })),
    el("p", { id: "model-message", className: "error", role: "status" }));

  const wizard = el("div", { id: "teach-wizard", className: "card teach", dataset: { minRole: "engineer" } },
    el("h2", {}, "Teach the selected model"),
    el("ol", { className: "wizard" },
      el("li", {}, "Empty the station. ",
        el("button", { id: "sim-clear", type: "button", className: "small-button", hidden: true, on: { click: clearStation } }, "Clear the station (simulator)")),
      el("li", {}, "Teach in rounds, the object turned between them: ",
        el("label", { className: "inline" }, el("input", { id: "teach-rounds", type: "number", min: 1, max: 12, step: 1, value: 1, on: { change: changeRounds } }), " rounds"),
        " ", el("span", { id: "teach-rounds-why", className: "small" }), " ",
        el("span", { id: "teach-round", className: "small" }), " ",
        el("progress", { id: "teach-rounds-progress", max: 1, value: 0 })),
      el("li", {}, el("form", { id: "teach-form", className: "row", on: { submit: startTeach } },
        "Start teaching ", el("span", { id: "teach-kind", className: "small" }), ": ",
        el("select", { id: "teach-background" }, el("option", { value: "grab" }, "grab the empty background first"),
          el("option", { value: "stored" }, "stored backgrounds (object already there)")),
        el("select", { id: "teach-rolls", title: "Camera rolls of the top view" },
          el("option", { value: "all" }, "all top rolls"), el("option", { value: "one" }, "one top roll (quick)")),
        el("label", { className: "inline" }, el("input", { id: "teach-replace", type: "checkbox" }), " replace the earlier views"),
        el("button", { id: "teach-start", type: "submit", className: "small-button" }, "Start teaching"))),
      el("li", { id: "teach-place" }, "Place the object when the job waits for it. ",
        el("span", { id: "hand-place", className: "small" }, "(by hand at the station)"),
        el("span", { id: "sim-place", hidden: true },
          el("select", { id: "place-name" }),
          el("label", { className: "inline" }, " yaw° ", el("input", { id: "place-yaw", type: "number", min: -180, max: 180, step: 1, value: 0 })),
          el("button", { id: "place-object", type: "button", className: "small-button", on: { click: placeObject } }, "Place at the station"))),
      el("li", {}, "Watch the views arrive; the part's height is measured and the threshold chosen again at the end of each round.")),
    el("div", { className: "teach-live" },
      el("div", {}, el("img", { id: "teach-camera", alt: "Live camera while teaching", hidden: true }),
        el("p", { id: "teach-camera-status", className: "small" })),
      el("div", {}, el("p", { id: "teach-state", className: "small" }),
        el("progress", { id: "teach-progress", max: 1, value: 0, hidden: true }),
        el("ul", { id: "teach-steps", className: "samples" }))),
    el("div", { id: "teach-result" }),
    el("div", { id: "teach-height-ask", className: "warning row", hidden: true },
      el("span", { id: "teach-height-why" }), " ",
      el("label", {}, "Height (mm) ", el("input", { id: "teach-height-mm", type: "number", min: 0.1, max: 500, step: 0.1 })),
      el("button", { id: "teach-height-save", type: "button", className: "small-button", on: { click: () => saveHeight("#teach-height-mm") } }, "Set height")),
    el("p", { id: "teach-message", className: "error", role: "status" }));

  const thresholds = el("div", { className: "card thresholds" },
    el("h2", {}, "Thresholds"),
    el("p", { id: "threshold-summary", className: "small" }),
    el("div", { id: "threshold-advice", className: "warning", hidden: true }),
    el("p", { id: "threshold-none", className: "small" }),
    el("div", { id: "threshold-plots", className: "chart-pair" },
      el("figure", {}, el("canvas", { id: "score-hist", className: "chart" }), el("figcaption", { className: "small" }, "Best-score distributions of held-out views: own model (genuine) and others (impostor); dashed: the global threshold.")),
      el("figure", {}, el("canvas", { id: "roc", className: "chart" }), el("figcaption", { className: "small" }, "ROC over the threshold; red: the threshold in force."))),
    el("h3", {}, "Per-model thresholds"),
    el("canvas", { id: "per-model-thresholds", className: "chart bars" }),
    el("div", { id: "threshold-confusable" }),
    engineer(el("form", { id: "global-form", className: "row", on: { submit: saveGlobal } },
      el("label", {}, "Global threshold by hand ", el("input", { id: "global-threshold", type: "number", min: 0, max: 1, step: 0.01 })),
      el("input", { id: "global-note", type: "text", placeholder: "why (audit trail)", maxlength: 500 }),
      el("button", { id: "global-save", type: "submit", className: "small-button" }, "Set"))),
    el("p", { id: "threshold-message", className: "error", role: "status" }));

  return el("section", { id: "models-page", className: "page" },
    el("div", { className: "models-grid" }, list, detail, wizard, thresholds));
}

export default {
  id: "models",
  title: "Models",
  minRole: "viewer",

  mount(target, context) {
    root = target;
    ctx = context;
    generation++;
    root.append(build());
    applyRoles(root, ctx.role, ctx.rank);
    listen(ctx.live, "job", (ev) => {
      if (ev.detail.kind === "teach") onTeachJob(ev.detail);
      // The automatic threshold keeper chose again (after a change of the views): show it.
      else if (ev.detail.kind === "threshold" && ev.detail.state === "done") loadThresholds();
    });
    listen(ctx.live, "open", (ev) => { if (ev.detail.reconnected) loadModels(); });
    loadModels().then(() => {
      if (!selected && models.length) selectModel(models[0].id);
      loadThresholds();
    });
    detectSim();
  },

  unmount() {
    generation++;
    listeners.forEach((off) => off());
    listeners = [];
    stopCamera();
    if (root) { releaseImages(root); releaseBlob(q("#teach-camera")); }
    root = null;
    ctx = null;
    teachJob = null;
  },
};
