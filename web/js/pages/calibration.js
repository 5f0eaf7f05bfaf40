// The Calibration page: sessions, their calibrations and samples, reports with plots,
// Activate and the automatic run for engineers (followed through the live link's job events).

import { api, fetchBlob } from "../api.js";
import { $, $$, applyRoles, el, fromTemplate, releaseBlob, setText, showBlob } from "../dom.js";

let root = null;
let ctx = null;
let listeners = [];
let selected = null;
let autoJobId = null;
let generation = 0;

function listen(target, type, fn) {
  target.addEventListener(type, fn);
  listeners.push(() => target.removeEventListener(type, fn));
}

const q = (sel) => (root ? $(sel, root) : null);

function messageRow(text, span) {
  return el("tr", {}, el("td", { className: "small", colSpan: span }, text));
}

function boardText(b) {
  if (b.type === "charuco") return `ChArUco ${b.squares_x}x${b.squares_y}, ${(b.square_m * 1000).toFixed(1)} mm`;
  return `${b.cols}x${b.rows}, ${(b.square_m * 1000).toFixed(1)} mm`;
}

function calibSummary(c) {
  const p = c.parameters;
  if (c.kind === "intrinsic") return `fx ${p.K[0][0].toFixed(1)}, fy ${p.K[1][1].toFixed(1)} px`;
  const t = p.T_ee_cam.slice(0, 3).map((r) => (r[3] * 1000).toFixed(1));
  return `t_ee_cam (${t.join(", ")}) mm`;
}

