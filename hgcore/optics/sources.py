"""Sourced light (Eq. 14): transverse covariance Σ⊥ of an emitter seen from a far receiver, and its HG modes.

A uniformly radiating emitter has f̃_σ ∝ F{1_X} (§5.1 "Light sources"): seen from a far receiver along the
unit direction d it is a uniform patch of intensity over its silhouette, whose second moments Σ⊥ (m², in the
transverse frame of d) give the shape matrix Θ = Σ⊥⁻¹ (Lemma 4.4 with its sign, see ``coherence``):

* sphere, radius R: a uniform disk, Σ = R²/4 · I.
* disk, radius R, unit normal n: the foreshortened disk, Σ = R²/4 (I − n⊥n⊥ᵀ), n⊥ = (n·x, n·y);
  eigenvalues R²/4 and R²cos²θ/4 with cosθ = |n·d|.
* rectangle w × h with unit edge axes u, v: an affine image of a uniform rectangle is a uniform
  parallelogram, so Σ = w²/12 u⊥u⊥ᵀ + h²/12 v⊥v⊥ᵀ exactly.
* gaussian, std σ: Σ = σ² I (the exact van Cittert–Zernike case).
* open cylinder (the emitter radiates from its lateral surface only, outwards), radius R, length L, unit
  axis a, sinθ = |a⊥|: seen along d, the visible outer surface projects onto (rectangle ℓ × 2R ∪ far end
  ellipse) minus the near end ellipse (through the open near end one sees the unlit inside), ℓ = L sinθ along
  û = a⊥/|a⊥|, ellipses with semi-axes b = R cosθ (along û) and R. Scaling û by R/b makes the ellipses
  circles; the region is then the rectangle plus the far circle's outer half-disk minus the near circle's
  inner half-disk, whatever ℓ (the half-disks cancel in area: A = 2Rℓ, the lateral surface's projected
  area). Its centroid is shifted by πb/4 towards the far end and its central second moments are
      Σ_uu = ℓ²/12 + b²(2/3 − π²/16),   Σ_vv = R²/3,   Σ_uv = 0   (exact, every θ).
  Side-on (b = 0) it is the strip diag(L²/12, R²/3); at R 1 cm, L 2 cm, 0.6 m, 30° it gives ℓ 15.1/9.1 µm
  (issue 12: the capped silhouette gave 9.8/7.4). End-on nothing radiates towards the receiver; the limit
  is used (isotropic R²/3 where the axis direction is undefined).

The ``*_covariance_components`` functions take sizes and 3-vectors of scalars/arrays and return
(Σ_xx, Σ_xy, Σ_yy) in the frame of the given transverse axes, on NumPy or inside Dr.Jit kernels.

HG coefficients (Eq. 14): c_nm = ⟨f̃/f̃(0) | Ψ̃^Θ_nm⟩. In the whitened coordinates u of Σ's principal frame
(``coherence.degree_of_coherence``) Θ becomes I, the basis is h_n(u₁)h_m(u₂) and the normalised angular
coherence of each kind is a universal function, so its coefficients ĉ_nm are constants per kind:
  disk (sphere, disk):          2J₁(v)/v with v = 2|u|   (Σ = R²/4 ⇒ v = R|k ξ/r| = 2|u|),
  rect (rectangle, cylinder):   sinc(√3 u₁) sinc(√3 u₂)  (w²/12 ⇒ w ζ/2 = √3 u),
  gaussian:                     exp(−|u|²/2).
A cylinder is the rectangle kind side-on (Fig. 7's case: its radiating surface projects onto the uniform
strip 2R × L); seen obliquely the projected region is a rectangle with a half-disk moved from one end to the
other. ``open_cylinder_angular_coherence`` gives that region's f̃ exactly (complex: the region has no centre
of symmetry) and ``open_cylinder_coefficients`` its even modes by exact integration, one set per view angle
(RMS error over |u| ≤ 3 at 16 modes: 0.014 at 10°, where the rectangle's are 0.049). After whitening the
region depends on b/ℓ alone (``open_cylinder_obliquity``), so the kernels interpolate one table over it
(``open_cylinder_coefficient_table``; error bound below). The rectangle's whitened square is
assumed aligned with Σ's principal axes (a rectangle seen face-on, or its edges' projections orthogonal).
Coefficients are the L²-closest expansion subject to μ(0) = Σ ĉ h_n(0) h_m(0) = 1 (a Lagrange-multiplier
correction of the projection; see ``_normalised_coefficients``).

Numeric path for tabulated emission: ``covariance_from_intensity_image`` (moments of a pixel image) and
``covariance_from_angular_coherence`` (finite differences of ln f̃ at 0, Theorem 5.1(ii)).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from scipy.special import j1

from hgcore.errors import InputError
from hgcore.optics.array_ops import NUMPY, ArrayOps, hermite_functions, transverse_modes
from hgcore.optics.expansion import project_csd, project_whitened_grid, whitened_quadrature
from hgcore.optics.frames import Vector3, cross3, dot3, transverse_frame, unit_vector

SOURCE_KINDS = ("sphere", "cylinder", "disk", "rect", "gaussian")
# Which universal angular-coherence function each source kind is expanded with (module docstring).
COEFFICIENT_KIND = {
    "sphere": "disk",
    "disk": "disk",
    "cylinder": "rect",
    "rect": "rect",
    "gaussian": "gaussian",
}
MAX_MODES = 64

# Below this squared length of the projected cylinder axis the view is end-on: Σ is isotropic R²/4 and the
# projected axis direction û (a division by |a⊥|) is undefined and not needed.
_END_ON_AXIS_SQUARED = 1e-12


def sphere_covariance_components(radius_m: Any) -> tuple[Any, Any, Any]:
    """Σ⊥ of a uniformly radiating sphere: a uniform disk of radius R, R²/4 · I (m²)."""
    variance = 0.25 * radius_m * radius_m
    return variance, 0.0 * variance, variance


def gaussian_covariance_components(sigma_m: Any) -> tuple[Any, Any, Any]:
    """Σ⊥ of a Gaussian emitter of standard deviation σ: σ² I (m²)."""
    variance = sigma_m * sigma_m
    return variance, 0.0 * variance, variance


def disk_covariance_components(
    radius_m: Any, normal: Vector3, x_axis: Vector3, y_axis: Vector3
) -> tuple[Any, Any, Any]:
    """Σ⊥ = R²/4 (I − n⊥n⊥ᵀ) of a uniform disk with unit ``normal`` (m², in the frame of x_axis/y_axis)."""
    variance = 0.25 * radius_m * radius_m
    normal_x = dot3(normal, x_axis)
    normal_y = dot3(normal, y_axis)
    return (
        variance * (1.0 - normal_x * normal_x),
        -variance * normal_x * normal_y,
        variance * (1.0 - normal_y * normal_y),
    )


def rectangle_covariance_components(
    width_m: Any, height_m: Any, u_axis: Vector3, v_axis: Vector3, x_axis: Vector3, y_axis: Vector3
) -> tuple[Any, Any, Any]:
    """Σ⊥ = w²/12 u⊥u⊥ᵀ + h²/12 v⊥v⊥ᵀ of a uniform w × h rectangle with unit edges u (width), v (height)."""
    width_variance = width_m * width_m / 12.0
    height_variance = height_m * height_m / 12.0
    u_x, u_y = dot3(u_axis, x_axis), dot3(u_axis, y_axis)
    v_x, v_y = dot3(v_axis, x_axis), dot3(v_axis, y_axis)
    return (
        width_variance * u_x * u_x + height_variance * v_x * v_x,
        width_variance * u_x * u_y + height_variance * v_x * v_y,
        width_variance * u_y * u_y + height_variance * v_y * v_y,
    )


def cylinder_silhouette_moments(
    radius_m: Any, length_m: Any, sin_theta: Any, cos_theta: Any
) -> tuple[Any, Any]:
    """(Σ_uu, Σ_vv) of an open cylinder's radiating lateral surface as projected (module docstring), m².

    ``sin_theta``/``cos_theta``: of the angle between the cylinder axis and the line of sight (cosθ ≥ 0).
    """
    projected_length = length_m * sin_theta
    end_semi_axis = radius_m * cos_theta
    sigma_uu = projected_length * projected_length / 12.0 + end_semi_axis * end_semi_axis * (
        2.0 / 3.0 - math.pi * math.pi / 16.0
    )
    sigma_vv = radius_m * radius_m / 3.0 + 0.0 * sigma_uu
    return sigma_uu, sigma_vv


def cylinder_covariance_components(
    radius_m: Any, length_m: Any, axis: Vector3, x_axis: Vector3, y_axis: Vector3, ops: ArrayOps = NUMPY
) -> tuple[Any, Any, Any]:
    """Σ⊥ = Σ_vv I + (Σ_uu − Σ_vv) ûûᵀ of an open cylinder with unit ``axis`` (m², x_axis/y_axis frame)."""
    axis_x = dot3(axis, x_axis)
    axis_y = dot3(axis, y_axis)
    sin_theta2 = axis_x * axis_x + axis_y * axis_y
    sin_theta = ops.sqrt(ops.minimum(sin_theta2, 1.0))
    cos_theta = ops.sqrt(ops.maximum(1.0 - sin_theta2, 0.0))
    sigma_uu, sigma_vv = cylinder_silhouette_moments(radius_m, length_m, sin_theta, cos_theta)
    end_on = sin_theta2 < _END_ON_AXIS_SQUARED
    # ûûᵀ = a⊥a⊥ᵀ/|a⊥|²; end-on the anisotropic part is zero and the division is skipped.
    anisotropic = ops.where(end_on, 0.0, sigma_uu - sigma_vv) / ops.where(end_on, 1.0, sin_theta2)
    return (
        sigma_vv + anisotropic * axis_x * axis_x,
        anisotropic * axis_x * axis_y,
        sigma_vv + anisotropic * axis_y * axis_y,
    )


@dataclass(frozen=True)
class TransverseCovariance:
    """Σ⊥ (m², 2×2) of a source seen along ``direction``, in the frame (x_axis, y_axis, direction)."""

    sigma_m2: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    direction: np.ndarray


def positive_size(value: float | None, name: str) -> float:
    """``value`` as a float if it is a positive finite size, else ValueError naming ``name``."""
    if value is None:
        raise InputError(f"{name}: required for this source")
    number = float(value)
    if not math.isfinite(number):
        raise InputError(f"{name}: must be a finite number, got {value}")
    if number <= 0.0:
        raise InputError(f"{name}: must be positive, got {value}")
    return number


def facing_plane_axes(axis: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """In-plane unit axes (u, v) of a flat emitter that contains ``axis`` and is turned about it to face the
    receiver: v = normalised d × u, so the plane is face-on when u ⟂ d and foreshortened by |u⊥| along u.
    """
    v_axis = np.cross(direction, axis)
    length = float(np.linalg.norm(v_axis))
    if length < 1e-6:
        raise InputError("axis: parallel to the direction, so a flat source is seen exactly edge-on")
    return axis, v_axis / length


def transverse_covariance(
    kind: str,
    *,
    direction: Sequence[float] = (0.0, 0.0, 1.0),
    axis: Sequence[float] = (1.0, 0.0, 0.0),
    radius_m: float | None = None,
    length_m: float | None = None,
    width_m: float | None = None,
    height_m: float | None = None,
    sigma_m: float | None = None,
    reference: Sequence[float] | None = None,
) -> TransverseCovariance:
    """Σ⊥ of a source ``kind`` seen along ``direction`` (source → receiver), in its transverse frame.

    ``axis``: the cylinder axis; for ``disk`` and ``rect`` an in-plane axis (a diameter; the width edge)
    about which the emitter is turned to face the receiver (``facing_plane_axes``); ignored otherwise.
    """
    if kind not in SOURCE_KINDS:
        raise InputError(f"source: must be one of {', '.join(SOURCE_KINDS)}, got {kind!r}")
    unit_direction = unit_vector(direction, "direction")
    unit_axis = unit_vector(axis, "axis")
    x_axis, y_axis = transverse_frame(unit_direction, reference)
    frame = (tuple(x_axis), tuple(y_axis))
    if kind == "sphere":
        components = sphere_covariance_components(positive_size(radius_m, "radius_m"))
    elif kind == "gaussian":
        components = gaussian_covariance_components(positive_size(sigma_m, "sigma_m"))
    elif kind == "cylinder":
        components = cylinder_covariance_components(
            positive_size(radius_m, "radius_m"), positive_size(length_m, "length_m"), tuple(unit_axis), *frame
        )
    elif kind == "disk":
        radius = positive_size(radius_m, "radius_m")
        u_axis, v_axis = facing_plane_axes(unit_axis, unit_direction)
        normal = cross3(tuple(u_axis), tuple(v_axis))
        components = disk_covariance_components(radius, normal, *frame)
    else:
        width, height = positive_size(width_m, "width_m"), positive_size(height_m, "height_m")
        u_axis, v_axis = facing_plane_axes(unit_axis, unit_direction)
        components = rectangle_covariance_components(width, height, tuple(u_axis), tuple(v_axis), *frame)
    sxx, sxy, syy = (float(c) for c in components)
    sigma = np.array([[sxx, sxy], [sxy, syy]])
    return TransverseCovariance(sigma_m2=sigma, x_axis=x_axis, y_axis=y_axis, direction=unit_direction)


def covariance_from_intensity_image(image: Any, pixel_size_m: float) -> np.ndarray:
    """Σ⊥ (m²) of a tabulated emission profile: image[row, column], columns along x, rows along y.

    Each pixel is taken as uniformly bright over its p × p square, so the exact second moments are those of
    the pixel centres about the intensity centroid plus p²/12 on the diagonal (the pixels' own variance).
    """
    intensity = np.asarray(image, dtype=float)
    if intensity.ndim != 2 or min(intensity.shape) < 1:
        raise InputError(f"image: expected a 2-D intensity array, got shape {intensity.shape}")
    if not np.all(np.isfinite(intensity)) or np.any(intensity < 0.0) or intensity.sum() <= 0.0:
        raise InputError("image: intensities must be finite, non-negative and not all zero")
    pixel = positive_size(pixel_size_m, "pixel_size_m")
    rows, columns = np.indices(intensity.shape, dtype=float)
    weights = intensity / intensity.sum()
    x = columns * pixel
    y = rows * pixel
    x_mean, y_mean = float(np.sum(weights * x)), float(np.sum(weights * y))
    dx, dy = x - x_mean, y - y_mean
    pixel_variance = pixel * pixel / 12.0
    sxx = float(np.sum(weights * dx * dx)) + pixel_variance
    sxy = float(np.sum(weights * dx * dy))
    syy = float(np.sum(weights * dy * dy)) + pixel_variance
    return np.array([[sxx, sxy], [sxy, syy]])


def log_hessian_at_origin(
    angular_coherence: Callable[[float, float], float], step_per_m: float
) -> np.ndarray:
    """∂²_ζ ln f̃(ζ) at ζ = 0 (m²) by central differences with Richardson extrapolation (error O(h⁴)).

    ``angular_coherence(ζ_x, ζ_y)``: f̃ at a transverse spatial frequency (1/m), need not be normalised.
    ``step_per_m``: the difference step h (1/m); choose h ≈ 0.05/(source size) so that ln f̃ changes
    by ~1e-3 over h while rounding (≈ 1e-16/h²·|ln f̃|) stays negligible.
    """
    step = positive_size(step_per_m, "step_per_m")

    def log_f(zx: float, zy: float) -> float:
        value = float(angular_coherence(zx, zy))
        if not (value > 0.0 and math.isfinite(value)):
            raise InputError(f"angular_coherence: must be positive near 0, got {value} at ({zx}, {zy})")
        return math.log(value)

    def central(h: float) -> np.ndarray:
        centre = log_f(0.0, 0.0)
        dxx = (log_f(h, 0.0) - 2.0 * centre + log_f(-h, 0.0)) / (h * h)
        dyy = (log_f(0.0, h) - 2.0 * centre + log_f(0.0, -h)) / (h * h)
        dxy = (log_f(h, h) - log_f(h, -h) - log_f(-h, h) + log_f(-h, -h)) / (4.0 * h * h)
        return np.array([[dxx, dxy], [dxy, dyy]])

    coarse, fine = central(step), central(0.5 * step)
    return fine + (fine - coarse) / 3.0


def covariance_from_angular_coherence(
    angular_coherence: Callable[[float, float], float], step_per_m: float
) -> np.ndarray:
    """Σ⊥ = −∂²_ζ ln f̃|₀ (m²), the inverse of Theorem 5.1(ii)'s shape matrix with Lemma 4.4's sign."""
    return -log_hessian_at_origin(angular_coherence, step_per_m)


def whitened_angular_coherence(kind: str) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The normalised f̃/f̃(0) of a coefficient kind as a function of whitened coordinates (u₁, u₂)."""
    if kind == "disk":

        def disk(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
            v = 2.0 * np.hypot(u1, u2)
            safe_v = np.where(v < 1e-8, 1.0, v)
            return np.where(v < 1e-8, 1.0 - v * v / 8.0, 2.0 * j1(safe_v) / safe_v)

        return disk
    if kind == "rect":
        # np.sinc(t) = sin(πt)/(πt); sin(√3u)/(√3u) = np.sinc(√3u/π).
        return lambda u1, u2: np.sinc(math.sqrt(3.0) * u1 / math.pi) * np.sinc(math.sqrt(3.0) * u2 / math.pi)
    if kind == "gaussian":
        return lambda u1, u2: np.exp(-0.5 * (u1 * u1 + u2 * u2))
    raise InputError(f"kind: must be one of disk, rect, gaussian, got {kind!r}")


@lru_cache(maxsize=64)
def _normalised_coefficients(coefficient_kind: str, mode_count: int) -> tuple[tuple[int, int, float], ...]:
    """``_constrained_expansion`` of a coefficient kind's universal whitened f̃."""
    return _constrained_expansion(whitened_angular_coherence(coefficient_kind), mode_count)


def _constrained_expansion(
    whitened: Callable[[np.ndarray, np.ndarray], np.ndarray], mode_count: int
) -> tuple[tuple[int, int, float], ...]:
    """L²-closest expansion of a whitened f̃ subject to μ(0) = Σ ĉ_nm h_n(0) h_m(0) = 1 (``_constrain``)."""
    projected = project_csd(whitened, np.eye(2), mode_count)
    degrees = list(projected)
    return _constrain(degrees, np.array([projected[degree] for degree in degrees]))


def _constrain(
    degrees: Sequence[tuple[int, int]], projected: np.ndarray
) -> tuple[tuple[int, int, float], ...]:
    """The constrained coefficients ĉ of the orthonormal projections p = ⟨f̃ | h_n h_m⟩ onto ``degrees``.

    With a_nm = h_n(0) h_m(0), the minimiser of ‖f̃ − Σ ĉ h_n h_m‖² subject to a·ĉ = 1 is ĉ = p + λa with
    λ = (1 − a·p)/(a·a) (one Lagrange multiplier). Because the mode sets are nested, its L² error cannot grow
    as modes are added, unlike a plain rescaling of p. ĉ is affine in p.
    """
    h_at_zero = hermite_functions(0.0, max(max(n, m) for n, m in degrees), NUMPY)
    at_origin = np.array([h_at_zero[n] * h_at_zero[m] for n, m in degrees])
    multiplier = (1.0 - float(at_origin @ projected)) / float(at_origin @ at_origin)
    normalised = projected + multiplier * at_origin
    return tuple((n, m, float(value)) for (n, m), value in zip(degrees, normalised, strict=True))


def source_coefficients(kind: str, mode_count: int) -> dict[tuple[int, int], float]:
    """Universal whitened-basis coefficients ĉ_nm of a source kind's angular coherence (Eq. 14), μ(0) = 1.

    ``kind``: a source kind (``SOURCE_KINDS``) or a coefficient kind (disk, rect, gaussian). Computed once
    per (kind, mode_count) by Gauss–Hermite quadrature and cached. Use with ``coherence.degree_of_coherence``.
    """
    if isinstance(mode_count, bool) or not isinstance(mode_count, int) or not 1 <= mode_count <= MAX_MODES:
        raise InputError(f"mode_count: must be an integer in 1..{MAX_MODES}, got {mode_count!r}")
    coefficient_kind = COEFFICIENT_KIND.get(kind, kind)
    if coefficient_kind not in ("disk", "rect", "gaussian"):
        raise InputError(f"source: must be one of {', '.join(SOURCE_KINDS)}, got {kind!r}")
    return {(n, m): value for n, m, value in _normalised_coefficients(coefficient_kind, mode_count)}


# Gauss–Legendre rule across the cylinder's end ellipses (v = R sin φ, φ ∈ [−π/2, π/2]): the integrand is
# smooth and entire in φ, so 64 nodes are exact to rounding for |ζ_v| R ≲ 40 (whitened |u| ≲ 20).
_END_NODES, _END_WEIGHTS = np.polynomial.legendre.leggauss(64)


def open_cylinder_angular_coherence(
    radius_m: float, length_m: float, sin_theta: float, zeta_u: Any, zeta_v: Any
) -> Any:
    """Exact normalised angular coherence f̃(ζ)/f̃(0) of an open cylinder's radiating region (complex).

    The region seen along d (module docstring): the rectangle ℓ × 2R (ℓ = L sin θ along û, the projected
    axis towards the far end; v across) plus the far end ellipse's outer half minus the near end ellipse's
    inner half (semi-axes b = R cos θ along û and R). Its Fourier transform about the centroid c = (πb/4, 0),
    ζ = (ζ_u, ζ_v) in rad/m (k ξ / r for a receiver at distance r and separation ξ):

        f̃/f̃(0) = e^{iζ_u πb/4} [ sinc(ζ_u ℓ/2) sinc(ζ_v R) − (i sin(ζ_u ℓ/2)/(Rℓ)) H(ζ) ],
        H(ζ) = ∫_{−R}^{R} e^{−iζ_v v} w(v) e^{−iζ_u w/2} sinc(ζ_u w/2) dv,   w(v) = b √(1 − v²/R²),

    (sinc x = sin x / x), H by Gauss–Legendre in φ (v = R sin φ). The region has no centre of symmetry
    unless θ = 90°, so f̃ is complex; its real part is the even part that the renderer's even HG modes carry.
    """
    if not 0.0 < sin_theta <= 1.0:
        raise InputError(
            f"sin_theta: an open cylinder radiates towards a receiver only for 0 < sinθ ≤ 1, got {sin_theta}"
        )
    cos_theta = math.sqrt(max(1.0 - sin_theta * sin_theta, 0.0))
    zeta_u = np.asarray(zeta_u, dtype=float)
    zeta_v = np.asarray(zeta_v, dtype=float)
    half_length = 0.5 * length_m * sin_theta
    end_semi_axis = radius_m * cos_theta
    phi = 0.5 * math.pi * _END_NODES
    v = radius_m * np.sin(phi)
    width = end_semi_axis * np.cos(phi)
    jacobian = 0.5 * math.pi * radius_m * np.cos(phi) * _END_WEIGHTS
    zu = zeta_u[..., None]
    zv = zeta_v[..., None]
    half_phase = 0.5 * zu * width
    along = width * np.exp(-1j * half_phase) * np.sinc(half_phase / math.pi)
    ends = np.sum(jacobian * np.exp(-1j * zv * v) * along, axis=-1)
    rectangle = np.sinc(zeta_u * half_length / math.pi) * np.sinc(zeta_v * radius_m / math.pi)
    value = rectangle - 1j * np.sin(zeta_u * half_length) * ends / (2.0 * radius_m * half_length)
    return np.exp(1j * zeta_u * (0.25 * math.pi * end_semi_axis)) * value


def open_cylinder_obliquity(
    radius_m: Any, length_m: Any, sin_theta: Any, cos_theta: Any, ops: ArrayOps = NUMPY
) -> Any:
    """α = atan2(b, ℓ) = atan2(R cosθ, L sinθ) ∈ [0, π/2] (rad): the one parameter of the whitened region.

    Whitening scales û by 1/√Σ_uu and v by 1/√Σ_vv, so the whitened region (rectangle ℓ × 2R, half-ellipses
    of semi-axes b, R) depends on the aspect b/ℓ = tan α alone: one table over α serves every cylinder.
    α = 0 side-on (the rectangle), α → π/2 towards end-on (a thin crescent; the limit is finite).
    """
    return ops.atan2(radius_m * cos_theta, length_m * sin_theta)


def _open_cylinder_projections_at(
    radius_m: float, length_m: float, sin_theta: float, mode_count: int
) -> np.ndarray:
    """p_nm = ⟨Re f̃/f̃(0) | h_n h_m⟩ of an open cylinder in whitened coordinates, u₁ along û and u₂ along v,
    for the modes of ``transverse_modes(mode_count)`` (``expansion.project_whitened_grid``).

    Re f̃ is even in each axis (``open_cylinder_coefficient_table``), so it is evaluated on the quadrature
    grid's positive quadrant only and mirrored (the rule's nodes are symmetric).
    """
    cos_theta = math.sqrt(max(1.0 - sin_theta * sin_theta, 0.0))
    sigma_uu, sigma_vv = cylinder_silhouette_moments(radius_m, length_m, sin_theta, cos_theta)
    nodes, _ = whitened_quadrature()
    count = len(nodes)
    positive = nodes[count // 2 :]
    mirror = np.maximum(np.arange(count), count - 1 - np.arange(count)) - count // 2
    along, across = np.meshgrid(positive / math.sqrt(sigma_uu), positive / math.sqrt(sigma_vv), indexing="ij")
    quadrant = np.real(open_cylinder_angular_coherence(radius_m, length_m, sin_theta, along, across))
    return project_whitened_grid(quadrant[np.ix_(mirror, mirror)], mode_count)


def open_cylinder_coefficients(
    radius_m: float, length_m: float, sin_theta: float, mode_count: int
) -> dict[tuple[int, int], float]:
    """Whitened-basis coefficients ĉ_nm (μ(0) = 1) of an open cylinder seen at sinθ, by exact integration.

    Use with ``coherence.degree_of_coherence`` and the cylinder's Σ⊥: the whitened coordinates are
    u = √λ ζ along Σ's principal axes (major first), which for the cylinder are û and v (Σ_uv = 0). The
    expanded function is the real (even) part of :func:`open_cylinder_angular_coherence` — exact in Σ and in
    every even mode; its odd part (the imaginary part about the centroid, a phase of the fringes, not their
    contrast to first order) is outside the even-mode basis. Side-on (sinθ = 1) it is the rectangle kind's.
    """
    if isinstance(mode_count, bool) or not isinstance(mode_count, int) or not 1 <= mode_count <= MAX_MODES:
        raise InputError(f"mode_count: must be an integer in 1..{MAX_MODES}, got {mode_count!r}")
    cos_theta = math.sqrt(max(1.0 - sin_theta * sin_theta, 0.0))
    sigma_uu, sigma_vv = cylinder_silhouette_moments(radius_m, length_m, sin_theta, cos_theta)
    degrees = transverse_modes(mode_count)
    # p in the (û, v) order; where v is the major axis, u₁ runs along v: p_nm(v, û) = p_mn(û, v).
    order = degrees if sigma_uu >= sigma_vv else [(m, n) for n, m in degrees]
    projected = _open_cylinder_projections_at(radius_m, length_m, sin_theta, MAX_MODES)
    columns = [transverse_modes(MAX_MODES).index(degree) for degree in order]
    return {(n, m): value for n, m, value in _constrain(degrees, projected[columns])}


# The kernels' open-cylinder modes: ĉ(α) tabulated at OPEN_CYLINDER_TABLE_SAMPLES uniform α ∈ [0, π/2] and
# interpolated linearly. Measured (bench/bench_cylinder_modes.py, the interpolant at every midpoint against
# exact integration there): at 65 samples max |Δĉ_nm| 9.3e-4 and max Σ_nm |Δĉ_nm| 3.1e-3 over every mode
# count 1–16 and both labels (both largest near end-on, α ≈ 89°; 33 samples: 3.7e-3 / 1.2e-2, error ∝ h²).
# With |h_n| ≤ π^{-1/4} (Cramér) this bounds |Δμ| ≤ Σ|Δĉ|/√π ≤ 1.8e-3 everywhere, below the 16-mode
# expansion's own error (RMS 0.014 over |u| ≤ 3 at 10°).
OPEN_CYLINDER_TABLE_SAMPLES = 65
OPEN_CYLINDER_TABLE_MAX_ABS_ERROR = 9.3e-4
OPEN_CYLINDER_TABLE_SUM_ABS_ERROR = 3.1e-3
# End-on (α = π/2) the region's limit is taken at θ = 1e-6 rad (b/ℓ = 1e6): the shape differs from the
# limit by O(1e-6).
_END_ON_LIMIT_RAD = 1e-6


def open_cylinder_table_obliquities(samples: int = OPEN_CYLINDER_TABLE_SAMPLES) -> np.ndarray:
    """The table's nodes α_i = i·(π/2)/(samples − 1), rad."""
    return np.linspace(0.0, 0.5 * math.pi, samples)


def _open_cylinder_at_obliquity(alpha: float) -> tuple[float, float, float]:
    """(R, L, sinθ) of a representative cylinder at obliquity α: R = L = 1, θ = π/2 − α (clamped end-on)."""
    theta = max(0.5 * math.pi - alpha, _END_ON_LIMIT_RAD)
    return 1.0, 1.0, math.sin(theta)


@lru_cache(maxsize=4)
def _open_cylinder_projections(samples: int) -> np.ndarray:
    """p_nm(α_i) in the (û, v) order for the modes of ``transverse_modes(MAX_MODES)``, one row per node.

    The projections onto a prefix of the modes are a prefix of these, so one pass serves every mode count
    (~10 ms per node).
    """
    return np.array(
        [
            _open_cylinder_projections_at(*_open_cylinder_at_obliquity(float(alpha)), MAX_MODES)
            for alpha in open_cylinder_table_obliquities(samples)
        ]
    )


@lru_cache(maxsize=2 * MAX_MODES)
def open_cylinder_coefficient_table(
    mode_count: int, samples: int = OPEN_CYLINDER_TABLE_SAMPLES
) -> tuple[tuple[tuple[int, int], ...], np.ndarray]:
    """(modes, table): the open cylinder's ĉ at the nodes α_i, ``table[i, label, j]`` for ``modes[j]``.

    ``label`` 0: û is Σ's major axis (u₁ along û); 1: v is (u₁ along v) — the principal-axes order that
    ``coherence.degree_of_coherence`` uses, which flips where Σ_uu = Σ_vv. ``modes`` are those of
    ``transverse_modes(mode_count)`` with n and m both even: Re f̃ is even in each axis (the region is
    symmetric about û, and f̃(−ζ) = f̃(ζ)*), so the others vanish (to 1e-16). Each row is the constrained
    expansion (``_constrain``) of exact-integration projections, as :func:`open_cylinder_coefficients`.
    """
    if isinstance(mode_count, bool) or not isinstance(mode_count, int) or not 1 <= mode_count <= MAX_MODES:
        raise InputError(f"mode_count: must be an integer in 1..{MAX_MODES}, got {mode_count!r}")
    degrees = transverse_modes(mode_count)
    projections = _open_cylinder_projections(samples)[:, : len(degrees)]
    swapped_columns = [transverse_modes(MAX_MODES).index((m, n)) for n, m in degrees]
    swapped = _open_cylinder_projections(samples)[:, swapped_columns]
    kept = [j for j, (n, m) in enumerate(degrees) if n % 2 == 0 and m % 2 == 0]
    table = np.empty((samples, 2, len(kept)))
    for i in range(samples):
        for label, rows in enumerate((projections, swapped)):
            constrained = _constrain(degrees, rows[i])
            table[i, label] = [constrained[j][2] for j in kept]
    return tuple(degrees[j] for j in kept), table
