// Compare two jobs' images: side by side with a split slider, or a difference map (absolute, relative,
// CIEDE2000 ΔE₀₀, ꟻLIP) in false colour with its statistics. Reused by the regression dashboard.
//
// Usage:
//   import { mountCompare } from "/web/js/compare.js";
//   import { Api } from "/web/js/api.js";
//   const view = await mountCompare(document.querySelector("#here"), {
//     leftJobId: "<32 hex>", rightJobId: "<32 hex>", api: new Api(),
//     mode: "split",          // "split" | "abs" | "rel" | "de2000" | "flip"   (optional)
//     ev: 3.2,                // exposure of both images and of ΔE₀₀ / ꟻLIP (optional; default: the
//                             // service's automatic exposure of a, as a regression run uses)
//     tonemap: "clamp",       // tone map of the two displayed images (optional)
//     names: ["baseline", "current"],  // labels of a and b (optional)
//   });
//   await view.update({ mode: "de2000" });   // change any option; view.stats holds {mean, p95, max}
//   view.destroy();                           // remove the DOM it created
//
// `api` is an instance of Api (web/js/api.js) or any object with the same `floats(path)` method.
// Both jobs must have succeeded and have images of the same size. ΔE₀₀ and ꟻLIP are computed by the
// server (GET /v1/compare → hgcore/image_metrics.py, the code regression runs use) from the spectral
// bands at the exposure shown here; the tone map only changes how the two images are displayed.

import { displayRgb8, TONE_MAPS } from "./imaging.js";
import { drawColourBar, formatValue, makeScale, viridis } from "./colormap.js";

const DE2000_RANGE = [0, 10]; // ΔE₀₀ ≈ 1 is just noticeable; 10 already reads as a different colour
const FLIP_RANGE = [0, 1]; // ꟻLIP's per-pixel error is in [0, 1]
const MODES = [
  ["split", "side by side (split slider)"],
  ["abs", "absolute difference |b − a|"],
  ["rel", "relative difference |b − a| / |a|"],
  ["de2000", "CIEDE2000 ΔE₀₀"],
  ["flip", "ꟻLIP (LDR, as displayed)"],
];
let instances = 0;

