// Image view of one finished job (or a dropped EXR): zoom/pan, exposure, offset, gamma and tone mapping
// with a histogram, display modes (sRGB, one spectral band in false colour, coherence diagnostics in false
// colour with legends), coherence ellipses to an absolute µm scale, a hover readout of pixel values, values
// drawn on the pixels at high zoom (as tev), A/B markers of the pixel inspector, and downloads.
//
// Pixel (x, y) counts from the top-left, y down. The diagnostics' `angle` is measured from +x towards
// image +y UP, so on screen (SVG, y down) an ellipse's ℓ₁ axis is rotated by −angle. Every diagnostic is
// shown at the wavelength slider's λ, in the units of web/js/diagnostics.js (maps, readouts, ellipses and
// inspector alike), and every readout is cleared when the job, the layer or λ changes.

import { autoExposureEv, displayRgb8, luminance } from "./imaging.js";
import { cyclic, drawColourBar, formatValue, makeScale, viridis } from "./colormap.js";
import {
  coherenceKey,
  COHERENCE_QUANTITIES,
  DIAGNOSTIC_MODES,
  displayValue,
  layerName,
  orientationT,
  quantityTitle,
  REFERENCE_WAVELENGTH_NM,
} from "./diagnostics.js";
import { PixelInspector, saveBlob, SLOT_COLOURS } from "./inspector.js";
import { previewRevision } from "./jobs.js";
const UNCOVERED_RGB = [40, 40, 40];
const HISTOGRAM_BINS = 64;
const LARGE_IMAGE_PIXELS = 1 << 20;
const HISTOGRAM_EV_RANGE = [-12, 4];
export const EV_SLIDER_HALF_RANGE = 12; // the slider spans auto ± 12 EV; the number box takes any EV in ±64
const EV_STEP = 0.5; // E / Shift+E
const VALUE_ZOOM = 48; // screen pixels per image pixel from which values are drawn on the pixels
export const UM_PER_PX_CHOICES = [0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000];
const MIN_SEMI_AXIS_SCREEN_PX = 1.5; // thinner ellipses are drawn this wide (said in the legend)
// "auto" ellipse scale: the 1-2-5 step at which the median ℓ₁ is this fraction of the grid spacing; an
// ellipse whose ℓ₁ would then exceed half the spacing is drawn shrunk to it (shape and angle kept, dashed),
// so every ellipse stays inside its grid cell and the picture stays visible under them.
const AUTO_MEDIAN_FRACTION = 0.35;
const AUTO_MAX_FRACTION = 0.5;
const ELLIPSE_HINT = "Hover an ellipse for its numbers.";
// Default grid spacing: about this many cells across the image's shorter side (an even number of pixels
// in the slider's range), until the user moves the slider; then their spacing is kept for every image.
const ELLIPSE_CELLS_ACROSS = 16;
const ELLIPSE_SCALE_KEY = "hgrender.ellipseUmPerPx";
const SCALE_BAR_TARGET_PX = 100;
const CHANNEL_TEXT_COLOURS = ["#ff9a9a", "#9aff9a", "#9ab8ff"]; // R, G, B values on the pixels (as tev)
export const PREVIEW_POLL_MS = 1000; // how often a running job's preview checks for a newer one

export class ImageViewer {
  constructor(root, api, { onError }) {
    this.root = root;
    this.api = api;
    this.onError = onError;
    const $ = (selector) => root.querySelector(selector);
    this.canvas = $("#image-canvas");
    this.overlay = $("#ellipse-overlay");
    this.halo = $("#ellipse-halo");
    this.markers = $("#marker-overlay");
    this.valueCanvas = $("#value-canvas");
    this.viewport = $("#viewport");
    this.stage = $("#stage");
    this.controls = {
      mode: $("#display-mode"),
      band: $("#band-slider"),
      bandLabel: $("#band-label"),
      ev: $("#ev-slider"),
      evValue: $("#ev-value"),
      evNote: $("#ev-note"),
      offset: $("#offset"),
      gamma: $("#gamma"),
      transfer: $("#transfer"),
      tonemap: $("#tonemap"),
      logScale: $("#log-scale"),
      ellipses: $("#show-ellipses"),
      spacing: $("#ellipse-spacing"),
      spacingLabel: $("#ellipse-spacing-label"),
      ellipseScale: $("#ellipse-scale"),
    };
    this.layers = new Map(); // layer name → Float32Array (full resolution)
    this.state = { zoom: 1, panX: 0, panY: 0 };
    this.inspector = new PixelInspector($("#inspector"), api, {
      onError,
      wavelengthNm: () => this.wavelengthNm(),
      onChange: () => this.drawMarkers(),
    });
    const scale = this.controls.ellipseScale;
    scale.replaceChildren(new Option("auto (fit the grid)", "auto"), ...UM_PER_PX_CHOICES.map((v) => new Option(`1 px = ${v} µm`, String(v))));
    scale.value = window.localStorage.getItem(ELLIPSE_SCALE_KEY) || "auto";
    this.bindControls();
    this.bindPointer();
  }

