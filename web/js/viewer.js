// Image view of one finished job: zoom/pan, exposure and tone mapping with a histogram, display modes
// (sRGB, one spectral band in false colour, coherence diagnostics in false colour with legends),
// coherence-ellipse overlay and the pixel inspector.
//
// Pixel (x, y) counts from the top-left, y down. The diagnostics' `angle` is measured from +x towards
// image +y UP, so on screen (SVG, y down) an ellipse's ℓ₁ axis is rotated by −angle.

import { autoExposureEv, displayRgb8, luminance } from "./imaging.js";
import { drawColourBar, formatValue, makeScale, viridis } from "./colormap.js";
import { PixelInspector } from "./inspector.js";

export const DIAGNOSTIC_LAYERS = [
  ["coherence.l1_um", "ℓ₁ (coherence length, major)"],
  ["coherence.l2_um", "ℓ₂ (coherence length, minor)"],
  ["coherence.anisotropy", "anisotropy ℓ₁/ℓ₂"],
  ["coherence.area_um2", "coherence area π·ℓ₁·ℓ₂"],
  ["coherence.r_m", "propagation distance r"],
  ["coherence.angle", "ℓ₁ orientation"],
];
const REFERENCE_WAVELENGTH_NM = 550; // diagnostics are reported at 550 nm and scale ∝ λ
const UNCOVERED_RGB = [40, 40, 40];
const HISTOGRAM_BINS = 64;
const LARGE_IMAGE_PIXELS = 1 << 20;
const HISTOGRAM_EV_RANGE = [-12, 4];

export class ImageViewer {
  constructor(root, api, { onError }) {
    this.root = root;
    this.api = api;
    this.onError = onError;
    this.canvas = root.querySelector("#image-canvas");
    this.overlay = root.querySelector("#ellipse-overlay");
    this.viewport = root.querySelector("#viewport");
    this.stage = root.querySelector("#stage");
    this.controls = {
      mode: root.querySelector("#display-mode"),
      band: root.querySelector("#band-slider"),
      bandLabel: root.querySelector("#band-label"),
      ev: root.querySelector("#ev-slider"),
      evLabel: root.querySelector("#ev-label"),
      tonemap: root.querySelector("#tonemap"),
      logScale: root.querySelector("#log-scale"),
      ellipses: root.querySelector("#show-ellipses"),
      spacing: root.querySelector("#ellipse-spacing"),
      spacingLabel: root.querySelector("#ellipse-spacing-label"),
      ellipseScale: root.querySelector("#ellipse-scale"),
    };
    this.layers = new Map(); // layer name → Float32Array (full resolution)
    this.state = { zoom: 1, panX: 0, panY: 0 };
    this.inspector = new PixelInspector(root.querySelector("#inspector"), api, { onError });
    this.bindControls();
    this.bindPointer();
  }

  bindControls() {
    const c = this.controls;
    const redraw = () => this.draw().catch((e) => this.onError(e));
    c.mode.addEventListener("change", redraw);
    c.band.addEventListener("input", () => {
      this.updateBandLabel();
      redraw();
      this.drawEllipses();
    });
    c.ev.addEventListener("input", () => {
      c.evLabel.textContent = `${Number(c.ev.value).toFixed(1)} EV`;
      redraw();
    });
    this.root.querySelector("#ev-auto").addEventListener("click", () => {
      this.setAutoExposure();
      redraw();
    });
    c.tonemap.addEventListener("change", redraw);
    c.logScale.addEventListener("change", redraw);
    c.ellipses.addEventListener("change", () => this.loadEllipses().catch((e) => this.onError(e)));
    c.spacing.addEventListener("change", () => this.loadEllipses().catch((e) => this.onError(e)));
    c.spacing.addEventListener("input", () => (c.spacingLabel.textContent = `${c.spacing.value} px`));
    c.ellipseScale.addEventListener("change", () => this.drawEllipses());
    this.root.querySelector("#zoom-in").addEventListener("click", () => this.zoomBy(1.5));
    this.root.querySelector("#zoom-out").addEventListener("click", () => this.zoomBy(1 / 1.5));
    this.root.querySelector("#zoom-fit").addEventListener("click", () => this.fit());
  }

