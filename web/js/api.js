// REST client: the bearer token on every call, the JSON error body surfaced as ApiError.
//
// A 401 to a call made with the current token means the session is over (the token was
// revoked, expired, or the server restarted and revoked its start-up token): the token is
// forgotten at once, so no later call sends it again (each would count as a failed sign-in
// against this address and soon block everyone behind it), and the handler registered with
// onTokenRefused() returns the console to the sign-in form.  Without a token no call is made.

let token = "";
let refusedHandler = null;

/** Remember the token used by every later call. */
export function setToken(value) { token = value || ""; }

/** Call `fn(detail)` when the server refuses the token in use (once per token). */
export function onTokenRefused(fn) { refusedHandler = fn; }

/** The server answered `res` to a call made with `sent`: end the session on a 401. */
export function checkRefused(res, sent) {
  if (res.status !== 401 || !sent || sent !== token) return;
  token = "";
  if (refusedHandler) refusedHandler();
}

function signedOut() { return new ApiError(401, "signed_out", "signed out: sign in again"); }

/** The current token ("" when signed out). */
export function getToken() { return token; }

/** An API refusal: `status` (HTTP), `code` (the body's "error") and the `detail` text. */
export class ApiError extends Error {
  constructor(status, code, detail) {
    super(detail || `HTTP ${status}`);
    this.name = "ApiError";
    this.status = status;
    this.code = code || "";
    this.detail = detail || "";
  }
}

async function errorOf(res) {
  const text = await res.text();
  let body = null;
  try { body = text ? JSON.parse(text) : null; } catch (_) { body = null; }
  if (body && typeof body === "object" && !Array.isArray(body)) {
    const detail = typeof body.detail === "string" ? body.detail : JSON.stringify(body.detail ?? "");
    return new ApiError(res.status, body.error, detail || res.statusText);
  }
  return new ApiError(res.status, "", text.slice(0, 200) || res.statusText);
}

function headers(extra = {}) {
  return token ? { Authorization: `Bearer ${token}`, ...extra } : { ...extra };
}

/** Call `METHOD /api{path}` with an optional JSON body; resolves to the parsed JSON answer. */
export async function api(method, path, body) {
  const opts = { method, headers: headers() };
  if (body !== undefined) {
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body);
  }
  const sent = token;
  if (!sent) throw signedOut();
  let res;
  try { res = await fetch(`/api${path}`, opts); }
  catch (e) { throw new ApiError(0, "network", "the cell does not answer"); }
  if (!res.ok) { checkRefused(res, sent); throw await errorOf(res); }
  const text = await res.text();
  return text ? JSON.parse(text) : {};
}

/** GET a binary resource (an image) with the token; resolves to a Blob. */
export async function fetchBlob(url, { signal } = {}) {
  const sent = token;
  if (!sent) throw signedOut();
  const res = await fetch(url, { headers: headers(), signal });
  if (!res.ok) { checkRefused(res, sent); throw await errorOf(res); }
  return res.blob();
}

/** `GET /api/health` (no token needed). */
export async function health() {
  const res = await fetch("/api/health");
  if (!res.ok) throw await errorOf(res);
  return res.json();
}
