"""The skeleton of the materials that are "a specular part with probability p, else a lobe" (rough
conductors and dielectrics, thin films, gratings), and the hero-wavelength mean of per-wavelength values."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from worker.render.bsdfs.common import MaterialSample


def split_specular(u: mi.Float, specular_probability: mi.Float) -> tuple[mi.Bool, mi.Float]:
    """Choose a material's specular (Dirac) part with probability p: (chosen, the uniform in [0, 1) left
    for sampling the lobe otherwise, (u − p)/(1 − p))."""
    chosen = u < specular_probability
    rest = (u - specular_probability) / dr.maximum(1.0 - specular_probability, 1e-12)
    return chosen, dr.clip(rest, 0.0, 0.999999)


def specular_or_lobe(
    chosen: mi.Bool,
    specular_probability: mi.Float,
    wo: mi.Vector3f,
    specular_weight: mi.Spectrum,
    lobe_value: mi.Spectrum,
    lobe_pdfs: mi.Spectrum,
    lobe_valid: mi.Bool,
    eta: mi.Float | float = 1.0,
    specular_ratios: mi.Spectrum | None = None,
) -> MaterialSample:
    """The sample of a "specular part with probability p, else the lobe" material (rough surfaces, films,
    gratings), given the direction ``wo`` taken, the specular part's weight (over its selection probability)
    and the lobe's value and per-wavelength densities p_k at ``wo``: a lobe sample weighs value/(p̄·(1 − p))
    with p̄ = mean_k p_k and has the pdf ratios q_k = p_k/p̄ (p is the same for every hero), an invalid
    (evanescent) one 0; the specular part has pdf 1, is a Dirac delta and has the ratios
    ``specular_ratios`` (default 1: a selection probability that does not depend on the hero)."""
    lobe_pdf = mean_over_wavelengths(lobe_pdfs)
    lobe_weight = lobe_value / dr.maximum(lobe_pdf * (1.0 - specular_probability), 1e-20)
    weight = dr.select(chosen, specular_weight, dr.select(lobe_valid & (lobe_pdf > 0), lobe_weight, 0.0))
    pdf = dr.select(chosen, mi.Spectrum(1.0), lobe_pdfs)
    lobe_ratios = lobe_pdfs / dr.maximum(lobe_pdf, 1e-20)
    ratios = dr.select(chosen, mi.Spectrum(1.0) if specular_ratios is None else specular_ratios, lobe_ratios)
    return MaterialSample(wo, weight, pdf, chosen, mi.Float(eta), pdf_ratios=ratios)


def mean_over_wavelengths(values: list[mi.Float] | mi.Spectrum) -> mi.Float:
    """mean_k of per-wavelength values (a list, or the four components of a spectrum)."""
    total = values[0]
    for j in range(1, len(values)):
        total = total + values[j]
    return total / len(values)