  bindPointer() {
    const vp = this.viewport;
    let drag = null;
    vp.addEventListener("pointerdown", (event) => {
      drag = { x: event.clientX, y: event.clientY, panX: this.state.panX, panY: this.state.panY, moved: false };
      vp.setPointerCapture(event.pointerId);
    });
    vp.addEventListener("pointermove", (event) => {
      if (!drag) return;
      const dx = event.clientX - drag.x;
      const dy = event.clientY - drag.y;
      if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
      if (drag.moved) {
        this.state.panX = drag.panX + dx;
        this.state.panY = drag.panY + dy;
        this.applyTransform();
      }
    });
    vp.addEventListener("pointerup", (event) => {
      const wasClick = drag && !drag.moved;
      drag = null;
      if (!wasClick || !this.jobId) return;
      const pixel = this.pixelAt(event.clientX, event.clientY);
      if (pixel) this.inspector.inspect(this.jobId, pixel.x, pixel.y).catch((e) => this.onError(e));
    });
    vp.addEventListener(
      "wheel",
      (event) => {
        event.preventDefault();
        const rect = vp.getBoundingClientRect();
        this.zoomBy(event.deltaY < 0 ? 1.25 : 0.8, event.clientX - rect.left, event.clientY - rect.top);
      },
      { passive: false },
    );
    vp.addEventListener("keydown", (event) => {
      const step = 40;
      const actions = {
        ArrowLeft: () => (this.state.panX += step),
        ArrowRight: () => (this.state.panX -= step),
        ArrowUp: () => (this.state.panY += step),
        ArrowDown: () => (this.state.panY -= step),
        "+": () => this.zoomBy(1.5),
        "=": () => this.zoomBy(1.5),
        "-": () => this.zoomBy(1 / 1.5),
        0: () => this.fit(),
      };
      if (actions[event.key]) {
        event.preventDefault();
        actions[event.key]();
        this.applyTransform();
      }
    });
    this.overlay.addEventListener("pointerover", (event) => {
      const target = event.target.closest("ellipse");
      if (target) this.showEllipseInfo(target);
    });
  }

  /** Image pixel under a client position (null outside the image). */
  pixelAt(clientX, clientY) {
    const rect = this.canvas.getBoundingClientRect();
    const x = Math.floor(((clientX - rect.left) / rect.width) * this.canvas.width);
    const y = Math.floor(((clientY - rect.top) / rect.height) * this.canvas.height);
    return x >= 0 && y >= 0 && x < this.canvas.width && y < this.canvas.height ? { x, y } : null;
  }

  zoomBy(factor, cx = this.viewport.clientWidth / 2, cy = this.viewport.clientHeight / 2) {
    const zoom = Math.min(Math.max(this.state.zoom * factor, 0.05), 256);
    const applied = zoom / this.state.zoom;
    this.state.panX = cx - (cx - this.state.panX) * applied;
    this.state.panY = cy - (cy - this.state.panY) * applied;
    this.state.zoom = zoom;
    this.applyTransform();
  }

  fit() {
    const { width, height } = this.canvas;
    const vw = this.viewport.clientWidth;
    const vh = this.viewport.clientHeight;
    this.state.zoom = Math.max(Math.min(vw / width, vh / height), 0.05);
    this.state.panX = (vw - width * this.state.zoom) / 2;
    this.state.panY = (vh - height * this.state.zoom) / 2;
    this.applyTransform();
  }