  // ---- controls ------------------------------------------------------------------------------------

  bindControls() {
    const c = this.controls;
    const redraw = () => this.draw().catch((e) => this.onError(e));
    c.mode.addEventListener("change", () => {
      this.clearReadouts();
      redraw();
    });
    c.band.addEventListener("input", () => {
      this.updateBandLabel();
      this.clearReadouts(); // they were at the previous λ
      redraw();
      this.drawEllipses();
      this.inspector.render();
    });
    c.ev.addEventListener("input", () => {
      this.setExposure(Number(c.ev.value));
      redraw();
    });
    c.evValue.addEventListener("change", () => {
      this.setExposure(Number(c.evValue.value));
      redraw();
    });
    this.root.querySelector("#ev-auto").addEventListener("click", () => {
      this.setAutoExposure();
      redraw();
    });
    for (const control of [c.offset, c.gamma, c.transfer, c.tonemap, c.logScale]) control.addEventListener("change", redraw);
    c.ellipses.addEventListener("change", () => this.loadEllipses().catch((e) => this.onError(e)));
    c.spacing.addEventListener("change", () => {
      this.spacingChosen = true;
      this.loadEllipses().catch((e) => this.onError(e));
    });
    c.spacing.addEventListener("input", () => (c.spacingLabel.textContent = `${c.spacing.value} px`));
    c.ellipseScale.addEventListener("change", () => {
      window.localStorage.setItem(ELLIPSE_SCALE_KEY, c.ellipseScale.value);
      this.drawEllipses();
    });
    this.root.querySelector("#zoom-in").addEventListener("click", () => this.zoomBy(1.5));
    this.root.querySelector("#zoom-out").addEventListener("click", () => this.zoomBy(1 / 1.5));
    this.root.querySelector("#zoom-fit").addEventListener("click", () => this.fit());
    this.root.querySelector("#download-png").addEventListener("click", () => this.downloadPng());
    this.root.querySelector("#download-exr").addEventListener("click", () => this.download(`/v1/jobs/${this.jobId}/artifacts/image.exr`, `${this.jobId}.exr`));
    this.root.querySelector("#download-diagnostics").addEventListener("click", () => this.download(`/v1/jobs/${this.jobId}/diagnostics.exr`, `${this.jobId}_diagnostics.exr`));
  }

  /**
   * The keyboard shortcuts (tev's where they apply), handled at the page level so that they work without
   * clicking the image first. Returns true when `event` was one of them.
   */
  handleKey(event) {
    if (!this.catalogue) return false;
    const c = this.controls;
    const redraw = () => this.draw().catch((e) => this.onError(e));
    const pan = 40;
    const shift = event.shiftKey;
    const key = event.key.length === 1 ? event.key.toLowerCase() : event.key;
    const actions = {
      e: () => (this.setExposure(this.exposureEv() + (shift ? -EV_STEP : EV_STEP)), redraw()),
      o: () => ((c.offset.value = String(Number(c.offset.value) + (shift ? -0.1 : 0.1)).slice(0, 8)), redraw()),
      g: () => ((c.gamma.value = String(Math.max(0.1, Number(c.gamma.value) + (shift ? -0.1 : 0.1)).toFixed(2))), (c.transfer.value = "gamma"), redraw()),
      n: () => (shift ? this.resetDisplay() : this.setAutoExposure(), redraw()),
      f: () => this.fit(),
      0: () => this.fit(),
      "+": () => this.zoomBy(1.5),
      "=": () => this.zoomBy(1.5),
      "-": () => this.zoomBy(1 / 1.5),
      l: () => ((c.logScale.checked = !c.logScale.checked), redraw()),
      c: () => ((c.ellipses.checked = !c.ellipses.checked), this.loadEllipses().catch((e) => this.onError(e))),
      ArrowLeft: () => this.panBy(pan, 0),
      ArrowRight: () => this.panBy(-pan, 0),
      ArrowUp: () => this.panBy(0, pan),
      ArrowDown: () => this.panBy(0, -pan),
    };
    if (/^[1-9]$/.test(event.key)) {
      const option = c.mode.options[Number(event.key) - 1];
      if (!option) return false;
      c.mode.value = option.value;
      this.clearReadouts();
      redraw();
      return true;
    }
    if (!actions[key]) return false;
    actions[key]();
    return true;
  }

  exposureEv() {
    return this.ev ?? 0;
  }

  /**
   * Set the exposure (any EV in ±64). The slider spans the automatic exposure ± 12 EV; beyond it the
   * slider rests at its end and the note says that the box holds the value.
   */
  setExposure(ev) {
    const c = this.controls;
    const value = Math.min(Math.max(Number.isFinite(ev) ? ev : 0, -64), 64);
    this.ev = value; // exact (the automatic exposure is not rounded); the box shows 2 decimals
    c.evValue.value = value.toFixed(2);
    const [lo, hi] = [Number(c.ev.min), Number(c.ev.max)];
    c.ev.value = String(Math.min(Math.max(value, lo), hi));
    const outside = value < lo || value > hi;
    c.evNote.textContent = outside
      ? `clamped: the slider ends at ${value < lo ? lo : hi} EV; the exposure is ${value.toFixed(2)} EV (box)`
      : `auto ${this.autoEv.toFixed(2)} EV`;
    c.evNote.classList.toggle("warning", outside);
    c.ev.setAttribute("aria-valuetext", `${value.toFixed(1)} EV`);
  }

