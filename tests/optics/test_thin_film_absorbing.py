"""Absorbing thin films (complex film index n_f + iκ_f) on silver and gold.

References written independently here with NumPy complex arithmetic: the coherent reflectance from the
characteristic (transfer) matrix of the layer (Born & Wolf §1.6.2, Macleod "Thin-Film Optical Filters"
§2.2; e^{−iωt} convention, so the layer matrix carries −i), and the incoherent limit from the explicit
beam sum with each round trip's attenuation. Neither uses ``hgcore.optics.fresnel`` nor the closed-form
all-beam sums of ``hgcore.optics.thin_film``; agreement is to float64 round-off (1e-9 allowed: the
transfer matrix loses a few digits to cancellation in its numerator near R → 1).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hgcore.errors import InputError
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.ior import spectral_ior
from hgcore.optics.thin_film import (
    combine_reflectance_terms,
    film_amplitudes,
    film_reflectance_terms,
    film_shear,
    gaussian_visibilities,
    validate_thin_film,
)

TOLERANCE = 1e-9
ANGLES_DEG = np.arange(0.0, 80.1, 5.0)
WAVELENGTHS_NM = (420.0, 530.0, 650.0)
FILMS = tuple(itertools.product((2.7,), (0.05, 0.4, 0.8, 2.0), (0.03e-6, 0.1e-6, 0.3e-6)))


def _substrate(name: str, wavelength_nm: float) -> complex:
    n, kappa = spectral_ior(name, wavelength_nm)
    return complex(float(np.asarray(n).ravel()[0]), float(np.asarray(kappa).ravel()[0]))


def _admittances(eta: complex, sin_sq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tilted admittances (s: η cos θ; p: η/cos θ = η²/(η cos θ)) with Im(η cos θ) ≥ 0."""
    q = np.sqrt(eta * eta - sin_sq + 0j)
    q = np.where(q.imag < 0, -q, q)
    return q, eta * eta / q


def _transfer_matrix_reflectance(
    cos_i: np.ndarray, wavelength_m: float, thickness_m: float, film: complex, substrate: complex
) -> tuple[np.ndarray, np.ndarray]:
    """(R_s, R_p) of air | film | substrate from the layer's characteristic matrix.

    [B, C]ᵀ = M [1, Y_2]ᵀ, M = [[cos β, −i sin β / Y_1], [−i Y_1 sin β, cos β]], β = k η_1 cos θ_1 τ;
    r = (Y_0 B − C)/(Y_0 B + C) (its sign convention differs from Fresnel's r_p; |r|² does not).
    """
    sin_sq = 1.0 - cos_i**2
    q1 = np.sqrt(film * film - sin_sq + 0j)
    q1 = np.where(q1.imag < 0, -q1, q1)
    beta = 2.0 * np.pi / wavelength_m * q1 * thickness_m
    result = []
    for index in (0, 1):
        y0 = _admittances(1.0 + 0j, sin_sq)[index]
        y1 = _admittances(film, sin_sq)[index]
        y2 = _admittances(substrate, sin_sq)[index]
        b = np.cos(beta) - 1j * np.sin(beta) / y1 * y2
        c = -1j * y1 * np.sin(beta) + np.cos(beta) * y2
        r = (y0 * b - c) / (y0 * b + c)
        result.append(np.abs(r) ** 2)
    return result[0], result[1]


def _beam_sum_incoherent(
    cos_i: np.ndarray, wavelength_m: float, thickness_m: float, film: complex, substrate: complex
) -> np.ndarray:
    """Σ_p |a_p|², unpolarised, from the explicit beams a_0 = r_01,
    a_p = t_01 t_10 r_12 (r_10 r_12)^{p−1} e^{ipδ}, summed until the remaining beams are below 1e-18 of the
    incident power (each round trip attenuates by |e^{iδ}| = e^{−2k Im q_1 τ})."""
    sin_sq = 1.0 - cos_i**2
    q0 = cos_i + 0j
    q1 = np.sqrt(film * film - sin_sq + 0j)
    q2 = np.sqrt(substrate * substrate - sin_sq + 0j)
    phase = np.exp(2j * (2.0 * np.pi / wavelength_m) * q1 * thickness_m)
    total = np.zeros_like(cos_i)
    for pol in ("s", "p"):
        if pol == "s":
            r01, r10 = (q0 - q1) / (q0 + q1), (q1 - q0) / (q1 + q0)
            t01, t10 = 2 * q0 / (q0 + q1), 2 * q1 / (q1 + q0)
            r12 = (q1 - q2) / (q1 + q2)
        else:
            r01 = (film**2 * q0 - q1) / (film**2 * q0 + q1)
            r10 = (q1 - film**2 * q0) / (q1 + film**2 * q0)
            t01 = 2 * film * q0 / (film**2 * q0 + q1)
            t10 = 2 * film * q1 / (q1 + film**2 * q0)
            r12 = (substrate**2 * q1 - film**2 * q2) / (substrate**2 * q1 + film**2 * q2)
        beam = t01 * t10 * r12 * phase
        power = np.abs(r01) ** 2
        for _ in range(100000):
            power = power + np.abs(beam) ** 2
            if np.all(np.abs(beam) ** 2 < 1e-18):
                break
            beam = beam * r10 * r12 * phase
        total = total + 0.5 * power
    return total


