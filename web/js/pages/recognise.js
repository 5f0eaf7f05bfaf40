// The Recognise page (viewer): drop or pick an image and see what the cell makes of it
// (POST /api/recognition/recognise): the decision, every model's score against its
// threshold, and the matched view's outline drawn over the image on a canvas.  Operators
// may store the result as an inspection (source "upload").  Below, the automatic threshold:
// its state (recomputed after every change of the trained views), the rule, the figures and
// what to add when the data cannot support the target (GET /api/recognition/threshold).
// Every text from the server goes in as a text node.

import { ApiError, getToken } from "../api.js";
import { $, el, setText } from "../dom.js";

const STATUS_PERIOD_MS = 3000;
const MAX_BYTES = 16 * 1024 * 1024;

let root = null;
let ctx = null;
let timer = null;
let generation = 0;
let listeners = [];

const q = (sel) => (root ? $(sel, root) : null);

function listen(target, type, fn) {
  target.addEventListener(type, fn);
  listeners.push(() => target.removeEventListener(type, fn));
}

function layout() {
  const canStore = ctx.can("operator");
  return el("section", { className: "page", id: "recognise-page" },
    el("div", { className: "card" },
    el("h2", {}, "Recognise an image"),
    el("p", { className: "small" },
      "Drop a PNG or JPEG image here or pick one: the cell compares it with every trained view of the viewpoint."),
    el("form", { id: "recognise-form" },
      el("div", { id: "recognise-drop", className: "drop-zone", tabindex: "0" },
        "Drop an image here"),
      el("label", {}, "Image ", el("input", { type: "file", id: "recognise-file", accept: "image/png,image/jpeg" })),
      el("label", {}, " Viewpoint ",
        el("select", { id: "recognise-viewpoint" },
          el("option", { value: "1" }, "1 (top)"), el("option", { value: "2" }, "2 (inner side)"),
          el("option", { value: "3" }, "3 (outer side)"))),
      canStore ? el("label", {}, " ", el("input", { type: "checkbox", id: "recognise-store" }),
        " store as an inspection") : null,
      el("button", { type: "submit", id: "recognise-run" }, "Recognise")),
    el("p", { id: "recognise-message", className: "message", role: "status" }),
    el("div", { className: "recognise-result" },
      el("canvas", { id: "recognise-canvas", width: "480", height: "360" }),
      el("div", {},
        el("p", { id: "recognise-decision", className: "decision" }),
        el("p", { id: "recognise-pose", className: "small" }),
        el("table", { id: "recognise-scores" },
          el("thead", {}, el("tr", {}, el("th", {}, "model"), el("th", {}, "score"),
            el("th", {}, "threshold"), el("th", {}, "passes"))),
          el("tbody", {})),
        el("p", { id: "recognise-times", className: "small" })))),
    el("div", { className: "card" },
      el("h2", {}, "Automatic threshold"),
      el("p", { id: "threshold-state", className: "small" }),
      el("p", { id: "threshold-rule" }),
      el("p", { id: "threshold-figures", className: "small" }),
      el("ul", { id: "threshold-advice" })));
}

function file() {
  const input = q("#recognise-file");
  return input && input.files && input.files.length ? input.files[0] : null;
}

async function draw(f, result) {
  const canvas = q("#recognise-canvas");
  const bitmap = await createImageBitmap(f);
  const scale = Math.min(1, 640 / Math.max(bitmap.width, bitmap.height));
  canvas.width = Math.round(bitmap.width * scale);
  canvas.height = Math.round(bitmap.height * scale);
  const g = canvas.getContext("2d");
  g.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
  bitmap.close();
  const pts = result ? result.outline_px : [];
  if (pts.length >= 3) {
    g.strokeStyle = result.decision === "recognized" ? "#16a34a" : "#e07a1e";
    g.lineWidth = 2;
    g.beginPath();
    pts.forEach(([x, y], k) => (k ? g.lineTo(x * scale, y * scale) : g.moveTo(x * scale, y * scale)));
    g.closePath();
    g.stroke();
    if (result.pose) {
      g.fillStyle = g.strokeStyle;
      g.beginPath();
      g.arc(result.pose.x_px * scale, result.pose.y_px * scale, 4, 0, 2 * Math.PI);
      g.fill();
    }
  }
  canvas.dataset.outline = String(pts.length);
}