async function loadSessions() {
  const gen = generation;
  try {
    const [list, active] = await Promise.all([api("GET", "/calibration/sessions"), api("GET", "/calibration/active")]);
    if (gen !== generation) return;
    const body = q("#calib-sessions tbody");
    body.replaceChildren();
    for (const s of list.data) {
      const tr = el("tr", { dataset: { id: Number(s.id) }, on: { click: () => selectSession(s.id) } },
        el("td", {}, String(s.id)), el("td", {}, s.kind), el("td", {}, boardText(s.board)),
        el("td", {}, `${s.accepted_count} / ${s.sample_count}`), el("td", { className: `status-${s.status}` }, s.status),
        el("td", {}, s.created_at.slice(0, 19).replace("T", " ")));
      if (selected === s.id) tr.classList.add("selected");
      body.append(tr);
    }
    if (!list.count) body.append(messageRow("No calibration sessions yet.", 6));
    const parts = Object.entries(active).map(([k, v]) => `${k}: ${v ? `#${v.id} (${v.rms_px.toFixed(3)} px)` : "none"}`);
    setText(q("#calib-active"), `Active: ${parts.join(", ")}`);
    if (selected !== null) await selectSession(selected);
  } catch (e) { setText(q("#calib-active"), e.message); }
}

async function selectSession(id) {
  const gen = generation;
  selected = id;
  $$("#calib-sessions tbody tr", root).forEach((tr) => tr.classList.toggle("selected", Number(tr.dataset.id) === id));
  let d;
  try { d = await api("GET", `/calibration/sessions/${id}`); }
  catch (e) { setText(q("#calib-message"), e.message); return; }
  if (gen !== generation) return;
  q("#calib-detail").hidden = false;
  setText(q("#calib-detail-title"), `Session ${id}: ${d.session.kind}, ${boardText(d.session.board)} (${d.session.status})`);
  const body = q("#calib-calibrations tbody");
  body.replaceChildren();
  for (const c of d.calibrations) {
    const actions = el("td", {}, el("button", { className: "small-button", on: { click: () => showReport(c.id) } }, "Report"));
    if (ctx.can("engineer") && !c.active) {
      actions.append(el("button", { className: "small-button activate", dataset: { id: Number(c.id) }, on: { click: () => activate(c.id) } }, "Activate"));
    }
    body.append(el("tr", {}, el("td", {}, `#${c.id} ${c.kind}`), el("td", {}, c.rms_px === null ? "-" : c.rms_px.toFixed(3)),
      el("td", {}, calibSummary(c)), el("td", { className: c.active ? "status-active" : "" }, c.active ? "active" : ""), actions));
  }
  if (!d.calibrations.length) body.append(messageRow("Not solved yet.", 5));
  q("#calib-samples").replaceChildren(...d.samples.map((s) =>
    el("li", { className: s.accepted ? "" : "rejected" }, `${s.index} ${s.name}: ${s.accepted ? "" : "rejected, "}${s.reason}`)));
}

async function authImage(img, url) {
  try {
    const blob = await fetchBlob(url);
    if (!root) return;
    showBlob(img, blob);
    img.hidden = false;
  } catch (_) { img.hidden = true; }
}

async function showReport(id) {
  const gen = generation;
  let r;
  try { r = await api("GET", `/calibration/calibrations/${id}/report`); }
  catch (e) { setText(q("#calib-message"), e.message); return; }
  if (gen !== generation) return;
  const s = r.summary;
  q("#calib-report").hidden = false;
  setText(q("#calib-report-title"), `Report of calibration ${id} (${r.calibration.kind})`);
  const lines = [];
  if (r.calibration.kind === "intrinsic") {
    lines.push(`RMS ${s.rms_px.toFixed(3)} px, model ${s.model}, ${s.views_used} images used, ${s.views_rejected} rejected`);
    for (const [k, v] of Object.entries(s.intrinsics)) lines.push(`${k} = ${v.value.toFixed(2)} ± ${v.std.toFixed(2)} px`);
    for (const [k, v] of Object.entries(s.distortion)) lines.push(`${k} = ${v.value.toFixed(5)} ± ${v.std.toFixed(5)}`);
  } else {
    const c = s.consistency;
    lines.push(`T_ee_cam by ${s.method}${s.refined ? " + refinement" : ""}: t = (${s.translation_mm.map((v) => v.toFixed(2)).join(", ")}) mm`);
    lines.push(`board pose consistency: RMS ${c.translation_rms_mm.toFixed(3)} mm (max ${c.translation_max_mm.toFixed(3)}), RMS ${c.rotation_rms_deg.toFixed(4)} deg (max ${c.rotation_max_deg.toFixed(4)})`);
    lines.push(`reprojection RMS ${s.rms_px.toFixed(3)} px`);
    s.warnings.forEach((w) => lines.push(`warning: ${w}`));
  }
  s.rejected.forEach((x) => lines.push(`rejected ${x.name}: ${x.reason}`));
  setText(q("#calib-summary"), lines.join("\n"));
  await authImage(q("#plot-residuals"), r.plots.residuals);
  if (gen !== generation) return;
  await authImage(q("#plot-coverage"), r.plots.coverage);
  if (gen !== generation) return;
  if (r.plots.consistency) await authImage(q("#plot-consistency"), r.plots.consistency);
  else q("#plot-consistency").hidden = true;
}

async function activate(id) {
  setText(q("#calib-message"), "");
  try {
    await api("POST", `/calibration/calibrations/${id}/activate`);
    await loadSessions();
  } catch (e) { setText(q("#calib-message"), e.message); }
}

// -- automatic calibration: progress arrives as live job events (no polling) -----------------
function showAutoJob(job) {
  if (!root) return;
  const bar = q("#calib-auto-progress");
  bar.hidden = false;
  bar.value = job.progress;
  let text = `${job.state}: ${job.message || ""}`;
  if (job.error) text = `${job.state}: ${job.error.detail}`;
  else if (job.state === "done" && job.result) {
    const r = job.result;
    text = `done: session ${r.session_id}, calibration #${r.calibration_id}, RMS ${r.rms_px.toFixed(3)} px, ${r.accepted} views${r.active ? ", active" : ""}`;
  }
  setText(q("#calib-auto-status"), text);
  q("#calib-auto-start").disabled = job.state === "running";
}

function onJob(job) {
  if (job.kind !== "calibrate") return;
  if (job.id === autoJobId) showAutoJob(job);
  if (job.state !== "running") loadSessions();
}

async function catchUp() {
  // The link was down: the job's end may have been missed.
  if (autoJobId === null) return loadSessions();
  try { showAutoJob((await api("GET", `/jobs/${autoJobId}`)).job); } catch (_) { /* gone */ }
  return loadSessions();
}

async function startAuto(ev) {
  ev.preventDefault();
  setText(q("#calib-auto-status"), "planning views...");
  q("#calib-auto-start").disabled = true;
  try {
    const { job } = await api("POST", "/calibration/auto", {
      board: q("#calib-auto-board").value,
      n_poses: Number(q("#calib-auto-poses").value),
      activate: q("#calib-auto-activate").checked,
    });
    autoJobId = job.id;
    showAutoJob(job);
  } catch (e) {
    setText(q("#calib-auto-status"), e.message);
    if (root) q("#calib-auto-start").disabled = false;
  }
}

export default {
  id: "calibration",
  title: "Calibration",
  minRole: "viewer",

  mount(target, context) {
    generation += 1;
    ctx = context;
    root = target;
    root.append(fromTemplate("calibration-template"));
    applyRoles(root, ctx.role, ctx.rank);
    q("#calib-refresh").addEventListener("click", loadSessions);
    q("#calib-auto-form").addEventListener("submit", startAuto);
    listen(ctx.live, "job", (ev) => onJob(ev.detail));
    listen(ctx.live, "open", (ev) => { if (ev.detail.reconnected) catchUp(); });
    catchUp();
  },

  unmount() {
    generation += 1;
    listeners.forEach((off) => off());
    listeners = [];
    if (root) $$("img", root).forEach(releaseBlob);
    root = null;
    ctx = null;
  },
};
