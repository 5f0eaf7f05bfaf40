// Small canvas charts (no library, nothing from a CDN): horizontal bars, histograms, lines.
//
// Each function draws into a <canvas> sized by CSS (its client width and height), at the
// device pixel ratio, and returns nothing.  Labels are drawn as canvas text, never as HTML.

const INK = "#1d2330";
const MUTED = "#6b7280";
const GRID = "#e5e7eb";
export const COLORS = ["#e07a1e", "#2563eb", "#15803d", "#c81e1e", "#7c3aed", "#0891b2", "#a16207", "#be185d"];
const FONT = "12px system-ui, sans-serif";

/** A 2D context scaled to CSS pixels, with the canvas' CSS size {w, h}. */
function setup(canvas, minH = 120) {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(120, canvas.clientWidth || 300);
  const h = Math.max(minH, canvas.clientHeight || minH);
  canvas.width = Math.round(w * dpr);
  canvas.height = Math.round(h * dpr);
  const g = canvas.getContext("2d");
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, w, h);
  g.font = FONT;
  g.textBaseline = "middle";
  return { g, w, h };
}

function empty(g, w, h, text) {
  g.fillStyle = MUTED;
  g.textAlign = "center";
  g.fillText(text, w / 2, h / 2);
}

/** An axis top for counts whose four tick steps are whole numbers. */
const countTop = (top) => Math.max(4, Math.ceil((top * 1.1) / 4) * 4);

const fmt = (v) => (Math.abs(v) >= 100 ? v.toFixed(0) : Math.abs(v) >= 10 ? v.toFixed(1) : v.toFixed(2));

/**
 * Horizontal bars: `items` = [{label, value, color?, mark?}], values in [0, max].  `mark`
 * draws a vertical line (a threshold) at that value across all bars; an item's own `mark`
 * draws a tick on its bar only (its own threshold).
 */
export function bars(canvas, items, { max = 1, mark = null, unit = "" } = {}) {
  const rowH = 22;
  canvas.style.height = `${Math.max(60, items.length * rowH + 26)}px`;
  const { g, w, h } = setup(canvas, 60);
  if (!items.length) { empty(g, w, h, "no data"); return; }
  const left = Math.min(160, Math.max(...items.map((it) => g.measureText(it.label).width)) + 10);
  const right = 54;
  const span = Math.max(1e-9, max);
  const x = (v) => left + (w - left - right) * Math.min(1, Math.max(0, v / span));
  items.forEach((it, i) => {
    const y = 8 + i * rowH;
    g.fillStyle = INK;
    g.textAlign = "right";
    g.fillText(it.label.length > 24 ? `${it.label.slice(0, 23)}…` : it.label, left - 6, y + rowH / 2 - 2);
    g.fillStyle = GRID;
    g.fillRect(left, y + 2, w - left - right, rowH - 8);
    g.fillStyle = it.color || COLORS[0];
    g.fillRect(left, y + 2, x(it.value) - left, rowH - 8);
    g.fillStyle = INK;
    g.textAlign = "left";
    g.fillText(`${fmt(it.value)}${unit}`, w - right + 6, y + rowH / 2 - 2);
    if (it.mark !== undefined && it.mark !== null && Number.isFinite(it.mark)) {
      g.fillStyle = "#c81e1e";
      g.fillRect(x(it.mark) - 1.5, y, 3, rowH - 4);
    }
  });
  if (mark !== null && Number.isFinite(mark)) {
    g.strokeStyle = "#c81e1e";
    g.setLineDash([4, 3]);
    g.beginPath();
    g.moveTo(x(mark), 4);
    g.lineTo(x(mark), h - 14);
    g.stroke();
    g.setLineDash([]);
    g.fillStyle = "#c81e1e";
    g.textAlign = "center";
    g.fillText(`threshold ${fmt(mark)}`, x(mark), h - 7);
  }
}

