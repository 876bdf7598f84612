"""Thin film (Eq. 18) on a rough conductor or dielectric substrate.

The film is the rough interface of Eq. 15 (``rough_conductor``: specular part and lobe) whose reflectance
is the P-beam partially coherent sum R(V) = R_incoherent + Σ_d V_d·X_d, V_d = μ(d·s) the visibility of
the incident light at the d-th beam's shear s (``hgcore.optics.thin_film.film_shear``: 2τ tan θ_t in the
plane of incidence, docs/physics_interactions.md §3) (``VisibilityModel``). Sampling uses the incoherent part
R_incoherent and returns the terms (``FilmSample``); the integrator rescales the throughput by
R(V)/R_incoherent once the path has reached the light's source and its coherence is known.

What a pixel sees (docs/physics_interactions.md §3, "What a pixel sees"). The film evaluates every plane wave
of an incoherent source coherently at its own incidence, so the light a pixel collects carries the film's
interference term averaged over the source directions that the film passes towards the pixel: the source's
angular distribution times the film's *acceptance* (``hgcore.optics.acceptance``). The specular part passes
one direction (the path's own: V = 1, its own phase); the lobe passes its width around the mirror
direction; a film seen through a non-specular vertex passes the whole source (the paper's Eq. 18).
``detected_light`` combines the two (per wavelength: the lobe's width ∝ λ), ``film_at_directions`` takes
the film's terms and shear at the detected mean direction m (the interference phase of the light that
reaches the pixel), ``visible_reflectance`` applies the visibilities with the detected spread C. Next-event
estimation (``ThinFilm.eval_pdf``) and the integrator's pending record (``integrator._film_factor``) share
them. On a dielectric substrate the film also transmits T(V) = 1 − R(V), specularly, into and out of the
substrate (clear films only: the schema accepts an absorbing film, index n_f + iκ_f, on conductors alone).
"""

from __future__ import annotations

from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from hgcore.optics.acceptance import (
    ELLIPSE_OFFSET_SCALE,
    PARALLELOGRAM_OFFSET_SCALE,
    flat_top_axes,
    flat_top_product_components,
    lobe_acceptance_variance,
    lobe_covariance_components,
)
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
    spectra: VertexSpectra, cos_i: mi.Float | list[mi.Float], thickness_m: mi.Float | None = None
) -> list[mi.Spectrum]:
    """[R_incoherent, X_1 … X_{P−1}] per wavelength (``film_reflectance``) at incidence cos_i of the film
    whose spectra are ``spectra``, with every beam (``hgcore.optics.thin_film.film_reflectance_terms``);
    ``cos_i`` is one cosine for all wavelengths or one per wavelength. The film's index is n_f + iκ_f where
    a film of the scene absorbs (``MaterialParams.film_absorbing``), else the real n_f as before.
    ``thickness_m``: the film's local thickness τ (default: the vertex's, from its texture where it has
    one)."""
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
            cos_i[j] if isinstance(cos_i, list) else cos_i,
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


class DetectedLight(NamedTuple):
    """The part of a source that an interaction passes towards the pixel, per wavelength: the mean
    direction offset m_j (rad) and the covariance C_j (rad²) of the arrival directions, in a transverse
    basis (x, y, k) of a reference direction k of the incident light (``hgcore.optics.acceptance``)."""

    means: list[tuple[mi.Float, mi.Float]]
    covariances: list[tuple[mi.Float, mi.Float, mi.Float]]


