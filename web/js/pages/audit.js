// The Audit page (engineer): who changed which threshold, model, trained view, active
// calibration, user or token, when, from what to what and why (GET /api/audit).
// Read only: the API has no way to edit the trail.  Every text goes in as a text node.

import { $, el, isoUtc, setText } from "../dom.js";

const KINDS = ["threshold", "model", "view", "negative", "calibration", "user", "token", "estop", "recipe"];
const PAGE_SIZE = 50;

let root = null;
let ctx = null;
let offset = 0;
let generation = 0;

const q = (sel) => (root ? $(sel, root) : null);

/** JSON text with a space after each comma and colon between members (strings untouched). */
function spacedJson(v) {
  if (Array.isArray(v)) return `[${v.map(spacedJson).join(", ")}]`;
  if (v !== null && typeof v === "object") {
    return `{${Object.entries(v).map(([k, x]) => `${JSON.stringify(k)}: ${spacedJson(x)}`).join(", ")}}`;
  }
  return JSON.stringify(v) ?? "null";
}

/**
 * A JSON value as short text for a table cell ("-" for none), spaced between members so
 * that a long value wraps between them, not inside a word or a number.
 */
function valueText(v) {
  if (v === null || v === undefined) return "-";
  const text = spacedJson(v);
  return text.length > 300 ? `${text.slice(0, 297)}...` : text;
}

function filterQuery() {
  const params = new URLSearchParams();
  const kind = q("#audit-kind").value;
  const entity = q("#audit-entity").value.trim();
  const actor = q("#audit-actor").value.trim();
  const since = isoUtc(q("#audit-since").value);
  const until = isoUtc(q("#audit-until").value);
  if (kind) params.set("kind", kind);
  if (entity) params.set("entity_id", entity.slice(0, 64));
  if (actor) params.set("actor", actor.slice(0, 64));
  if (since) params.set("since", since);
  if (until) params.set("until", until);
  params.set("limit", String(PAGE_SIZE));
  params.set("offset", String(offset));
  return params.toString();
}

function row(e) {
  return el("tr", { dataset: { id: Number(e.id), kind: e.kind, entity: e.entity_id } },
    el("td", {}, e.at.slice(0, 19).replace("T", " ")),
    el("td", {}, `${e.actor} (${e.actor_role})`),
    el("td", {}, e.kind),
    el("td", {}, e.entity_id),
    el("td", {}, e.action),
    el("td", { className: "audit-value" }, valueText(e.old)),
    el("td", { className: "audit-value" }, valueText(e.new)),
    el("td", {}, e.reason || ""));
}

async function load() {
  const gen = ++generation;
  setText(q("#audit-message"), "");
  try {
    const page = await ctx.api("GET", `/audit?${filterQuery()}`);
    if (gen !== generation || !root) return;
    const body = q("#audit-table tbody");
    body.replaceChildren(...page.data.map(row));
    if (!page.count) body.append(el("tr", {}, el("td", { className: "small", colSpan: 8 }, "No changes match.")));
    const last = Math.min(offset + page.data.length, page.count);
    setText(q("#audit-range"), page.count ? `${offset + 1}-${last} of ${page.count}` : "0 of 0");
    q("#audit-prev").disabled = offset === 0;
    q("#audit-next").disabled = last >= page.count;
  } catch (e) {
    if (gen === generation && root) setText(q("#audit-message"), e.message);
  }
}

function build() {
  const kind = el("select", { id: "audit-kind" }, el("option", { value: "" }, "any kind"),
    ...KINDS.map((k) => el("option", { value: k }, k)));
  const form = el("form", { id: "audit-filters", className: "row",
    on: { submit: (ev) => { ev.preventDefault(); offset = 0; load(); } } },
  el("label", {}, "Kind ", kind),
  el("label", {}, "Entity id ", el("input", { id: "audit-entity", type: "text", maxlength: 64, size: 8 })),
  el("label", {}, "Actor ", el("input", { id: "audit-actor", type: "text", maxlength: 64, size: 12 })),
  el("label", {}, "From ", el("input", { id: "audit-since", type: "datetime-local" })),
  el("label", {}, "To ", el("input", { id: "audit-until", type: "datetime-local" })),
  el("button", { id: "audit-apply", type: "submit", className: "small-button" }, "Apply"));
  const table = el("table", { id: "audit-table" },
    el("thead", {}, el("tr", {}, ...["When (UTC)", "Who", "Kind", "Id", "Action", "Old", "New", "Reason"]
      .map((h) => el("th", {}, h)))),
    el("tbody"));
  const pager = el("p", { className: "row" },
    el("button", { id: "audit-prev", type: "button", className: "small-button",
      on: { click: () => { offset = Math.max(0, offset - PAGE_SIZE); load(); } } }, "Newer"),
    el("span", { id: "audit-range", className: "small" }),
    el("button", { id: "audit-next", type: "button", className: "small-button",
      on: { click: () => { offset += PAGE_SIZE; load(); } } }, "Older"));
  return el("section", { id: "audit-page", className: "page" },
    el("div", { className: "card" },
      el("h2", {}, "Audit trail"),
      el("p", { className: "small" },
        "Every change of a threshold, model, trained view, active calibration, user or token, and every emergency stop, newest first. "
        + "The trail cannot be edited."),
      form, table, pager,
      el("p", { id: "audit-message", className: "error", role: "status" })));
}

export default {
  id: "audit",
  title: "Audit",
  minRole: "engineer",
  mount(rootEl, context) {
    root = rootEl;
    ctx = context;
    offset = 0;
    root.append(build());
    load();
  },
  unmount() {
    generation++;
    root = null;
    ctx = null;
  },
};