/** Axes with ticks; returns the data-to-pixel maps. */
function axes(g, w, h, { x0, x1, y0, y1, xLabel = "", yLabel = "", xTicks = null }) {
  const L = 46, R = 12, T = 10, B = 34;
  const sx = (v) => L + ((v - x0) / (x1 - x0 || 1)) * (w - L - R);
  const sy = (v) => h - B - ((v - y0) / (y1 - y0 || 1)) * (h - T - B);
  g.strokeStyle = GRID;
  g.fillStyle = MUTED;
  g.lineWidth = 1;
  for (let k = 0; k <= 4; k++) {
    const v = y0 + ((y1 - y0) * k) / 4;
    g.beginPath(); g.moveTo(L, sy(v)); g.lineTo(w - R, sy(v)); g.stroke();
    g.textAlign = "right";
    g.fillText(fmt(v), L - 4, sy(v));
  }
  const ticks = xTicks || [0, 1, 2, 3, 4].map((k) => ({ v: x0 + ((x1 - x0) * k) / 4, label: fmt(x0 + ((x1 - x0) * k) / 4) }));
  g.textAlign = "center";
  for (const t of ticks) g.fillText(t.label, sx(t.v), h - B + 12);
  g.fillStyle = INK;
  if (xLabel) g.fillText(xLabel, (L + w - R) / 2, h - 8);
  if (yLabel) {
    g.save(); g.translate(10, (T + h - B) / 2); g.rotate(-Math.PI / 2); g.fillText(yLabel, 0, 0); g.restore();
  }
  return { sx, sy, L, R, T, B };
}

function legend(g, w, series) {
  let x = w - 12;
  g.textAlign = "right";
  for (const s of [...series].reverse()) {
    if (!s.label) continue;
    g.fillStyle = INK;
    g.fillText(s.label, x, 10);
    x -= g.measureText(s.label).width + 4;
    g.fillStyle = s.color;
    g.fillRect(x - 10, 5, 10, 10);
    x -= 22;
  }
}

/**
 * Histograms sharing bin `edges` (n + 1 values): `series` = [{counts (n ints), color,
 * label}], drawn as outlined, translucent bars; `mark` draws a threshold line; `density`
 * normalises each series to sum 1.
 */
export function histogram(canvas, edges, series, { mark = null, density = false, xLabel = "score" } = {}) {
  const { g, w, h } = setup(canvas, 140);
  const shown = series.map((s) => {
    const total = s.counts.reduce((a, b) => a + b, 0);
    return { ...s, values: s.counts.map((c) => (density && total ? c / total : c)) };
  });
  const top = Math.max(0, ...shown.flatMap((s) => s.values));
  if (!edges.length || top === 0) { empty(g, w, h, "no data"); return; }
  const a = axes(g, w, h, { x0: edges[0], x1: edges[edges.length - 1], y0: 0, y1: density ? top * 1.1 : countTop(top),
    xLabel, yLabel: density ? "share" : "count" });
  shown.forEach((s, si) => {
    const color = s.color || COLORS[si % COLORS.length];
    s.values.forEach((v, i) => {
      if (!v) return;
      const x = a.sx(edges[i]), x2 = a.sx(edges[i + 1]), y = a.sy(v);
      g.globalAlpha = 0.35;
      g.fillStyle = color;
      g.fillRect(x, y, x2 - x, a.sy(0) - y);
      g.globalAlpha = 1;
      g.strokeStyle = color;
      g.strokeRect(x + 0.5, y + 0.5, x2 - x - 1, a.sy(0) - y - 1);
    });
  });
  if (mark !== null && Number.isFinite(mark)) {
    g.strokeStyle = "#c81e1e";
    g.setLineDash([4, 3]);
    g.beginPath(); g.moveTo(a.sx(mark), a.T); g.lineTo(a.sx(mark), a.sy(0)); g.stroke();
    g.setLineDash([]);
  }
  legend(g, w, shown.map((s, si) => ({ label: s.label, color: s.color || COLORS[si % COLORS.length] })));
}

/**
 * Lines: `series` = [{points: [[x, y], ...], color, label, dots?}].  `x0..x1`, `y0..y1`
 * default to the data's extent; `xTicks` = [{v, label}] replaces the numeric ticks.
 */
