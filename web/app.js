// VisionCell console: sign in with a token, follow the cell live, drive the arm.
"use strict";

const $ = (sel) => document.querySelector(sel);
const deg = (rad) => (rad * 180 / Math.PI).toFixed(2);
let token = sessionStorage.getItem("visioncell-token") || "";
let role = "";
let ws = null;
let cameraTimer = null;

async function api(method, path, body) {
  const opts = { method, headers: { Authorization: `Bearer ${token}` } };
  if (body !== undefined) {
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body);
  }
  const res = await fetch(`/api${path}`, opts);
  const text = await res.text();
  const data = text ? JSON.parse(text) : {};
  if (!res.ok) {
    const err = new Error(data.detail || res.statusText);
    err.status = res.status;
    err.code = data.error;
    throw err;
  }
  return data;
}

function showMessage(text) { $("#message").textContent = text || ""; }

async function signIn(candidate) {
  token = candidate;
  const me = await api("GET", "/users/me");
  sessionStorage.setItem("visioncell-token", token);
  role = me.role;
  $("#who").textContent = `${me.name} (${me.role})`;
  $("#calib-auto").hidden = role !== "engineer";
  $("#login-page").hidden = true;
  $("#nav").hidden = false;
  $("#logout").hidden = false;
  showPage(location.hash === "#calibration" ? "calibration" : "cell");
  await startCell();
}

function signOut() {
  sessionStorage.removeItem("visioncell-token");
  token = "";
  if (ws) ws.close();
  if (cameraTimer) clearInterval(cameraTimer);
  location.reload();
}

async function startCell() {
  const health = await (await fetch("/api/health")).json();
  if (health.viser_port) {
    const url = `${location.protocol}//${location.hostname}:${health.viser_port}/`;
    $("#view3d").src = url;
    $("#view3d-link").href = url;
  }
  const st = await api("GET", "/robot/state");
  renderState(st.state, st.speed);
  $("#speed").value = st.speed;
  $("#speed-value").textContent = Number(st.speed).toFixed(2);
  const jobs = await api("GET", "/jobs");
  jobs.data.slice(0, 20).reverse().forEach(renderJob);
  connectLive();
  refreshCamera();
  cameraTimer = setInterval(refreshCamera, 500);
}

function renderState(s, speed) {
  s.q.forEach((v, i) => { $(`[data-joint="${i}"]`).textContent = deg(v); });
  s.qd.forEach((v, i) => { $(`[data-vel="${i}"]`).textContent = deg(v); });
  const flags = [];
  flags.push(s.connected ? "connected" : "<span class=alarm>DISCONNECTED</span>");
  if (s.moving) flags.push("moving");
  if (s.estopped) flags.push("<span class=alarm>E-STOP ACTIVE</span>");
  if (s.fault) flags.push(`<span class=alarm>${s.fault}</span>`);
  $("#flags").innerHTML = flags.join(" · ");
  if (speed !== undefined && document.activeElement !== $("#speed")) {
    $("#speed").value = speed;
    $("#speed-value").textContent = Number(speed).toFixed(2);
  }
}

function renderJob(job) {
  let li = document.getElementById(`job-${job.id}`);
  if (!li) {
    li = document.createElement("li");
    li.id = `job-${job.id}`;
    $("#jobs").prepend(li);
  }
  li.className = `state-${job.state}`;
  let detail = job.error ? job.error.detail : (job.result && job.result.reason) || job.message || "";
  if (detail === job.state) detail = "";
  li.textContent = `${job.kind} ${job.id}: ${job.state}${detail ? ` (${detail})` : ""}`;
}

function connectLive() {
  const proto = location.protocol === "https:" ? "wss" : "ws";
  ws = new WebSocket(`${proto}://${location.host}/api/ws`);
  ws.onopen = () => ws.send(JSON.stringify({ token }));
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "hello") { $("#conn").textContent = "live"; $("#conn").className = "badge on"; }
    else if (msg.type === "state") renderState(msg.state, msg.speed);
    else if (msg.type === "job") {
      renderJob(msg.job);
      if (msg.job.kind === "calibrate" && msg.job.state !== "running" && !$("#calibration-page").hidden) loadSessions();
    }
  };
  ws.onclose = (ev) => {
    $("#conn").textContent = "offline";
    $("#conn").className = "badge off";
    if (ev.code === 4401) { signOut(); return; }
    if (token) setTimeout(connectLive, 1000);
  };
}

