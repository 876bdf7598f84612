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
    lobe_pdf: mi.Float,
    lobe_valid: mi.Bool,
    eta: mi.Float | float = 1.0,
) -> MaterialSample:
    """The sample of a "specular part with probability p, else the lobe" material (rough surfaces, films,
    gratings), given the direction ``wo`` taken, the specular part's weight (over its selection probability)
    and the lobe's value and hero-MIS pdf at ``wo``: a lobe sample weighs value/(pdf·(1 − p)), an invalid
    (evanescent) one 0; the specular part has pdf 1 and is a Dirac delta."""
    lobe_weight = lobe_value / dr.maximum(lobe_pdf * (1.0 - specular_probability), 1e-20)
    weight = dr.select(chosen, specular_weight, dr.select(lobe_valid & (lobe_pdf > 0), lobe_weight, 0.0))
    pdf = dr.select(chosen, 1.0, lobe_pdf)
    return MaterialSample(wo, weight, pdf, chosen, mi.Float(eta))


def mean_over_wavelengths(values: list[mi.Float]) -> mi.Float:
    total = values[0]
    for value in values[1:]:
        total = total + value
    return total / len(values)
