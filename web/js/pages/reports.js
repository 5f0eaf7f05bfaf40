// The Reports page: filters (time range, cell, model, decision, policy) over the stored
// inspections; totals and yield, throughput per hour, cycle-time percentiles and the stage
// breakdown, score distributions per model, the confusion matrix against the simulator's
// truth, a gallery of unknown and failed inspections, the matching inspections, a drill-down
// to one inspection (views, scores, pose, durations, the replay of its recorded 3D scene)
// and the CSV export.  Data: /api/reports/* (docs: /work/wt/API_REPORTS.md) and
// /api/inspections.

import { api, ApiError, fetchBlob } from "../api.js";
import { $, el, isoUtc, lazyImage, releaseImages, setText } from "../dom.js";
import { COLORS, bars, columns, histogram } from "../charts.js";
import { everyScore } from "./inspection.js";

const TABLE_SIZE = 20;
const GALLERY_SIZE = 12;
const DECISION_COLORS = { recognized: "#15803d", unknown: "#a16207", failed: "#c81e1e" };

let root = null;
let ctx = null;
let generation = 0;
let offset = 0;
let replayUrl = null;
let modelNames = [];       // every taught model (each gets a score bar in the drill-down)

const q = (sel) => (root ? $(sel, root) : null);
const pct = (v) => (v === null || v === undefined ? "-" : `${(v * 100).toFixed(1)} %`);
const sec = (v) => (v === null || v === undefined ? "-" : `${v.toFixed(2)} s`);
const when = (iso) => (iso ? iso.slice(0, 19).replace("T", " ") : "-");

/** The report filters as query parameters (names of the reporting API). */
function filters() {
  const p = new URLSearchParams();
  const from = isoUtc(q("#rep-from").value);
  const to = isoUtc(q("#rep-to").value);
  if (from) p.set("from", from);
  if (to) p.set("to", to);
  for (const [id, key] of [["#rep-cell", "cell"], ["#rep-model", "model"], ["#rep-decision", "decision"], ["#rep-policy", "policy"]]) {
    const v = q(id).value;
    if (v) p.set(key, v);
  }
  return p;
}

/** The same filters for GET /api/inspections (its names: since, until; the running cell). */
function listFilters(extra = {}) {
  const f = filters();
  const p = new URLSearchParams();
  if (f.get("from")) p.set("since", f.get("from"));
  if (f.get("to")) p.set("until", f.get("to"));
  for (const k of ["model", "decision", "policy"]) if (f.get(k)) p.set(k, f.get(k));
  for (const [k, v] of Object.entries(extra)) p.set(k, String(v));
  return p;
}

function say(text) { setText(q("#rep-message"), text || ""); }

// -- summary ---------------------------------------------------------------------------------
function renderSummary(s) {
  const by = s.by_decision || {};
  setText(q("#rep-count"), s.count);
  setText(q("#rep-recognized"), by.recognized ?? 0);
  setText(q("#rep-unknown"), by.unknown ?? 0);
  setText(q("#rep-failed"), by.failed ?? 0);
  setText(q("#rep-yield"), pct(s.yield));
  setText(q("#rep-views"), s.views_mean === null ? "-" : s.views_mean.toFixed(2));
  setText(q("#rep-span"), s.count ? `${when(s.first)} … ${when(s.last)} UTC` : "no inspections match");
  const c = s.cycle_s || {};
  q("#rep-cycle tbody").replaceChildren(el("tr", {}, ...["p50", "p95", "p99", "mean", "max"].map((k) => el("td", {}, sec(c[k])))));
  const stages = Object.entries(s.stages || {}).sort((a, b) => (b[1].mean ?? 0) - (a[1].mean ?? 0));
  const maxStage = Math.max(0.001, ...stages.map(([, v]) => v.p95 ?? v.mean ?? 0));
  bars(q("#rep-stages"), stages.map(([k, v], i) => ({ label: `${k} (p95 ${sec(v.p95)})`, value: v.mean ?? 0, color: COLORS[i % COLORS.length] })),
    { max: maxStage, unit: " s" });
  const models = s.per_model || [];
  const edges = models.length ? models[0].hist.edges : [];
  histogram(q("#rep-scores"), edges, models.map((m, i) => ({ label: `${m.model} (${m.count})`, counts: m.hist.counts, color: COLORS[i % COLORS.length] })),
    { density: false });
  q("#rep-models tbody").replaceChildren(...models.map((m) => el("tr", {},
    el("td", {}, m.model), el("td", {}, m.count), ...["p50", "p95", "min", "max"].map((k) => el("td", {}, m.score[k] === null ? "-" : m.score[k].toFixed(3))))));
}

