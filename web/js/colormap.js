// False colour: viridis (a 6th-order polynomial fit of matplotlib's map, after Matt Zucker's shader) for
// magnitudes, a cyclic hue wheel for orientations, a colour bar and unit-aware tick labels. t in [0, 1] →
// 8-bit RGB, quantised as floor(255·v + 0.5).

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

// The cyclic map: constant OKLab lightness L and chroma C, hue h = 2π·t (t = 0 and t = 1 are the same
// colour, as −90° and +90° are the same orientation). L = 0.75, C = 0.12 stays inside the sRGB gamut at
// every hue (min channel 0.02, max 0.96), so no hue is clipped and neighbouring angles stay distinct.
const CYCLIC_LIGHTNESS = 0.75;
const CYCLIC_CHROMA = 0.12;

/** Cyclic colour of t (period 1) as [r, g, b] in 0..255: OKLab (Ottosson 2020) → linear sRGB → sRGB. */
export function cyclic(t) {
  const h = 2 * Math.PI * (Number.isFinite(t) ? t : 0);
  const [L, a, b] = [CYCLIC_LIGHTNESS, CYCLIC_CHROMA * Math.cos(h), CYCLIC_CHROMA * Math.sin(h)];
  const l = (L + 0.3963377774 * a + 0.2158037573 * b) ** 3;
  const m = (L - 0.1055613458 * a - 0.0638541728 * b) ** 3;
  const s = (L - 0.0894841775 * a - 1.291485548 * b) ** 3;
  const linear = [
    4.0767416621 * l - 3.3077115913 * m + 0.2309699292 * s,
    -1.2684380046 * l + 2.6097574011 * m - 0.3413193965 * s,
    -0.0041960863 * l - 0.7034186147 * m + 1.707614701 * s,
  ];
  return linear.map((v) => {
    const c = Math.min(Math.max(v, 0), 1);
    const encoded = c <= 0.0031308 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055;
    return Math.floor(encoded * 255 + 0.5);
  });
}

export const SYMLOG_DECADES = 3;

/**
 * A scale from values to t ∈ [0, 1]: linear over [lo, hi], or logarithmic (`log`). Log of a range with
 * lo > 0 is log10 over [lo, hi]; when lo ≤ 0 (a black pixel in the 1st percentile, negative values) it
 * is symlog: s(v) = sign(v)·log10(1 + |v|/c), linear within ±c, with c = max(|lo|, |hi|)·10^−3 (three
 * decades of log range below the largest magnitude), mapped linearly from s(lo) to s(hi).
 * `kind` says which: "linear", "log" or "symlog".
 */
export function makeScale(lo, hi, log = false) {
  if (log && lo > 0 && hi > lo) {
    const a = Math.log10(lo);
    const span = Math.log10(hi) - a;
    return { lo, hi, log: true, kind: "log", t: (v) => (v > 0 ? (Math.log10(v) - a) / span : 0), value: (t) => Math.pow(10, a + t * span) };
  }
  if (log && hi > lo) {
    const c = Math.max(Math.abs(lo), Math.abs(hi)) * Math.pow(10, -SYMLOG_DECADES);
    const s = (v) => Math.sign(v) * Math.log10(1 + Math.abs(v) / c);
    const inverse = (u) => Math.sign(u) * c * (Math.pow(10, Math.abs(u)) - 1);
    const [s0, span] = [s(lo), s(hi) - s(lo)];
    return { lo, hi, log: true, kind: "symlog", linearWithin: c, t: (v) => (s(v) - s0) / span, value: (t) => inverse(s0 + t * span) };
  }
  const span = hi > lo ? hi - lo : 1;
  return { lo, hi, log: false, kind: "linear", t: (v) => (v - lo) / span, value: (t) => lo + t * span };
}

/** Compact number with its unit: 3 significant digits, exponent for very large or small values. */
export function formatValue(value, unit = "") {
  if (value === null || value === undefined || !Number.isFinite(value)) return "—";
  const magnitude = Math.abs(value);
  const text = magnitude !== 0 && (magnitude >= 1e5 || magnitude < 1e-2) ? value.toExponential(2) : value.toPrecision(3);
  return unit && unit !== "1" ? `${text} ${unit}` : text;
}

/**
 * Draw a horizontal colour bar with 5 tick labels into `container` (replaces its content). `colour(t)` is
 * the colour map (viridis by default); `tickValue(v)` turns a scale value into the number shown (e.g. a
 * length stored at 550 nm into its value at the shown wavelength, radians into degrees).
 */
export function drawColourBar(container, scale, unit, title, { colour = viridis, tickValue = (v) => v } = {}) {
  container.replaceChildren();
  const heading = document.createElement("div");
  heading.className = "colourbar-title";
  const kind = scale.kind === "symlog" ? ` (symlog: linear within ±${formatValue(scale.linearWithin)})` : scale.log ? " (log)" : "";
  heading.textContent = `${title}${unit && unit !== "1" ? ` [${unit}]` : ""}${kind}`;
  container.dataset.scale = scale.kind || "linear";
  const canvas = document.createElement("canvas");
  canvas.width = 256;
  canvas.height = 12;
  canvas.className = "colourbar";
  canvas.setAttribute("role", "img");
  canvas.setAttribute("aria-label", `colour bar from ${formatValue(tickValue(scale.lo), unit)} to ${formatValue(tickValue(scale.hi), unit)}`);
  const ctx = canvas.getContext("2d");
  for (let i = 0; i < 256; i++) {
    const [r, g, b] = colour(i / 255);
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.fillRect(i, 0, 1, 12);
  }
  const ticks = document.createElement("div");
  ticks.className = "colourbar-ticks";
  for (let k = 0; k <= 4; k++) {
    const tick = document.createElement("span");
    tick.textContent = formatValue(tickValue(scale.value(k / 4)), "");
    ticks.append(tick);
  }
  container.append(heading, canvas, ticks);
}
