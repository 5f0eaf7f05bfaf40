// DOM helpers: every text goes in as a text node, never as HTML.

/** The first element matching `sel` under `root` (default: the document). */
export const $ = (sel, root = document) => root.querySelector(sel);

/** All elements matching `sel` under `root`, as an array. */
export const $$ = (sel, root = document) => Array.from(root.querySelectorAll(sel));

/**
 * Build an element: `el("td", {className: "x", dataset: {id: 3}}, "text", child, ...)`.
 * Strings and numbers become text nodes; null/undefined/false children are skipped.
 */
export function el(tag, props = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(props || {})) {
    if (value === undefined || value === null) continue;
    if (key === "dataset") Object.assign(node.dataset, value);
    else if (key === "on") for (const [ev, fn] of Object.entries(value)) node.addEventListener(ev, fn);
    else if (key === "className" || key === "id" || key === "title" || key === "hidden"
      || key === "colSpan" || key === "href" || key === "type" || key === "value") node[key] = value;
    else node.setAttribute(key, String(value));
  }
  append(node, ...children);
  return node;
}

/** Append children (strings become text nodes). */
export function append(node, ...children) {
  for (const child of children.flat()) {
    if (child === undefined || child === null || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

/** Set the text of the element matching `sel` under `root`. */
export function setText(sel, text, root = document) {
  const node = typeof sel === "string" ? $(sel, root) : sel;
  if (node) node.textContent = text === undefined || text === null ? "" : String(text);
}

/** A deep copy of the `<template id=...>` content (static markup from index.html). */
export function fromTemplate(id) {
  const tpl = document.getElementById(id);
  if (!(tpl instanceof HTMLTemplateElement)) throw new Error(`no template #${id}`);
  return tpl.content.cloneNode(true);
}

/**
 * The next step for a user who lacks `need`: what it allows (`what`, e.g. "Teaching models"),
 * the role the user holds (`have`) and how to sign in with a token of that role.
 */
export function roleHint(what, need, have) {
  return el("p", { className: "role-hint", dataset: { needs: need } },
    `${what} needs the ${need} role; you are signed in as ${have || "nobody"}. `,
    "To do it, sign out and sign in with an ", el("strong", {}, need), " token: on the cell's computer ",
    el("code", {}, `visioncell user add NAME --role ${need}`),
    " prints one (an engineer can also issue one in the API, POST /api/users). On a demo cell "
      + "started on this computer with make run, the token it prints is an engineer's.");
}

/**
 * Hide every `[data-min-role]` element under `root` that `role` may not use; where such an
 * element names what it is for (`data-role-hint`), a {@link roleHint} takes its place.
 */
export function applyRoles(root, role, rank) {
  for (const node of $$("[data-min-role]", root)) {
    const denied = rank(role) < rank(node.dataset.minRole);
    node.hidden = denied;
    const next = node.nextElementSibling;
    const hint = next && next.classList.contains("role-hint") ? next : null;
    if (denied && node.dataset.roleHint && !hint) node.after(roleHint(node.dataset.roleHint, node.dataset.minRole, role));
    else if (!denied && hint) hint.remove();
  }
}

/**
 * Show a fetched image blob in `img`, freeing the previous object URL.
 * Returns the new URL.
 */
export function showBlob(img, blob) {
  const url = URL.createObjectURL(blob);
  const old = img.src;
  img.src = url;
  if (old.startsWith("blob:")) URL.revokeObjectURL(old);
  return url;
}

/** Free an image's object URL (on unmount). */
export function releaseBlob(img) {
  if (img && img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
}

let lazyObserver = null;

/**
 * An `<img loading="lazy">` for an API image: the bearer-token request (which the browser's
 * own lazy loading cannot make) starts only when the image comes near the viewport.
 * `fetchBlob(url)` is the caller's authenticated fetch; when it fails, a `fallback` text
 * (if given) takes the image's place.
 */
export function lazyImage(url, fetchBlob, { alt = "", className = "", fallback = "" } = {}) {
  const img = el("img", { alt, className, loading: "lazy", decoding: "async", dataset: { src: url } });
  if (!lazyObserver) {
    lazyObserver = new IntersectionObserver((entries) => {
      for (const e of entries) {
        if (!e.isIntersecting) continue;
        lazyObserver.unobserve(e.target);
        const node = e.target;
        node._fetch(node.dataset.src).then((blob) => {
          if (node.isConnected) showBlob(node, blob);
          node.dataset.loaded = "1";
        }).catch(() => {
          node.classList.add("broken");
          node.dataset.loaded = "0";
          if (node._fallback && node.isConnected) node.replaceWith(el("span", { className: `${node.className} fallback` }, node._fallback));
        });
      }
    }, { rootMargin: "200px" });
  }
  img._fetch = fetchBlob;
  img._fallback = fallback;
  lazyObserver.observe(img);
  return img;
}

/** Free the object URLs of every image under `root` (on unmount or before a re-render). */
export function releaseImages(root) {
  if (!root) return;
  for (const img of root.querySelectorAll("img")) {
    if (lazyObserver) lazyObserver.unobserve(img);
    releaseBlob(img);
  }
}

/** A datetime-local input's value as an ISO string in UTC ("" when empty or invalid). */
export function isoUtc(localValue) {
  if (!localValue) return "";
  const t = new Date(localValue);
  return Number.isFinite(t.getTime()) ? t.toISOString() : "";
}