  applyTransform() {
    const { zoom, panX, panY } = this.state;
    this.stage.style.transform = `translate(${panX}px, ${panY}px) scale(${zoom})`;
    // Strokes are in image pixels (the overlay is scaled with the image): keep them 1.5 screen pixels.
    this.overlay.style.strokeWidth = String(1.5 / zoom);
    this.root.querySelector("#zoom-label").textContent = `${Math.round(zoom * 100)}%`;
  }

  /** Load a job's catalogue and RGB; reset the controls that depend on the image. */
  async open(jobId) {
    this.jobId = jobId;
    this.layers.clear();
    this.catalogue = await this.api.json(`/v1/jobs/${jobId}/layers`);
    const { width, height } = this.catalogue;
    this.canvas.width = width;
    this.canvas.height = height;
    this.stage.style.width = `${width}px`;
    this.stage.style.height = `${height}px`;
    this.overlay.setAttribute("viewBox", `0 0 ${width} ${height}`);
    this.overlay.setAttribute("width", width);
    this.overlay.setAttribute("height", height);
    this.info = new Map(this.catalogue.layers.map((layer) => [layer.name, layer]));
    this.bandNames = this.catalogue.layers.filter((l) => l.kind === "band").map((l) => l.name);
    const band = this.controls.band;
    band.max = String(Math.max(this.bandNames.length - 1, 0));
    band.value = String(Math.floor(this.bandNames.length / 2));
    this.updateBandLabel();
    const mode = this.controls.mode;
    mode.replaceChildren(new Option("sRGB (from the spectrum)", "srgb"), new Option("single band (false colour)", "band"));
    for (const [name, label] of DIAGNOSTIC_LAYERS) if (this.info.has(name)) mode.append(new Option(label, name));
    this.root.querySelector("#viewer-title").textContent = `Job ${jobId}`;
    this.root.querySelector("#viewer-hint").hidden = true;
    const partial = this.catalogue.partial ? " — preview of the chunks finished so far (job running; reopen to refresh)" : "";
    this.root.querySelector("#viewer-size").textContent = `${width}×${height} px, ${this.bandNames.length} bands${partial}`;
    await this.layer("rgb");
    this.setAutoExposure();
    this.fit();
    await this.draw();
    this.inspector.reset(this.catalogue);
    await this.loadEllipses();
  }

  async layer(name) {
    if (!this.layers.has(name)) {
      // Half precision halves the transfer of large images (relative rounding 2⁻¹¹, below one 8-bit level).
      const format = this.catalogue.width * this.catalogue.height > LARGE_IMAGE_PIXELS ? "f16" : "f32";
      const path = `/v1/jobs/${this.jobId}/layers/${encodeURIComponent(name)}?format=${format}`;
      const array = await this.api.floats(path);
      this.layers.set(name, array.data);
    }
    return this.layers.get(name);
  }

  /** Exposure that maps the 99th percentile of luminance to white, on the slider's 0.5 EV steps. */
  setAutoExposure() {
    const slider = this.controls.ev;
    const ev = Math.round(autoExposureEv(this.layers.get("rgb")) / Number(slider.step)) * Number(slider.step);
    slider.value = String(Math.min(Math.max(ev, Number(slider.min)), Number(slider.max)));
    this.controls.evLabel.textContent = `${Number(slider.value).toFixed(1)} EV`;
  }

  updateBandLabel() {
    const name = this.bandNames?.[Number(this.controls.band.value)];
    const nm = name ? this.info.get(name).wavelength_nm : REFERENCE_WAVELENGTH_NM;
    this.controls.bandLabel.textContent = `${nm.toFixed(1)} nm`;
    this.controls.band.setAttribute("aria-valuetext", `${nm.toFixed(1)} nanometres`);
  }

  /** Current wavelength of the slider (nm). */
  wavelengthNm() {
    const name = this.bandNames?.[Number(this.controls.band.value)];
    return name ? this.info.get(name).wavelength_nm : REFERENCE_WAVELENGTH_NM;
  }

