// VisionCell console: sign in with a token, follow the cell live, drive the arm.
"use strict";

const $ = (sel) => document.querySelector(sel);
const deg = (rad) => (rad * 180 / Math.PI).toFixed(2);
let token = sessionStorage.getItem("visioncell-token") || "";
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
  $("#who").textContent = `${me.name} (${me.role})`;
  $("#login-page").hidden = true;
  $("#cell-page").hidden = false;
  $("#nav").hidden = false;
  $("#logout").hidden = false;
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
    else if (msg.type === "job") renderJob(msg.job);
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

$("#login-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  $("#login-error").textContent = "";
  try { await signIn($("#token").value.trim()); }
  catch (e) { $("#login-error").textContent = e.status === 401 ? "That token is not valid." : e.message; }
});
$("#logout").addEventListener("click", signOut);
$("#estop").addEventListener("click", () => command("POST", "/robot/estop"));
$("#home").addEventListener("click", () => command("POST", "/robot/home", { speed: Number($("#speed").value) }));
$("#stop").addEventListener("click", () => command("POST", "/robot/stop"));
$("#reset").addEventListener("click", () => command("POST", "/robot/reset"));
$("#speed").addEventListener("change", () => {
  $("#speed-value").textContent = Number($("#speed").value).toFixed(2);
  command("PUT", "/robot/speed", { speed: Number($("#speed").value) });
});

if (token) signIn(token).catch(() => { sessionStorage.removeItem("visioncell-token"); token = ""; });