  /** The automatic exposure: the server's (99th luminance percentile → white, as regression runs use). */
  setAutoExposure() {
    this.setExposure(this.autoEv);
  }

  resetDisplay() {
    this.controls.offset.value = "0";
    this.controls.gamma.value = "2.2";
    this.controls.transfer.value = "srgb";
    this.setExposure(0);
  }

  displayOptions() {
    const c = this.controls;
    return { offset: Number(c.offset.value) || 0, gamma: c.transfer.value === "gamma" ? Number(c.gamma.value) || 2.2 : null };
  }

  // ---- pointer, zoom and pan -------------------------------------------------------------------------

  bindPointer() {
    const vp = this.viewport;
    let drag = null;
    vp.addEventListener("pointerdown", (event) => {
      drag = { x: event.clientX, y: event.clientY, panX: this.state.panX, panY: this.state.panY, moved: false };
      vp.setPointerCapture(event.pointerId);
    });
    vp.addEventListener("pointermove", (event) => {
      this.showHover(event.clientX, event.clientY);
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
    vp.addEventListener("pointerleave", () => (this.root.querySelector("#hover-readout").textContent = ""));
    vp.addEventListener(
      "wheel",
      (event) => {
        event.preventDefault();
        const rect = vp.getBoundingClientRect();
        this.zoomBy(event.deltaY < 0 ? 1.25 : 0.8, event.clientX - rect.left, event.clientY - rect.top);
      },
      { passive: false },
    );
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

  panBy(dx, dy) {
    this.state.panX += dx;
    this.state.panY += dy;
    this.applyTransform();
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
    // Strokes are in image pixels (the overlays are scaled with the image): keep them 1.5 screen pixels.
    this.overlay.style.strokeWidth = String(1.5 / zoom);
    // White outlines over a halo (a black copy of each ellipse under it, 1 screen px wider on each side)
    // stay visible on white, black and false-colour images alike.
    this.halo.style.strokeWidth = String(3.5 / zoom);
    this.overlay.style.setProperty("--dash", `${4 / zoom} ${3 / zoom}`); // dashes of 4 and 3 screen px
    this.markers.style.strokeWidth = String(2 / zoom);
    this.root.querySelector("#zoom-label").textContent = `${Math.round(zoom * 100)}%`;
    if (this.ellipses?.length) this.drawEllipses(); // the thinnest axes keep a visible screen width
    this.drawScaleBar();
    this.drawPixelValues();
  }

  // ---- opening an image ------------------------------------------------------------------------------

  /** Show that there is no image (wrong id, job without an image): nothing of the previous one stays. */
  clear(title) {
    this.stopFollowing();
    this.jobId = null;
    this.catalogue = null;
    this.layers.clear();
    this.ellipses = [];
    this.canvas.width = 1;
    this.canvas.height = 1;
    this.canvas.getContext("2d").clearRect(0, 0, 1, 1);
    for (const node of [this.overlay, this.halo, this.markers, this.root.querySelector("#legend"), this.root.querySelector("#ellipse-legend")]) node.replaceChildren();
    this.valueCanvas.getContext("2d").clearRect(0, 0, this.valueCanvas.width, this.valueCanvas.height);
    this.root.querySelector("#scale-bar").hidden = true;
    this.root.querySelector("#viewer-title").textContent = title;
    this.root.querySelector("#viewer-size").textContent = "";
    this.root.querySelector("#viewer-hint").hidden = false;
    this.root.querySelector("#downloads").hidden = true;
    this.inspector.reset({ job_id: "", layers: [], width: 1, height: 1 });
    this.clearReadouts();
    delete this.canvas.dataset.mode;
  }

  /** The hover readout and the ellipse readout describe what was under the pointer in the previous
   * job, layer or wavelength: cleared on every change of those (the next pointer move fills them in). */
  clearReadouts() {
    const readout = this.root.querySelector("#hover-readout");
    readout.textContent = "";
    delete readout.dataset.x;
    delete readout.dataset.y;
    this.root.querySelector("#ellipse-info").textContent = ELLIPSE_HINT;
  }

  /**
   * Load a job's (or an uploaded image's) catalogue and RGB; reset the controls that depend on it.
   * `ellipses`: open with the coherence ellipses shown (a gallery scene whose telling view they are);
   * otherwise the first view is the picture alone, the ellipses one key (C) away.
   */
  async open(jobId, { label, ellipses = false } = {}) {
    if (!/^[0-9a-f]{32}$/.test(jobId)) {
      this.clear("No such job");
      throw new Error(`no such job: ${jobId} (job ids are 32 hexadecimal digits)`);
    }
    this.stopFollowing();
    this.jobId = jobId;
    this.layers.clear();
    // Nothing of the previous job may be read as this one's while it loads.
    this.ellipses = [];
    this.controls.ellipses.checked = ellipses;
    this.inspector.reset({ job_id: jobId, layers: [], width: 1, height: 1 });
    this.clearReadouts();
    try {
      this.catalogue = await this.api.json(`/v1/jobs/${jobId}/layers`);
    } catch (error) {
      this.clear(error.status === 404 ? "No such job" : `Job ${jobId}`);
      if (error.status === 404) throw new Error(`no such job: ${jobId}`);
      throw error;
    }
    const { width, height } = this.catalogue;
    this.canvas.width = width;
    this.canvas.height = height;
    this.stage.style.width = `${width}px`;
    this.stage.style.height = `${height}px`;
    for (const svg of [this.overlay, this.halo, this.markers]) {
      svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
      svg.setAttribute("width", width);
      svg.setAttribute("height", height);
    }
    this.useCatalogue(this.catalogue);
    if (!this.spacingChosen) this.setSpacing(Math.min(width, height) / ELLIPSE_CELLS_ACROSS);
    const band = this.controls.band;
    band.max = String(Math.max(this.bandNames.length - 1, 0));
    // The band nearest 550 nm, where the renderer reports the diagnostics: the first readouts are the
    // stored values (those of the diagnostics EXR and of tev).
    band.value = String(nearestIndex(this.bandNames.map((name) => this.info.get(name).wavelength_nm), REFERENCE_WAVELENGTH_NM));
    this.updateBandLabel();
    const mode = this.controls.mode;
    mode.replaceChildren(new Option("1 · sRGB (from the spectrum)", "srgb"), new Option("2 · single band (false colour)", "band"));
    for (const key of DIAGNOSTIC_MODES) {
      if (this.info.has(layerName(key))) mode.append(new Option(`${mode.options.length + 1} · ${COHERENCE_QUANTITIES[key].title}`, layerName(key)));
    }
    this.root.querySelector("#viewer-title").textContent = this.catalogue.uploaded ? `Local file ${label || ""}`.trim() : `Job ${label || jobId}`;
    this.root.querySelector("#viewer-hint").hidden = true;
    this.describe();
    // The slider is centred on this image's automatic exposure, so it always holds it.
    this.autoEv = this.catalogue.exposure_ev ?? autoExposureEv(await this.layer("rgb"));
    const centre = Math.round(this.autoEv);
    this.controls.ev.min = String(centre - EV_SLIDER_HALF_RANGE);
    this.controls.ev.max = String(centre + EV_SLIDER_HALF_RANGE);
    await this.layer("rgb");
    this.setAutoExposure();
    this.fit();
    await this.draw();
    this.inspector.reset(this.catalogue);
    await this.loadEllipses();
    if (this.catalogue.partial) this.follow(jobId);
  }

  /** Take the layer catalogue of the image being shown. */
  useCatalogue(catalogue) {
    this.catalogue = catalogue;
    this.info = new Map(catalogue.layers.map((layer) => [layer.name, layer]));
    this.bandNames = catalogue.layers.filter((l) => l.kind === "band").map((l) => l.name);
  }

  /** The line under the title (size, bands, what a preview is) and the download buttons. */
  describe() {
    const { width, height, uploaded, partial, spp } = this.catalogue;
    const refining = partial ? ` — preview at ${spp ?? "?"} spp (job running; refreshes as chunks or rounds finish)` : "";
    const source = uploaded ? " — dropped EXR, held in the service's memory (not stored)" : "";
    const size = this.root.querySelector("#viewer-size");
    size.textContent = `${width}×${height} px, ${this.bandNames.length} bands${refining}${source}`;
    size.dataset.spp = spp ?? "";
    this.root.querySelector("#downloads").hidden = false;
    const exr = this.root.querySelector("#download-exr");
    exr.disabled = uploaded || partial;
    exr.title = exr.disabled ? "the spectral EXR exists once the job has finished (a dropped file is already on your disk)" : "";
    this.root.querySelector("#download-diagnostics").disabled = !this.info.has("coherence.weight");
  }

  /**
   * While a running job's preview is shown, check its job every PREVIEW_POLL_MS and load the newer
   * preview when a chunk or a noise-target round finished, or the final image once it succeeded. The
   * zoom, pan, exposure and display mode stay as the user set them.
   */
  follow(jobId) {
    let revision = null;
    const tick = async () => {
      if (this.jobId !== jobId) return;
      try {
        const job = await this.api.json(`/v1/jobs/${jobId}`);
        const now = `${job.status}/${previewRevision(job)}`;
        if (revision !== null && now !== revision) await this.refresh(jobId);
        revision = now;
        if (job.status !== "running") return this.stopFollowing();
      } catch {
        // A transient error (the preview replaced while it was read): the next tick tries again.
      }
      if (this.jobId === jobId) this.followTimer = window.setTimeout(tick, PREVIEW_POLL_MS);
    };
    this.followTimer = window.setTimeout(tick, 0);
  }

  stopFollowing() {
    window.clearTimeout(this.followTimer);
    this.followTimer = null;
  }

  /** Load the job's current image (a newer preview or the final image) in place of the one shown. */
  async refresh(jobId) {
    const catalogue = await this.api.json(`/v1/jobs/${jobId}/layers`);
    if (this.jobId !== jobId || catalogue.width !== this.catalogue.width || catalogue.height !== this.catalogue.height) return;
    // The layers shown are loaded anew before anything is drawn; if one fails, the old image stays.
    const shown = [...this.layers.keys()];
    const previous = { layers: this.layers, catalogue: this.catalogue };
    this.layers = new Map();
    this.useCatalogue(catalogue);
    try {
      for (const name of shown) await this.layer(name);
    } catch (error) {
      this.layers = previous.layers;
      this.useCatalogue(previous.catalogue);
      throw error;
    }
    if (this.jobId !== jobId) return;
    await this.draw();
    this.describe(); // after the draw: the line never names a preview that is not on the canvas yet
    this.inspector.render();
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

  updateBandLabel() {
    const nm = this.wavelengthNm();
    this.controls.bandLabel.textContent = `${nm.toFixed(1)} nm`;
    this.controls.band.setAttribute("aria-valuetext", `${nm.toFixed(1)} nanometres`);
  }

  /** Current wavelength of the slider (nm). */
  wavelengthNm() {
    const name = this.bandNames?.[Number(this.controls.band.value)];
    return name ? this.info.get(name).wavelength_nm : REFERENCE_WAVELENGTH_NM;
  }

  /** The layer shown now: name, display unit, channel count (rgb: 3) and coherence key (null if none). */
  currentLayer() {
    const mode = this.controls.mode.value;
    if (mode === "srgb") return { name: "rgb", unit: this.info.get("rgb")?.unit ?? "", channels: 3, key: null };
    const name = mode === "band" ? this.bandNames[Number(this.controls.band.value)] : mode;
    const key = coherenceKey(name);
    return { name, unit: key ? COHERENCE_QUANTITIES[key].unit : this.info.get(name).unit, channels: 1, key };
  }

  // ---- drawing -------------------------------------------------------------------------------------

  /** Render the current mode into the canvas (one canvas pixel per image pixel). */
  async draw() {
    if (!this.catalogue) return;
    const { width, height } = this.catalogue;
    const mode = this.controls.mode.value;
    const ev = this.exposureEv();
    const operator = this.controls.tonemap.value;
    const image = new ImageData(width, height);
    const legend = this.root.querySelector("#legend");
    const isSrgb = mode === "srgb";
    for (const control of ["tonemap", "ev", "evValue", "offset", "gamma", "transfer"]) this.controls[control].disabled = !isSrgb;
    this.controls.logScale.disabled = isSrgb;
    let histogramValues;
    if (isSrgb) {
      const rgb = await this.layer("rgb");
      const options = this.displayOptions();
      displayRgb8(rgb, image.data, ev, operator, options);
      const scale = Math.pow(2, ev);
      histogramValues = Array.from(luminance(rgb), (y) => (y > 0 ? Math.log2(y * scale) : -Infinity));
      legend.replaceChildren();
      const transfer = options.gamma ? `gamma ${options.gamma}` : "sRGB curve";
      legend.textContent = `sRGB display: ${ev.toFixed(1)} EV, offset ${options.offset}, ${operator}, ${transfer}`;
      this.drawHistogram(histogramValues, HISTOGRAM_EV_RANGE, "log₂ luminance (EV, 0 = white)");
    } else {
      const { name, unit, key } = this.currentLayer();
      const info = this.info.get(name);
      const values = await this.layer(name);
      const covered = info.kind === "coherence" ? await this.layer("coherence.weight") : null;
      // An orientation is cyclic: a fixed [−90°, 90°] range on a colour wheel, never a log scale.
      const orientation = key === "angle";
      this.controls.logScale.disabled = orientation;
      const scale = orientation ? makeScale(-Math.PI / 2, Math.PI / 2) : makeScale(info.p01 ?? 0, info.p99 ?? 1, this.controls.logScale.checked);
      const colourOf = orientation ? (v) => cyclic(orientationT(v)) : (v) => viridis(scale.t(v));
      histogramValues = [];
      for (let i = 0; i < values.length; i++) {
        const rgb = covered && !(covered[i] > 0) ? UNCOVERED_RGB : colourOf(values[i]);
        if (!covered || covered[i] > 0) histogramValues.push(orientation ? orientationT(values[i]) : scale.t(values[i]));
        image.data[4 * i] = rgb[0];
        image.data[4 * i + 1] = rgb[1];
        image.data[4 * i + 2] = rgb[2];
        image.data[4 * i + 3] = 255;
      }
      // The colour scale is of the stored (550 nm) values; its ticks, like every readout, are at the
      // slider's λ. Scaling values and bounds alike leaves each pixel's colour as it is.
      const nm = this.wavelengthNm();
      const title = key ? quantityTitle(key, nm) : `band ${info.wavelength_nm.toFixed(1)} nm`;
      drawColourBar(legend, scale, unit, title, {
        colour: orientation ? cyclic : viridis,
        tickValue: key ? (v) => displayValue(key, v, nm) : undefined,
      });
      if (orientation) legend.querySelector(".colourbar-title").textContent += " — cyclic: −90° and +90° are the same direction";
      this.drawHistogram(histogramValues, [0, 1], "colour-bar position");
    }
    this.canvas.getContext("2d").putImageData(image, 0, 0);
    this.canvas.dataset.mode = mode;
    this.canvas.dataset.ev = String(ev);
    this.canvas.setAttribute("aria-label", `rendered image: ${this.controls.mode.selectedOptions[0]?.textContent ?? mode}`);
    this.drawPixelValues();
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

  /** The value(s) of the shown layer at pixel (x, y) as text (RGB: three values). */
  valueText(x, y, withUnit = true) {
    const layer = this.currentLayer();
    const data = this.layers.get(layer.name);
    if (!data) return "";
    const i = y * this.catalogue.width + x;
    const unit = withUnit ? layer.unit : "";
    if (layer.channels === 3) return [0, 1, 2].map((c) => formatValue(data[3 * i + c])).join(" ") + (unit ? ` ${unit}` : "");
    if (!layer.key) return formatValue(data[i], unit);
    const weight = this.layers.get("coherence.weight");
    if (weight && !(weight[i] > 0)) return "no diagnostics";
    return formatValue(displayValue(layer.key, data[i], this.wavelengthNm()), unit);
  }

  showHover(clientX, clientY) {
    const readout = this.root.querySelector("#hover-readout");
    const pixel = this.catalogue && this.pixelAt(clientX, clientY);
    if (!pixel) {
      readout.textContent = "";
      return;
    }
    const layer = this.currentLayer();
    const name = layer.name === "rgb" ? "linear R G B" : layer.key ? quantityTitle(layer.key, this.wavelengthNm()) : layer.name;
    readout.textContent = `(${pixel.x}, ${pixel.y}) ${name}: ${this.valueText(pixel.x, pixel.y)}`;
    readout.dataset.x = String(pixel.x);
    readout.dataset.y = String(pixel.y);
  }

  /** At ≥ 48 screen px per image pixel, each visible pixel shows its value (as tev does). */
  drawPixelValues() {
    const canvas = this.valueCanvas;
    const { clientWidth: w, clientHeight: h } = this.viewport;
    if (canvas.width !== w || canvas.height !== h) [canvas.width, canvas.height] = [w, h];
    const ctx = canvas.getContext("2d");
    ctx.clearRect(0, 0, w, h);
    const { zoom, panX, panY } = this.state;
    canvas.dataset.values = "0";
    if (!this.catalogue || zoom < VALUE_ZOOM) return;
    const layer = this.currentLayer();
    const data = this.layers.get(layer.name);
    if (!data) return;
    const [x0, x1] = [Math.max(0, Math.floor(-panX / zoom)), Math.min(this.catalogue.width, Math.ceil((w - panX) / zoom))];
    const [y0, y1] = [Math.max(0, Math.floor(-panY / zoom)), Math.min(this.catalogue.height, Math.ceil((h - panY) / zoom))];
    ctx.font = `${Math.min(13, zoom / 5)}px ui-monospace, monospace`;
    ctx.textAlign = "center";
    ctx.textBaseline = "middle";
    ctx.lineWidth = 3;
    ctx.strokeStyle = "rgba(0, 0, 0, 0.8)";
    ctx.fillStyle = "#fff";
    let drawn = 0;
    for (let y = y0; y < y1; y++) {
      for (let x = x0; x < x1; x++) {
        const cx = panX + (x + 0.5) * zoom;
        const cy = panY + (y + 0.5) * zoom;
        const lines = layer.channels === 3 ? this.valueText(x, y, false).split(" ") : [this.valueText(x, y, false)];
        lines.forEach((text, k) => {
          const ty = cy + (k - (lines.length - 1) / 2) * Math.min(14, zoom / 4);
          ctx.fillStyle = lines.length === 3 ? CHANNEL_TEXT_COLOURS[k] : "#fff";
          ctx.strokeText(text, cx, ty);
          ctx.fillText(text, cx, ty);
        });
        drawn += 1;
      }
    }
    canvas.dataset.values = String(drawn);
  }

  /** A and B of the pixel inspector: a square around the pixel and its letter, in the slot's colour. */
  drawMarkers() {
    this.markers.replaceChildren();
    const ns = "http://www.w3.org/2000/svg";
    for (const [slot, pixel] of Object.entries(this.inspector.pixels)) {
      if (!pixel) continue;
      const group = document.createElementNS(ns, "g");
      group.dataset.slot = slot;
      group.setAttribute("class", "marker");
      const square = document.createElementNS(ns, "rect");
      Object.entries({ x: pixel.x, y: pixel.y, width: 1, height: 1, fill: "none", stroke: SLOT_COLOURS[slot] }).forEach(([k, v]) => square.setAttribute(k, v));
      const letter = document.createElementNS(ns, "text");
      Object.entries({ x: pixel.x + 1.2, y: pixel.y + 0.2, fill: SLOT_COLOURS[slot], "font-size": Math.max(1.2, 14 / this.state.zoom), "dominant-baseline": "hanging" }).forEach(([k, v]) => letter.setAttribute(k, v));
      letter.textContent = slot;
      group.append(square, letter);
      this.markers.append(group);
    }
  }

  // ---- coherence ellipses ----------------------------------------------------------------------------

  async loadEllipses() {
    this.ellipses = [];
    const jobId = this.jobId;
    if (jobId && this.controls.ellipses.checked) {
      const grid = await this.api.json(`/v1/jobs/${jobId}/ellipses?spacing=${this.controls.spacing.value}`);
      if (this.jobId !== jobId || !this.controls.ellipses.checked) return; // another job, or switched off
      this.ellipses = grid.ellipses;
    }
    this.drawEllipses();
  }

  /** Grid spacing of the ellipses: the even number of pixels nearest `px` within the slider's range. */
  setSpacing(px) {
    const c = this.controls;
    const even = 2 * Math.round(px / 2);
    c.spacing.value = String(Math.min(Math.max(even, Number(c.spacing.min)), Number(c.spacing.max)));
    c.spacingLabel.textContent = `${c.spacing.value} px`;
  }

  /** Is the ellipse scale "auto" (chosen per image, with the largest ellipses kept inside their cell)? */
  autoScale() {
    return this.controls.ellipseScale.value === "auto";
  }

  /**
   * µm per image pixel of the ellipses: the chosen fixed value (kept across jobs, so they compare), or
   * "auto": the 1-2-5 value at which the median ℓ₁ at the slider's λ is AUTO_MEDIAN_FRACTION of the grid
   * spacing.
   */
  umPerPx() {
    if (!this.autoScale()) return Number(this.controls.ellipseScale.value);
    const factor = this.wavelengthNm() / REFERENCE_WAVELENGTH_NM;
    const l1 = this.ellipses.map((e) => e.l1_um * factor).sort((a, b) => a - b);
    const target = l1[Math.floor(l1.length / 2)] / (AUTO_MEDIAN_FRACTION * Number(this.controls.spacing.value));
    return UM_PER_PX_CHOICES.find((v) => v >= target) ?? UM_PER_PX_CHOICES[UM_PER_PX_CHOICES.length - 1];
  }

  /** What the ellipses show, said whether they are drawn or not (`state`: on/off and the key). */
  ellipseExplanation(nm, state) {
    return (
      `Coherence ellipses (${state}): at each grid point, the patch over which the light reaching that pixel ` +
      `stays coherent (|μ| ≥ 1/√e); semi-axes ℓ₁ ≥ ℓ₂ at λ = ${nm.toFixed(0)} nm (the wavelength slider; ` +
      `reported at 550 nm, ∝ λ).`
    );
  }

  /**
   * Ellipses: semi-axes ℓ₁(λ), ℓ₂(λ) in µm at the slider's λ, drawn at `umPerPx`; rotated by −angle;
   * clipped to the image. With the auto scale an ellipse longer than AUTO_MAX_FRACTION of the grid spacing
   * is shrunk to it, both axes alike, and drawn dashed (the legend says how many).
   */
  drawEllipses() {
    this.overlay.replaceChildren();
    this.halo.replaceChildren();
    const legend = this.root.querySelector("#ellipse-legend");
    legend.replaceChildren();
    const grid = this.ellipses || [];
    this.root.querySelector("#scale-bar").hidden = !grid.length;
    this.overlay.dataset.count = String(grid.length);
    this.overlay.dataset.shrunk = "0";
    delete this.overlay.dataset.umPerPx;
    this.root.querySelector("#ellipse-info").hidden = !grid.length;
    const nm = this.wavelengthNm();
    const note = document.createElement("p");
    note.className = "small ellipse-scale-note";
    if (!grid.length) {
      const state = this.controls.ellipses.checked ? "none: no grid point has diagnostics" : "off: press C to draw them";
      if (this.info?.has("coherence.l1_um")) note.textContent = this.ellipseExplanation(nm, state);
      legend.append(note);
      return;
    }
    const lambdaFactor = nm / REFERENCE_WAVELENGTH_NM;
    const umPerPx = this.umPerPx();
    this.overlay.dataset.umPerPx = String(umPerPx);
    const minRadius = MIN_SEMI_AXIS_SCREEN_PX / this.state.zoom;
    const maxRadius = this.autoScale() ? AUTO_MAX_FRACTION * Number(this.controls.spacing.value) : Infinity;
    const areas = grid.map((e) => e.area_um2);
    const areaScale = makeScale(Math.min(...areas), Math.max(...areas), true);
    const legendScale = makeScale(areaScale.lo * lambdaFactor ** 2, areaScale.hi * lambdaFactor ** 2, true);
    drawColourBar(legend, legendScale, "µm²", `ellipse fill: coherence area at ${nm.toFixed(0)} nm`);
    const ns = "http://www.w3.org/2000/svg";
    let shrunk = 0;
    for (const e of grid) {
      const cx = e.x + 0.5;
      const cy = e.y + 0.5;
      const major = (e.l1_um * lambdaFactor) / umPerPx;
      const shrink = major > maxRadius ? maxRadius / major : 1;
      if (shrink < 1) shrunk += 1;
      const shape = document.createElementNS(ns, "ellipse");
      const [r, g, b] = viridis(areaScale.t(e.area_um2));
      shape.setAttribute("cx", cx);
      shape.setAttribute("cy", cy);
      shape.setAttribute("rx", Math.max(major * shrink, minRadius));
      shape.setAttribute("ry", Math.max(((e.l2_um * lambdaFactor) / umPerPx) * shrink, minRadius));
      shape.setAttribute("transform", `rotate(${(-e.angle * 180) / Math.PI} ${cx} ${cy})`);
      shape.setAttribute("fill", `rgb(${r},${g},${b})`);
      if (shrink < 1) shape.classList.add("shrunk");
      Object.assign(shape.dataset, {
        x: e.x,
        y: e.y,
        l1Um: e.l1_um * lambdaFactor,
        l2Um: e.l2_um * lambdaFactor,
        angle: e.angle,
        areaUm2: e.area_um2 * lambdaFactor * lambdaFactor,
        shrink,
      });
      const halo = shape.cloneNode();
      for (const attribute of ["fill", "stroke"]) halo.removeAttribute(attribute);
      this.halo.append(halo);
      const title = document.createElementNS(ns, "title");
      title.textContent = ellipseText(shape.dataset, nm);
      shape.append(title);
      this.overlay.append(shape);
    }
    this.overlay.dataset.shrunk = String(shrunk);
    const scaleText = `${this.autoScale() ? "Auto scale: " : ""}1 image px = ${umPerPx} µm`;
    const shrunkText = shrunk ? ` ${shrunk} of ${grid.length} would outgrow their grid cell: dashed, shrunk to it (shape kept; hover for the true size).` : "";
    note.textContent = `${this.ellipseExplanation(nm, "C hides them")} ${scaleText}; clipped to the image; semi-axes under ${MIN_SEMI_AXIS_SCREEN_PX} screen px drawn ${MIN_SEMI_AXIS_SCREEN_PX} px wide.${shrunkText}`;
    legend.append(note);
    this.drawScaleBar();
  }

  /** A bar of a round number of µm, on screen at the ellipses' scale and the current zoom. */
  drawScaleBar() {
    const bar = this.root.querySelector("#scale-bar");
    if (!this.ellipses?.length) return;
    const screenPxPerUm = this.state.zoom / this.umPerPx();
    const target = SCALE_BAR_TARGET_PX / screenPxPerUm;
    const power = Math.pow(10, Math.floor(Math.log10(target)));
    const lengthUm = [5, 2, 1].map((m) => m * power).find((v) => v <= target) ?? power;
    bar.querySelector(".scale-bar-line").style.width = `${lengthUm * screenPxPerUm}px`;
    bar.querySelector(".scale-bar-label").textContent = `${formatValue(lengthUm, "µm")} (ellipses at ${this.wavelengthNm().toFixed(0)} nm)`;
    bar.dataset.lengthUm = String(lengthUm);
    bar.dataset.widthPx = String(lengthUm * screenPxPerUm);
  }

  showEllipseInfo(shape) {
    this.root.querySelector("#ellipse-info").textContent = ellipseText(shape.dataset, this.wavelengthNm());
  }

  // ---- downloads -------------------------------------------------------------------------------------

  /** The canvas as shown (mode, exposure, tone map, offset, gamma), one PNG pixel per image pixel. */
  downloadPng() {
    const mode = this.controls.mode.value.replace(/[^A-Za-z0-9_.-]/g, "_");
    this.canvas.toBlob((blob) => saveBlob(blob, `${this.jobId}_${mode}.png`), "image/png");
  }

  /** An authenticated download (the token is a header, so a plain link cannot carry it). */
  async download(path, filename) {
    try {
      const response = await this.api.request(path);
      saveBlob(await response.blob(), filename);
    } catch (error) {
      this.onError(error);
    }
  }
}

export function ellipseText(d, wavelengthNm) {
  const degrees = displayValue("angle", Number(d.angle), wavelengthNm);
  return (
    `pixel (${d.x}, ${d.y}) at ${wavelengthNm.toFixed(0)} nm: ℓ₁ ${formatValue(Number(d.l1Um), "µm")}, ` +
    `ℓ₂ ${formatValue(Number(d.l2Um), "µm")}, angle ${degrees.toFixed(1)}°, area ${formatValue(Number(d.areaUm2), "µm²")}`
  );
}

/** Index of the value nearest `target` (0 for an empty list). */
function nearestIndex(values, target) {
  let best = 0;
  values.forEach((v, i) => {
    if (Math.abs(v - target) < Math.abs(values[best] - target)) best = i;
  });
  return best;
}