function renderTimeseries(ts) {
  const items = ts.data.map((d) => ({ label: d.t.slice(5, 13).replace("T", " ") + "h", recognized: d.recognized, unknown: d.unknown, failed: d.failed }));
  columns(q("#rep-throughput"), items, {
    yLabel: "per hour",
    stack: ["recognized", "unknown", "failed"].map((k) => ({ key: k, label: k, color: DECISION_COLORS[k] })),
  });
}

function renderConfusion(c) {
  const table = q("#rep-confusion");
  if (!c.count) { table.replaceChildren(el("caption", { className: "small" }, "No inspection with the simulator's truth matches.")); return; }
  const head = el("tr", {}, el("th", {}, "truth \\ decided"), ...c.labels.map((l) => el("th", {}, l)));
  const rows = c.truth.map((t, i) => el("tr", {}, el("th", {}, t), ...c.matrix[i].map((n, j) => el("td", {
    className: n === 0 ? "zero" : c.labels[j] === t ? "hit" : "miss",
  }, n))));
  table.replaceChildren(el("caption", { className: "small" }, `${c.count} inspections with truth; rows: the object, columns: the decision.`),
    el("thead", {}, head), el("tbody", {}, ...rows));
}

// -- inspections: gallery and table ------------------------------------------------------------
function thumb(r) {
  return el("figure", { className: `frame decision-${r.decision}`, dataset: { id: Number(r.id) }, on: { click: () => openInspection(r.id) } },
    r.images.length ? lazyImage(r.images[0], fetchBlob, { alt: `inspection ${r.id}` }) : el("div", { className: "noimage" }, "no image"),
    el("figcaption", {}, `#${r.id} ${r.decision} ${when(r.started_at).slice(11)}`));
}

async function loadGallery() {
  const gen = generation;
  const wanted = q("#rep-decision").value;
  const kinds = wanted ? [wanted].filter((d) => d !== "recognized") : ["unknown", "failed"];
  const pages = await Promise.all(kinds.map((d) => api("GET", `/inspections?${listFilters({ decision: d, limit: GALLERY_SIZE })}`)));
  if (gen !== generation || !root) return;
  const rows = pages.flatMap((p) => p.data).sort((a, b) => b.id - a.id).slice(0, GALLERY_SIZE);
  const box = q("#rep-gallery");
  releaseImages(box);
  box.replaceChildren(...rows.map(thumb));
  if (!rows.length) box.append(el("p", { className: "small" }, "No unknown or failed inspection matches."));
}

async function loadTable() {
  const gen = generation;
  const page = await api("GET", `/inspections?${listFilters({ limit: TABLE_SIZE, offset })}`);
  if (gen !== generation || !root) return;
  q("#rep-table tbody").replaceChildren(...page.data.map((r) => el("tr", {
    dataset: { id: Number(r.id) }, className: `decision-${r.decision}`, on: { click: () => openInspection(r.id) },
  },
  el("td", {}, `#${r.id}`), el("td", {}, when(r.started_at)), el("td", {}, r.decision), el("td", {}, r.model || ""),
  el("td", {}, r.score === null ? "-" : r.score.toFixed(3)), el("td", {}, r.policy), el("td", {}, r.viewpoints_visited.length),
  el("td", {}, sec(r.duration_s)), el("td", {}, r.truth ? r.truth.name : ""),
  el("td", { className: "rep-bin" }, pickCell(r)))));
  if (!page.count) q("#rep-table tbody").append(el("tr", {}, el("td", { colSpan: 10, className: "small" }, "No inspections match.")));
  const last = Math.min(offset + page.data.length, page.count);
  setText(q("#rep-range"), page.count ? `${offset + 1}-${last} of ${page.count} (this cell)` : "0 of 0");
  q("#rep-prev").disabled = offset === 0;
  q("#rep-next").disabled = last >= page.count;
}