  /** Render the current mode into the canvas (one canvas pixel per image pixel). */
  async draw() {
    if (!this.catalogue) return;
    const { width, height } = this.catalogue;
    const mode = this.controls.mode.value;
    const ev = Number(this.controls.ev.value);
    const operator = this.controls.tonemap.value;
    const image = new ImageData(width, height);
    const legend = this.root.querySelector("#legend");
    const isSrgb = mode === "srgb";
    this.controls.tonemap.disabled = !isSrgb;
    this.controls.ev.disabled = !isSrgb;
    this.controls.logScale.disabled = isSrgb;
    let histogramValues;
    if (isSrgb) {
      const rgb = await this.layer("rgb");
      displayRgb8(rgb, image.data, ev, operator);
      const scale = Math.pow(2, ev);
      histogramValues = Array.from(luminance(rgb), (y) => (y > 0 ? Math.log2(y * scale) : -Infinity));
      legend.replaceChildren();
      this.drawHistogram(histogramValues, HISTOGRAM_EV_RANGE, "log₂ luminance (EV, 0 = white)");
    } else {
      const name = mode === "band" ? this.bandNames[Number(this.controls.band.value)] : mode;
      const info = this.info.get(name);
      const values = await this.layer(name);
      const covered = info.kind === "coherence" ? await this.layer("coherence.weight") : null;
      const scale = makeScale(info.p01 ?? 0, info.p99 ?? 1, this.controls.logScale.checked);
      histogramValues = [];
      for (let i = 0; i < values.length; i++) {
        const rgb = covered && !(covered[i] > 0) ? UNCOVERED_RGB : viridis(scale.t(values[i]));
        if (!covered || covered[i] > 0) histogramValues.push(scale.t(values[i]));
        image.data[4 * i] = rgb[0];
        image.data[4 * i + 1] = rgb[1];
        image.data[4 * i + 2] = rgb[2];
        image.data[4 * i + 3] = 255;
      }
      const title = mode === "band" ? `band ${info.wavelength_nm.toFixed(1)} nm` : this.controls.mode.selectedOptions[0].textContent;
      drawColourBar(legend, scale, info.unit, title);
      this.drawHistogram(histogramValues, [0, 1], "colour-bar position");
    }
    this.canvas.getContext("2d").putImageData(image, 0, 0);
    this.canvas.dataset.mode = mode;
    this.canvas.setAttribute("aria-label", `rendered image: ${this.controls.mode.selectedOptions[0]?.textContent ?? mode}`);
    this.canvas.dataset.drawn = String((Number(this.canvas.dataset.drawn) || 0) + 1);
  }

  drawHistogram(values, [lo, hi], label) {
    const canvas = this.root.querySelector("#histogram");
    const ctx = canvas.getContext("2d");
    const counts = new Array(HISTOGRAM_BINS).fill(0);
    for (const v of values) {
      if (!Number.isFinite(v)) continue;
      const bin = Math.min(Math.max(Math.floor(((v - lo) / (hi - lo)) * HISTOGRAM_BINS), 0), HISTOGRAM_BINS - 1);
      counts[bin] += 1;
    }
    const peak = Math.max(...counts, 1);
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    ctx.fillStyle = "#8ab4f8";
    const w = canvas.width / HISTOGRAM_BINS;
    counts.forEach((count, i) => {
      const h = (Math.sqrt(count) / Math.sqrt(peak)) * (canvas.height - 2);
      ctx.fillRect(i * w, canvas.height - h, Math.max(w - 1, 1), h);
    });
    if (lo < 0 && hi > 0) {
      ctx.fillStyle = "#f28b82";
      ctx.fillRect(((0 - lo) / (hi - lo)) * canvas.width, 0, 1, canvas.height);
    }
    canvas.setAttribute("aria-label", `histogram of ${label} from ${lo} to ${hi}`);
    this.root.querySelector("#histogram-label").textContent = `${label}: ${lo} … ${hi}`;
  }

