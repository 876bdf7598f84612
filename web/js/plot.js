// Small SVG line plots with real axes (1-2-5 ticks with values and units), a legend, horizontal reference
// lines (thresholds) and a hover readout of the nearest x. Used by the pixel inspector (spectra) and the
// regression dashboard (trends).
//
// Hand-written rather than a vendored library (uPlot draws axes and ticks into a canvas): every tick,
// legend entry and readout here is a DOM node, so tests assert on what is shown, and the two plots need
// ~150 lines, not a dependency.

import { formatValue } from "./colormap.js";

const SVG_NS = "http://www.w3.org/2000/svg";
const MARGIN = { left: 56, right: 12, top: 10, bottom: 34 };

/** About `count` round tick values (1, 2, 5 × 10^k steps) covering [lo, hi]. */
export function niceTicks(lo, hi, count = 5) {
  if (!(hi > lo)) return [lo];
  const raw = (hi - lo) / count;
  const power = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * power).find((s) => s >= raw) ?? 10 * power;
  const ticks = [];
  for (let v = Math.ceil(lo / step - 1e-9) * step; v <= hi + step * 1e-9; v += step) ticks.push(Math.abs(v) < step * 1e-9 ? 0 : v);
  return ticks;
}

function node(parent, tag, attrs = {}, text) {
  const element = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) element.setAttribute(k, v);
  if (text !== undefined) element.textContent = text;
  parent.append(element);
  return element;
}

/**
 * Draw into `svg` (its viewBox gives the size). `series`: [{id?, name, colour, points: [[x, y], ...],
 * hollow: (point index) → bool}]; `x`/`y`: {label, unit, format(value) → text, min?, max?};
 * `lines`: [{y, label, colour}] horizontal reference lines; `legend`: an element for the legend;
 * `readout`: an element that shows the values at the x nearest the pointer (`readoutText(x, hits)`).
 */
export function drawPlot(svg, { series, x, y, lines = [], legend, readout, readoutText }) {
  const [, , width, height] = (svg.getAttribute("viewBox") || "0 0 320 160").split(/\s+/).map(Number);
  svg.replaceChildren();
  const all = series.flatMap((s) => s.points).filter(([, v]) => Number.isFinite(v));
  const xs = all.map(([u]) => u);
  const ys = [...all.map(([, v]) => v), ...lines.map((l) => l.y)];
  const x0 = x.min ?? Math.min(...xs);
  const x1 = x.max ?? Math.max(...xs);
  const y0 = y.min ?? Math.min(0, ...ys);
  const y1 = y.max ?? (Math.max(...ys) * 1.05 || 1);
  const px = (u) => MARGIN.left + ((u - x0) / (x1 - x0 || 1)) * (width - MARGIN.left - MARGIN.right);
  const py = (v) => height - MARGIN.bottom - ((v - y0) / (y1 - y0 || 1)) * (height - MARGIN.top - MARGIN.bottom);
  const formatX = x.format || ((u) => formatValue(u));
  const formatY = y.format || ((v) => formatValue(v));

  // ---- axes and ticks ----
  const bottom = height - MARGIN.bottom;
  node(svg, "line", { class: "axis", x1: MARGIN.left, y1: bottom, x2: width - MARGIN.right, y2: bottom });
  node(svg, "line", { class: "axis", x1: MARGIN.left, y1: MARGIN.top, x2: MARGIN.left, y2: bottom });
  for (const u of x.ticks || niceTicks(x0, x1, 5)) {
    node(svg, "line", { class: "grid", x1: px(u), x2: px(u), y1: MARGIN.top, y2: bottom });
    node(svg, "text", { class: "tick x-tick", x: px(u), y: bottom + 12, "text-anchor": "middle", "data-value": u }, formatX(u));
  }
  for (const v of niceTicks(y0, y1, 4)) {
    node(svg, "line", { class: "grid", x1: MARGIN.left, x2: width - MARGIN.right, y1: py(v), y2: py(v) });
    node(svg, "text", { class: "tick y-tick", x: MARGIN.left - 4, y: py(v) + 3, "text-anchor": "end", "data-value": v }, formatY(v));
  }
  node(svg, "text", { class: "axis-label x-label", x: (MARGIN.left + width - MARGIN.right) / 2, y: height - 4, "text-anchor": "middle" }, `${x.label}${x.unit ? ` [${x.unit}]` : ""}`);
  node(svg, "text", { class: "axis-label y-label", x: 10, y: MARGIN.top + (bottom - MARGIN.top) / 2, "text-anchor": "middle", transform: `rotate(-90 10 ${MARGIN.top + (bottom - MARGIN.top) / 2})` }, `${y.label}${y.unit ? ` [${y.unit}]` : ""}`);

  // ---- reference lines and series ----
  for (const line of lines) {
    node(svg, "line", { class: "reference", x1: MARGIN.left, x2: width - MARGIN.right, y1: py(line.y), y2: py(line.y), stroke: line.colour || "#f28b82", "stroke-dasharray": "4 3" });
    node(svg, "text", { class: "tick reference-label", x: width - MARGIN.right, y: py(line.y) - 3, "text-anchor": "end", fill: line.colour || "#f28b82" }, line.label);
  }
  for (const s of series) {
    const finite = s.points.filter(([, v]) => Number.isFinite(v));
    if (finite.length > 1) node(svg, "polyline", { points: finite.map(([u, v]) => `${px(u)},${py(v)}`).join(" "), fill: "none", stroke: s.colour, "stroke-width": 2, "data-series": s.id ?? s.name });
    finite.forEach(([u, v], i) => {
      const hollow = s.hollow?.(i);
      const dot = node(svg, "circle", { cx: px(u), cy: py(v), r: 3.5, stroke: s.colour, "stroke-width": 2, fill: hollow ? "none" : s.colour, "data-series": s.id ?? s.name, "data-x": u, "data-y": v });
      node(dot, "title", {}, `${s.name}: ${formatX(u)} → ${formatY(v)}`);
    });
  }
  if (legend) {
    legend.replaceChildren(
      ...series.map((s) => {
        const entry = document.createElement("span");
        entry.className = "legend-entry";
        entry.dataset.series = s.id ?? s.name;
        entry.innerHTML = `<span class="swatch" style="background:${s.colour}"></span>`;
        entry.append(s.name);
        return entry;
      }),
    );
  }

  // ---- hover readout: nearest x over every series ----
  const cursor = node(svg, "line", { class: "cursor", y1: MARGIN.top, y2: bottom, visibility: "hidden" });
  const xsSorted = [...new Set(xs)].sort((a, b) => a - b);
  const hover = (event) => {
    const box = svg.getBoundingClientRect();
    const u = x0 + (((event.clientX - box.left) * (width / box.width) - MARGIN.left) / (width - MARGIN.left - MARGIN.right)) * (x1 - x0);
    const nearest = xsSorted.reduce((best, v) => (Math.abs(v - u) < Math.abs(best - u) ? v : best), xsSorted[0]);
    cursor.setAttribute("x1", px(nearest));
    cursor.setAttribute("x2", px(nearest));
    cursor.setAttribute("visibility", "visible");
    const hits = series.map((s) => ({ name: s.name, point: s.points.find(([p]) => p === nearest) })).filter((h) => h.point);
    if (readout) readout.textContent = readoutText ? readoutText(nearest, hits) : `${formatX(nearest)}: ${hits.map((h) => `${h.name} ${formatY(h.point[1])}`).join(", ")}`;
  };
  svg.onpointermove = xsSorted.length ? hover : null;
  svg.onpointerleave = () => cursor.setAttribute("visibility", "hidden");
  return { px, py };
}
