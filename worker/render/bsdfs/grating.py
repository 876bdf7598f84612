"""Binary phase grating (Eq. 20): the 0th order (specular, coherence kept) and diffraction lobes.

Orders sit at the grating equation; each lobe is the intrinsic lobe PSD convolved with the Fourier
transform of the incident cross-spectral density (Eq. 19/20 per lobe), so its width depends on the
incident Σ⊥ projected on the grating plane. A grating is lit through next-event estimation only
(``materials.NEE_ONLY_KINDS``, docs/integrator.md).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from hgcore.optics import grating as grating_model
from worker.render import materials as mat
from worker.render.bsdfs.common import (
    OPS,
    IncidentCoherence,
    LobeModes,
    Material,
    MaterialSample,
    ShadingPoint,
    vec,
)
from worker.render.bsdfs.lobes import specular_or_lobe, split_specular


class Grating(Material):
    kind = mat.MaterialKind.GRATING
    per_material = True
    spectra = (mat.ETA_ID, mat.KAPPA_ID)
    model: grating_model.BinaryGrating

    def _rotation(self, material: mi.UInt32) -> tuple[mi.Float, mi.Float]:
        angle = self.params.param(material, mat.ORIENTATION_RAD)
        return dr.cos(angle), dr.sin(angle)

    def _to_grating(self, material: mi.UInt32, v: mi.Vector3f) -> mi.Vector3f:
        cos_a, sin_a = self._rotation(material)
        return mi.Vector3f(cos_a * v.x + sin_a * v.y, -sin_a * v.x + cos_a * v.y, v.z)

    def _from_grating(self, material: mi.UInt32, v: mi.Vector3f) -> mi.Vector3f:
        cos_a, sin_a = self._rotation(material)
        return mi.Vector3f(cos_a * v.x - sin_a * v.y, sin_a * v.x + cos_a * v.y, v.z)

    def _angular_covariance(
        self, material: mi.UInt32, coherence: IncidentCoherence, frame: mi.Frame3f
    ) -> tuple[mi.Float, mi.Float, mi.Float]:
        """Σ'/s²: the incident Σ⊥ projected on the grating plane (grating axes) over the squared distance."""
        cos_a, sin_a = self._rotation(material)
        axis_u, axis_v = frame.s * cos_a + frame.t * sin_a, frame.t * cos_a - frame.s * sin_a
        a, b = dr.dot(axis_u, coherence.frame_x), dr.dot(axis_u, coherence.frame_y)
        c, d = dr.dot(axis_v, coherence.frame_x), dr.dot(axis_v, coherence.frame_y)
        sxx, sxy, syy = coherence.sigma_xx, coherence.sigma_xy, coherence.sigma_yy
        inv_r2 = dr.rcp(dr.square(dr.maximum(coherence.distance_m, 1e-9)))
        return (
            (a * a * sxx + 2 * a * b * sxy + b * b * syy) * inv_r2,
            (a * c * sxx + (a * d + b * c) * sxy + b * d * syy) * inv_r2,
            (c * c * sxx + 2 * c * d * sxy + d * d * syy) * inv_r2,
        )

    def eval_pdf(
        self, point: ShadingPoint, wo: mi.Vector3f, coherence: IncidentCoherence, wo_phase: mi.Vector3f
    ) -> tuple[mi.Spectrum, mi.Spectrum]:
        material, wi, wavelengths = point.material, point.wi, point.wavelengths
        light = vec(self._to_grating(material, wo))
        view = vec(self._to_grating(material, wi))
        angular_cov = self._angular_covariance(material, coherence, point.frame)
        fresnel = self.params.interface_reflectance(point.spectra, wo.z)
        mode_sets = self.params.visibility.lobe_modes(coherence)
        value = mi.Spectrum(0.0)
        pdfs = mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            brdf = self._lobes(light, view, wavelength_m, fresnel[j], angular_cov, mode_sets)
            value[j] = brdf * wo.z
            pdfs[j] = grating_model.grating_pdf(self.model, view, light, wavelength_m, angular_cov, OPS)
        return value, pdfs

    def _lobes(
        self,
        light: tuple[mi.Float, mi.Float, mi.Float],
        view: tuple[mi.Float, mi.Float, mi.Float],
        wavelength_m: mi.Float,
        reflectance: mi.Float,
        angular_cov: tuple[mi.Float, mi.Float, mi.Float],
        mode_sets: LobeModes,
    ) -> mi.Float:
        """The diffracted BRDF under the incident light's modes: the disk's (or the Gaussian's), and the
        rectangle's where the source expands like one."""
        brdf = grating_model.grating_eval(
            self.model, light, view, wavelength_m, reflectance, angular_cov, OPS, mode_sets.disk
        )
        if mode_sets.rect is not None:
            brdf_rect = grating_model.grating_eval(
                self.model, light, view, wavelength_m, reflectance, angular_cov, OPS, mode_sets.rect
            )
            brdf = dr.select(mode_sets.rect_source, brdf_rect, brdf)
        return brdf

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        """The 0th order with probability η_00(λ_hero), else a diffraction lobe.

        Lobes are drawn with the intrinsic lobe width only: the coherence of indirect light is not known
        when the direction is chosen, and direct light reaches gratings through next-event estimation only
        (docs/integrator.md).
        """
        grating, material, wi, wavelengths = self.model, point.material, point.wi, point.wavelengths
        view = vec(self._to_grating(material, wi))
        hero_m = wavelengths[0] * 1e-9
        zero_cov = (mi.Float(0.0), mi.Float(0.0), mi.Float(0.0))
        specular_probability = grating_model.specular_efficiency(grating, hero_m, OPS)
        choose_specular, order_sample = split_specular(sample1, specular_probability)
        lobe_dir, _, lobe_valid, _ = grating_model.grating_sample(
            grating, view, hero_m, zero_cov, order_sample, sample2[0], sample2[1], OPS
        )
        lobe_wo = self._from_grating(material, mi.Vector3f(*lobe_dir))
        wo = dr.select(choose_specular, mi.reflect(wi), lobe_wo)
        fresnel = self.params.interface_reflectance(point.spectra, wo.z)
        lobe_value = mi.Spectrum(0.0)
        # Hero k picks a lobe with 1 − η_00(λ_k) and draws it with its own density: p_k relative to the
        # hero's selection probability, which ``specular_or_lobe`` divides by.
        lobe_pdfs = mi.Spectrum(0.0)
        specular_weight = mi.Spectrum(0.0)
        specular_ratios = mi.Spectrum(0.0)
        light = vec(self._to_grating(material, lobe_wo))
        for j in range(len(wavelengths)):
            wavelength_m = wavelengths[j] * 1e-9
            brdf = grating_model.grating_eval(grating, light, view, wavelength_m, fresnel[j], zero_cov, OPS)
            lobe_value[j] = brdf * lobe_wo.z
            eta_00 = grating_model.specular_efficiency(grating, wavelength_m, OPS)
            lobe_pdfs[j] = grating_model.grating_pdf(grating, view, light, wavelength_m, zero_cov, OPS) * (
                (1.0 - eta_00) / dr.maximum(1.0 - specular_probability, 1e-20)
            )
            specular_weight[j] = fresnel[j] * eta_00 / dr.maximum(specular_probability, 1e-20)
            specular_ratios[j] = eta_00 / dr.maximum(specular_probability, 1e-20)
        return specular_or_lobe(
            choose_specular,
            specular_probability,
            wo,
            specular_weight,
            lobe_value,
            lobe_pdfs,
            lobe_valid,
            specular_ratios=specular_ratios,
        )
