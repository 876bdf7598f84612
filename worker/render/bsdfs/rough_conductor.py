"""Rough statistical reflector (Eq. 15, Harvey–Shack): a specular part e^{−g} and a PSD lobe.

The lobe is F(1 − e^{−g})·S(φ⊥/2π)/(λ²P), renormalised over its propagating part P, with the camera side
as the incident side (``hgcore.optics.rough_surface``; the model is not reciprocal and this choice gives the
estimator the albedo F exactly). ``RoughConductor`` reflects with the conductor's Fresnel F at ``wi``; the
thin film (``thin_film.ThinFilm``) is the same interface with the film's reflectance instead.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from hgcore.optics import rough_surface
from worker.render import materials as mat
from worker.render.bsdfs.common import (
    OPS,
    IncidentCoherence,
    Material,
    MaterialParams,
    MaterialSample,
    ShadingPoint,
    vec,
)
from worker.render.bsdfs.lobes import mean_over_wavelengths, specular_or_lobe, split_specular


class RoughConductor(Material):
    kind = mat.MaterialKind.ROUGH_CONDUCTOR
    per_material = True
    spectra = (mat.ETA_ID, mat.KAPPA_ID, mat.TINT_ID)
    model: rough_surface.RoughSurface

    def __init__(self, params: MaterialParams, index: int | None = None) -> None:
        super().__init__(params, index)
        # The propagating fraction P on a (sin θ, λ) grid (``_reflection_fraction``), built once per surface;
        # with a textured ℓ_c on a (sin θ, ℓ_c/λ) grid over the texture's range and the spectral grid's.
        self._ratio_nodes: np.ndarray | None = None
        if self.record.textured(mat.CORRELATION_LENGTH_M):
            low, high = self.record.texture_ranges[mat.CORRELATION_LENGTH_M]
            self._ratio_nodes = rough_surface.ratio_table_nodes(
                low / rough_surface.TABLE_WAVELENGTHS_M[-1], high / rough_surface.TABLE_WAVELENGTHS_M[0]
            )
            table = rough_surface.reflection_fraction_ratio_table(self.model, self._ratio_nodes)
        else:
            table = rough_surface.reflection_fraction_table(self.model)
        self._fraction_table = mi.Float(table.ravel())

    def kernel_tables(self) -> list[mi.Float]:
        return [self._fraction_table]

    def reflectance(self, point: ShadingPoint, wo: mi.Vector3f) -> list[mi.Spectrum]:
        """The interface's reflectance terms for light arriving along ``wo``: [F(θ_i)·tint] for a conductor
        (the first term is the incoherent reflectance that scales both parts)."""
        fresnel = self.params.interface_reflectance(point.spectra, point.wi.z)
        return [self.params.tint(fresnel, point.spectra)]

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        sampled, _ = self.sample_reflection(point, sample1, sample2)
        return sampled

    def eval_pdf(
        self, point: ShadingPoint, wo: mi.Vector3f, coherence: IncidentCoherence, wo_phase: mi.Vector3f
    ) -> tuple[mi.Spectrum, mi.Spectrum]:
        return self.lobe_eval(point, wo, self.reflectance(point, wo)[0])

    def lobe_eval(
        self, point: ShadingPoint, wo: mi.Vector3f, reflectance: mi.Spectrum
    ) -> tuple[mi.Spectrum, mi.Spectrum]:
        """Scattered lobe value f·cos θo and the per-wavelength lobe densities p_k for light arriving along
        ``wo``.

        Harvey–Shack's incident-side factors (1 − e^{−g}, the propagating fraction) are those of the side
        the path arrives from, ``wi``. ``reflectance`` is the caller's F (conductors: at ``wi``).
        """
        surface, wi, wavelengths = self.surface(point), point.wi, point.wavelengths
        value = mi.Spectrum(0.0)
        pdfs = mi.Spectrum(0.0)
        light, view = vec(wo), vec(wi)
        sin_view = dr.sqrt(dr.maximum(wi.x * wi.x + wi.y * wi.y, 0.0))
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            fraction = self._reflection_fraction(sin_view, wavelengths[j], surface)
            brdf = rough_surface.rough_reflection_eval(
                surface, view, light, wavelength_m, reflectance[j], OPS, fraction=fraction
            )
            value[j] = brdf * wo.z
            pdfs[j] = rough_surface.rough_reflection_pdf(surface, view, light, wavelength_m, OPS)
        return value, pdfs

    def _reflection_fraction(
        self, sin_theta: mi.Float, wavelength_nm: mi.Float, surface: rough_surface.RoughSurface
    ) -> mi.Float:
        """Propagating fraction P of reflection in air, bilinear in ``reflection_fraction_table`` (built once
        per surface): 4 gathers instead of a 32-node angular integral per wavelength and sample. With a
        textured ℓ_c the second axis is ln(ℓ_c/λ) (``reflection_fraction_ratio_table``)."""
        table = self._fraction_table
        if self._ratio_nodes is None:
            columns = len(rough_surface.TABLE_WAVELENGTHS_M)
            first = float(rough_surface.TABLE_WAVELENGTHS_M[0]) * 1e9
            last = float(rough_surface.TABLE_WAVELENGTHS_M[-1]) * 1e9
            column_position = (wavelength_nm - first) / (last - first)
        else:
            columns = len(self._ratio_nodes)
            low, high = math.log(self._ratio_nodes[0]), math.log(self._ratio_nodes[-1])
            ratio = surface.correlation_length_m / (wavelength_nm * 1e-9)
            column_position = (dr.log(ratio) - low) / (high - low)
        # Invert sin θ = 1 − (1 − x)², then cell coordinates along both axes.
        x = 1.0 - dr.sqrt(dr.maximum(1.0 - sin_theta, 0.0))
        rows = rough_surface.TABLE_ANGLE_NODES
        row_f = dr.clip(x * (rows - 1), 0.0, rows - 1.001)
        column_f = dr.clip(column_position * (columns - 1), 0.0, columns - 1.001)
        row, column = mi.UInt32(row_f), mi.UInt32(column_f)
        a, b = row_f - mi.Float(row), column_f - mi.Float(column)

        def at(r: mi.UInt32, c: mi.UInt32) -> mi.Float:
            return dr.gather(mi.Float, table, r * columns + c)

        top = at(row, column) * (1.0 - b) + at(row, column + 1) * b
        bottom = at(row + 1, column) * (1.0 - b) + at(row + 1, column + 1) * b
        return top * (1.0 - a) + bottom * a

    def sample_reflection(
        self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f
    ) -> tuple[MaterialSample, list[mi.Spectrum]]:
        """Specular (delta) part with probability ⟨e^{−g}⟩ (the mean over the path's wavelengths), else an
        exact PSD-lobe sample at λ_hero.

        The specular fraction e^{−g} varies by orders of magnitude across the spectrum (g ∝ 1/λ²); choosing
        by the hero's alone would give the other wavelengths weights up to e^{g_hero − g_j} (fireflies).
        The mean is a one-sample MIS over the wavelengths: every weight is at most 4·F_j/F. Returns the
        sample and the reflectance terms (``reflectance``) at the sampled direction.
        """
        surface, wi, wavelengths = self.surface(point), point.wi, point.wavelengths
        hero_m = wavelengths[0] * 1e-9
        specular_probability = mean_over_wavelengths(
            [
                dr.exp(-rough_surface.roughness_exponent(surface.rms_height_m, wi.z, wavelengths[j] * 1e-9))
                for j in range(len(wavelengths))
            ]
        )
        choose_specular, lobe_sample1 = split_specular(sample1, specular_probability)
        lobe_dir, _, lobe_valid = rough_surface.rough_reflection_sample(
            surface, vec(wi), hero_m, lobe_sample1, sample2[0], OPS
        )
        lobe_wo = mi.Vector3f(*lobe_dir)
        wo = dr.select(choose_specular, mi.reflect(wi), lobe_wo)
        terms = self.reflectance(point, wo)
        reflectance = terms[0]
        lobe_value, lobe_pdfs = self.lobe_eval(point, lobe_wo, reflectance)
        specular_weight = mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            g_j = rough_surface.roughness_exponent(surface.rms_height_m, wi.z, wavelengths[j] * 1e-9)
            specular_weight[j] = reflectance[j] * dr.exp(-g_j) / dr.maximum(specular_probability, 1e-20)
        sampled = specular_or_lobe(
            choose_specular, specular_probability, wo, specular_weight, lobe_value, lobe_pdfs, lobe_valid
        )
        return sampled, terms
