// False colour: viridis (a 6th-order polynomial fit of matplotlib's map, after Matt Zucker's shader) with a
// colour bar and unit-aware tick labels. t in [0, 1] → 8-bit RGB, quantised as floor(255·v + 0.5).

const VIRIDIS = [
  [0.2777273272234177, 0.005407344544966578, 0.3340998053353061],
  [0.1050930431085774, 1.404613529898575, 1.384590162594685],
  [-0.3308618287255563, 0.214847559468213, 0.09509516302823659],
  [-4.634230498983486, -5.799100973351585, -19.33244095627987],
  [6.228269936347081, 14.17993336680509, 56.69055260068105],
  [4.776384997670288, -13.74514537774601, -65.35303263337234],
  [-5.435455855934631, 4.645852612178535, 26.3124352495832],
];

/** Viridis colour of t (clamped to [0, 1]) as [r, g, b] in 0..255. */
export function viridis(t) {
  const x = Math.min(Math.max(Number.isFinite(t) ? t : 0, 0), 1);
  const rgb = [0, 0, 0];
  for (let c = 0; c < 3; c++) {
    let v = VIRIDIS[6][c];
    for (let k = 5; k >= 0; k--) v = VIRIDIS[k][c] + x * v;
    rgb[c] = Math.floor(Math.min(Math.max(v, 0), 1) * 255 + 0.5);
  }
  return rgb;
}

/**
 * A scale from values to t ∈ [0, 1]: linear over [lo, hi], or log10 over [lo, hi] (lo > 0 required;
 * falls back to linear otherwise).
 */
export function makeScale(lo, hi, log = false) {
  const useLog = log && lo > 0 && hi > lo;
  if (useLog) {
    const a = Math.log10(lo);
    const span = Math.log10(hi) - a;
    return { lo, hi, log: true, t: (v) => (v > 0 ? (Math.log10(v) - a) / span : 0), value: (t) => Math.pow(10, a + t * span) };
  }
  const span = hi > lo ? hi - lo : 1;
  return { lo, hi, log: false, t: (v) => (v - lo) / span, value: (t) => lo + t * span };
}

/** Compact number with its unit: 3 significant digits, exponent for very large or small values. */
export function formatValue(value, unit = "") {
  if (value === null || value === undefined || !Number.isFinite(value)) return "—";
  const magnitude = Math.abs(value);
  const text = magnitude !== 0 && (magnitude >= 1e5 || magnitude < 1e-2) ? value.toExponential(2) : value.toPrecision(3);
  return unit && unit !== "1" ? `${text} ${unit}` : text;
}

/** Draw a horizontal colour bar with 5 tick labels into `container` (replaces its content). */
export function drawColourBar(container, scale, unit, title) {
  container.replaceChildren();
  const heading = document.createElement("div");
  heading.className = "colourbar-title";
  heading.textContent = `${title}${unit && unit !== "1" ? ` [${unit}]` : ""}${scale.log ? " (log)" : ""}`;
  const canvas = document.createElement("canvas");
  canvas.width = 256;
  canvas.height = 12;
  canvas.className = "colourbar";
  canvas.setAttribute("role", "img");
  canvas.setAttribute("aria-label", `colour bar from ${formatValue(scale.lo, unit)} to ${formatValue(scale.hi, unit)}`);
  const ctx = canvas.getContext("2d");
  for (let i = 0; i < 256; i++) {
    const [r, g, b] = viridis(i / 255);
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.fillRect(i, 0, 1, 12);
  }
  const ticks = document.createElement("div");
  ticks.className = "colourbar-ticks";
  for (let k = 0; k <= 4; k++) {
    const tick = document.createElement("span");
    tick.textContent = formatValue(scale.value(k / 4), "");
    ticks.append(tick);
  }
  container.append(heading, canvas, ticks);
}