export function lines(canvas, series, opts = {}) {
  const { g, w, h } = setup(canvas, 140);
  const pts = series.flatMap((s) => s.points).filter((p) => Number.isFinite(p[0]) && Number.isFinite(p[1]));
  if (!pts.length) { empty(g, w, h, "no data"); return; }
  const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
  let x0 = opts.x0 ?? Math.min(...xs), x1 = opts.x1 ?? Math.max(...xs);
  if (x0 === x1) { x0 -= 1; x1 += 1; }
  const y0 = opts.y0 ?? Math.min(0, ...ys);
  let y1 = opts.y1 ?? Math.max(...ys) * 1.1;
  if (y1 <= y0) y1 = y0 + 1;
  const a = axes(g, w, h, { x0, x1, y0, y1, xLabel: opts.xLabel, yLabel: opts.yLabel, xTicks: opts.xTicks });
  series.forEach((s, si) => {
    const color = s.color || COLORS[si % COLORS.length];
    g.strokeStyle = color;
    g.fillStyle = color;
    g.lineWidth = 2;
    g.beginPath();
    s.points.forEach(([x, y], i) => (i ? g.lineTo(a.sx(x), a.sy(y)) : g.moveTo(a.sx(x), a.sy(y))));
    g.stroke();
    if (s.dots) for (const [x, y] of s.points) { g.beginPath(); g.arc(a.sx(x), a.sy(y), 3, 0, 2 * Math.PI); g.fill(); }
    g.lineWidth = 1;
  });
  if (opts.mark) {
    const [mx, my] = opts.mark;
    g.fillStyle = "#c81e1e";
    g.beginPath(); g.arc(a.sx(mx), a.sy(my), 5, 0, 2 * Math.PI); g.fill();
  }
  legend(g, w, series.map((s, si) => ({ label: s.label, color: s.color || COLORS[si % COLORS.length] })));
}

/**
 * Vertical bars over categories: `items` = [{label, value}] (e.g. inspections per hour);
 * `stack` = [{key, color, label}] stacks item[key] values instead of one value.
 */
export function columns(canvas, items, { stack = null, yLabel = "" } = {}) {
  const { g, w, h } = setup(canvas, 140);
  const total = (it) => (stack ? stack.reduce((a, s) => a + (it[s.key] || 0), 0) : it.value || 0);
  const top = Math.max(0, ...items.map(total));
  if (!items.length || top === 0) { empty(g, w, h, "no data"); return; }
  const every = Math.max(1, Math.ceil(items.length / 8));
  const ticks = items.map((it, i) => ({ v: i + 0.5, label: i % every ? "" : it.label }));
  const a = axes(g, w, h, { x0: 0, x1: items.length, y0: 0, y1: countTop(top), yLabel, xTicks: ticks });
  const bw = Math.max(1, (a.sx(1) - a.sx(0)) * 0.8);
  items.forEach((it, i) => {
    let base = 0;
    for (const s of stack || [{ key: "value", color: COLORS[0] }]) {
      const v = it[s.key] || 0;
      if (!v) continue;
      g.fillStyle = s.color;
      g.fillRect(a.sx(i + 0.5) - bw / 2, a.sy(base + v), bw, a.sy(base) - a.sy(base + v));
      base += v;
    }
  });
  if (stack) legend(g, w, stack);
}

/**
 * The ROC of a score threshold from genuine and impostor scores: points (FAR, 1 - FRR) for
 * every threshold t (a score >= t is accepted).  Returns [[far, tar, t], ...] from t = 1 to 0.
 */
export function rocPoints(genuine, impostor) {
  const ts = [...new Set([...genuine, ...impostor, 0, 1])].sort((p, q) => q - p);
  const g = [...genuine].sort((p, q) => q - p);
  const im = [...impostor].sort((p, q) => q - p);
  let gi = 0, ii = 0;
  const out = [];
  for (const t of ts) {
    while (gi < g.length && g[gi] >= t) gi++;
    while (ii < im.length && im[ii] >= t) ii++;
    out.push([im.length ? ii / im.length : 0, g.length ? gi / g.length : 0, t]);
  }
  return out;
}

/** Counts of `values` in the bins of `edges` (the last bin includes its right edge). */
export function binCounts(values, edges) {
  const n = edges.length - 1;
  const counts = new Array(n).fill(0);
  for (const v of values) {
    if (!Number.isFinite(v) || v < edges[0] || v > edges[n]) continue;
    let k = Math.floor(((v - edges[0]) / (edges[n] - edges[0])) * n);
    if (k >= n) k = n - 1;
    counts[k]++;
  }
  return counts;
}