// The bin an inspection's object went to, or what happened to it instead (short, for the table).
function pickCell(r) {
  const p = r.pick_outcome || { outcome: "not_sorted", bin: null };
  if (p.outcome === "placed" || p.outcome === "rejected") return p.bin || p.outcome;
  return p.outcome.replace("_", " ");
}

// -- one inspection ------------------------------------------------------------------------------
async function openInspection(id) {
  const gen = generation;
  let r;
  try { r = await api("GET", `/inspections/${id}`); } catch (e) { say(e.message); return; }
  if (gen !== generation || !root) return;
  const box = q("#rep-detail");
  const opening = box.hidden;
  box.hidden = false;
  for (const tr of root.querySelectorAll("#rep-table tbody tr")) tr.classList.toggle("selected", Number(tr.dataset.id) === r.id);
  setText(q("#rep-detail-title"), `Inspection #${r.id}: ${r.decision}${r.model ? ` ${r.model}` : ""}${r.score === null ? "" : ` (${r.score.toFixed(3)})`}`);
  setText(q("#rep-detail-reason"), `${r.reason} · policy ${r.policy}${r.recipe ? ` · recipe ${r.recipe} (#${r.recipe_id})` : " · no recipe"} · started ${when(r.started_at)} UTC · ${sec(r.duration_s)}`);
  const pick = r.pick_outcome || { outcome: "not_sorted", bin: null, text: "not sorted" };
  const pickNode = q("#rep-detail-pick");
  pickNode.className = `small pick pick-${pick.outcome}${pick.outcome === "not_placed" ? " error" : ""}`;
  pickNode.dataset.outcome = pick.outcome;
  pickNode.dataset.bin = pick.bin || "";
  setText(pickNode, `Pick: ${pick.text}${r.pick && r.pick.how ? ` (${r.pick.how})` : ""}`);
  const views = q("#rep-detail-views");
  releaseImages(views);
  views.replaceChildren(...r.images.map((url, k) => el("figure", {},
    lazyImage(url, fetchBlob, { alt: `inspection ${r.id} view ${k}`, className: "detail-image" }),
    el("figcaption", { className: "small" }, `view ${k + 1}: viewpoint ${r.viewpoints_visited[k] ?? "?"}`))));
  if (!r.images.length) views.append(el("p", { className: "small" }, "No images kept (retention setting)."));
  bars(q("#rep-detail-scores"), everyScore(r.scores, modelNames)
    .map(([m, s]) => ({ label: m, value: s, color: m === r.model ? "#15803d" : "#9ca3af" })), { max: 1 });
  const durations = Object.entries(r.durations || {});
  q("#rep-detail-durations tbody").replaceChildren(...durations.map(([k, v]) => el("tr", {}, el("td", {}, k), el("td", {}, typeof v === "number" ? sec(v) : String(v)))));
  const T = r.pose && r.pose.T_base_obj;
  const poseText = T ? `x ${(T[0][3] * 1000).toFixed(1)} mm, y ${(T[1][3] * 1000).toFixed(1)} mm, z ${(T[2][3] * 1000).toFixed(1)} mm, yaw ${(Math.atan2(T[1][0], T[0][0]) * 180 / Math.PI).toFixed(1)}°` : "no pose";
  const truth = r.truth && r.truth.T_base_obj
    ? ` · truth ${r.truth.name}: x ${(r.truth.T_base_obj[0][3] * 1000).toFixed(1)} mm, y ${(r.truth.T_base_obj[1][3] * 1000).toFixed(1)} mm` : "";
  setText(q("#rep-detail-pose"), `Pose: ${poseText}${truth}`);
  // The drill-down sits below the long lists: bring it into view (it opened off screen).
  if (opening || !inView(box)) box.scrollIntoView({ block: "start", behavior: "smooth" });
  await loadReplay(r.id, gen);
}

/** Whether the top of `node` is on screen. */
function inView(node) {
  const top = node.getBoundingClientRect().top;
  return top >= 0 && top < window.innerHeight - 80;
}

/**
 * The recorded 3D scene: its bytes are fetched with the token, handed to the viser client
 * (served by this server at /replay/, same origin) as a blob URL in ``playbackPath``.
 */
async function loadReplay(id, gen) {
  const frame = q("#rep-replay");
  const status = q("#rep-replay-status");
  if (replayUrl) { URL.revokeObjectURL(replayUrl); replayUrl = null; }
  frame.hidden = true;
  frame.src = "about:blank";
  try {
    const blob = await fetchBlob(`/api/inspections/${id}/scene`);
    if (gen !== generation || !root) return;
    replayUrl = URL.createObjectURL(blob);
    frame.src = `/replay/?playbackPath=${encodeURIComponent(replayUrl)}`;
    frame.hidden = false;
    setText(status, `${(blob.size / 1024).toFixed(0)} kB recorded`);
  } catch (e) {
    setText(status, e instanceof ApiError && e.status === 404 ? "no 3D scene was recorded for this inspection" : `replay unavailable: ${e.message}`);
  }
}

// -- export ----------------------------------------------------------------------------------------
async function exportCsv() {
  say("");
  try {
    const blob = await fetchBlob(`/api/reports/export.csv?${filters()}`);
    const url = URL.createObjectURL(blob);
    const a = el("a", { href: url, download: `inspections-${new Date().toISOString().slice(0, 19).replace(/:/g, "")}.csv` });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10_000);
  } catch (e) { say(e.message); }
}

async function load() {
  const gen = ++generation;
  say("");
  const f = filters();
  // A reversed range is refused here, in the page's own words, before any request: the
  // reports and the inspection list would each refuse it in their API's terms.
  if (f.get("from") && f.get("to") && f.get("from") > f.get("to")) {
    say(`From (${when(f.get("from"))}) is after To (${when(f.get("to"))}): nothing to report.`);
    return;
  }
  try {
    const [summary, ts, conf] = await Promise.all([
      api("GET", `/reports/summary?${f}`),
      api("GET", `/reports/timeseries?${new URLSearchParams([...f, ["bucket", "hour"]])}`),
      api("GET", `/reports/confusion?${f}`),
    ]);
    if (gen !== generation || !root) return;
    renderSummary(summary);
    renderTimeseries(ts);
    renderConfusion(conf);
  } catch (e) { if (gen === generation) say(e.message); }
  // The first refusal stays shown (the lists' would repeat it in other words).
  try { await Promise.all([loadGallery(), loadTable()]); } catch (e) {
    if (gen === generation && !q("#rep-message").textContent) say(e.message);
  }
}

async function loadChoices() {
  try {
    const [cells, models] = await Promise.all([api("GET", "/cells?limit=100"), api("GET", "/models?limit=1000")]);
    if (!root) return;
    modelNames = models.data.map((m) => m.name);
    q("#rep-cell").append(...cells.data.map((c) => el("option", { value: c.name }, c.name)));
    q("#rep-model").append(...models.data.map((m) => el("option", { value: m.name }, m.name)));
  } catch (e) { say(e.message); }
}

function build() {
  const select = (id, first, values) => el("select", { id }, el("option", { value: "" }, first), ...values.map((v) => el("option", { value: v }, v)));
  const form = el("form", { id: "rep-filters", className: "row", on: { submit: (ev) => { ev.preventDefault(); offset = 0; load(); } } },
    el("label", { className: "inline" }, "From ", el("input", { id: "rep-from", type: "datetime-local" })),
    el("label", { className: "inline" }, "To ", el("input", { id: "rep-to", type: "datetime-local" })),
    el("label", { className: "inline" }, "Cell ", select("rep-cell", "all cells", [])),
    el("label", { className: "inline" }, "Model ", select("rep-model", "any model", [])),
    el("label", { className: "inline" }, "Decision ", select("rep-decision", "any", ["recognized", "unknown", "failed"])),
    el("label", { className: "inline" }, "Policy ", select("rep-policy", "any", ["naive", "top-only", "two-views", "best-next"])),
    el("button", { id: "rep-apply", type: "submit", className: "small-button" }, "Apply"),
    el("button", { id: "rep-export", type: "button", className: "small-button", on: { click: exportCsv } }, "Export CSV"));
  const counter = (id, label, cls = "") => el("div", { className: `counter ${cls}` }, el("span", { id }, "-"), el("small", {}, label));
  const totals = el("div", { className: "card rep-totals" },
    el("h2", {}, "Totals"),
    el("div", { className: "counters" }, counter("rep-count", "inspections"), counter("rep-recognized", "recognized", "ok"),
      counter("rep-unknown", "unknown", "unknown"), counter("rep-failed", "failed", "failed"), counter("rep-yield", "yield"), counter("rep-views", "views / object")),
    el("p", { id: "rep-span", className: "small" }),
    el("h3", {}, "Cycle time"),
    el("table", { id: "rep-cycle" }, el("thead", {}, el("tr", {}, ...["p50", "p95", "p99", "mean", "max"].map((h) => el("th", {}, h)))), el("tbody")),
    el("h3", {}, "Stages (mean)"),
    el("canvas", { id: "rep-stages", className: "chart bars" }));
  const charts = el("div", { className: "card rep-charts" },
    el("h2", {}, "Throughput per hour"),
    el("canvas", { id: "rep-throughput", className: "chart" }),
    el("h3", {}, "Scores of the decided model"),
    el("canvas", { id: "rep-scores", className: "chart" }),
    el("table", { id: "rep-models" }, el("thead", {}, el("tr", {}, ...["Model", "Count", "p50", "p95", "min", "max"].map((h) => el("th", {}, h)))), el("tbody")));
  const confusion = el("div", { className: "card rep-confusion" }, el("h2", {}, "Confusion against the simulator's truth"), el("table", { id: "rep-confusion", className: "confusion" }));
  const gallery = el("div", { className: "card rep-gallery" }, el("h2", {}, "Unknown and failed"), el("div", { id: "rep-gallery", className: "filmstrip" }));
  const list = el("div", { className: "card rep-list" },
    el("h2", {}, "Inspections"),
    el("table", { id: "rep-table" }, el("thead", {}, el("tr", {}, ...["Id", "Started (UTC)", "Decision", "Model", "Score", "Policy", "Views", "Cycle", "Truth", "Bin"].map((h) => el("th", {}, h)))), el("tbody")),
    el("p", { className: "row" },
      el("button", { id: "rep-prev", type: "button", className: "small-button", on: { click: () => { offset = Math.max(0, offset - TABLE_SIZE); loadTable(); } } }, "Newer"),
      el("span", { id: "rep-range", className: "small" }),
      el("button", { id: "rep-next", type: "button", className: "small-button", on: { click: () => { offset += TABLE_SIZE; loadTable(); } } }, "Older")));
  const detail = el("div", { id: "rep-detail", className: "card rep-detail", hidden: true },
    el("h2", { id: "rep-detail-title" }, "Inspection"),
    el("p", { id: "rep-detail-reason", className: "small" }),
    el("p", { id: "rep-detail-pick", className: "small pick" }),
    el("div", { id: "rep-detail-views", className: "live-images" }),
    el("p", { id: "rep-detail-pose", className: "small" }),
    el("div", { className: "chart-pair" },
      el("div", {}, el("h3", {}, "Scores ", el("span", { className: "small" }, "every taught model")), el("canvas", { id: "rep-detail-scores", className: "chart bars" })),
      el("div", {}, el("h3", {}, "Durations"), el("table", { id: "rep-detail-durations" }, el("tbody")))),
    el("h3", {}, "3D scene replay ", el("span", { id: "rep-replay-status", className: "small" })),
    el("iframe", { id: "rep-replay", title: "Replay of the recorded 3D scene", hidden: true }));
  return el("section", { id: "reports-page", className: "page" },
    el("div", { className: "card" }, form, el("p", { id: "rep-message", className: "error", role: "status" })),
    el("div", { className: "rep-grid" }, totals, charts, confusion, gallery, list, detail));
}

export default {
  id: "reports",
  title: "Reports",
  minRole: "viewer",

  mount(target, context) {
    root = target;
    ctx = context;
    offset = 0;
    root.append(build());
    loadChoices();
    load();
  },

  unmount() {
    generation++;
    if (root) releaseImages(root);
    if (replayUrl) URL.revokeObjectURL(replayUrl);
    replayUrl = null;
    root = null;
    ctx = null;
  },
};
