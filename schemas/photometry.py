"""Spectra of scene models and the radiometric/photometric conversions used by the USD bridge.

* A :data:`schemas.scene.Spectrum` evaluates as documented on its model: ``constant`` → value; ``blackbody``
  → Planck's law B_λ(T) in W·m⁻²·sr⁻¹·nm⁻¹; ``d65``/``cie_f`` → the CIE table divided by its value at
  560 nm; ``tabulated`` → piecewise-linear through the samples, 0 outside. Tables come from
  ``hgcore.optics.spectra`` (NumPy only; no Mitsuba).
* Luminance of a Lambertian emitter with spectral radiance L_λ = c·s(λ) (W·m⁻²·sr⁻¹·nm⁻¹):
  L_v = K_m · c · ∫ s(λ) ȳ(λ) dλ in cd·m⁻² ("nits"), K_m = 683 lm/W, ȳ the CIE 1931 2° function.
* Power of an emitter of area A (m²), Lambertian on its emitting side: P = π · A · c · ∫_{λmin}^{λmax} s dλ.
Integrals use the trapezoid rule on a 1 nm grid (the CIE tables' own spacing).
"""

from __future__ import annotations

import math

import numpy as np

from hgcore.colour import xyz_to_linear_srgb
from hgcore.errors import InputError
from hgcore.optics.spectra import (
    cie_cmf,
    cie_illuminant,
    planck_radiance,
    spectrum_to_xyz,
)
from schemas.scene import (
    BlackbodySpectrum,
    CieFSpectrum,
    ConstantSpectrum,
    CylinderEmitter,
    D65Spectrum,
    DiskEmitter,
    EnvironmentEmitter,
    RectangleEmitter,
    SphereEmitter,
    SunEmitter,
    TabulatedSpectrum,
)

SpectrumModel = ConstantSpectrum | BlackbodySpectrum | D65Spectrum | CieFSpectrum | TabulatedSpectrum
SurfaceEmitterModel = SphereEmitter | CylinderEmitter | RectangleEmitter | DiskEmitter
EmitterModel = SurfaceEmitterModel | EnvironmentEmitter | SunEmitter

LUMINOUS_EFFICACY_LM_PER_W = 683.0
#: The visible range of the CIE 1931 tables, nm; luminance integrals run over it.
VISIBLE_MIN_NM = 360.0
VISIBLE_MAX_NM = 830.0
#: Knots of the piecewise-linear spectrum used for RGB colours (blue, green, red plateaus): a white colour
#: gives exactly 1 everywhere, so the colour only tints.
RGB_KNOTS_NM = (360.0, 490.0, 500.0, 580.0, 590.0, 830.0)


def evaluate_spectrum(spectrum: SpectrumModel, wavelength_nm: np.ndarray) -> np.ndarray:
    """Values of ``spectrum`` at ``wavelength_nm`` (nm), with the normalisations stated above."""
    wavelengths = np.asarray(wavelength_nm, dtype=float)
    if isinstance(spectrum, ConstantSpectrum):
        return np.full_like(wavelengths, spectrum.value)
    if isinstance(spectrum, BlackbodySpectrum):
        return planck_radiance(wavelengths, spectrum.temperature_k)
    if isinstance(spectrum, D65Spectrum | CieFSpectrum):
        name = "d65" if isinstance(spectrum, D65Spectrum) else spectrum.name.lower()
        return cie_illuminant(name, wavelengths) / float(cie_illuminant(name, 560.0))
    return np.interp(wavelengths, spectrum.wavelengths_nm, spectrum.values, left=0.0, right=0.0)


def integrate_spectrum(
    spectrum: SpectrumModel, wavelength_min_nm: float, wavelength_max_nm: float, weight_y_bar: bool = False
) -> float:
    """∫ s(λ) dλ (or ∫ s(λ) ȳ(λ) dλ) over [min, max] nm by the trapezoid rule on a ≤1 nm grid."""
    sample_count = max(2, math.ceil(wavelength_max_nm - wavelength_min_nm) + 1)
    wavelengths = np.linspace(wavelength_min_nm, wavelength_max_nm, sample_count)
    values = evaluate_spectrum(spectrum, wavelengths)
    if weight_y_bar:
        values = values * cie_cmf(wavelengths)[:, 1]
    return float(np.trapezoid(values, wavelengths))


def luminance_per_radiance_scale(spectrum: SpectrumModel) -> float:
    """L_v / c in cd·m⁻² for radiance c·s(λ): K_m ∫ s ȳ dλ."""
    return LUMINOUS_EFFICACY_LM_PER_W * integrate_spectrum(spectrum, VISIBLE_MIN_NM, VISIBLE_MAX_NM, True)