def detected_light(
    normal: tuple[mi.Float, mi.Float, mi.Float],
    source_mean: tuple[mi.Float, mi.Float],
    source_cov: tuple[mi.Float, mi.Float, mi.Float],
    acceptance_mean: tuple[mi.Float, mi.Float],
    lobe_variance: mi.Spectrum,
    unbounded: mi.Bool | bool,
    rect_source: mi.Bool | bool,
    wavelengths: mi.Spectrum,
) -> DetectedLight:
    """The source (mean offset, covariance C_s = Σ⊥/r², a uniform ellipse or, where ``rect_source``, a
    uniform parallelogram) times the film's acceptance: its lobe, of per-axis variance v_j (rad², in
    direction cosines) stretched to v_j (I + n⊥n⊥ᵀ/n_z²) in the transverse plane, around
    ``acceptance_mean`` (v = 0: the specular part, a single direction), or every direction where
    ``unbounded`` (``hgcore.optics.acceptance.flat_top_product_components``). ``normal``: the film
    normal's components (n·x, n·y, n·k)."""
    offset_scale = dr.select(rect_source, PARALLELOGRAM_OFFSET_SCALE, ELLIPSE_OFFSET_SCALE)
    shape = lobe_covariance_components(1.0, normal, OPS)  # the lobe's, at every wavelength (a scale)
    # The axes of the combination: the source's for an anisotropic source (a tube: the product lies along
    # it), the lobe's for a round one; a scale of the lobe leaves them, so they serve every wavelength.
    axes = flat_top_axes(source_cov, shape, OPS)
    # The combination at the hero wavelength (diagonal on these axes unless ``unbounded``). The others'
    # lobes differ in width only (∝ λ): their spreads follow from the hero's per axis as Gaussians combine,
    # 1/c_j = 1/c_0 − 1/a_0 + 1/a_j (a the lobe's variance on the axis, c the combined) — exact where the
    # lobe is much narrower or much wider than the source, a quarter of the truncations.
    hero_lobe = tuple(lobe_variance[0] * component for component in shape)
    mean, hero_cov = flat_top_product_components(
        source_mean, source_cov, acceptance_mean, hero_lobe, unbounded, offset_scale, OPS, axes
    )
    means, covariances = [mean], [hero_cov]
    (e1x, e1y), (e2x, e2y) = axes
    per_axis = []
    for ex, ey in axes:
        lobe_axis = ex * ex * shape[0] + 2.0 * ex * ey * shape[1] + ey * ey * shape[2]
        combined = ex * ex * hero_cov[0] + 2.0 * ex * ey * hero_cov[1] + ey * ey * hero_cov[2]
        source_axis = ex * ex * source_cov[0] + 2.0 * ex * ey * source_cov[1] + ey * ey * source_cov[2]
        per_axis.append((lobe_axis, combined, dr.maximum(source_axis, 0.0)))
    for j in range(1, len(wavelengths)):
        variances = []
        for lobe_axis, combined, source_axis in per_axis:
            hero_a, other_a = lobe_variance[0] * lobe_axis, lobe_variance[j] * lobe_axis
            information = dr.rcp(dr.maximum(combined, 1e-30)) - dr.rcp(dr.maximum(hero_a, 1e-30))
            information = dr.maximum(information, 0.0) + dr.rcp(dr.maximum(other_a, 1e-30))
            variance = dr.minimum(dr.rcp(information), source_axis)
            variances.append(dr.select((combined > 0.0) & (other_a > 0.0), variance, combined))
        c1, c2 = variances
        covariance = (
            c1 * e1x * e1x + c2 * e2x * e2x,
            c1 * e1x * e1y + c2 * e2x * e2y,
            c1 * e1y * e1y + c2 * e2y * e2y,
        )
        if unbounded is not False:  # every direction of the source reaches the pixel: its own spread
            covariance = tuple(
                dr.select(unbounded, s, c) for s, c in zip(source_cov, covariance, strict=True)
            )
        means.append(mean)
        covariances.append(covariance)
    return DetectedLight(means, covariances)


