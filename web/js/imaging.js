// Display transforms of the viewer: the same formulas as hgcore/imaging.py (tests compare canvas pixels
// with the server's display_rgb8 of the same data).
//
//   exposure:     linear × 2^EV
//   tone maps:    clamp (identity), reinhard x/(1+x), aces (Narkowicz 2015) x(2.51x+0.03)/(x(2.43x+0.59)+0.14),
//                 each on max(x, 0) per channel, then clipped to [0, 1]
//   sRGB curve:   12.92·x for x ≤ 0.0031308, else 1.055·x^(1/2.4) − 0.055   (IEC 61966-2-1)
//   8-bit:        floor(255·v + 0.5)   (round half up)
//
// Two display controls of tev go beyond hgrender/imaging.py (they are viewer-only; at their defaults,
// offset 0 and the sRGB curve, the display is exactly display_rgb8):
//   offset:       added after the exposure, before the tone map: x·2^EV + offset
//   gamma γ:      v^(1/γ) instead of the sRGB curve

export const TONE_MAPS = ["clamp", "reinhard", "aces"];
export const REC709_LUMINANCE = [0.2126, 0.7152, 0.0722];

/** Tone-mapped value in [0, 1] of one linear channel value. */
export function toneMap(x, operator) {
  const v = Math.max(x, 0);
  let mapped;
  if (operator === "clamp") mapped = v;
  else if (operator === "reinhard") mapped = v / (1 + v);
  else if (operator === "aces") mapped = (v * (2.51 * v + 0.03)) / (v * (2.43 * v + 0.59) + 0.14);
  else throw new Error(`tonemap: must be one of ${TONE_MAPS.join(", ")}, got ${operator}`);
  return Math.min(Math.max(mapped, 0), 1);
}

/** The sRGB transfer curve of a value in [0, 1]. */
export function srgbEncode(linear) {
  return linear <= 0.0031308 ? 12.92 * linear : 1.055 * Math.pow(linear, 1 / 2.4) - 0.055;
}

/** The transfer curve: sRGB (gamma null) or v^(1/γ). */
function encoder(gamma) {
  return gamma ? (v) => Math.pow(v, 1 / gamma) : srgbEncode;
}

/**
 * Fill `rgba` (Uint8ClampedArray, 4 per pixel) with the display of interleaved linear RGB `rgb`
 * (Float32Array, 3 per pixel). `offset` and `gamma` as in tev (see the top of this file).
 */
export function displayRgb8(rgb, rgba, exposureEv, operator, { offset = 0, gamma = null } = {}) {
  const scale = Math.pow(2, exposureEv);
  const encode = encoder(gamma);
  const pixels = rgb.length / 3;
  for (let i = 0; i < pixels; i++) {
    for (let c = 0; c < 3; c++) {
      const encoded = encode(toneMap(rgb[3 * i + c] * scale + offset, operator));
      rgba[4 * i + c] = Math.floor(encoded * 255 + 0.5);
    }
    rgba[4 * i + 3] = 255;
  }
  return rgba;
}

/** Rec. 709 luminance of interleaved linear RGB, one value per pixel. */
export function luminance(rgb) {
  const out = new Float64Array(rgb.length / 3);
  for (let i = 0; i < out.length; i++) {
    out[i] = REC709_LUMINANCE[0] * rgb[3 * i] + REC709_LUMINANCE[1] * rgb[3 * i + 1] + REC709_LUMINANCE[2] * rgb[3 * i + 2];
  }
  return out;
}

/** EV that maps the given percentile of luminance to 1 (0 for a black image), as auto_exposure_ev. */
export function autoExposureEv(rgb, percentile = 99) {
  const lum = Array.from(luminance(rgb)).sort((a, b) => a - b);
  if (lum.length === 0) return 0;
  // numpy's default (linear interpolation between closest ranks).
  const rank = (percentile / 100) * (lum.length - 1);
  const lo = Math.floor(rank);
  const hi = Math.min(lo + 1, lum.length - 1);
  const high = lum[lo] + (lum[hi] - lum[lo]) * (rank - lo);
  return high > 0 && Number.isFinite(high) ? -Math.log2(high) : 0;
}
