// Pixel inspector: spectrum across bands (plot with nm and radiance axes, legend, hover readout), linear
// RGB and coherence values of up to two pixels (slots A and B, marked on the image by the viewer), and
// each pixel's spectrum as CSV. Values come from GET /v1/jobs/{id}/pixel.
//
// Units and wavelength as everywhere in the viewer (web/js/diagnostics.js): lengths, area and M at the
// wavelength slider's λ (the renderer reports them at 550 nm), angles in degrees.

import { formatValue } from "./colormap.js";
import { COHERENCE_QUANTITIES, displayValue } from "./diagnostics.js";
import { drawPlot } from "./plot.js";

export const SLOT_COLOURS = { A: "#fbbc04", B: "#f28b82" };
const COHERENCE_ROWS = ["l1_um", "l2_um", "angle", "anisotropy", "area_um2", "r_m", "Mxx", "Mxy", "Myy"];

/** CSV of one pixel's spectrum: a header naming pixel, job and unit, then wavelength_nm,value rows. */
export function spectrumCsv(jobId, pixel) {
  const lines = [`# job ${jobId} pixel x=${pixel.x} y=${pixel.y}; band-averaged spectral radiance in ${pixel.spectrum_unit}`, "wavelength_nm,radiance"];
  pixel.wavelengths_nm.forEach((nm, i) => lines.push(`${nm},${pixel.spectrum[i] ?? ""}`));
  return lines.join("\n") + "\n";
}

/** Let the browser save `blob` as `filename`. */
export function saveBlob(blob, filename) {
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = filename;
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 10_000);
}

export class PixelInspector {
  /** `wavelengthNm()` gives the slider's λ; `onChange(pixels)` is called when A or B changes. */
  constructor(root, api, { onError, wavelengthNm, onChange }) {
    this.root = root;
    this.api = api;
    this.onError = onError;
    this.wavelengthNm = wavelengthNm;
    this.onChange = onChange;
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
    for (const slot of ["A", "B"]) {
      root.querySelector(`.pixels > [data-slot="${slot}"] .pixel-csv`).addEventListener("click", () => {
        const pixel = this.pixels[slot];
        if (pixel) saveBlob(new Blob([spectrumCsv(this.jobId, pixel)], { type: "text/csv" }), `spectrum_${this.jobId.slice(0, 8)}_x${pixel.x}_y${pixel.y}.csv`);
      });
    }
  }

  reset(catalogue) {
    this.jobId = catalogue.job_id;
    this.unit = catalogue.layers.find((l) => l.kind === "band")?.unit || "";
    this.pixels = { A: null, B: null };
    this.root.querySelector("#spectrum-readout").textContent = "";
    this.root.querySelector("#inspect-x").max = String(catalogue.width - 1);
    this.root.querySelector("#inspect-y").max = String(catalogue.height - 1);
    this.render();
  }

  /** Fetch pixel (x, y) into the slot chosen by the "click sets" control. */
  async inspect(jobId, x, y) {
    this.jobId = jobId;
    const slot = this.root.querySelector('input[name="inspect-slot"]:checked')?.value || "A";
    const pixel = await this.api.json(`/v1/jobs/${jobId}/pixel?x=${x}&y=${y}`);
    if (this.jobId !== jobId) return; // another job was opened meanwhile: its inspector starts empty
    this.pixels[slot] = pixel;
    this.root.querySelector("#inspect-x").value = String(x);
    this.root.querySelector("#inspect-y").value = String(y);
    this.render();
  }

  render() {
    for (const slot of ["A", "B"]) this.renderSlot(slot, this.pixels[slot]);
    this.plotSpectra();
    this.onChange?.(this.pixels);
  }

  renderSlot(slot, pixel) {
    const box = this.root.querySelector(`.pixels > [data-slot="${slot}"]`);
    box.hidden = !pixel;
    if (!pixel) return;
    const nm = this.wavelengthNm();
    box.querySelector(".pixel-title").textContent = `Pixel ${slot}: (${pixel.x}, ${pixel.y})`;
    box.querySelector(".pixel-title").style.color = SLOT_COLOURS[slot];
    box.querySelector(".pixel-rgb").textContent = `linear RGB ${pixel.rgb.map((v) => formatValue(v)).join(", ")} ${pixel.spectrum_unit}`;
    const rows = COHERENCE_ROWS.map((key) => {
      const { label, unit } = COHERENCE_QUANTITIES[key];
      const value = displayValue(key, pixel.coherence[key], nm);
      return `<tr data-key="${key}" data-value="${value ?? ""}"><th scope="row">${label}</th><td>${formatValue(value, unit)}</td></tr>`;
    });
    box.querySelector(".pixel-coherence").innerHTML = pixel.coherence_covered
      ? `<caption>coherence at ${nm.toFixed(0)} nm (wavelength slider; ℓ, area and M scale with λ)</caption>${rows.join("")}`
      : "<caption>no coherence diagnostics at this pixel</caption>";
  }

  /** Spectrum plot of slots A and B (shared axes: wavelength in nm, band radiance). */
  plotSpectra() {
    const svg = this.root.querySelector("#spectrum-plot");
    const present = ["A", "B"].filter((s) => this.pixels[s]);
    svg.toggleAttribute("hidden", !present.length); // SVG elements have no .hidden property
    this.root.querySelector("#inspector-hint").hidden = Boolean(present.length);
    this.root.querySelector("#spectrum-legend").hidden = !present.length;
    if (!present.length) {
      svg.replaceChildren();
      return;
    }
    const readout = this.root.querySelector("#spectrum-readout");
    readout.textContent = "Hover the plot for band values.";
    drawPlot(svg, {
      series: present.map((slot) => {
        const p = this.pixels[slot];
        return { id: slot, name: `${slot} (${p.x}, ${p.y})`, colour: SLOT_COLOURS[slot], points: p.wavelengths_nm.map((nm, i) => [nm, p.spectrum[i]]) };
      }),
      x: { label: "wavelength λ", unit: "nm", format: (nm) => nm.toFixed(0) },
      y: { label: "radiance", unit: this.unit },
      legend: this.root.querySelector("#spectrum-legend"),
      readout,
      readoutText: (nm, hits) => `λ ${nm.toFixed(1)} nm: ${hits.map((h) => `${h.name.split(" ")[0]} ${formatValue(h.point[1], this.unit)}`).join(", ")}`,
    });
    svg.setAttribute("aria-label", `spectrum of pixel ${present.join(" and ")}: wavelength in nm against radiance in ${this.unit}`);
  }
}