def _pair(value: complex, like: np.ndarray) -> ComplexPair:
    return ComplexPair(np.full_like(like, value.real), np.full_like(like, value.imag))


@pytest.mark.parametrize("metal", ["Ag", "Au"])
@pytest.mark.parametrize(("n_f", "kappa_f", "thickness_m"), FILMS)
def test_coherent_reflectance_matches_transfer_matrix(metal, n_f, kappa_f, thickness_m):
    """V = 1, s and p separately (the explicit beam series, long enough to converge) and unpolarised
    (the renderer's closed-form all-beam sum), against the characteristic matrix at 0–80°."""
    cos_i = np.cos(np.radians(ANGLES_DEG))
    film = complex(n_f, kappa_f)
    for wavelength_nm in WAVELENGTHS_NM:
        wavelength_m = wavelength_nm * 1e-9
        substrate = _substrate(metal, wavelength_nm)
        r_s, r_p = _transfer_matrix_reflectance(cos_i, wavelength_m, thickness_m, film, substrate)
        amplitudes = film_amplitudes(
            cos_i, wavelength_m, thickness_m, _pair(film, cos_i), _pair(substrate, cos_i), 1.0, 400, NUMPY
        )
        for beams, reference in zip(amplitudes, (r_s, r_p), strict=True):
            total = beams[0]
            for beam in beams[1:]:
                total = total + beam
            np.testing.assert_allclose(total.abs2(), reference, rtol=0, atol=TOLERANCE)
        for beam_count in (3, 4, 8):
            terms = film_reflectance_terms(
                cos_i,
                wavelength_m,
                thickness_m,
                _pair(film, cos_i),
                _pair(substrate, cos_i),
                1.0,
                beam_count,
                NUMPY,
            )
            coherent = combine_reflectance_terms(terms, [1.0] * (beam_count - 1))
            np.testing.assert_allclose(coherent, 0.5 * (r_s + r_p), rtol=0, atol=TOLERANCE)


@pytest.mark.parametrize("metal", ["Ag", "Au"])
@pytest.mark.parametrize(("n_f", "kappa_f", "thickness_m"), FILMS)
def test_incoherent_limit_matches_attenuated_beam_sum(metal, n_f, kappa_f, thickness_m):
    cos_i = np.cos(np.radians(ANGLES_DEG))
    film = complex(n_f, kappa_f)
    for wavelength_nm in WAVELENGTHS_NM:
        wavelength_m = wavelength_nm * 1e-9
        substrate = _substrate(metal, wavelength_nm)
        terms = film_reflectance_terms(
            cos_i, wavelength_m, thickness_m, _pair(film, cos_i), _pair(substrate, cos_i), 1.0, 4, NUMPY
        )
        reference = _beam_sum_incoherent(cos_i, wavelength_m, thickness_m, film, substrate)
        np.testing.assert_allclose(terms[0], reference, rtol=0, atol=TOLERANCE)


def test_reflectance_is_a_fraction_and_series_converges():
    """R(V) ∈ [0, 1] with no clipping for every coherence between the limits (Gaussian V_d = V_1^{d²}),
    and |b| = |r_10 r_12 e^{iδ}| < 1 (the closed form's premise), over absorbing films on Ag and Au,
    0–89°, 0.01–1 µm, κ_f 0.01–10. The over-coherent tail (module docstring) stays below the clear films'
    bound 2e-3, which absorption can only lower."""
    cos_i = np.cos(np.radians(np.linspace(0.0, 89.0, 90)))
    worst = -np.inf
    lowest = np.inf
    for metal, n_f, kappa_f, thickness_um, wavelength_nm in itertools.product(
        ("Ag", "Au"), (1.5, 2.7, 4.0), (0.01, 0.3, 1.0, 10.0), (0.01, 0.08, 0.3, 1.0), (400.0, 550.0, 700.0)
    ):
        substrate = _substrate(metal, wavelength_nm)
        film = complex(n_f, kappa_f)
        sin_sq = 1.0 - cos_i**2
        q0, q1 = cos_i + 0j, np.sqrt(film * film - sin_sq + 0j)
        q2 = np.sqrt(substrate * substrate - sin_sq + 0j)
        for r10, r12 in (
            ((q1 - q0) / (q1 + q0), (q1 - q2) / (q1 + q2)),
            (
                (q1 - film**2 * q0) / (q1 + film**2 * q0),
                (substrate**2 * q1 - film**2 * q2) / (substrate**2 * q1 + film**2 * q2),
            ),
        ):
            phase = np.exp(2j * (2.0 * np.pi / (wavelength_nm * 1e-9)) * q1 * thickness_um * 1e-6)
            assert np.all(np.abs(r10 * r12 * phase) < 1.0)
        terms = film_reflectance_terms(
            cos_i,
            wavelength_nm * 1e-9,
            thickness_um * 1e-6,
            _pair(film, cos_i),
            _pair(substrate, cos_i),
            1.0,
            4,
            NUMPY,
        )
        for first in (0.0, 0.5, 0.9, 0.99, 1.0):
            value = combine_reflectance_terms(terms, gaussian_visibilities(first, 3, NUMPY))
            worst, lowest = max(worst, float(value.max())), min(lowest, float(value.min()))
    assert lowest >= 0.0
    assert worst <= 1.0 + 2e-3