/** Mount the compare view into `element`; resolves to a controller {update, destroy, stats, root}. */
export async function mountCompare(element, { leftJobId, rightJobId, api, mode = "split", ev = null, tonemap = "clamp", names = [] }) {
  if (!leftJobId || !rightJobId) throw new Error("leftJobId: both leftJobId and rightJobId are required");
  if (!TONE_MAPS.includes(tonemap)) throw new Error(`tonemap: must be one of ${TONE_MAPS.join(", ")}`);
  const id = `compare-${++instances}`;
  const root = document.createElement("section");
  root.className = "compare";
  root.setAttribute("aria-label", "compare two jobs");
  root.innerHTML = `
    <div class="controls">
      <label for="${id}-mode">View</label>
      <select id="${id}-mode" class="compare-mode">${MODES.map(([v, t]) => `<option value="${v}">${t}</option>`).join("")}</select>
      <label for="${id}-ev">Exposure</label>
      <input id="${id}-ev" class="compare-ev" type="range" step="0.1">
      <input class="compare-ev-value" type="number" min="-64" max="64" step="0.1" aria-label="exposure in EV"> EV
      <output class="compare-ev-label small" for="${id}-ev"></output>
      <label for="${id}-tonemap">Tone map</label>
      <select id="${id}-tonemap" class="compare-tonemap">${TONE_MAPS.map((t) => `<option>${t}</option>`).join("")}</select>
      <label for="${id}-split">Split</label>
      <input id="${id}-split" class="compare-split" type="range" min="0" max="100" step="1" value="50">
    </div>
    <div class="compare-body">
      <div class="compare-main">
        <div class="compare-names"><a class="compare-left-name"></a><a class="compare-right-name"></a></div>
        <div class="compare-stage">
          <canvas class="compare-left" role="img" aria-label="left image (a)"></canvas>
          <canvas class="compare-right" role="img" aria-label="right image (b)"></canvas>
          <div class="compare-divider" aria-hidden="true"></div>
          <canvas class="compare-diff" role="img" aria-label="difference map" hidden></canvas>
        </div>
      </div>
      <div class="compare-side">
        <div class="compare-legend"></div>
        <p class="compare-stats" aria-live="polite"></p>
        <output class="compare-readout small" aria-live="off"></output>
      </div>
    </div>`;
  element.append(root);
  const $ = (selector) => root.querySelector(selector);
  let left, right, catalogue;
  try {
    [left, right, catalogue] = await Promise.all([
      api.floats(`/v1/jobs/${leftJobId}/layers/rgb?format=f32`),
      api.floats(`/v1/jobs/${rightJobId}/layers/rgb?format=f32`),
      api.json(`/v1/jobs/${leftJobId}/layers`),
    ]);
  } catch (error) {
    root.remove(); // nothing half-mounted stays behind
    throw error;
  }
  // The slider spans a's automatic exposure ± 12 EV (it always holds it); the box takes any EV.
  const autoEv = catalogue.exposure_ev;
  const options = { mode, ev: ev ?? autoEv, tonemap };
  $(".compare-ev").min = String(Math.round(autoEv) - 12);
  $(".compare-ev").max = String(Math.round(autoEv) + 12);
  if (left.width !== right.width || left.height !== right.height) {
    root.remove();
    throw new Error(`rightJobId: image is ${right.width}x${right.height}, left is ${left.width}x${left.height}`);
  }
  // Each name links to its job in the image view; a long one is cut with an ellipsis (the tooltip has it).
  for (const [selector, slot, jobId, name] of [[".compare-left-name", "a", leftJobId, names[0]], [".compare-right-name", "b", rightJobId, names[1]]]) {
    const link = $(selector);
    link.textContent = `${slot}: ${name || jobId.slice(0, 8)}`;
    link.title = `${link.textContent} (${jobId}): open in the image view`;
    link.href = `/#/view/${jobId}`;
  }
  for (const canvas of root.querySelectorAll("canvas")) {
    canvas.width = left.width;
    canvas.height = left.height;
  }
  $(".compare-stage").style.aspectRatio = `${left.width} / ${left.height}`;
  // The image column is as wide as the window's height allows for this aspect ratio (app.css).
  root.style.setProperty("--compare-aspect", String(left.width / left.height));

  const controller = { root, stats: null, update, destroy: () => root.remove() };
  let lastDiff = null;

  // Hover readout: both images' linear RGB at the pixel under the pointer, and the difference map's value.
  $(".compare-stage").addEventListener("pointermove", (event) => {
    const rect = $(".compare-stage").getBoundingClientRect();
    const x = Math.floor(((event.clientX - rect.left) / rect.width) * left.width);
    const y = Math.floor(((event.clientY - rect.top) / rect.height) * left.height);
    if (x < 0 || y < 0 || x >= left.width || y >= left.height) return;
    const i = y * left.width + x;
    const rgb = (floats) => [0, 1, 2].map((c) => formatValue(floats.data[3 * i + c])).join(" ");
    const diffText = options.mode !== "split" && lastDiff ? `; ${options.mode} ${formatValue(lastDiff[i])}` : "";
    $(".compare-readout").textContent = `(${x}, ${y}) linear R G B a: ${rgb(left)}, b: ${rgb(right)}${diffText}`;
  });

  function drawImage(canvas, floats) {
    const image = new ImageData(floats.width, floats.height);
    displayRgb8(floats.data, image.data, options.ev, options.tonemap);
    canvas.getContext("2d").putImageData(image, 0, 0);
  }

  function applySplit() {
    const percent = Number($(".compare-split").value);
    $(".compare-right").style.clipPath = `inset(0 0 0 ${percent}%)`;
    $(".compare-divider").style.left = `${percent}%`;
  }

  async function drawDifference() {
    const query = `a=${leftJobId}&b=${rightJobId}&mode=${options.mode}&ev=${options.ev}`;
    const diff = await api.floats(`/v1/compare?${query}`);
    const stats = JSON.parse(diff.headers.get("X-Stats"));
    const fixed = { de2000: DE2000_RANGE, flip: FLIP_RANGE }[options.mode];
    const range = fixed || [0, stats.p95 > 0 ? stats.p95 : stats.max || 1];
    const scale = makeScale(range[0], range[1], false);
    const image = new ImageData(diff.width, diff.height);
    for (let i = 0; i < diff.data.length; i++) {
      const [r, g, b] = viridis(scale.t(diff.data[i]));
      image.data.set([r, g, b, 255], 4 * i);
    }
    $(".compare-diff").getContext("2d").putImageData(image, 0, 0);
    lastDiff = diff.data;
    const [unit, title] = {
      abs: ["W·m⁻²·sr⁻¹·nm⁻¹", "|b − a| (mean of R, G, B)"],
      rel: ["1", "|b − a| / |a|"],
      de2000: ["1", "ΔE₀₀"],
      flip: ["1", "ꟻLIP"],
    }[options.mode];
    drawColourBar($(".compare-legend"), scale, unit, title);
    controller.stats = stats;
    const statsNode = $(".compare-stats");
    Object.assign(statsNode.dataset, { mode: options.mode, mean: stats.mean, p95: stats.p95, max: stats.max });
    const at = ["de2000", "flip"].includes(options.mode) ? ` at ${Number(options.ev).toFixed(2)} EV` : "";
    statsNode.dataset.ev = String(options.ev);
    statsNode.textContent = `${title}${at}: mean ${formatValue(stats.mean)}, 95th percentile ${formatValue(stats.p95)}, max ${formatValue(stats.max)}`;
  }

  async function update(changes = {}) {
    Object.assign(options, changes);
    $(".compare-readout").textContent = ""; // it described the previous view (the next move refills it)
    $(".compare-mode").value = options.mode;
    $(".compare-ev").value = String(options.ev);
    $(".compare-ev-value").value = Number(options.ev).toFixed(2);
    const [lo, hi] = [Number($(".compare-ev").min), Number($(".compare-ev").max)];
    $(".compare-ev-label").textContent = options.ev < lo || options.ev > hi ? `beyond the slider (${lo}…${hi} EV)` : `auto ${autoEv.toFixed(2)} EV`;
    $(".compare-tonemap").value = options.tonemap;
    const split = options.mode === "split";
    $(".compare-diff").hidden = split;
    for (const selector of [".compare-left", ".compare-right", ".compare-divider"]) $(selector).hidden = !split;
    $(".compare-split").disabled = !split;
    drawImage($(".compare-left"), left);
    drawImage($(".compare-right"), right);
    applySplit();
    if (split) {
      $(".compare-legend").replaceChildren();
      $(".compare-stats").textContent = "";
    } else {
      await drawDifference();
    }
    root.dataset.ready = String((Number(root.dataset.ready) || 0) + 1);
    return controller;
  }

  // A failed update shows its error in place of the statistics and leaves no map or numbers of before.
  const report = (promise) =>
    promise.catch((error) => {
      lastDiff = null;
      controller.stats = null;
      const diff = $(".compare-diff");
      diff.getContext("2d").clearRect(0, 0, diff.width, diff.height);
      $(".compare-legend").replaceChildren();
      const statsNode = $(".compare-stats");
      for (const key of ["mode", "mean", "p95", "max", "ev"]) delete statsNode.dataset[key];
      statsNode.textContent = String(error.message || error);
    });
  $(".compare-mode").addEventListener("change", (e) => report(update({ mode: e.target.value })));
  $(".compare-ev").addEventListener("input", (e) => report(update({ ev: Number(e.target.value) })));
  $(".compare-ev-value").addEventListener("change", (e) => report(update({ ev: Number(e.target.value) })));
  $(".compare-tonemap").addEventListener("change", (e) => report(update({ tonemap: e.target.value })));
  $(".compare-split").addEventListener("input", applySplit);
  try {
    return await update();
  } catch (error) {
    root.remove();
    throw error;
  }
}
