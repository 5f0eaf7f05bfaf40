// The Recipes page: the cell's named inspection configurations (GET /api/recipes) and the
// active one.  Everyone reads; an operator selects the active recipe (a line changeover:
// a run going takes it from its next object); an engineer creates, edits and deletes
// recipes (the server enforces the roles too).  Every text goes in as a text node.

import { api } from "../api.js";
import { $, applyRoles, el, setText } from "../dom.js";

const POLICIES = ["two-views", "best-next", "top-only", "naive"];

let root = null;
let ctx = null;
let generation = 0;
let recipes = [];
let editing = null;        // the recipe being edited (API form), null: a new one
let modelNames = [];       // every model's name (the models a recipe may name)
let binNames = [];         // the cell's bins (empty: a cell without bins)

const q = (sel) => (root ? $(sel, root) : null);

/** Show `text` in the message line `sel`: in red, or in green when `ok`. */
function say(sel, text, ok = false) {
  const node = q(sel);
  if (!node) return;
  setText(node, text || "");
  node.classList.toggle("ok", ok);
}

async function call(msgSel, method, path, body) {
  say(msgSel, "");
  try { return await api(method, path, body); }
  catch (e) { say(msgSel, e.message); return null; }
}

/** One line saying what a recipe does. */
export function recipeSummary(r) {
  const threshold = r.threshold === null ? "automatic threshold" : `threshold ${r.threshold.toFixed(2)}`;
  const models = r.models.length ? r.models.join(", ") : "every model";
  const bins = Object.entries(r.bins).map(([m, b]) => `${m} → ${b}`).join(", ");
  return `${r.policy}, up to ${r.max_views} view(s), sorting ${r.sort ? "on" : "off"}, ${threshold}, `
    + `belt ${r.belt_mode || "as it is"}; ${models}${bins ? `; bins: ${bins}` : ""}`;
}

function showActive(active) {
  const box = q("#recipe-active");
  if (!box) return;
  if (!active) {
    box.replaceChildren(el("strong", {}, "No active recipe"), ": inspections use the options they are started with (the defaults otherwise).");
    return;
  }
  box.replaceChildren(el("strong", { id: "recipe-active-name" }, `${active.name} (no. ${active.number})`), ": ", recipeSummary(active));
}

async function loadRecipes() {
  const gen = generation;
  const page = await call("#recipes-message", "GET", "/recipes?limit=1000");
  if (!page || gen !== generation || !root) return;
  recipes = page.data;
  showActive(page.active);
  const body = q("#recipes-table tbody");
  body.replaceChildren(...recipes.map((r) => el("tr", { dataset: { id: Number(r.id), name: r.name }, className: r.active ? "selected" : "" },
    el("td", {}, String(r.number)),
    el("td", {}, r.name, r.active ? el("span", { className: "badge on" }, " active") : ""),
    el("td", { className: "small" }, recipeSummary(r)),
    el("td", {},
      el("button", { type: "button", className: "small-button recipe-activate", disabled: r.active || !ctx.can("operator") ? "" : null,
        hidden: !ctx.can("operator"), on: { click: () => activate(r) } }, "Activate"),
      ctx.can("engineer") ? el("button", { type: "button", className: "small-button recipe-edit", on: { click: () => edit(r) } }, "Edit") : ""))));
  if (!recipes.length) body.append(el("tr", {}, el("td", { colSpan: 4, className: "small" }, "No recipes yet.")));
}

async function activate(r) {
  const done = await call("#recipes-message", "POST", `/recipes/${r.id}/activate`, { reason: "selected in the console" });
  if (done) { say("#recipes-message", `${done.name} is the active recipe`, true); await loadRecipes(); }
}