  async loadEllipses() {
    this.ellipses = [];
    if (this.jobId && this.controls.ellipses.checked) {
      const grid = await this.api.json(`/v1/jobs/${this.jobId}/ellipses?spacing=${this.controls.spacing.value}`);
      this.ellipses = grid.ellipses;
    }
    this.drawEllipses();
  }

  /** Ellipses: semi-axes ∝ ℓ₁, ℓ₂ (linear or log scale), rotated by −angle on screen, coloured by area. */
  drawEllipses() {
    this.overlay.replaceChildren();
    const legend = this.root.querySelector("#ellipse-legend");
    legend.replaceChildren();
    const grid = this.ellipses || [];
    if (!grid.length) return;
    const spacing = Number(this.controls.spacing.value);
    const radiusPx = 0.45 * spacing;
    const l1Max = Math.max(...grid.map((e) => e.l1_um));
    const l2Min = Math.min(...grid.map((e) => e.l2_um));
    const logScale = this.controls.ellipseScale.value === "log";
    const decades = Math.log10(l1Max / l2Min) + 0.3; // +0.3: the shortest axis keeps a visible length
    const radius = (l) => Math.max(logScale ? (radiusPx * (Math.log10(l / l2Min) + 0.3)) / decades : (radiusPx * l) / l1Max, 0.25);
    const areas = grid.map((e) => e.area_um2);
    const areaScale = makeScale(Math.min(...areas), Math.max(...areas), true);
    const lambdaFactor = this.wavelengthNm() / REFERENCE_WAVELENGTH_NM;
    const legendScale = makeScale(areaScale.lo * lambdaFactor ** 2, areaScale.hi * lambdaFactor ** 2, true);
    drawColourBar(legend, legendScale, "µm²", `ellipse colour: coherence area at ${this.wavelengthNm().toFixed(0)} nm`);
    const ns = "http://www.w3.org/2000/svg";
    for (const e of grid) {
      const cx = e.x + 0.5;
      const cy = e.y + 0.5;
      const shape = document.createElementNS(ns, "ellipse");
      const [r, g, b] = viridis(areaScale.t(e.area_um2));
      shape.setAttribute("cx", cx);
      shape.setAttribute("cy", cy);
      shape.setAttribute("rx", radius(e.l1_um));
      shape.setAttribute("ry", radius(e.l2_um));
      shape.setAttribute("transform", `rotate(${(-e.angle * 180) / Math.PI} ${cx} ${cy})`);
      shape.setAttribute("stroke", `rgb(${r},${g},${b})`);
      shape.setAttribute("fill", `rgb(${r},${g},${b})`);
      shape.setAttribute("fill-opacity", "0.2");
      Object.assign(shape.dataset, {
        x: e.x,
        y: e.y,
        l1Um: e.l1_um * lambdaFactor,
        l2Um: e.l2_um * lambdaFactor,
        angle: e.angle,
        areaUm2: e.area_um2 * lambdaFactor * lambdaFactor,
      });
      const title = document.createElementNS(ns, "title");
      title.textContent = ellipseText(shape.dataset, this.wavelengthNm());
      shape.append(title);
      this.overlay.append(shape);
    }
    this.overlay.dataset.count = String(grid.length);
  }

  showEllipseInfo(shape) {
    this.root.querySelector("#ellipse-info").textContent = ellipseText(shape.dataset, this.wavelengthNm());
  }
}

function ellipseText(d, wavelengthNm) {
  const degrees = (Number(d.angle) * 180) / Math.PI;
  return (
    `pixel (${d.x}, ${d.y}) at ${wavelengthNm.toFixed(0)} nm: ℓ₁ ${formatValue(Number(d.l1Um), "µm")}, ` +
    `ℓ₂ ${formatValue(Number(d.l2Um), "µm")}, angle ${degrees.toFixed(1)}°, area ${formatValue(Number(d.areaUm2), "µm²")}`
  );
}