def test_absorption_deepens_the_fringes_on_silver():
    """Why Fig. 7's coating absorbs: a clear film on silver is Gires–Tournois-limited (|r_12| ≈ 0.95, the
    coherent R stays high at every λ and angle), an absorbing one (n 2.7 + 0.4i, tarnish-like) balances
    the top reflection |r_01| against the attenuated back-reflection and reaches deep minima. Transfer-matrix
    values, 0–40°, 400–700 nm, 0.12 µm (the clear film n 2.4, 0.3 µm, of the earlier Fig. 7 scenes)."""
    wavelengths = np.linspace(400.0, 700.0, 61)
    cos_i = np.cos(np.radians(np.arange(0.0, 41.0, 10.0)))

    def reflectance(film: complex, thickness_m: float) -> np.ndarray:
        values = []
        for wavelength_nm in wavelengths:
            substrate = _substrate("Ag", wavelength_nm)
            r_s, r_p = _transfer_matrix_reflectance(cos_i, wavelength_nm * 1e-9, thickness_m, film, substrate)
            values.append(0.5 * (r_s + r_p))
        return np.asarray(values)

    clear, absorbing = reflectance(2.4 + 0j, 0.3e-6), reflectance(2.7 + 0.4j, 0.12e-6)
    assert clear.min() > 0.6
    assert absorbing.min() < 0.15
    # the spectral contrast (max/min over λ at each angle) that makes a colour
    assert np.all(absorbing.max(axis=0) / absorbing.min(axis=0) > 3.0 * clear.max(axis=0) / clear.min(axis=0))


def test_zero_extinction_is_the_real_index():
    """κ_f = 0 as a ComplexPair gives the real-index result (to round-off: the kernels keep the real path
    for scenes without absorbing films, so renders stay bitwise identical)."""
    cos_i = np.cos(np.radians(ANGLES_DEG))
    substrate = _pair(_substrate("Ag", 550.0), cos_i)
    real = film_reflectance_terms(cos_i, 550e-9, 0.3e-6, 2.4, substrate, 1.0, 4, NUMPY)
    lifted = film_reflectance_terms(cos_i, 550e-9, 0.3e-6, _pair(2.4 + 0j, cos_i), substrate, 1.0, 4, NUMPY)
    for a, b in zip(real, lifted, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)


def test_shear_uses_the_real_part():
    normal = (np.zeros(3), np.zeros(3), np.ones(3))
    direction = (np.array([0.3, 0.5, 0.7]), np.zeros(3), -np.sqrt(1 - np.array([0.3, 0.5, 0.7]) ** 2))
    clear = film_shear(normal, direction, 1e-7, np.full(3, 2.7), 1.0, NUMPY)
    absorbing = film_shear(normal, direction, 1e-7, ComplexPair(np.full(3, 2.7), np.full(3, 0.6)), 1.0, NUMPY)
    for a, b in zip(clear, absorbing, strict=True):
        np.testing.assert_array_equal(a, b)


def test_validation_names_film_extinction():
    validate_thin_film(1e-7, 2.7, 1.0, 0.6, dielectric_substrate=False)
    for kwargs in ({"film_extinction": -0.1}, {"film_extinction": 11.0}, {"film_extinction": float("nan")}):
        with pytest.raises(InputError, match="film_extinction"):
            validate_thin_film(1e-7, 2.7, 1.0, **kwargs)
    with pytest.raises(InputError, match=r"film_extinction.*conductor substrate"):
        validate_thin_film(1e-7, 2.7, 1.0, 0.6, dielectric_substrate=True)