// -- the editor (engineer) ------------------------------------------------------------------
function fillModels(selectedModels, bins) {
  const list = q("#recipe-models");
  list.replaceChildren(...modelNames.map((name) => el("label", { className: "inline recipe-model" },
    el("input", { type: "checkbox", value: name, dataset: { model: name } }), ` ${name} `,
    binNames.length ? el("select", { className: "recipe-bin", dataset: { model: name } },
      el("option", { value: "" }, "its part's bin"), ...binNames.map((b) => el("option", { value: b }, b))) : "")));
  for (const box of list.querySelectorAll("input[type=checkbox]")) box.checked = selectedModels.includes(box.value);
  for (const sel of list.querySelectorAll("select.recipe-bin")) sel.value = bins[sel.dataset.model] || "";
  if (!modelNames.length) list.append(el("span", { className: "small" }, "No models yet: every model taught later is in play."));
}

function edit(r) {
  editing = r;
  setText(q("#recipe-form-title"), r ? `Edit recipe ${r.name}` : "New recipe");
  q("#recipe-name").value = r ? r.name : "";
  q("#recipe-number").value = r ? String(r.number) : String(Math.max(0, ...recipes.map((x) => x.number)) + 1);
  q("#recipe-policy").value = r ? r.policy : "two-views";
  q("#recipe-max-views").value = String(r ? r.max_views : 3);
  q("#recipe-sort").checked = r ? r.sort : false;
  q("#recipe-threshold").value = r && r.threshold !== null ? String(r.threshold) : "";
  q("#recipe-belt").value = r && r.belt_mode ? r.belt_mode : "";
  q("#recipe-description").value = r ? r.description : "";
  fillModels(r ? r.models : [], r ? r.bins : {});
  q("#recipe-delete").hidden = !r;
  say("#recipe-message", "");
}

function formBody() {
  const text = q("#recipe-threshold").value.trim();
  const threshold = text === "" ? null : Number(text);
  if (threshold !== null && (!Number.isFinite(threshold) || threshold < 0 || threshold > 1)) {
    throw new Error(`threshold must be a number in [0, 1] or empty (automatic), got ${JSON.stringify(text)}`);
  }
  const number = Number(q("#recipe-number").value);
  if (!Number.isInteger(number) || number < 1 || number > 9999) throw new Error(`number must be a whole number 1..9999, got ${q("#recipe-number").value}`);
  const models = Array.from(root.querySelectorAll("#recipe-models input[type=checkbox]")).filter((b) => b.checked).map((b) => b.value);
  const bins = {};
  for (const sel of root.querySelectorAll("#recipe-models select.recipe-bin")) {
    if (sel.value && (!models.length || models.includes(sel.dataset.model))) bins[sel.dataset.model] = sel.value;
  }
  return {
    name: q("#recipe-name").value.trim(), number, policy: q("#recipe-policy").value,
    max_views: Number(q("#recipe-max-views").value), sort: q("#recipe-sort").checked, threshold,
    belt_mode: q("#recipe-belt").value || null, models, bins,
    description: q("#recipe-description").value, reason: "saved in the console",
  };
}

async function save(ev) {
  ev.preventDefault();
  let body;
  try { body = formBody(); } catch (e) { say("#recipe-message", e.message); return; }
  const r = editing
    ? await call("#recipe-message", "PATCH", `/recipes/${editing.id}`, body)
    : await call("#recipe-message", "POST", "/recipes", body);
  if (!r) return;
  say("#recipe-message", `recipe ${r.name} saved`, true);
  editing = r;
  q("#recipe-delete").hidden = false;
  setText(q("#recipe-form-title"), `Edit recipe ${r.name}`);
  await loadRecipes();
}

async function remove() {
  if (!editing || !window.confirm(`Delete recipe ${editing.name}?`)) return;
  const r = await call("#recipe-message", "DELETE", `/recipes/${editing.id}?reason=console`);
  if (r === null) return;
  edit(null);
  await loadRecipes();
}