function showResult(r) {
  const what = r.decision === "recognized" ? `recognized: ${r.model}`
    : r.decision === "ambiguous" ? `ambiguous: ${r.contenders.join(", ")}` : "unknown";
  const dec = q("#recognise-decision");
  setText(dec, `${what} (best ${r.best_model || "none"} ${r.score.toFixed(3)} against ${r.threshold.toFixed(3)})`);
  dec.dataset.decision = r.decision;
  setText(q("#recognise-pose"), r.pose
    ? `Matched view ${r.view_id} at x ${r.pose.x_px.toFixed(1)} px, y ${r.pose.y_px.toFixed(1)} px, `
      + `turned ${(r.pose.angle_rad * 180 / Math.PI).toFixed(1)} deg, scale ${r.pose.scale.toFixed(3)}`
      + (r.inspection_id ? `; stored as inspection ${r.inspection_id}` : "")
    : (r.inspection_id ? `Stored as inspection ${r.inspection_id}` : ""));
  q("#recognise-scores tbody").replaceChildren(...r.scores.map((s) => el("tr", {
    dataset: { model: s.model }, className: s.passed ? "passed" : "",
  }, el("td", {}, s.model), el("td", {}, s.score.toFixed(3)), el("td", {}, s.threshold.toFixed(3)),
  el("td", {}, s.passed ? "yes" : "no"))));
  if (!r.scores.length) {
    q("#recognise-scores tbody").append(el("tr", {}, el("td", { colSpan: 4, className: "small" }, "No trained models at this viewpoint.")));
  }
  const d = r.durations;
  setText(q("#recognise-times"), Object.entries(d).map(([k, v]) => `${k} ${(v * 1000).toFixed(1)} ms`).join(", "));
}

async function run(ev) {
  if (ev) ev.preventDefault();
  const f = file();
  if (!f) { setText(q("#recognise-message"), "choose or drop an image first"); return; }
  if (f.size > MAX_BYTES) { setText(q("#recognise-message"), `the image has ${f.size} bytes; at most ${MAX_BYTES}`); return; }
  const gen = ++generation;
  const form = new FormData();
  form.append("images", f, f.name);
  form.append("viewpoint", q("#recognise-viewpoint").value);
  const store = q("#recognise-store");
  form.append("store", store && store.checked ? "true" : "false");
  setText(q("#recognise-message"), "recognising…");
  try {
    const token = getToken();
    const res = await fetch("/api/recognition/recognise", {
      method: "POST", body: form, headers: token ? { Authorization: `Bearer ${token}` } : {},
    });
    const text = await res.text();
    const body = text ? JSON.parse(text) : {};
    if (!res.ok) throw new ApiError(res.status, body.error, typeof body.detail === "string" ? body.detail : JSON.stringify(body.detail));
    if (gen !== generation || !root) return;
    const r = body.data[0];
    setText(q("#recognise-message"), "");
    showResult(r);
    await draw(f, r);
  } catch (e) {
    if (gen !== generation || !root) return;
    setText(q("#recognise-message"), e.message);
    await draw(f, null).catch(() => {});
  }
}

function onDrop(ev) {
  ev.preventDefault();
  const files = ev.dataTransfer ? ev.dataTransfer.files : null;
  if (!files || !files.length) return;
  q("#recognise-file").files = files;
  run(null);
}

async function loadThreshold() {
  if (!root) return;
  try {
    const s = await ctx.api("GET", "/recognition/threshold");
    if (!root) return;
    const set = s.settings;
    const d = set.detail || {};
    const state = !s.follow ? "recomputed by teaches only"
      : s.state === "running" ? `recomputing now (job ${s.job})`
        : s.state === "waiting" ? "changes seen: recomputing once they settle" : "up to date";
    setText(q("#threshold-state"), `Follows every change of the trained views: ${state}.`);
    q("#threshold-state").dataset.state = s.state;
    setText(q("#threshold-rule"), `Global threshold ${set.global_threshold.toFixed(3)} (${set.chosen_by})`
      + (d.rule ? `: ${d.rule}` : ""));
    const figs = [];
    if (Number.isFinite(d.far)) figs.push(`false accepts ${(d.far * 100).toFixed(2)} % of impostor scores`);
    if (Number.isFinite(d.frr)) figs.push(`false rejects ${(d.frr * 100).toFixed(2)} % of held-out views`);
    if (d.genuine) figs.push(`${d.genuine.length} genuine and ${(d.impostor || []).length} impostor scores`);
    if (Number.isFinite(d.views)) figs.push(`${d.views} views`);
    if (Number.isFinite(d.negatives)) figs.push(`${d.negatives} negative images`);
    setText(q("#threshold-figures"), figs.join(", "));
    const advice = (s.last && !s.last.stored && s.last.advice && s.last.advice.length) ? s.last.advice : (d.advice || []);
    q("#threshold-advice").replaceChildren(...advice.map((a) => el("li", {}, a)));
  } catch (e) {
    setText(q("#threshold-state"), e.message);
  }
}

export default {
  id: "recognise",
  title: "Recognise",
  minRole: "viewer",
  mount(rootEl, context) {
    root = rootEl;
    ctx = context;
    root.replaceChildren(layout());
    listen(q("#recognise-form"), "submit", run);
    listen(q("#recognise-file"), "change", () => { setText(q("#recognise-message"), ""); });
    const drop = q("#recognise-drop");
    listen(drop, "dragover", (ev) => ev.preventDefault());
    listen(drop, "drop", onDrop);
    loadThreshold();
    timer = setInterval(loadThreshold, STATUS_PERIOD_MS);
  },
  unmount() {
    if (timer) clearInterval(timer);
    timer = null;
    for (const off of listeners) off();
    listeners = [];
    generation += 1;
    root = null;
  },
};
