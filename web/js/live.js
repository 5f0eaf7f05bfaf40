// The live link: an EventTarget over the /api/ws WebSocket, reconnecting with backoff.
//
// Events: "open" and "close" (link up/down), "hello" (detail: {user, role, driver}),
// "state" (detail: {state, speed}), "job" (detail: the job, on start, progress and end),
// "inspection" (detail: an ended inspection's id, decision, model, score, viewpoints, ...),
// "camera" (detail: the camera's health), "estop" (detail: {active, conveyors}),
// "unauthorized" (the server closed with 4401: the token is no longer valid).

const MIN_DELAY_MS = 500;
const MAX_DELAY_MS = 10000;

export class Live extends EventTarget {
  constructor() {
    super();
    this.ws = null;
    this.token = "";
    this.timer = null;
    this.delay = MIN_DELAY_MS;
    this.connected = false;
    this.everConnected = false;
  }

  /** Connect with `token`; reconnects until `close()`. */
  start(token) {
    this.stop();
    this.token = token;
    this._connect();
  }

  /** Close the link for good (sign-out). */
  stop() {
    this.token = "";
    clearTimeout(this.timer);
    this.timer = null;
    if (this.ws) {
      this.ws.onclose = null;
      this.ws.close();
      this.ws = null;
    }
    if (this.connected) this._emit("close", {});
    this.connected = false;
  }

  _emit(type, detail) { this.dispatchEvent(new CustomEvent(type, { detail })); }

  _connect() {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    const ws = new WebSocket(`${proto}://${location.host}/api/ws`);
    this.ws = ws;
    ws.onopen = () => ws.send(JSON.stringify({ token: this.token }));
    ws.onmessage = (ev) => {
      let msg;
      try { msg = JSON.parse(ev.data); } catch (_) { return; }
      if (msg.type === "hello") {
        const again = this.everConnected;
        this.connected = true;
        this.everConnected = true;
        this.delay = MIN_DELAY_MS;
        this._emit("open", { reconnected: again, ...msg });
        this._emit("hello", msg);
      } else if (msg.type === "state") this._emit("state", msg);
      else if (msg.type === "job" && msg.job) this._emit("job", msg.job);
      else if (msg.type === "inspection" && msg.inspection) this._emit("inspection", msg.inspection);
      else if (msg.type === "camera" && msg.camera) this._emit("camera", msg.camera);
      else if (msg.type === "estop") this._emit("estop", msg);
    };
    ws.onclose = (ev) => {
      const was = this.connected;
      this.connected = false;
      this.ws = null;
      if (was) this._emit("close", { code: ev.code });
      if (ev.code === 4401) { this._emit("unauthorized", {}); return; }
      if (!this.token) return;
      // Exponential backoff with jitter, so a restarted server is not hit by every console at once.
      const wait = this.delay * (0.5 + Math.random());
      this.delay = Math.min(this.delay * 2, MAX_DELAY_MS);
      this.timer = setTimeout(() => this._connect(), wait);
    };
  }
}