async function refreshCamera() {
  try {
    const res = await fetch("/api/camera/frame.jpg", { headers: { Authorization: `Bearer ${token}` } });
    if (res.ok) {
      const url = URL.createObjectURL(await res.blob());
      const img = $("#camera");
      const old = img.src;
      img.src = url;
      if (old.startsWith("blob:")) URL.revokeObjectURL(old);
      $("#camera-status").textContent = "";
    } else {
      const data = await res.json();
      $("#camera-status").textContent = data.detail || "unavailable";
    }
  } catch (e) { $("#camera-status").textContent = "unavailable"; }
}

async function command(method, path, body) {
  showMessage("");
  try { return await api(method, path, body); }
  catch (e) { showMessage(`${e.message}`); return null; }
}

// -- pages ----------------------------------------------------------------------------
function showPage(name) {
  document.querySelectorAll("#nav .tab").forEach((a) => a.classList.toggle("active", a.dataset.page === name));
  $("#cell-page").hidden = name !== "cell";
  $("#calibration-page").hidden = name !== "calibration";
  if (name === "calibration") loadSessions();
}

// -- calibration ----------------------------------------------------------------------
let calibSession = null;

function el(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined) e.textContent = text;
  if (cls) e.className = cls;
  return e;
}

function messageRow(text, span) {
  const tr = el("tr");
  const td = el("td", text, "small");
  td.colSpan = span;
  tr.append(td);
  return tr;
}

function boardText(b) {
  if (b.type === "charuco") return `ChArUco ${b.squares_x}x${b.squares_y}, ${(b.square_m * 1000).toFixed(1)} mm`;
  return `${b.cols}x${b.rows}, ${(b.square_m * 1000).toFixed(1)} mm`;
}

