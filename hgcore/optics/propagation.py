"""Transport of a beam's coherence: free space and perfect specular reflection/refraction (§5).

Def. 4.1 writes the CSD in the scaled coordinates k/r·Qξ with Θ fixed, so:

* free-space propagation over a distance s only grows r → r + s (the coherence area grows ∝ r/k, Fig. 5);
* a perfect mirror or a perfect refraction "does not change the coherence properties of light" (§5,
  "Perfectly specular reflectors"): Θ is kept in the beam's local frame, the frame is carried along by the
  reflection/refraction, and r keeps accumulating (it is not reset at the specular vertex).

A mirror (Householder matrix H = I − 2nnᵀ) maps the frame (x, y, d) to (Hx, Hy, Hd), which is left-handed;
the state keeps right-handed frames, x' = Hx and y' = d' × x' = −Hy, so Σ_xy changes sign while Σ_xx and
Σ_yy are kept. A refraction turns (x, y, d) by the rotation that takes d to the refracted d' (about d × d').
Units: Σ⊥ in m², r in metres, directions and axes dimensionless unit vectors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from hgcore.errors import InputError
from hgcore.optics.array_ops import NUMPY, ArrayOps
from hgcore.optics.coherence import (
    DEFAULT_WAVELENGTH_M,
    CoherenceDiagnostics,
    coherence_diagnostics,
    degree_of_coherence,
    require_positive_definite,
    shape_matrix_from_covariance,
    symmetric_2x2,
)
from hgcore.optics.frames import unit_vector
from hgcore.optics.sources import TransverseCovariance


def _rotation_between(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The rotation matrix taking unit ``source`` to unit ``target`` about their common normal (Rodrigues)."""
    axis = np.cross(source, target)
    sine = float(np.linalg.norm(axis))
    cosine = float(np.dot(source, target))
    if sine < 1e-12:
        # Parallel (refraction at normal incidence): no turn. Antiparallel cannot arise from refraction.
        return np.eye(3)
    k = axis / sine
    cross_matrix = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + sine * cross_matrix + (1.0 - cosine) * (cross_matrix @ cross_matrix)