async function loadChoices() {
  const gen = generation;
  const [models, bins] = await Promise.all([
    api("GET", "/models?limit=1000").catch(() => ({ data: [] })),
    api("GET", "/recipes/bins").catch(() => ({ data: [] })),
  ]);
  if (gen !== generation || !root) return;
  modelNames = models.data.map((m) => m.name);
  binNames = bins.data.map((b) => b.name);
  edit(editing);
}

function build() {
  const list = el("div", { className: "card recipes-list" },
    el("h2", {}, "Recipes ", el("button", { type: "button", className: "small-button", on: { click: loadRecipes } }, "Refresh")),
    el("p", { id: "recipe-active", role: "status" }),
    el("table", { id: "recipes-table" },
      el("thead", {}, el("tr", {}, ...["No.", "Name", "What it does", ""].map((h) => el("th", {}, h)))),
      el("tbody")),
    el("p", { className: "small" }, "Runs and single inspections use the active recipe; options an operator sets on the "
      + "Inspection page override it. Selecting another recipe during a run applies from the next object."),
    el("p", { id: "recipes-message", className: "error", role: "status" }));
  const editor = el("div", { id: "recipe-editor", className: "card recipe-editor", dataset: { minRole: "engineer", roleHint: "Creating and editing recipes" } },
    el("h2", { id: "recipe-form-title" }, "New recipe"),
    el("form", { id: "recipe-form", novalidate: "", on: { submit: save } },
      el("div", { className: "row" },
        el("label", { className: "inline" }, "Name ", el("input", { id: "recipe-name", type: "text", required: "", maxlength: 64 })),
        el("label", { className: "inline" }, "Number ", el("input", { id: "recipe-number", type: "number", min: 1, max: 9999, step: 1, required: "" }))),
      el("div", { className: "row" },
        el("label", { className: "inline" }, "Policy ", el("select", { id: "recipe-policy" }, ...POLICIES.map((p) => el("option", { value: p }, p)))),
        el("label", { className: "inline" }, "Max views ", el("select", { id: "recipe-max-views" }, ...[3, 2, 1].map((v) => el("option", { value: v }, String(v))))),
        el("label", { className: "inline" }, el("input", { id: "recipe-sort", type: "checkbox" }), " sort into bins")),
      el("div", { className: "row" },
        el("label", { className: "inline" }, "Threshold ", el("input", { id: "recipe-threshold", type: "number", min: 0, max: 1, step: 0.01, placeholder: "automatic" })),
        el("label", { className: "inline" }, "Belt ", el("select", { id: "recipe-belt" },
          el("option", { value: "" }, "as it is"), el("option", { value: "index" }, "index"), el("option", { value: "continuous" }, "continuous")))),
      el("p", { className: "small" }, "Models in play (none ticked: every model) and the bin each goes to:"),
      el("div", { id: "recipe-models", className: "row" }),
      el("div", { className: "row" },
        el("input", { id: "recipe-description", type: "text", placeholder: "description", maxlength: 2000, size: 40 })),
      el("div", { className: "row" },
        el("button", { id: "recipe-save", type: "submit", className: "small-button" }, "Save"),
        el("button", { id: "recipe-new", type: "button", className: "small-button", on: { click: () => edit(null) } }, "New"),
        el("button", { id: "recipe-delete", type: "button", className: "small-button", hidden: true, on: { click: remove } }, "Delete"))),
    el("p", { id: "recipe-message", className: "error", role: "status" }));
  return el("section", { id: "recipes-page", className: "page" }, el("div", { className: "models-grid" }, list, editor));
}

export default {
  id: "recipes",
  title: "Recipes",
  minRole: "viewer",

  mount(target, context) {
    root = target;
    ctx = context;
    generation++;
    editing = null;
    root.append(build());
    applyRoles(root, ctx.role, ctx.rank);
    loadRecipes();
    if (ctx.can("engineer")) loadChoices();
  },

  unmount() {
    generation++;
    root = null;
    ctx = null;
    editing = null;
  },
};
