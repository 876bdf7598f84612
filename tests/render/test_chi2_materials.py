"""χ² goodness-of-fit of every material's sampler against its pdf, as the path tracer's kernels run them.

For each material of ``worker.render.materials.MaterialKind`` that samples directions (diffuse, mirror,
smooth and rough dielectric, rough conductor, thin film on a conductor and on a dielectric, 1-D and 2-D
gratings; ``black`` absorbs and samples nothing) and for incidence from both sides where the material
transmits, 2²⁰ ≈ 1.05e6 samples are histogrammed on the sphere (``tests/support/chi2.py``) and compared with
the kernels' own ``eval_pdf`` integrated over the cells, scaled by the model's probability of choosing that
regular component; the Dirac components' probabilities (e^{−g}, R·e^{−g_r} + T·e^{−g_t}, η_00, a film's
R) come from ``hgcore.optics``. Family level α = 0.01 over all the tests of this module, Šidák-corrected.

Smooth dielectrics and mirrors are all Dirac: their test is the reflect/refract split against Fresnel
(a two-outcome χ²) and the exact directions. ``test_chi2_rejects_a_wrong_lobe_width`` shows that the test
can fail: the same samples against the pdf of a lobe 3 % wider are rejected.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from hgcore.optics import grating as grating_model
from hgcore.optics import rough_surface
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.fresnel import fresnel_dielectric
from hgcore.optics.thin_film import film_reflectance_terms
from tests.render.kernel_harness import MaterialAdapter, material_adapter
from tests.support.chi2 import RegularLobe, SphereGrid, direction_chi2, discrete_chi2, sidak_level

SAMPLES = 2**20
ALPHA = 0.01
GRID = SphereGrid(phi_cells=120, cos_cells=60)  # full sphere: a sample on the wrong side fails outright
QUADRATURE_NODES = 6  # per cell and axis; the regular mass converges to < 1e-6 (checked at 10 nodes)


def local_direction(theta_deg: float, phi_deg: float = 0.0, lower: bool = False) -> np.ndarray:
    theta, phi = math.radians(theta_deg), math.radians(phi_deg)
    z = -math.cos(theta) if lower else math.cos(theta)
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), z])


@dataclass(frozen=True)
class Case:
    """One material at one incident direction and wavelength, with its model's component probabilities:
    ``dirac(wi, λ)`` = P(Dirac) and ``scale(wi, λ, upper)`` = P(regular component of that side) / (what the
    kernels' pdf already includes)."""

    material: dict[str, Any]
    wi: np.ndarray
    wavelength_nm: float
    dirac: Callable[[np.ndarray, float], float]
    scale: Callable[[np.ndarray, float, bool], float]


def _surface(material: dict[str, Any]) -> rough_surface.RoughSurface:
    return rough_surface.RoughSurface(
        material["roughness_rms_um"] * 1e-6,
        material["correlation_length_um"] * 1e-6,
        material.get("psd", "gaussian"),
        material.get("psd_exponent", 2.0),
    )


def _specular_fraction(
    material: dict[str, Any], cos_i: float, wavelength_nm: float, n_i: float = 1.0
) -> float:
    """e^{−g}, g = (4π σ n_i cos θ_i/λ)² (Harvey): the specular share of the reflected power."""
    g = rough_surface.roughness_exponent(
        material["roughness_rms_um"] * 1e-6, cos_i, wavelength_nm * 1e-9, n_i
    )
    return math.exp(-g)


def rough_reflector(material: dict[str, Any], theta_deg: float, wavelength_nm: float) -> Case:
    """Rough conductor or film on a conductor: Dirac with e^{−g}, else the lobe (pdf without 1 − e^{−g})."""
    wi = local_direction(theta_deg, 30.0)

    def dirac(w: np.ndarray, lam: float) -> float:
        return _specular_fraction(material, w[2], lam)

    return Case(material, wi, wavelength_nm, dirac, lambda w, lam, upper: 1.0 - dirac(w, lam))


def rough_glass(material: dict[str, Any], theta_deg: float, wavelength_nm: float, inside: bool) -> Case:
    """Reflect with R(θ), transmit with T = 1 − R; within each, Dirac with e^{−g_r} or e^{−g_t}. The pdf
    includes R and T (``bsdfs._rough_dielectric_eval``), not 1 − e^{−g}."""
    wi = local_direction(theta_deg, 30.0, lower=inside)
    n = material["ior"]
    n_camera, n_other = (n, 1.0) if inside else (1.0, n)
    sigma_m = material["roughness_rms_um"] * 1e-6

    def fractions(w: np.ndarray, lam: float) -> tuple[float, float, float, float]:
        cos_i = abs(w[2])
        reflectance, cos_t = fresnel_dielectric(np.array(cos_i), n_other / n_camera, NUMPY)
        reflectance, cos_t = float(reflectance), float(cos_t)
        g_r = rough_surface.roughness_exponent(sigma_m, cos_i, lam * 1e-9, n_camera)
        g_t = rough_surface.transmission_roughness_exponent(
            sigma_m, cos_i, cos_t, lam * 1e-9, n_camera, n_other
        )
        transmittance = 0.0 if cos_t == 0.0 else 1.0 - reflectance
        return reflectance, transmittance, math.exp(-g_r), math.exp(-g_t)

    def dirac(w: np.ndarray, lam: float) -> float:
        r, t, s_r, s_t = fractions(w, lam)
        return r * s_r + t * s_t

    def scale(w: np.ndarray, lam: float, upper: bool) -> float:
        _, _, s_r, s_t = fractions(w, lam)
        camera_side = upper != inside  # the reflected lobe lies on the camera's side
        return 1.0 - (s_r if camera_side else s_t)

    return Case(material, wi, wavelength_nm, dirac, scale)


def film_reflectance(material: dict[str, Any], cos_i: float, wavelength_nm: float) -> float:
    """Incoherent reflectance Σ_p |a_p|² of the film, every beam (what the sampler selects reflection by)."""
    substrate = material["substrate"]
    terms = film_reflectance_terms(
        np.array(cos_i),
        wavelength_nm * 1e-9,
        material["film_thickness_um"] * 1e-6,
        material["film_ior"],
        ComplexPair(substrate["ior"], 0.0),
        1.0,
        material.get("beams", 4),
        NUMPY,
    )
    return float(terms[0])


def coated_glass(material: dict[str, Any], theta_deg: float, wavelength_nm: float) -> Case:
    """Film on a dielectric, from outside: reflect with R_f (Dirac e^{−g} or the lobe), else refract (Dirac).
    The lobe's pdf is the rough film's alone (no R_f, no 1 − e^{−g})."""
    wi = local_direction(theta_deg, 30.0)

    def dirac(w: np.ndarray, lam: float) -> float:
        r = film_reflectance(material, w[2], lam)
        return r * _specular_fraction(material, w[2], lam) + (1.0 - r)

    def scale(w: np.ndarray, lam: float, upper: bool) -> float:
        return film_reflectance(material, w[2], lam) * (1.0 - _specular_fraction(material, w[2], lam))

    return Case(material, wi, wavelength_nm, dirac, scale)


def grating_case(material: dict[str, Any], theta_deg: float, wavelength_nm: float) -> Case:
    """0th order (Dirac) with η_00(λ), else a diffraction lobe whose pdf is normalised over the orders."""
    model = grating_model.BinaryGrating(
        pitch_x_m=material["pitch_um"] * 1e-6,
        pitch_y_m=material["pitch_y_um"] * 1e-6 if "pitch_y_um" in material else None,
        duty_cycle=material.get("duty", 0.5),
        depth_m=material["pit_depth_nm"] * 1e-9,
        pit_ior=material.get("pit_ior", 1.55),
        lobe_width_per_um=material["lobe_width_per_um"],
        max_order=material.get("max_order", 3),
    )
    wi = local_direction(theta_deg, 15.0)

    def dirac(w: np.ndarray, lam: float) -> float:
        return float(grating_model.specular_efficiency(model, lam * 1e-9, NUMPY))

    return Case(material, wi, wavelength_nm, dirac, lambda w, lam, upper: 1.0 - dirac(w, lam))


ROUGH_AU = {
    "type": "rough_conductor",
    "conductor": "Au",
    "roughness_rms_um": 0.05,
    "correlation_length_um": 1.0,
}
FILM_ON_GLASS = {
    "type": "thin_film",
    "film_thickness_um": 0.4,
    "film_ior": 2.1,
    "substrate": {"ior": 1.5},
    "roughness_rms_um": 0.04,
    "correlation_length_um": 1.5,
}
GLASS_LOBE = {"type": "rough_dielectric", "ior": 1.5, "roughness_rms_um": 0.1, "correlation_length_um": 1.0}
GRATING = {"type": "grating", "pitch_um": 1.6, "pit_depth_nm": 110.0, "lobe_width_per_um": 2.0}

CASES: dict[str, Case] = {
    "diffuse": Case(
        {"type": "diffuse", "reflectance": 0.8},
        local_direction(30.0),
        550.0,
        lambda w, lam: 0.0,
        lambda w, lam, upper: 1.0,
    ),
    "rough conductor, Gaussian, 40°": rough_reflector(ROUGH_AU, 40.0, 550.0),
    "rough conductor, Gaussian, grazing 75°": rough_reflector(
        {**ROUGH_AU, "roughness_rms_um": 0.1, "correlation_length_um": 2.0}, 75.0, 450.0
    ),
    "rough conductor, ABC": rough_reflector(
        {**ROUGH_AU, "correlation_length_um": 0.5, "psd": "abc", "psd_exponent": 2.5}, 55.0, 650.0
    ),
    "rough dielectric, outside": rough_glass(GLASS_LOBE, 30.0, 550.0, inside=False),
    "rough dielectric, inside": rough_glass(GLASS_LOBE, 20.0, 500.0, inside=True),
    "rough dielectric, inside beyond the critical angle": rough_glass(GLASS_LOBE, 60.0, 600.0, inside=True),
    "rough dielectric, ABC, outside": rough_glass(
        {**GLASS_LOBE, "psd": "abc", "correlation_length_um": 0.5}, 50.0, 450.0, inside=False
    ),
    "thin film on a conductor": rough_reflector(
        {
            "type": "thin_film",
            "film_thickness_um": 0.3,
            "film_ior": 1.45,
            "substrate": {"conductor": "Ag"},
            "roughness_rms_um": 0.05,
            "correlation_length_um": 1.0,
        },
        45.0,
        550.0,
    ),
    "thin film on a dielectric, outside": coated_glass(FILM_ON_GLASS, 35.0, 550.0),
    "grating, 1-D": grating_case(GRATING, 20.0, 550.0),
    "grating, 2-D, rotated": grating_case(
        {**GRATING, "pitch_y_um": 1.2, "orientation_deg": 30.0, "lobe_width_per_um": 3.0}, 35.0, 600.0
    ),
}
DISCRETE_CASES = ["mirror", "dielectric, outside", "dielectric, inside", "thin film on a dielectric, inside"]
TEST_COUNT = len(CASES) + len(DISCRETE_CASES) + 1  # + the wrong-width check's exact-width half
LEVEL = sidak_level(ALPHA, TEST_COUNT)


def _uniforms(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).random((SAMPLES, 3))


def _case_chi2(case: Case, adapter: MaterialAdapter, seed: int, pdf: Callable[[np.ndarray], np.ndarray]):
    sampled = adapter.sample(_uniforms(seed))
    lobe = RegularLobe(
        pdf,
        lambda wo: np.where(
            wo[:, 2] >= 0.0,
            case.scale(case.wi, case.wavelength_nm, True),
            case.scale(case.wi, case.wavelength_nm, False),
        ),
    )
    dirac_probability = case.dirac(case.wi, case.wavelength_nm)
    return direction_chi2(
        sampled.wo, sampled.dirac, sampled.rejected, lobe, dirac_probability, GRID, QUADRATURE_NODES
    )


@pytest.mark.slow  # ≈ 2–5 s per case once the kernels are compiled (tens of seconds cold)
@pytest.mark.parametrize("name", list(CASES))
def test_sampler_matches_pdf(name: str) -> None:
    case = CASES[name]
    adapter = material_adapter(case.material, case.wi, case.wavelength_nm)
    result = _case_chi2(case, adapter, seed=sum(map(ord, name)), pdf=adapter.pdf)
    assert result.passes(LEVEL), (name, LEVEL, result.messages)


def _reflect(wi: np.ndarray) -> np.ndarray:
    return np.array([-wi[0], -wi[1], wi[2]])


def _refract(wi: np.ndarray, eta: float) -> np.ndarray:
    """Snell's direction for relative index η = n_t/n_i (local frame, through the plane z = 0)."""
    cos_i = abs(wi[2])
    cos_t = math.sqrt(1.0 - (1.0 - cos_i * cos_i) / (eta * eta))
    return np.array([-wi[0] / eta, -wi[1] / eta, -math.copysign(cos_t, wi[2])])


@pytest.mark.slow
@pytest.mark.parametrize("name", DISCRETE_CASES)
def test_dirac_materials_split_by_fresnel(name: str) -> None:
    """All-Dirac samplers: every sample is the mirror or Snell direction, reflected with probability R."""
    if name == "mirror":
        material: dict[str, Any] = {"type": "mirror", "conductor": "perfect"}
        wi, reflectance, eta = local_direction(50.0, 10.0), 1.0, 1.0
    elif name.startswith("dielectric"):
        material = {"type": "dielectric", "ior": 1.5}
        inside = name.endswith("inside")
        wi = local_direction(30.0 if inside else 50.0, 10.0, lower=inside)
        eta = 1.0 / 1.5 if inside else 1.5
        reflectance = float(fresnel_dielectric(np.array(abs(wi[2])), eta, NUMPY)[0])
    else:
        material = FILM_ON_GLASS
        wi = local_direction(25.0, 10.0, lower=True)  # below the substrate's critical angle (41.8°)
        eta = 1.0 / 1.5
        exterior_cos = math.sqrt(1.0 - (1.5 * math.sin(math.radians(25.0))) ** 2)
        reflectance = film_reflectance(material, exterior_cos, 550.0)
    sampled = material_adapter(material, wi, 550.0).sample(_uniforms(len(name)))
    assert np.all(sampled.dirac)
    reflected = np.all(np.abs(sampled.wo - _reflect(wi)) < 1e-5, axis=1)
    refracted = (
        np.all(np.abs(sampled.wo - _refract(wi, eta)) < 1e-5, axis=1) if reflectance < 1 else ~reflected
    )
    assert np.all(reflected | refracted), np.unique(sampled.wo[~(reflected | refracted)], axis=0)[:5]
    if reflectance >= 1.0:
        assert np.all(reflected)
        return
    result = discrete_chi2(
        np.array([reflected.sum(), refracted.sum()]), np.array([reflectance, 1 - reflectance])
    )
    assert result.passes(LEVEL), (name, reflectance, result.messages)


# The wrong-width check: the conductor case's samples against hgcore's NumPy pdf with ℓ_c exact (must pass:
# the kernels' pdf is the model's) and 3 % off (must be rejected: the test has power against it).
WRONG_WIDTH_FACTOR = 1.03


@pytest.mark.slow
def test_chi2_rejects_a_wrong_lobe_width() -> None:
    case = CASES["rough conductor, Gaussian, 40°"]
    adapter = material_adapter(case.material, case.wi, case.wavelength_nm)
    exact = _surface(case.material)

    def numpy_pdf(surface: rough_surface.RoughSurface) -> Callable[[np.ndarray], np.ndarray]:
        def pdf(wo: np.ndarray) -> np.ndarray:
            wi = tuple(np.full(len(wo), c) for c in case.wi)
            return rough_surface.rough_reflection_pdf(
                surface, wi, tuple(wo.T), case.wavelength_nm * 1e-9, NUMPY
            )

        return pdf

    wider = rough_surface.RoughSurface(exact.rms_height_m, exact.correlation_length_m / WRONG_WIDTH_FACTOR)
    right = _case_chi2(case, adapter, seed=7, pdf=numpy_pdf(exact))
    wrong = _case_chi2(case, adapter, seed=7, pdf=numpy_pdf(wider))
    assert right.passes(LEVEL), right.messages
    assert not wrong.passes(LEVEL), wrong.messages