@dataclass(frozen=True)
class CoherenceState:
    """A beam's coherence: Σ⊥ = Θ⁻¹ (m²) in its frame (x_axis, y_axis, direction), r (m) and HG modes."""

    sigma_m2: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    direction: np.ndarray
    r_m: float
    coefficients: Mapping[tuple[int, int], float] = field(
        default_factory=lambda: {(0, 0): math.sqrt(math.pi)}
    )

    def __post_init__(self) -> None:
        require_positive_definite(symmetric_2x2(self.sigma_m2, "sigma_m2"), "sigma_m2")
        if not (self.r_m > 0.0 and math.isfinite(self.r_m)):
            raise InputError(f"r_m: must be a positive finite distance in metres, got {self.r_m}")
        frame = np.array([self.x_axis, self.y_axis, self.direction], dtype=float)
        if frame.shape != (3, 3) or not np.allclose(frame @ frame.T, np.eye(3), atol=1e-9):
            raise InputError("x_axis: (x_axis, y_axis, direction) must be an orthonormal frame")
        if np.linalg.det(frame) < 0.0:
            raise InputError("y_axis: (x_axis, y_axis, direction) must be right-handed (y = direction × x)")

    @classmethod
    def from_source(
        cls,
        covariance: TransverseCovariance,
        distance_m: float,
        coefficients: Mapping[tuple[int, int], float] | None = None,
    ) -> CoherenceState:
        """The beam a source (``sources.transverse_covariance``) gives after ``distance_m`` of free space.

        ``coefficients``: the source's HG modes (``sources.source_coefficients``); default the 0th mode.
        """
        state = cls(
            sigma_m2=covariance.sigma_m2,
            x_axis=covariance.x_axis,
            y_axis=covariance.y_axis,
            direction=covariance.direction,
            r_m=float(distance_m),
        )
        return state if coefficients is None else replace(state, coefficients=dict(coefficients))

    @property
    def theta_per_m2(self) -> np.ndarray:
        """The shape matrix Θ = Σ⊥⁻¹ (1/m²)."""
        return shape_matrix_from_covariance(self.sigma_m2)

    def propagated(self, distance_m: float) -> CoherenceState:
        """After ``distance_m`` more metres of free space: r grows, Θ and the frame are unchanged."""
        if not (distance_m >= 0.0 and math.isfinite(distance_m)):
            raise InputError(f"distance_m: must be a non-negative finite distance, got {distance_m}")
        return replace(self, r_m=self.r_m + float(distance_m))

    def reflected(self, normal: Sequence[float]) -> CoherenceState:
        """After a perfect mirror with surface ``normal`` (either side): frame mirrored, Θ kept, r kept."""
        unit_normal = unit_vector(normal, "normal")
        householder = np.eye(3) - 2.0 * np.outer(unit_normal, unit_normal)
        direction = householder @ self.direction
        x_axis = householder @ self.x_axis
        sigma = self.sigma_m2.copy()
        sigma[0, 1] = sigma[1, 0] = -self.sigma_m2[0, 1]  # y' = −Hy (module docstring)
        return replace(
            self, sigma_m2=sigma, x_axis=x_axis, y_axis=np.cross(direction, x_axis), direction=direction
        )

    def refracted(self, normal: Sequence[float], relative_ior: float) -> CoherenceState:
        """After a perfect refraction into a medium with n_t/n_i = ``relative_ior``: frame turned, Θ kept.

        Raises ValueError on total internal reflection (no refracted beam exists).
        """
        if not (relative_ior > 0.0 and math.isfinite(relative_ior)):
            raise InputError(f"relative_ior: must be a positive finite ratio, got {relative_ior}")
        unit_normal = unit_vector(normal, "normal")
        cos_incident = -float(np.dot(self.direction, unit_normal))
        if cos_incident < 0.0:  # normal given on the far side: face it towards the incident beam
            unit_normal, cos_incident = -unit_normal, -cos_incident
        eta = 1.0 / relative_ior
        sin_transmitted2 = eta * eta * (1.0 - cos_incident * cos_incident)
        if sin_transmitted2 > 1.0:
            raise InputError(f"relative_ior: total internal reflection at cos θi = {cos_incident:.6g}")
        cos_transmitted = math.sqrt(1.0 - sin_transmitted2)
        direction = eta * self.direction + (eta * cos_incident - cos_transmitted) * unit_normal
        direction = direction / np.linalg.norm(direction)
        rotation = _rotation_between(self.direction, direction)
        x_axis = rotation @ self.x_axis
        return replace(self, x_axis=x_axis, y_axis=np.cross(direction, x_axis), direction=direction)

    def in_frame(self, x_axis: Sequence[float]) -> CoherenceState:
        """The same beam with Σ⊥ expressed in the transverse frame with x axis ``x_axis`` (⟂ direction)."""
        new_x = unit_vector(x_axis, "x_axis")
        if abs(float(np.dot(new_x, self.direction))) > 1e-9:
            raise InputError("x_axis: must be perpendicular to the propagation direction")
        new_y = np.cross(self.direction, new_x)
        # Rows: new axes in the old (x, y) coordinates; Σ' = R Σ Rᵀ.
        rotation = np.array(
            [[new_x @ self.x_axis, new_x @ self.y_axis], [new_y @ self.x_axis, new_y @ self.y_axis]]
        )
        return replace(self, sigma_m2=rotation @ self.sigma_m2 @ rotation.T, x_axis=new_x, y_axis=new_y)

    def diagnostics(self, wavelength_m: float = DEFAULT_WAVELENGTH_M) -> CoherenceDiagnostics:
        """ℓ₁, ℓ₂, angle, anisotropy, area and M of this beam (``coherence.coherence_diagnostics``)."""
        return coherence_diagnostics(self.sigma_m2, self.r_m, wavelength_m)

    def degree_of_coherence(
        self, xi_m: Sequence[Any], wavelength_m: float = DEFAULT_WAVELENGTH_M, ops: ArrayOps = NUMPY
    ) -> Any:
        """μ(ξ) for a transverse separation ξ = (ξ_x, ξ_y) (m) in this state's frame."""
        sigma = (self.sigma_m2[0, 0], self.sigma_m2[0, 1], self.sigma_m2[1, 1])
        return degree_of_coherence(xi_m, sigma, self.r_m, wavelength_m, self.coefficients, ops)