async function loadSessions() {
  try {
    const [list, active] = await Promise.all([api("GET", "/calibration/sessions"), api("GET", "/calibration/active")]);
    const body = $("#calib-sessions tbody");
    body.replaceChildren();
    list.data.forEach((s) => {
      const tr = el("tr");
      tr.dataset.id = s.id;
      if (calibSession === s.id) tr.classList.add("selected");
      tr.append(el("td", String(s.id)), el("td", s.kind), el("td", boardText(s.board)),
        el("td", `${s.accepted_count} / ${s.sample_count}`), el("td", s.status, `status-${s.status}`),
        el("td", s.created_at.slice(0, 19).replace("T", " ")));
      tr.addEventListener("click", () => selectSession(s.id));
      body.append(tr);
    });
    if (!list.count) body.append(messageRow("No calibration sessions yet.", 6));
    const parts = Object.entries(active).map(([k, v]) => `${k}: ${v ? `#${v.id} (${v.rms_px.toFixed(3)} px)` : "none"}`);
    $("#calib-active").textContent = `Active: ${parts.join(", ")}`;
    if (calibSession !== null) await selectSession(calibSession);
  } catch (e) { $("#calib-active").textContent = e.message; }
}

function calibSummary(c) {
  const p = c.parameters;
  if (c.kind === "intrinsic") return `fx ${p.K[0][0].toFixed(1)}, fy ${p.K[1][1].toFixed(1)} px`;
  const t = p.T_ee_cam.slice(0, 3).map((r) => (r[3] * 1000).toFixed(1));
  return `t_ee_cam (${t.join(", ")}) mm`;
}

async function selectSession(id) {
  calibSession = id;
  document.querySelectorAll("#calib-sessions tbody tr").forEach((tr) => tr.classList.toggle("selected", Number(tr.dataset.id) === id));
  const d = await api("GET", `/calibration/sessions/${id}`);
  $("#calib-detail").hidden = false;
  $("#calib-detail-title").textContent = `Session ${id}: ${d.session.kind}, ${boardText(d.session.board)} (${d.session.status})`;
  const body = $("#calib-calibrations tbody");
  body.replaceChildren();
  d.calibrations.forEach((c) => {
    const tr = el("tr");
    const view = el("button", "Report", "small-button");
    view.addEventListener("click", () => showReport(c.id));
    const cell = el("td");
    cell.append(view);
    if (role === "engineer" && !c.active) {
      const act = el("button", "Activate", "small-button activate");
      act.dataset.id = c.id;
      act.addEventListener("click", () => activateCalibration(c.id));
      cell.append(act);
    }
    tr.append(el("td", `#${c.id} ${c.kind}`), el("td", c.rms_px === null ? "-" : c.rms_px.toFixed(3)),
      el("td", calibSummary(c)), el("td", c.active ? "active" : "", c.active ? "status-active" : ""), cell);
    body.append(tr);
  });
  if (!d.calibrations.length) body.append(messageRow("Not solved yet.", 5));
  const ul = $("#calib-samples");
  ul.replaceChildren();
  d.samples.forEach((s) => ul.append(el("li", `${s.index} ${s.name}: ${s.accepted ? "" : "rejected, "}${s.reason}`, s.accepted ? "" : "rejected")));
}

async function authImage(img, url) {
  const res = await fetch(url, { headers: { Authorization: `Bearer ${token}` } });
  if (!res.ok) { img.hidden = true; return; }
  const old = img.src;
  img.src = URL.createObjectURL(await res.blob());
  img.hidden = false;
  if (old.startsWith("blob:")) URL.revokeObjectURL(old);
}

async function showReport(id) {
  const r = await api("GET", `/calibration/calibrations/${id}/report`);
  const s = r.summary;
  $("#calib-report").hidden = false;
  $("#calib-report-title").textContent = `Report of calibration ${id} (${r.calibration.kind})`;
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
  $("#calib-summary").textContent = lines.join("\n");
  await authImage($("#plot-residuals"), r.plots.residuals);
  await authImage($("#plot-coverage"), r.plots.coverage);
  if (r.plots.consistency) await authImage($("#plot-consistency"), r.plots.consistency);
  else $("#plot-consistency").hidden = true;
}

async function activateCalibration(id) {
  $("#calib-message").textContent = "";
  try {
    await api("POST", `/calibration/calibrations/${id}/activate`);
    await loadSessions();
  } catch (e) { $("#calib-message").textContent = e.message; }
}

// -- automatic calibration (engineers) -------------------------------------------------
let autoTimer = null;

function showAutoJob(job) {
  const bar = $("#calib-auto-progress");
  bar.hidden = false;
  bar.value = job.progress;
  let text = `${job.state}: ${job.message || ""}`;
  if (job.error) text = `${job.state}: ${job.error.detail}`;
  else if (job.state === "done" && job.result) {
    const r = job.result;
    text = `done: session ${r.session_id}, calibration #${r.calibration_id}, RMS ${r.rms_px.toFixed(3)} px, ${r.accepted} views${r.active ? ", active" : ""}`;
  }
  $("#calib-auto-status").textContent = text;
  $("#calib-auto-start").disabled = job.state === "running";
}

async function followAutoJob(id) {
  clearTimeout(autoTimer);
  try {
    const { job } = await api("GET", `/jobs/${id}`);
    showAutoJob(job);
    if (job.state === "running") autoTimer = setTimeout(() => followAutoJob(id), 500);
    else loadSessions();
  } catch (e) { $("#calib-auto-status").textContent = e.message; $("#calib-auto-start").disabled = false; }
}

async function startAutoCalibration(ev) {
  ev.preventDefault();
  $("#calib-auto-status").textContent = "planning views...";
  $("#calib-auto-start").disabled = true;
  try {
    const { job } = await api("POST", "/calibration/auto", {
      board: $("#calib-auto-board").value,
      n_poses: Number($("#calib-auto-poses").value),
      activate: $("#calib-auto-activate").checked,
    });
    showAutoJob(job);
    followAutoJob(job.id);
  } catch (e) {
    $("#calib-auto-status").textContent = e.message;
    $("#calib-auto-start").disabled = false;
  }
}

$("#login-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  $("#login-error").textContent = "";
  try { await signIn($("#token").value.trim()); }
  catch (e) { $("#login-error").textContent = e.status === 401 ? "That token is not valid." : e.message; }
});
$("#logout").addEventListener("click", signOut);
document.querySelectorAll("#nav .tab").forEach((a) => a.addEventListener("click", () => showPage(a.dataset.page)));
$("#calib-refresh").addEventListener("click", loadSessions);
$("#calib-auto-form").addEventListener("submit", startAutoCalibration);
$("#estop").addEventListener("click", () => command("POST", "/robot/estop"));
$("#home").addEventListener("click", () => command("POST", "/robot/home", { speed: Number($("#speed").value) }));
$("#stop").addEventListener("click", () => command("POST", "/robot/stop"));
$("#reset").addEventListener("click", () => command("POST", "/robot/reset"));
$("#speed").addEventListener("change", () => {
  $("#speed-value").textContent = Number($("#speed").value).toFixed(2);
  command("PUT", "/robot/speed", { speed: Number($("#speed").value) });
});

if (token) signIn(token).catch(() => { sessionStorage.removeItem("visioncell-token"); token = ""; });
