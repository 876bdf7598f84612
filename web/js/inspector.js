// Pixel inspector: spectrum across bands (plot), linear RGB and coherence values of up to two pixels
// (slots A and B) for side-by-side comparison. Values come from GET /v1/jobs/{id}/pixel.

import { formatValue } from "./colormap.js";

const SLOT_COLOURS = { A: "#fbbc04", B: "#f28b82" };
const COHERENCE_ROWS = [
  ["l1_um", "ℓ₁", "µm"],
  ["l2_um", "ℓ₂", "µm"],
  ["angle", "angle", "rad"],
  ["anisotropy", "ℓ₁/ℓ₂", "1"],
  ["area_um2", "area", "µm²"],
  ["r_m", "r", "m"],
  ["Mxx", "Mxx", "m⁻²"],
  ["Mxy", "Mxy", "m⁻²"],
  ["Myy", "Myy", "m⁻²"],
];

export class PixelInspector {
  constructor(root, api, { onError }) {
    this.root = root;
    this.api = api;
    this.onError = onError;
    this.pixels = { A: null, B: null };
    root.querySelector("#inspect-form").addEventListener("submit", (event) => {
      event.preventDefault();
      const x = Number(root.querySelector("#inspect-x").value);
      const y = Number(root.querySelector("#inspect-y").value);
      if (this.jobId) this.inspect(this.jobId, x, y).catch((e) => this.onError(e));
    });
    root.querySelector("#clear-b").addEventListener("click", () => {
      this.pixels.B = null;
      this.render();
    });
  }

  reset(catalogue) {
    this.jobId = catalogue.job_id;
    this.unit = catalogue.layers.find((l) => l.kind === "band")?.unit || "";
    this.pixels = { A: null, B: null };
    this.root.querySelector("#inspect-x").max = String(catalogue.width - 1);
    this.root.querySelector("#inspect-y").max = String(catalogue.height - 1);
    this.render();
  }

  /** Fetch pixel (x, y) into the slot chosen by the "click sets" control. */
  async inspect(jobId, x, y) {
    this.jobId = jobId;
    const slot = this.root.querySelector('input[name="inspect-slot"]:checked')?.value || "A";
    this.pixels[slot] = await this.api.json(`/v1/jobs/${jobId}/pixel?x=${x}&y=${y}`);
    this.root.querySelector("#inspect-x").value = String(x);
    this.root.querySelector("#inspect-y").value = String(y);
    this.render();
  }

  render() {
    for (const slot of ["A", "B"]) this.renderSlot(slot, this.pixels[slot]);
    this.plotSpectra();
  }

  renderSlot(slot, pixel) {
    const box = this.root.querySelector(`.pixels > [data-slot="${slot}"]`);
    box.hidden = !pixel;
    if (!pixel) return;
    box.querySelector(".pixel-title").textContent = `Pixel ${slot}: (${pixel.x}, ${pixel.y})`;
    box.querySelector(".pixel-rgb").textContent = `linear RGB ${pixel.rgb.map((v) => formatValue(v)).join(", ")} ${pixel.spectrum_unit}`;
    const rows = COHERENCE_ROWS.map(([key, label, unit]) => {
      const value = pixel.coherence[key];
      return `<tr data-key="${key}" data-value="${value ?? ""}"><th scope="row">${label}</th><td>${formatValue(value, unit)}</td></tr>`;
    });
    box.querySelector(".pixel-coherence").innerHTML = pixel.coherence_covered
      ? `<caption>coherence at 550 nm</caption>${rows.join("")}`
      : "<caption>no coherence diagnostics at this pixel</caption>";
    const list = box.querySelector(".pixel-spectrum");
    list.replaceChildren(
      ...pixel.wavelengths_nm.map((nm, i) => {
        const item = document.createElement("li");
        item.dataset.wavelengthNm = String(nm);
        item.dataset.value = String(pixel.spectrum[i]);
        item.textContent = `${nm.toFixed(1)} nm: ${formatValue(pixel.spectrum[i])}`;
        return item;
      }),
    );
  }

  /** Spectrum plot of slots A and B (shared axes, values in the band radiance unit). */
  plotSpectra() {
    const svg = this.root.querySelector("#spectrum-plot");
    const [width, height, left, bottom, top] = [320, 160, 48, 22, 8];
    svg.replaceChildren();
    const present = ["A", "B"].filter((s) => this.pixels[s]);
    svg.toggleAttribute("hidden", !present.length); // SVG elements have no .hidden property
    this.root.querySelector("#inspector-hint").hidden = Boolean(present.length);
    if (!present.length) return;
    const all = present.flatMap((s) => this.pixels[s].spectrum.filter((v) => v != null));
    const wavelengths = this.pixels[present[0]].wavelengths_nm;
    const [w0, w1] = [wavelengths[0], wavelengths[wavelengths.length - 1]];
    const vMax = Math.max(...all, 1e-12);
    const px = (nm) => left + ((nm - w0) / Math.max(w1 - w0, 1)) * (width - left - 8);
    const py = (v) => height - bottom - (v / vMax) * (height - bottom - top);
    const ns = "http://www.w3.org/2000/svg";
    const add = (tag, attrs, text) => {
      const node = document.createElementNS(ns, tag);
      for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
      if (text) node.textContent = text;
      svg.append(node);
      return node;
    };
    add("line", { x1: left, y1: height - bottom, x2: width - 8, y2: height - bottom, class: "axis" });
    add("line", { x1: left, y1: top, x2: left, y2: height - bottom, class: "axis" });
    add("text", { x: left, y: height - 6, class: "tick" }, `${w0.toFixed(0)} nm`);
    add("text", { x: width - 8, y: height - 6, class: "tick", "text-anchor": "end" }, `${w1.toFixed(0)} nm`);
    add("text", { x: 2, y: top + 8, class: "tick" }, `${formatValue(vMax)} ${this.unit}`);
    add("text", { x: 2, y: height - bottom, class: "tick" }, "0");
    for (const slot of present) {
      const pixel = this.pixels[slot];
      const points = pixel.wavelengths_nm.map((nm, i) => `${px(nm)},${py(pixel.spectrum[i] ?? 0)}`).join(" ");
      add("polyline", { points, fill: "none", stroke: SLOT_COLOURS[slot], "stroke-width": 2, "data-slot": slot });
      pixel.wavelengths_nm.forEach((nm, i) => {
        const dot = add("circle", { cx: px(nm), cy: py(pixel.spectrum[i] ?? 0), r: 3, fill: SLOT_COLOURS[slot], "data-slot": slot });
        dot.dataset.wavelengthNm = String(nm);
        dot.dataset.value = String(pixel.spectrum[i]);
      });
    }
    svg.setAttribute("aria-label", `spectrum of pixel ${present.join(" and ")} in ${this.unit}`);
  }
}