def film_at_directions(
    spectra: VertexSpectra,
    normal: tuple[mi.Float, mi.Float, mi.Float],
    means: list[tuple[mi.Float, mi.Float]],
    thickness_m: mi.Float | None = None,
) -> tuple[list[mi.Spectrum], list[tuple[mi.Float, mi.Float]]]:
    """The film's reflectance terms and its transverse shear ξ (m) for light arriving from the exterior
    along the detected mean direction (k ∝ (m, 1) in the basis of ``normal``), so that the interference
    phase and the visibility's argument belong to the light that reaches the pixel. The hero wavelength's
    m (and its n_f for the shear) serves all four: the means differ only through the lobe's width ∝ λ,
    where lobe and source are of a size, by a fraction of that width; one direction keeps the incidence
    shared by the four wavelengths' terms (the kernels compute what depends on it once). ``thickness_m``:
    the film's local thickness τ (default: the vertex's, from its texture where it has one)."""
    params, material = spectra.params, spectra.material
    exterior = params.param(material, mat.EXTERIOR_IOR)
    if thickness_m is None:
        thickness_m = spectra.param(mat.FILM_THICKNESS_M)
    film_n = spectra[mat.FILM_IOR_ID]
    mean_x, mean_y = means[0]
    inverse_norm = dr.rsqrt(1.0 + mean_x * mean_x + mean_y * mean_y)
    direction = (mean_x * inverse_norm, mean_y * inverse_norm, inverse_norm)
    cosine = -(direction[0] * normal[0] + direction[1] * normal[1] + direction[2] * normal[2])
    shear = film_shear(normal, direction, thickness_m, film_n[0], exterior, OPS)  # the hero's n_f, as ever
    return film_terms(spectra, cosine, thickness_m), [(shear[0], shear[1])] * len(means)


def visible_reflectance(
    terms: list[mi.Spectrum],
    shears: list[tuple[mi.Float, mi.Float]],
    covariances: list[tuple[mi.Float, mi.Float, mi.Float]],
    coherence: IncidentCoherence,
    visibility: VisibilityModel,
    wavelengths: mi.Spectrum,
) -> mi.Spectrum:
    """R(V) ∈ [0, 1] with V_d = μ(d·ξ_j) of the detected spread C_j (rad², the angular form: Σ = r²C at
    r = 1) and the source's modes (``VisibilityModel.degree``)."""
    visibilities = []
    for separation in range(1, len(terms)):
        values = mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            xi = (separation * shears[j][0], separation * shears[j][1])
            values[j] = visibility.degree(coherence, xi, covariances[j], 1.0, wavelengths[j] * 1e-9)
        visibilities.append(values)
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
        """The lobe lit from the exterior (``eval_domain``) by light whose phase reference is ``wo_phase``
        (an emitter's centre; ``coherence``: its Σ⊥ in a frame ⟂ that direction): the film's reflectance
        of the source directions its lobe passes towards ``wi`` (module docstring)."""
        frame, wi = point.frame, point.wi
        reference = -frame.to_world(wo_phase)  # the light's propagation direction k
        basis_x, basis_y = coherence.frame_x, coherence.frame_y
        normal = (dr.dot(frame.n, basis_x), dr.dot(frame.n, basis_y), dr.dot(frame.n, reference))
        inverse_r2 = dr.rcp(dr.square(dr.maximum(coherence.distance_m, 1e-9)))
        source_cov = (
            coherence.sigma_xx * inverse_r2,
            coherence.sigma_xy * inverse_r2,
            coherence.sigma_yy * inverse_r2,
        )
        # The lobe is centred on the mirror direction of wi: its offset from the reference, k_a − k.
        lobe_centre = -frame.to_world(mi.Vector3f(-wi.x, -wi.y, wi.z)) - reference
        acceptance_mean = (dr.dot(lobe_centre, basis_x), dr.dot(lobe_centre, basis_y))
        light = detected_light(
            normal,
            (mi.Float(0.0), mi.Float(0.0)),
            source_cov,
            acceptance_mean,
            self.lobe_variance(point.wavelengths),
            coherence.acceptance_unbounded,
            coherence.rect_source,
            point.wavelengths,
        )
        terms, shears = film_at_directions(point.spectra, normal, light.means)
        reflectance = visible_reflectance(
            terms, shears, light.covariances, coherence, self.params.visibility, point.wavelengths
        )
        return self.lobe_eval(point, wo, reflectance)

    def lobe_variance(self, wavelengths: mi.Spectrum) -> mi.Spectrum:
        """The per-axis variance (rad²) of the directions the film's rough lobe accepts, per wavelength
        (``hgcore.optics.acceptance.lobe_acceptance_variance``)."""
        exterior = self.record.values.get(mat.EXTERIOR_IOR, 1.0)
        result = mi.Spectrum(0.0)
        for j in range(len(wavelengths)):
            result[j] = lobe_acceptance_variance(self.model, exterior, wavelengths[j] * 1e-9, OPS)
        return result

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
