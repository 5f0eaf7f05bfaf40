// VisionCell console: sign-in, the page registry and the hash router (Back/Forward work).
//
// Each page module exports a default object {id, title, minRole, mount(root, ctx), unmount()};
// the router mounts the page named by the URL hash (#cell, #inspection, #models, #recipes, #recognise, #reports, #calibration, #audit) into #page-root and
// unmounts the previous one, which stops its timers and streams.

import { api, ApiError, onTokenRefused, setToken } from "./api.js";
import { $, el, setText } from "./dom.js";
import { Live } from "./live.js";
import cellPage from "./pages/cell.js";
import calibrationPage from "./pages/calibration.js";
import auditPage from "./pages/audit.js";
import modelsPage from "./pages/models.js";
import recipesPage from "./pages/recipes.js";
import inspectionPage from "./pages/inspection.js";
import reportsPage from "./pages/reports.js";
import recognisePage from "./pages/recognise.js";

const TOKEN_KEY = "visioncell-token";
const RANKS = { viewer: 1, operator: 2, engineer: 3 };

/** Rank of a role name (0 for anything unknown). */
export const rank = (role) => RANKS[role] || 0;

/** The pages, in menu order. */
export const PAGES = [cellPage, inspectionPage, modelsPage, recipesPage, recognisePage, reportsPage, calibrationPage, auditPage];

const live = new Live();
let user = null;
let current = null;

const ctx = {
  api,
  live,
  get user() { return user; },
  get role() { return user ? user.role : ""; },
  rank,
  /** True if the signed-in user holds at least `role`. */
  can(role) { return user !== null && rank(user.role) >= rank(role); },
};

function allowedPages() { return PAGES.filter((p) => ctx.can(p.minRole)); }

function pageForHash() {
  const id = location.hash.replace(/^#/, "");
  const pages = allowedPages();
  return pages.find((p) => p.id === id) || pages[0] || null;
}

function route() {
  if (!user) return;
  const page = pageForHash();
  if (page && location.hash !== `#${page.id}`) history.replaceState(null, "", `#${page.id}`);
  if (page === current) return;
  if (current) {
    try { current.unmount(); } catch (e) { console.error(e); }
  }
  const root = $("#page-root");
  root.replaceChildren();
  current = page;
  for (const a of document.querySelectorAll("#nav-pages a")) a.classList.toggle("active", a.dataset.page === page?.id);
  if (!page) return;
  document.title = `${page.title} · VisionCell`;
  page.mount(root, ctx);
}

function buildNav() {
  const links = allowedPages().map((p) => el("a", { href: `#${p.id}`, className: "tab", dataset: { page: p.id } }, p.title));
  $("#nav-pages").replaceChildren(...links);
}

async function signIn(candidate) {
  setToken(candidate);
  const me = await api("GET", "/users/me");
  sessionStorage.setItem(TOKEN_KEY, candidate);
  user = { name: me.name, role: me.role };
  setText("#who", `${me.name} (${me.role})`);
  $("#login-page").hidden = true;
  $("#nav").hidden = false;
  $("#logout").hidden = false;
  buildNav();
  live.start(candidate);
  route();
}

function signOut() {
  if (current) {
    try { current.unmount(); } catch (e) { console.error(e); }
    current = null;
  }
  live.stop();
  sessionStorage.removeItem(TOKEN_KEY);
  setToken("");
  user = null;
  $("#page-root").replaceChildren();
  $("#nav-pages").replaceChildren();
  $("#nav").hidden = true;
  $("#logout").hidden = true;
  setText("#who", "");
  $("#login-page").hidden = false;
  $("#token").value = "";
}

live.addEventListener("open", () => { setText("#conn", "live"); $("#conn").className = "badge on"; });
live.addEventListener("close", () => { setText("#conn", "offline"); $("#conn").className = "badge off"; });
/** The message of a session the server ended (shown on the sign-in form). */
export const SESSION_ENDED = "Signed out: the cell no longer accepts this token (revoked, expired, "
  + "or the cell restarted and issued a new one). Sign in with a current token: make run prints "
  + "the built-in user's; visioncell user add NAME --role ROLE makes another.";

/** The server refused the token in use: back to the sign-in form at once, every request stopped. */
function sessionEnded() {
  if (!user) return;  // a sign-in attempt: the form says why itself
  signOut();
  setText("#login-error", SESSION_ENDED);
}

onTokenRefused(sessionEnded);
live.addEventListener("unauthorized", sessionEnded);

window.addEventListener("hashchange", route);
$("#logout").addEventListener("click", signOut);
$("#login-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  setText("#login-error", "");
  try { await signIn($("#token").value.trim()); }
  catch (e) {
    setToken("");
    setText("#login-error", e instanceof ApiError && e.status === 401 ? "That token is not valid." : e.message);
  }
});

const saved = sessionStorage.getItem(TOKEN_KEY);
if (saved) {
  signIn(saved).catch((e) => {
    sessionStorage.removeItem(TOKEN_KEY);
    setToken("");
    if (e instanceof ApiError && e.status === 401) setText("#login-error", SESSION_ENDED);
  });
}
