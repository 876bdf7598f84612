"""Thin-film fringe visibility measured from a rendered spectrum, against the two-beam form of Eq. (18).

A coated surface seen at incidence θ reflects R(λ) = R_inc(λ) + 2·V·X₁(λ) (``hgcore.optics.thin_film`` with
two beams: R_inc = |a₀|² + |a₁|², X₁ = Re a₁a₀*), V the incident light's degree of coherence at the film's
transverse separation. The rendered radiance of a region is S_b = g(λ_b)·R_b with g a smooth factor (lobe
shape, source spectrum, geometry). Dividing by the band-averaged R_inc,b and modelling g as a quadratic in
1/λ gives the linear least-squares model

    S_b / R_inc,b ≈ c₀ + c₁/λ_b + c₂/λ_b² + c_V · 2X₁,b/R_inc,b,

whose fringe coefficient over the mean trend is the visibility: V̂ = c_V / mean(c₀ + c₁/λ + c₂/λ²) (exact
when g is constant; the product g·V is linearised otherwise). X₁ oscillates with the film phase
4π n τ cos θ_t/λ, so the fit only credits modulation with the film's own period and phase; the
lane-correlated noise of hero wavelength sampling (bands Λ/4 apart share samples) has another period.
Standard error: the ordinary least-squares covariance scaled by the residual variance (it absorbs noise and
model mismatch alike).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from hgcore.optics import ior
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.thin_film import film_amplitudes, reflectance_terms

SAMPLES_PER_BAND = 41


@dataclass(frozen=True)
class FringeFit:
    """Fitted visibility V̂ (dimensionless) and its standard error."""

    visibility: float
    standard_error: float


def two_beam_band_terms(
    edges_nm: np.ndarray, cos_incidence: float, thickness_m: float, film_ior: float, substrate: str
) -> tuple[np.ndarray, np.ndarray]:
    """Band averages of R_inc and X₁ (two beams, unpolarised) of a film on a named conductor."""
    incoherent, interference = [], []
    for low_nm, high_nm in itertools.pairwise(edges_nm):
        wavelength_nm = np.linspace(low_nm, high_nm, SAMPLES_PER_BAND)
        n, kappa = ior.spectral_ior(substrate, wavelength_nm)
        amplitudes = film_amplitudes(
            np.full_like(wavelength_nm, cos_incidence),
            wavelength_nm * 1e-9,
            thickness_m,
            film_ior,
            ComplexPair(n, kappa),
            1.0,
            2,
            NUMPY,
        )
        r_incoherent, x_1 = reflectance_terms(amplitudes)
        incoherent.append(np.mean(r_incoherent))
        interference.append(np.mean(x_1))
    return np.asarray(incoherent), np.asarray(interference)


def fit_fringe_visibility(
    spectrum: np.ndarray,
    edges_nm: np.ndarray,
    cos_incidence: float,
    thickness_m: float,
    film_ior: float,
    substrate: str,
) -> FringeFit:
    """V̂ of a region's summed band spectrum ``spectrum`` (B,) over bands with edges ``edges_nm`` (B + 1,)."""
    if spectrum.shape != (len(edges_nm) - 1,):
        raise ValueError(f"spectrum: expected {len(edges_nm) - 1} bands, got shape {spectrum.shape}")
    r_incoherent, x_1 = two_beam_band_terms(edges_nm, cos_incidence, thickness_m, film_ior, substrate)
    inverse_um = 2000.0 / (edges_nm[:-1] + edges_nm[1:])
    basis = np.stack([np.ones_like(inverse_um), inverse_um, inverse_um**2, 2.0 * x_1 / r_incoherent], axis=1)
    ratio = spectrum / r_incoherent
    coefficients, *_ = np.linalg.lstsq(basis, ratio, rcond=None)
    residual = ratio - basis @ coefficients
    dof = len(ratio) - basis.shape[1]
    covariance = np.linalg.inv(basis.T @ basis) * float(residual @ residual) / dof
    trend = float(np.mean(basis[:, :3] @ coefficients[:3]))
    return FringeFit(float(coefficients[3]) / trend, float(np.sqrt(covariance[3, 3])) / abs(trend))