def emitter_area_m2(emitter: SurfaceEmitterModel) -> float:
    """Emitting area in m²: sphere 4πR², open cylinder 2πRL, rectangle W·H, disk πR²."""
    if isinstance(emitter, SphereEmitter):
        return 4.0 * math.pi * emitter.radius_m**2
    if isinstance(emitter, CylinderEmitter):
        return 2.0 * math.pi * emitter.radius_m * math.dist(emitter.p0_m, emitter.p1_m)
    if isinstance(emitter, RectangleEmitter):
        return emitter.width_m * emitter.height_m
    return math.pi * emitter.radius_m**2


def emitter_radiance_scale(
    emitter: EmitterModel, wavelength_min_nm: float, wavelength_max_nm: float
) -> float:
    """The factor c of L_λ = c·s(λ): ``radiance_scale``, or c = P / (π A ∫_{film range} s dλ) for a surface
    emitter's power P, or c = E / (Ω ∫_{film range} s dλ) for a sun's irradiance E (Ω its solid angle)."""
    if emitter.radiance_scale is not None:
        return emitter.radiance_scale
    if isinstance(emitter, SunEmitter):
        assert emitter.irradiance_w_m2 is not None  # the model sets exactly one of the two
        integral = integrate_spectrum(emitter.spectrum, wavelength_min_nm, wavelength_max_nm)
        if integral <= 0.0:
            raise InputError(
                "spectrum: zero over the film's wavelength range, so irradiance_w_m2 cannot be met"
            )
        return emitter.irradiance_w_m2 / (emitter.solid_angle_sr() * integral)
    assert emitter.power_w is not None  # guaranteed by the model: exactly one of the two is set
    spectral_integral = integrate_spectrum(emitter.spectrum, wavelength_min_nm, wavelength_max_nm)
    if spectral_integral <= 0.0:
        raise InputError("spectrum: zero over the film's wavelength range, so power_w cannot be met")
    return emitter.power_w / (math.pi * emitter_area_m2(emitter) * spectral_integral)


def reflectance_rgb(spectrum: SpectrumModel) -> tuple[float, float, float]:
    """Approximate linear-sRGB colour of a reflectance under equal-energy light (white Y = 1), clipped."""
    wavelengths = np.arange(VISIBLE_MIN_NM, VISIBLE_MAX_NM + 1.0)
    white_y = float(spectrum_to_xyz(wavelengths, np.ones_like(wavelengths))[1])
    rgb = xyz_to_linear_srgb(spectrum_to_xyz(wavelengths, evaluate_spectrum(spectrum, wavelengths)) / white_y)
    red, green, blue = (float(c) for c in np.clip(rgb, 0.0, 1.0))
    return red, green, blue


def rgb_spectrum(rgb: tuple[float, float, float]) -> SpectrumModel:
    """A spectrum for a linear RGB colour: constant for greys, else blue/green/red plateaus (see knots)."""
    red, green, blue = (max(0.0, float(c)) for c in rgb)
    if red == green == blue:
        return ConstantSpectrum(type="constant", value=red)
    return TabulatedSpectrum(
        type="tabulated", wavelengths_nm=list(RGB_KNOTS_NM), values=[blue, blue, green, green, red, red]
    )


def tinted_spectrum(
    rgb: tuple[float, float, float], temperature_k: float | None
) -> tuple[SpectrumModel, float]:
    """The spectrum of a UsdLux light's colour and optional colour temperature, and its luminance reference.

    Returns ``(s, y)`` where ``y = K_m ∫ r ȳ dλ`` for the *untinted* reference r (1, or B_λ(T)): a UsdLux
    intensity of I nits then means c = I / y, so a white light of intensity I has luminance I and a colour
    tint scales it as the colour does (UsdLux: colour and temperature are multiplicative tints).
    """
    colour = rgb_spectrum(rgb)
    if temperature_k is None:
        reference: SpectrumModel = ConstantSpectrum(type="constant", value=1.0)
        return colour, luminance_per_radiance_scale(reference)
    reference = BlackbodySpectrum(type="blackbody", temperature_k=temperature_k)
    if isinstance(colour, ConstantSpectrum) and colour.value == 1.0:
        return reference, luminance_per_radiance_scale(reference)
    wavelengths = np.arange(VISIBLE_MIN_NM, VISIBLE_MAX_NM + 1.0, 10.0)
    product = evaluate_spectrum(reference, wavelengths) * evaluate_spectrum(colour, wavelengths)
    tinted = TabulatedSpectrum(type="tabulated", wavelengths_nm=wavelengths.tolist(), values=product.tolist())
    return tinted, luminance_per_radiance_scale(reference)
