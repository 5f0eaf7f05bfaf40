// The Cell page: robot controls, joint read-outs, the 3D view, the camera and the jobs.

import { api, ApiError, fetchBlob, health } from "../api.js";
import { $, applyRoles, el, fromTemplate, releaseBlob, setText, showBlob } from "../dom.js";

const CAMERA_PERIOD_MS = 500;
const MAX_JOBS = 50;
const deg = (rad) => (rad * 180 / Math.PI).toFixed(2);

let root = null;
let ctx = null;
let listeners = [];
let camera = null;
let view3dPort = null;

function listen(target, type, fn) {
  target.addEventListener(type, fn);
  listeners.push(() => target.removeEventListener(type, fn));
}

function showMessage(text) { if (root) setText($("#message", root), text || ""); }
function viewStatus(text) { if (root) setText($("#view3d-status", root), text || ""); }

async function command(method, path, body) {
  showMessage("");
  try { return await api(method, path, body); }
  catch (e) { showMessage(e.message); return null; }
}

// -- robot state ----------------------------------------------------------------------------
function renderState(s, speed) {
  if (!root) return;
  s.q.forEach((v, i) => setText($(`[data-joint="${i}"]`, root), deg(v)));
  s.qd.forEach((v, i) => setText($(`[data-vel="${i}"]`, root), deg(v)));
  const parts = [s.connected ? "connected" : el("span", { className: "alarm" }, "DISCONNECTED")];
  if (s.moving) parts.push("moving");
  if (s.estopped) parts.push(el("span", { className: "alarm" }, "E-STOP ACTIVE"));
  if (s.fault) parts.push(el("span", { className: "alarm" }, String(s.fault)));
  const flags = $("#flags", root);
  flags.replaceChildren();
  parts.forEach((p, i) => { if (i) flags.append(" · "); flags.append(p); });
  const slider = $("#speed", root);
  if (speed !== undefined && document.activeElement !== slider) {
    slider.value = speed;
    setText($("#speed-value", root), Number(speed).toFixed(2));
  }
}

// -- jobs -------------------------------------------------------------------------------------
function renderJob(job) {
  if (!root) return;
  const list = $("#jobs", root);
  const id = String(job.id);
  let li = list.querySelector(`li[data-job="${CSS.escape(id)}"]`);
  if (!li) {
    li = el("li", { id: `job-${id}`, dataset: { job: id } });
    list.prepend(li);
    while (list.children.length > MAX_JOBS) list.lastElementChild.remove();
  }
  li.className = `state-${job.state}`;
  let detail = jobDetail(job);
  if (detail === job.state) detail = "";
  const pct = job.state === "running" && job.progress > 0 ? ` ${Math.round(job.progress * 100)}%` : "";
  li.textContent = `${job.kind} ${job.id}: ${job.state}${pct}${detail ? ` (${detail})` : ""}`;
}

/**
 * What a job line says after its state: the step while it runs, the error when it failed,
 * and what came of it when it is done (never its last progress step: "done (viewpoint 2)").
 */
export function jobDetail(job) {
  if (job.error) return job.error.detail || job.error.error || "";
  if (job.state === "running") return job.message || "";
  const r = job.result || {};
  if (job.state !== "done") return job.message || "";
  if (r.inspection) {
    const i = r.inspection;
    const score = typeof i.score === "number" ? ` ${i.score.toFixed(2)}` : "";
    return `inspection #${i.id}: ${i.decision}${i.model ? ` ${i.model}` : ""}${score}`;
  }
  if (job.kind === "teach" && Array.isArray(r.views)) {
    return `${r.views.length} view(s) stored${r.model && r.model.name ? ` for ${r.model.name}` : ""}`;
  }
  if (typeof r.inspected === "number") {
    const counts = Object.entries(r.decisions || {}).map(([d, n]) => `${n} ${d}`).join(", ");
    return `${r.inspected} inspected${counts ? `: ${counts}` : ""}`;
  }
  return typeof r.reason === "string" ? r.reason : "";
}

async function loadJobs() {
  try {
    const jobs = await api("GET", "/jobs");
    jobs.data.slice(0, 20).reverse().forEach(renderJob);
  } catch (e) { showMessage(e.message); }
}

// -- 3D view ----------------------------------------------------------------------------------
function viserBase(port) { return `${location.protocol}//${location.hostname}:${port}/`; }

