// The coherence diagnostics as a person reads them: one quantity, one unit, one wavelength, wherever it is
// shown (false-colour map and its colour bar, hover readout, values drawn on the pixels, ellipses, pixel
// inspector).
//
// The renderer stores the `coherence.*` channels at λ₀ = 550 nm (BRIEF: lengths scale ∝ λ). With
// M = (k/r)²·Σ⊥ and k = 2π/λ, at another wavelength λ:
//   ℓ₁, ℓ₂ (= eigenvalues of M to the power −½)   × (λ/λ₀)
//   area π·ℓ₁·ℓ₂                                   × (λ/λ₀)²
//   Mxx, Mxy, Myy                                  × (λ/λ₀)⁻²
//   anisotropy ℓ₁/ℓ₂, propagation distance r, angle: independent of λ
// Angles are stored in radians (from image +x towards image +y up, in (−π/2, π/2]); they are shown in
// degrees, and an orientation is drawn with a cyclic colour map (−90° and +90° are the same direction).

export const REFERENCE_WAVELENGTH_NM = 550;
const PREFIX = "coherence.";

// key → label, longer title (display modes, colour bars), display unit, power of λ/λ₀ (null: the angle,
// shown in degrees).
export const COHERENCE_QUANTITIES = {
  l1_um: { label: "ℓ₁", title: "ℓ₁ (coherence length, major)", unit: "µm", power: 1 },
  l2_um: { label: "ℓ₂", title: "ℓ₂ (coherence length, minor)", unit: "µm", power: 1 },
  angle: { label: "angle", title: "ℓ₁ orientation", unit: "°", power: null },
  anisotropy: { label: "ℓ₁/ℓ₂", title: "anisotropy ℓ₁/ℓ₂", unit: "1", power: 0 },
  area_um2: { label: "area", title: "coherence area π·ℓ₁·ℓ₂", unit: "µm²", power: 2 },
  r_m: { label: "r", title: "propagation distance r", unit: "m", power: 0 },
  Mxx: { label: "Mxx", title: "Mxx", unit: "m⁻²", power: -2 },
  Mxy: { label: "Mxy", title: "Mxy", unit: "m⁻²", power: -2 },
  Myy: { label: "Myy", title: "Myy", unit: "m⁻²", power: -2 },
};

/** The display modes of the viewer, in their order (tev's channel groups after sRGB and band). */
export const DIAGNOSTIC_MODES = ["l1_um", "l2_um", "anisotropy", "area_um2", "r_m", "angle"];

/** `coherence.l1_um` → `l1_um`; null for a layer that is not a coherence diagnostic. */
export function coherenceKey(layerName) {
  const key = layerName?.startsWith(PREFIX) ? layerName.slice(PREFIX.length) : null;
  return key && key in COHERENCE_QUANTITIES ? key : null;
}

export function layerName(key) {
  return PREFIX + key;
}

/** A stored (550 nm) value in its display unit at `wavelengthNm`. */
export function displayValue(key, value, wavelengthNm) {
  if (value === null || value === undefined) return null;
  const { power } = COHERENCE_QUANTITIES[key];
  if (power === null) return (value * 180) / Math.PI;
  return power === 0 ? value : value * Math.pow(wavelengthNm / REFERENCE_WAVELENGTH_NM, power);
}

/** Does the quantity depend on the wavelength? */
export function scalesWithWavelength(key) {
  const { power } = COHERENCE_QUANTITIES[key];
  return power !== null && power !== 0;
}

/** "at 593 nm" for the quantities that scale with λ, "(same at every λ)" for the others: every legend
 * and readout says which wavelength its number is for. */
export function wavelengthPhrase(key, wavelengthNm) {
  return scalesWithWavelength(key) ? `at ${wavelengthNm.toFixed(0)} nm` : "(same at every λ)";
}

/** Colour-bar / legend title of a diagnostic: "ℓ₁ (coherence length, major) at 593 nm". */
export function quantityTitle(key, wavelengthNm) {
  return `${COHERENCE_QUANTITIES[key].title} ${wavelengthPhrase(key, wavelengthNm)}`;
}

/** The orientation's cyclic colour position: angle (rad, any multiple of π apart is the same) → [0, 1). */
export function orientationT(angleRad) {
  const t = (angleRad + Math.PI / 2) / Math.PI;
  return t - Math.floor(t);
}
