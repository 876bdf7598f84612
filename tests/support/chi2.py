"""Pearson χ² goodness-of-fit of a direction sampler against its density (after Mitsuba's ``chi2.py``).

The sphere of directions is cut into equal-area cells in (φ, cos θ) (dω = dφ d(cos θ), so a cell's
probability is the plain integral of the solid-angle density over it). Each sample lands in one outcome:

* a cell of the grid, if it is a regular (non-Dirac) sample with non-zero weight;
* the *Dirac* outcome, if the sampler chose a delta component (mirror-like reflection, specular
  refraction, a grating's 0th order) — its expected probability comes from the model, not the sampler;
* the *rejected* outcome, if the sampler returned a zero-weight regular sample (a drawn spatial frequency
  that is evanescent, |β_o| ≥ 1) — expected probability: the regular mass minus the density's integral.

The expected count of a cell is N ∫_cell c·p dω, integrated with an n×n Gauss–Legendre rule per cell
(exact for polynomials of degree 2n − 1 in each variable; far more accurate than the trapezoid rule of
Mitsuba for the smooth lobes tested here), where p is the material's pdf and c the probability with which
the sampler picks the regular component that p describes (``RegularLobe.scale``). Cells whose expected
counts are below 5 are pooled in increasing order of expectation (the usual validity condition of the χ²
approximation); the statistic has (outcomes after pooling − 1) degrees of freedom because N is fixed.
A sample in a cell of zero expectation rejects outright. The p-value is P(χ²_dof ≥ X²) and the test
rejects when it is below the Šidák-corrected level 1 − (1 − α)^{1/m} of m tests at family level α.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_distribution

POOL_THRESHOLD = 5.0

# (N, 3) unit directions -> (N,) solid-angle density
DensityFunction = Callable[[np.ndarray], np.ndarray]


def sidak_level(alpha: float, test_count: int) -> float:
    """Per-test significance so that m independent tests reject a true hypothesis with probability α."""
    return 1.0 - (1.0 - alpha) ** (1.0 / test_count)


@dataclass(frozen=True)
class SphereGrid:
    """``phi_cells`` × ``cos_cells`` equal-area cells over cos θ ∈ [z_min, z_max] (θ from +z)."""

    phi_cells: int
    cos_cells: int
    z_min: float = -1.0
    z_max: float = 1.0

    @property
    def cell_count(self) -> int:
        return self.phi_cells * self.cos_cells

    def cell_of(self, directions: np.ndarray) -> np.ndarray:
        """Cell index of each unit direction (clamped into the grid at its boundaries)."""
        phi = np.mod(np.arctan2(directions[:, 1], directions[:, 0]), 2.0 * math.pi)
        i = np.clip((phi / (2.0 * math.pi) * self.phi_cells).astype(int), 0, self.phi_cells - 1)
        u = (directions[:, 2] - self.z_min) / (self.z_max - self.z_min)
        j = np.clip((u * self.cos_cells).astype(int), 0, self.cos_cells - 1)
        return j * self.phi_cells + i

    def contains(self, directions: np.ndarray) -> np.ndarray:
        return (directions[:, 2] >= self.z_min) & (directions[:, 2] <= self.z_max)

    def integrate(self, density: DensityFunction, nodes: int = 4) -> np.ndarray:
        """∫ density dω over every cell (cell-major as ``cell_of``), n×n Gauss–Legendre per cell."""
        x, w = np.polynomial.legendre.leggauss(nodes)
        x, w = 0.5 * (x + 1.0), 0.5 * w  # on [0, 1]
        d_phi = 2.0 * math.pi / self.phi_cells
        d_z = (self.z_max - self.z_min) / self.cos_cells
        j, i, b, a = np.meshgrid(
            np.arange(self.cos_cells),
            np.arange(self.phi_cells),
            np.arange(nodes),
            np.arange(nodes),
            indexing="ij",
        )
        phi = (i + x[a]) * d_phi
        z = self.z_min + (j + x[b]) * d_z
        sin_theta = np.sqrt(np.maximum(1.0 - z * z, 0.0))
        points = np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), z], axis=-1).reshape(-1, 3)
        values = density(points).reshape(j.shape)
        weights = (w[b] * w[a]) * (d_phi * d_z)
        return np.sum(values * weights, axis=(2, 3)).reshape(-1)


@dataclass
class Chi2Result:
    statistic: float
    dof: int
    p_value: float
    messages: list[str] = field(default_factory=list)

    def passes(self, level: float) -> bool:
        return self.dof >= 1 and math.isfinite(self.p_value) and self.p_value >= level


def pooled_chi2(observed: np.ndarray, expected: np.ndarray) -> Chi2Result:
    """X² = Σ (O − E)²/E over the outcomes, cells with E < 5 pooled (ascending E) until each pool has
    E ≥ 5; a remainder pool below 5 joins the last pool formed. Observed samples where E = 0 give p = 0."""
    observed = np.asarray(observed, dtype=float)
    expected = np.asarray(expected, dtype=float)
    messages: list[str] = []
    impossible = (expected <= 0.0) & (observed > 0.0)
    if np.any(impossible):
        messages.append(
            f"{int(observed[impossible].sum())} samples in {int(impossible.sum())} cells of zero pdf"
        )
        return Chi2Result(math.inf, 0, 0.0, messages)
    order = np.argsort(expected, kind="stable")
    observed, expected = observed[order], expected[order]
    high = expected >= POOL_THRESHOLD
    o_groups = list(observed[high])
    e_groups = list(expected[high])
    low = ~high & (expected > 0.0)
    pooled_o: list[float] = []
    pooled_e: list[float] = []
    sum_o = sum_e = 0.0
    for o, e in zip(observed[low], expected[low], strict=True):
        sum_o += o
        sum_e += e
        if sum_e >= POOL_THRESHOLD:
            pooled_o.append(sum_o)
            pooled_e.append(sum_e)
            sum_o = sum_e = 0.0
    if sum_e > 0.0:
        if pooled_e:
            pooled_o[-1] += sum_o
            pooled_e[-1] += sum_e
        elif e_groups:  # no pool formed: the remainder joins the smallest regular cell
            o_groups[0] += sum_o
            e_groups[0] += sum_e
        else:
            pooled_o.append(sum_o)
            pooled_e.append(sum_e)
    if np.any(low):
        messages.append(f"pooled {int(low.sum())} low-expectation cells into {len(pooled_e)}")
    o_all = np.asarray(o_groups + pooled_o)
    e_all = np.asarray(e_groups + pooled_e)
    statistic = float(np.sum((o_all - e_all) ** 2 / e_all))
    dof = len(e_all) - 1
    p_value = float(chi2_distribution.sf(statistic, dof)) if dof >= 1 else math.nan
    messages.append(f"X² = {statistic:.1f}, dof = {dof}, p = {p_value:.3g}")
    return Chi2Result(statistic, dof, p_value, messages)


@dataclass(frozen=True)
class RegularLobe:
    """The sampler's regular (non-Dirac) part: it draws ω with density ``scale(ω)·pdf(ω)``.

    ``pdf`` is the material's density as the renderer evaluates it (for MIS and sample weights);
    ``scale`` is the model's probability of selecting the component it describes on each side of the
    surface (e.g. 1 − e^{−g} for a rough conductor). pdf may integrate to less than 1 where the sampler
    rejects (evanescent frequencies); that mass is the rejected outcome's.
    """

    pdf: DensityFunction
    scale: Callable[[np.ndarray], np.ndarray]

    def density(self, directions: np.ndarray) -> np.ndarray:
        return self.scale(directions) * self.pdf(directions)


def direction_chi2(
    wo: np.ndarray,
    dirac: np.ndarray,
    rejected: np.ndarray,
    lobe: RegularLobe,
    dirac_probability: float,
    grid: SphereGrid,
    nodes: int = 4,
) -> Chi2Result:
    """χ² of N sampled outcomes (directions ``wo``, flags ``dirac``/``rejected``) against the model.

    Outcomes: the grid's cells, Dirac (expected N·P_δ) and rejected (expected N(1 − P_δ − Σ_cells ∫c·p)).
    """
    count = len(wo)
    regular = ~dirac & ~rejected
    messages = []
    outside = regular & ~grid.contains(wo)
    if np.any(outside):
        messages.append(f"{int(outside.sum())} regular samples outside the grid")
    histogram = np.bincount(grid.cell_of(wo[regular & ~outside]), minlength=grid.cell_count).astype(float)
    cells = count * grid.integrate(lobe.density, nodes)
    regular_mass = 1.0 - dirac_probability
    rejected_expected = count * regular_mass - cells.sum()
    # The density may not integrate to more than the regular mass (beyond quadrature error, 1e-4).
    if rejected_expected < -1e-4 * count:
        messages.append(f"density integrates to {cells.sum() / count:.5f} > regular mass {regular_mass:.5f}")
        return Chi2Result(math.inf, 0, 0.0, messages)
    observed = np.concatenate([histogram, [dirac.sum(), rejected.sum() + outside.sum()]])
    expected = np.concatenate([cells, [count * dirac_probability, max(rejected_expected, 0.0)]])
    result = pooled_chi2(observed, expected)
    result.messages[:0] = messages
    result.messages.append(
        f"Dirac {int(dirac.sum())} vs {count * dirac_probability:.0f}, rejected {int(rejected.sum())} vs "
        f"{max(rejected_expected, 0.0):.0f}, ∫ c·p dω = {cells.sum() / count:.5f}"
    )
    return result


def discrete_chi2(observed: np.ndarray, probabilities: np.ndarray) -> Chi2Result:
    """χ² of counts over a finite set of outcomes with model probabilities (e.g. reflect / refract)."""
    observed = np.asarray(observed, dtype=float)
    return pooled_chi2(observed, observed.sum() * np.asarray(probabilities, dtype=float))