/** The viser page URL whose websocket carries a fresh signed link (signs the view in). */
async function signedViewUrl(port) {
  const base = viserBase(port);
  try {
    const r = await api("POST", "/view3d/link");
    if (!r.link) return base;
    const ws = `${location.protocol === "https:" ? "wss" : "ws"}://${location.hostname}:${port}${r.ws_path}`;
    return `${base}?websocket=${encodeURIComponent(ws)}`;
  } catch (e) {
    viewStatus(e instanceof ApiError ? `(${e.message}: sign in inside the view)` : "");
    return base;
  }
}

async function loadView() {
  const h = await health();
  view3dPort = h.viser_port;
  if (!view3dPort) { viewStatus("(not running)"); return; }
  const url = await signedViewUrl(view3dPort);
  if (root) $("#view3d", root).src = url;
}

async function openViewTab(ev) {
  ev.preventDefault();
  if (!view3dPort) return;
  const win = window.open("", "_blank");  // opened now, inside the click (popup rules)
  if (win) win.opener = null;
  const url = await signedViewUrl(view3dPort);
  if (win) win.location.href = url;
}

// -- camera: polled only while the image is on screen and the tab is visible -------------------
class CameraFeed {
  constructor(img, status) {
    this.img = img;
    this.status = status;
    this.onScreen = false;
    this.timer = null;
    this.busy = false;
    this.abort = new AbortController();
    this.observer = new IntersectionObserver((entries) => {
      this.onScreen = entries.some((e) => e.isIntersecting);
      this.update();
    });
    this.observer.observe(img);
    this.onVisibility = () => this.update();
    document.addEventListener("visibilitychange", this.onVisibility);
  }

  get active() { return this.onScreen && document.visibilityState === "visible"; }

  update() {
    if (this.active && this.timer === null && !this.busy) this.tick();
    if (!this.active && this.timer !== null) { clearTimeout(this.timer); this.timer = null; }
  }

  async tick() {
    this.timer = null;
    this.busy = true;
    try {
      const blob = await fetchBlob("/api/camera/frame.jpg", { signal: this.abort.signal });
      showBlob(this.img, blob);
      this.status.textContent = "";
    } catch (e) {
      if (e.name === "AbortError") return;
      this.status.textContent = e instanceof ApiError && e.detail ? e.detail : "unavailable";
    } finally { this.busy = false; }
    if (this.active && !this.abort.signal.aborted) this.timer = setTimeout(() => this.tick(), CAMERA_PERIOD_MS);
  }

  stop() {
    this.abort.abort();
    clearTimeout(this.timer);
    this.timer = null;
    this.observer.disconnect();
    document.removeEventListener("visibilitychange", this.onVisibility);
    releaseBlob(this.img);
  }
}

// -- page -------------------------------------------------------------------------------------
async function start() {
  try {
    const st = await api("GET", "/robot/state");
    renderState(st.state, st.speed);
  } catch (e) { showMessage(e.message); }
  await loadJobs();
  await loadView().catch((e) => viewStatus(e.message));
}

export default {
  id: "cell",
  title: "Cell",
  minRole: "viewer",

  mount(target, context) {
    ctx = context;
    root = target;
    root.append(fromTemplate("cell-template"));
    applyRoles(root, ctx.role, ctx.rank);
    $("#estop", root).addEventListener("click", () => command("POST", "/robot/estop"));
    $("#home", root).addEventListener("click", () => command("POST", "/robot/home", { speed: Number($("#speed", root).value) }));
    $("#stop", root).addEventListener("click", () => command("POST", "/robot/stop"));
    $("#reset", root).addEventListener("click", () => command("POST", "/robot/reset"));
    $("#speed", root).addEventListener("change", () => {
      const v = Number($("#speed", root).value);
      setText($("#speed-value", root), v.toFixed(2));
      command("PUT", "/robot/speed", { speed: v });
    });
    $("#view3d-link", root).addEventListener("click", openViewTab);
    listen(ctx.live, "state", (ev) => renderState(ev.detail.state, ev.detail.speed));
    listen(ctx.live, "job", (ev) => renderJob(ev.detail));
    listen(ctx.live, "open", (ev) => {
      if (!ev.detail.reconnected) return;
      loadJobs();  // catch up on what happened while the link was down
      loadView().catch(() => {});  // the server may have restarted: a fresh view link
    });
    camera = new CameraFeed($("#camera", root), $("#camera-status", root));
    start();
  },

  unmount() {
    listeners.forEach((off) => off());
    listeners = [];
    if (camera) camera.stop();
    camera = null;
    if (root) {
      const frame = $("#view3d", root);
      if (frame) frame.src = "about:blank";  // closes the view's websocket
    }
    root = null;
    ctx = null;
  },
};
