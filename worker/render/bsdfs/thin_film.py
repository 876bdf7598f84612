"""Thin film (Eq. 18) on a rough conductor or dielectric substrate.

The film is the rough interface of Eq. 15 (``rough_conductor``: specular part and lobe) whose reflectance
is the P-beam partially coherent sum R(V) = R_incoherent + Σ_d V_d·X_d, V_d = μ(d·s) the visibility of
the incident light at the d-th beam's shear s (``hgcore.optics.thin_film.film_shear``: 2τ tan θ_t in the
plane of incidence, docs/physics_interactions.md §3) (``VisibilityModel``). Sampling uses the incoherent part
R_incoherent and returns the terms (``FilmSample``); the integrator rescales the throughput by
R(V)/R_incoherent once the path has reached the light's source and its coherence is known.

The interference phase is taken along ``wo_phase``: towards the emitter's centre for light from an emitter
(BRIEF: sampled emitter points serve radiometry only), else the sampled direction. On a dielectric
substrate the film also transmits T(V) = 1 − R(V), specularly, into and out of the substrate (clear films
only: the schema accepts an absorbing film, index n_f + iκ_f, on conductors alone).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.fresnel import fresnel_dielectric
from hgcore.optics.thin_film import (
    bounded_reflectance,
    film_reflectance_terms,
    film_shear,
    transmission_terms,
)
from worker.render import materials as mat
from worker.render.bsdfs.common import (
    OPS,
    FilmSample,
    IncidentCoherence,
    MaterialSample,
    ShadingPoint,
    VertexSpectra,
    VisibilityModel,
    refract,
)
from worker.render.bsdfs.rough_conductor import RoughConductor


def film_terms(
    spectra: VertexSpectra, cos_i: mi.Float, thickness_m: mi.Float | None = None
) -> list[mi.Spectrum]:
    """[R_incoherent, X_1 … X_{P−1}] per wavelength (``film_reflectance``) at incidence cos_i of the film
    whose spectra are ``spectra``, with every beam (``hgcore.optics.thin_film.film_reflectance_terms``). The
    film's index is n_f + iκ_f where a film of the scene absorbs (``MaterialParams.film_absorbing``), else
    the real n_f as before. ``thickness_m``: the film's local thickness τ (default: the vertex's, from its
    texture where it has one)."""
    params, material, wavelengths = spectra.params, spectra.material, spectra.wavelengths
    exterior = params.param(material, mat.EXTERIOR_IOR)
    if thickness_m is None:
        thickness_m = spectra.param(mat.FILM_THICKNESS_M)
    film_n = spectra[mat.FILM_IOR_ID]
    film_kappa = params.param(material, mat.FILM_EXTINCTION) if params.film_absorbing else None
    substrate_n = spectra[mat.ETA_ID]
    substrate_k = spectra[mat.KAPPA_ID]
    terms = [mi.Spectrum(0.0) for _ in range(params.max_beams)]
    for j in range(len(wavelengths)):
        # every beam, the separations d ≥ P − 1 together (hgcore.optics.thin_film: "All beams")
        per_wavelength = film_reflectance_terms(
            cos_i,
            wavelengths[j] * 1e-9,
            thickness_m,
            film_n[j] if film_kappa is None else ComplexPair(film_n[j], film_kappa),
            ComplexPair(substrate_n[j], substrate_k[j]),
            exterior,
            params.max_beams,
            OPS,
        )
        for slot, term in enumerate(per_wavelength):
            terms[slot][j] = term
    return terms


def film_reflectance(
    terms: list[mi.Spectrum],
    visibility: VisibilityModel,
    coherence: IncidentCoherence,
    separation_world: mi.Vector3f,
    wavelengths: mi.Spectrum,
) -> mi.Spectrum:
    """R(V) ∈ [0, 1] of the partially coherent sum of every beam, V_d = μ(d·``separation_world``) of the light
    described by ``coherence``; ``separation_world`` is the film shear s (m) between successive beams."""
    visibilities = [
        visibility.at(coherence, separation_world * separation, wavelengths)
        for separation in range(1, len(terms))
    ]
    return bounded_reflectance(terms, visibilities, OPS)


class ThinFilm(RoughConductor):
    kind = mat.MaterialKind.THIN_FILM
    per_material = True
    spectra = (mat.ETA_ID, mat.KAPPA_ID, mat.FILM_IOR_ID)

    @property
    def transmits(self) -> bool:
        """On a dielectric substrate: reflects and transmits (one-sided like glass)."""
        return self.record.values.get(mat.FILM_TRANSMITS, 0.0) > 0.5

    def reflectance(self, point: ShadingPoint, wo: mi.Vector3f) -> list[mi.Spectrum]:
        """The film's terms at the sampled direction (R_incoherent first)."""
        return film_terms(point.spectra, wo.z)

    def sample_domain(self, wi: mi.Vector3f, active: mi.Bool) -> mi.Bool:
        return active & (wi.z != 0) if self.transmits else active & (wi.z > 0)

    def sample(self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f) -> MaterialSample:
        if self.transmits:
            return self._sample_on_dielectric(point, sample1, sample2)
        sampled, terms = self.sample_reflection(point, sample1, sample2)
        return sampled._replace(film=FilmSample(terms, mi.Bool(False)))

    def eval_pdf(
        self, point: ShadingPoint, wo: mi.Vector3f, coherence: IncidentCoherence, wo_phase: mi.Vector3f
    ) -> tuple[mi.Spectrum, mi.Spectrum]:
        terms = film_terms(point.spectra, wo_phase.z)
        # Direct light reaches the film from the exterior side (``eval_domain``): the shear of light
        # arriving along −wo_phase with the exterior's index (``hgcore.optics.thin_film.film_shear``).
        thickness_m = point.spectra.param(mat.FILM_THICKNESS_M)
        film_ior = point.spectra[mat.FILM_IOR_ID][0]
        exterior = self.params.param(point.material, mat.EXTERIOR_IOR)
        light_world = point.frame.to_world(wo_phase)
        separation = mi.Vector3f(
            *film_shear(point.frame.n, -light_world, thickness_m, film_ior, exterior, OPS)
        )
        reflectance = film_reflectance(
            terms, self.params.visibility, coherence, separation, point.wavelengths
        )
        return self.lobe_eval(point, wo, reflectance)

    def _sample_on_dielectric(
        self, point: ShadingPoint, sample1: mi.Float, sample2: mi.Point2f
    ) -> MaterialSample:
        """A film on a dielectric substrate reflects with R(V) and transmits T(V) = 1 − R(V)
        (``thin_film.transmission_terms``).

        From the exterior (wi.z > 0) reflect with probability R_incoherent(λ_hero), as the rough film does
        (specular part and Eq. 15 lobe), else refract specularly into the substrate; from the substrate
        the exterior-side angle follows from n_s sin θ_s = n_0 sin θ_0 through the stack (beyond the
        critical angle all light is reflected) and reflection and transmission are specular. A lossless
        stack has the same R from both sides (exact in the coherent and incoherent limits), so the
        exterior-side terms serve both. The film's roughness scatters reflected light only.
        """
        params, material, wi = self.params, point.material, point.wi
        exterior = params.param(material, mat.EXTERIOR_IOR)
        eta = point.spectra[mat.ETA_ID][0] / exterior
        outside = wi.z > 0
        eta_ti = dr.select(outside, eta, dr.rcp(eta))  # n_transmitted / n_incident (hero)
        _, cos_t = fresnel_dielectric(wi.z, eta_ti, OPS)
        cos_i = dr.abs(wi.z)
        total_internal = ~outside & (dr.square(eta_ti) < 1.0 - dr.square(cos_i))
        cos_exterior = dr.select(outside, cos_i, cos_t)
        terms = film_terms(point.spectra, cos_exterior)
        reflectance = dr.select(total_internal, 1.0, terms[0])
        reflect_probability = reflectance[0]
        reflect = sample1 < reflect_probability
        # exterior reflection: the rough film's own sampling with the remaining uniform
        u_reflect = dr.clip(sample1 / dr.maximum(reflect_probability, 1e-12), 0.0, 0.999999)
        lobe, lobe_terms = self.sample_reflection(point, u_reflect, sample2)
        r_weight = lobe.weight / dr.maximum(reflect_probability, 1e-12)
        # substrate-side reflection: specular, R/R_hero
        inner_weight = reflectance / dr.maximum(reflect_probability, 1e-12)
        # transmission: specular refraction with T/T_hero and the radiance factor (n_camera/n_light)²
        transmittance = 1.0 - reflectance
        t_ratios = transmittance / dr.maximum(1.0 - reflect_probability, 1e-12)
        t_weight = t_ratios * dr.square(dr.rcp(eta_ti))
        t_weight, t_ratios = params.hero_collapse(t_weight, t_ratios, material, mi.Bool(True))
        # Hero k reflects with R_k (then, outside, samples the rough film's lobe: its own ratios).
        r_ratios = dr.select(outside, inner_weight * lobe.pdf_ratios, inner_weight)
        wo = dr.select(reflect, dr.select(outside, lobe.wo, mi.reflect(wi)), refract(wi, eta_ti, cos_t))
        weight = dr.select(reflect, dr.select(outside, r_weight, inner_weight), t_weight)
        ratios = dr.select(reflect, r_ratios, t_ratios)
        pdf = dr.select(reflect & outside, lobe.pdf, mi.Spectrum(1.0))
        delta = dr.select(reflect & outside, lobe.delta, True)
        no_interference = [mi.Spectrum(1.0 if slot == 0 else 0.0) for slot in range(len(terms))]
        inner_terms = [dr.select(total_internal, a, b) for a, b in zip(no_interference, terms, strict=True)]
        reflected_terms = [dr.select(outside, a, b) for a, b in zip(lobe_terms, inner_terms, strict=True)]
        transmitted = ~reflect
        chosen = [
            dr.select(transmitted, a, b)
            for a, b in zip(transmission_terms(terms), reflected_terms, strict=True)
        ]
        eta_sampled = dr.select(transmitted, eta_ti, 1.0)
        return MaterialSample(wo, weight, pdf, delta, eta_sampled, FilmSample(chosen, transmitted), ratios)
