"""Reflectance spectra from linear sRGB colours: Jakob & Hanika's sigmoid-of-a-quadratic model.

Jakob & Hanika, "A Low-Dimensional Function Space for Efficient Spectral Upsampling" (Computer Graphics
Forum 38(2), 2019): a colour c becomes the smooth spectrum

    S_c(λ) = ½ + ½·x/√(1 + x²),   x = c₀λ² + c₁λ + c₂   (λ in nm; S in (0, 1), a valid reflectance),

with the three coefficients chosen so that S_c lit by the colour space's white (D65 for sRGB) has the colour
c: with the CIE 1931 2° functions x̄, ȳ, z̄ and D65's relative power D(λ),

    XYZ(S) = ∫ S D (x̄, ȳ, z̄) dλ / ∫ D ȳ dλ,   rgb(S) = M · XYZ(S),

M the XYZ → linear sRGB matrix of ``hgcore.colour`` (IEC 61966-2-1 at full precision), so a reflectance of
1 is the white (1, 1, 1). Mitsuba 3's ``srgb`` spectra use the same model: coefficients trilinearly
interpolated from a 3 × 64³ table fitted by the paper's optimiser (Mitsuba ships it as ``srgb.coeff``).

**Round trip.** Interpolating that table alone gives rgb(S_c) − c up to 2.7e-3 for random colours in
[0.01, 0.99]³ (3e-4 at the table's own nodes: the fit used other integrals and a rounded matrix). So
``fit_coefficients`` starts from the table and, where its colour is off by more than ``REFINE_ABOVE`` =
2e-4, takes Gauss–Newton steps on rgb(S_c) = c with this module's integrals (5 nm trapezoids of the CIE
tables, ``ROUND_TRIP_WAVELENGTHS_NM``), with backtracking. Every in-gamut colour then round-trips within
2e-4 on that grid, and within 3.2e-4 against integrals at the tables' own 1 nm spacing (the 5 nm grid's
own error for steep spectra; measured over 3000 random colours, ``tests/optics/test_rgb_upsampling.py``).
Greys are the constant spectrum exactly. Colours on the gamut boundary (a channel of exactly 0 or 1 with
others different) are the limit of infinite coefficients; channels are clipped to [1e-4, 1 − 1e-4].
Cost: ≈ 45 µs per distinct colour on one core (a texture's distinct colours are fitted once each).

``sigmoid_polynomial`` is written once for NumPy and Dr.Jit (``ArrayOps``): the renderer's kernels
evaluate a texel's spectrum with it (``worker.render.textures``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hgcore.colour import XYZ_TO_LINEAR_SRGB
from hgcore.errors import InputError
from hgcore.optics.array_ops import NUMPY, ArrayOps
from hgcore.optics.spectra import cie_cmf, cie_illuminant

#: The wavelengths (nm) of the fit and of the round trip's integrals: 360–830 nm, the CIE tables' range.
ROUND_TRIP_WAVELENGTHS_NM = np.arange(360.0, 830.0 + 1e-9, 5.0)
#: Channels are clipped to this interval before fitting: the model reaches 0 and 1 only in the limit.
CHANNEL_FLOOR = 1e-4
FIT_ITERATIONS = 8
FIT_TOLERANCE = 1e-7
#: Colours whose table coefficients already round-trip within this (largest channel error on the fit's
#: grid) are kept as fetched: half of random colours, for half the fitting time.
REFINE_ABOVE = 2e-4
_CENTRE_NM = 580.0  # the fit runs in u = (λ − 580)/100 (a well-scaled Jacobian), stored back per nm
_SCALE_NM = 100.0


def sigmoid_polynomial(coefficients: tuple[Any, Any, Any], wavelength_nm: Any, ops: ArrayOps = NUMPY) -> Any:
    """S(λ) = ½ + ½x/√(1 + x²), x = (c₀λ + c₁)λ + c₂ (λ in nm): a reflectance in (0, 1)."""
    c0, c1, c2 = coefficients
    x = (c0 * wavelength_nm + c1) * wavelength_nm + c2
    return 0.5 + 0.5 * x * ops.rsqrt(1.0 + x * x)


@functools.cache
def _rgb_weights() -> np.ndarray:
    """A (3, K) with rgb(S) = A·S(λ_k): the trapezoid weights of the D65-lit XYZ integrals, then M."""
    wavelengths = ROUND_TRIP_WAVELENGTHS_NM
    step = np.full_like(wavelengths, 5.0)
    step[[0, -1]] = 2.5  # trapezoid end points
    illuminant = cie_illuminant("d65", wavelengths) * step
    cmf = cie_cmf(wavelengths)
    xyz_weights = (cmf * illuminant[:, None]).T / float(illuminant @ cmf[:, 1])
    return XYZ_TO_LINEAR_SRGB @ xyz_weights


def reflectance_rgb(coefficients: np.ndarray) -> np.ndarray:
    """Linear sRGB (…, 3) of the reflectance spectra with these coefficients (…, 3), lit by D65."""
    c = np.asarray(coefficients, dtype=float)
    wavelengths = ROUND_TRIP_WAVELENGTHS_NM
    spectra = sigmoid_polynomial((c[..., 0:1], c[..., 1:2], c[..., 2:3]), wavelengths)
    return spectra @ _rgb_weights().T


@dataclass(frozen=True)
class CoefficientTable:
    """Jakob & Hanika's precomputed coefficients (the ``rgb2spec`` file format: ``SPEC``, the resolution
    n (uint32), n z-nodes, then 3 × n³ × 3 float32 coefficients indexed [largest channel][z][y][x][c])."""

    scale: np.ndarray  # (n,) the nodes of the largest channel's value z
    data: np.ndarray  # (3, n, n, n, 3)

    @classmethod
    def from_file(cls, path: Path) -> CoefficientTable:
        raw = Path(path).read_bytes()
        if raw[:4] != b"SPEC" or len(raw) < 8:
            raise InputError(f"path: {Path(path).name} is not an rgb2spec coefficient table")
        resolution = int(np.frombuffer(raw, np.uint32, 1, 4)[0])
        count = 3 * resolution**3 * 3
        if len(raw) < 8 + 4 * (resolution + count):
            raise InputError(f"path: {Path(path).name} is truncated")
        scale = np.frombuffer(raw, np.float32, resolution, 8).astype(float)
        data = np.frombuffer(raw, np.float32, count, 8 + 4 * resolution).reshape(3, *(resolution,) * 3, 3)
        return cls(scale, data.astype(float))

    def fetch(self, rgb: np.ndarray) -> np.ndarray:
        """Trilinearly interpolated coefficients (…, 3) for linear sRGB colours (…, 3) in [0, 1]: the
        largest channel z selects the table and its z node, the other two (in cyclic order after it),
        divided by z, the x and y nodes."""
        rgb = np.asarray(rgb, dtype=float)
        resolution = self.scale.size
        largest = 2 - np.argmax(rgb[..., ::-1], axis=-1)  # the last of equal maxima, as rgb2spec does
        z = np.take_along_axis(rgb, largest[..., None], -1)[..., 0]
        scale = (resolution - 1) / np.where(z > 0.0, z, 1.0)
        x = np.take_along_axis(rgb, ((largest + 1) % 3)[..., None], -1)[..., 0] * scale
        y = np.take_along_axis(rgb, ((largest + 2) % 3)[..., None], -1)[..., 0] * scale
        xi = np.clip(x.astype(int), 0, resolution - 2)
        yi = np.clip(y.astype(int), 0, resolution - 2)
        zi = np.clip(np.searchsorted(self.scale, z, side="right") - 1, 0, resolution - 2)
        fx, fy = x - xi, y - yi
        fz = (z - self.scale[zi]) / (self.scale[zi + 1] - self.scale[zi])
        result = np.zeros((*rgb.shape[:-1], 3))
        for dz, wz in ((0, 1.0 - fz), (1, fz)):
            for dy, wy in ((0, 1.0 - fy), (1, fy)):
                for dx, wx in ((0, 1.0 - fx), (1, fx)):
                    corner = self.data[largest, zi + dz, yi + dy, xi + dx]
                    result += (wz * wy * wx)[..., None] * corner
        return result


def _to_centred(c: np.ndarray) -> np.ndarray:
    """Coefficients per nm → per u = (λ − λ₀)/s (the same polynomial)."""
    a = c[..., 0] * _SCALE_NM**2
    b = (2.0 * c[..., 0] * _CENTRE_NM + c[..., 1]) * _SCALE_NM
    d = (c[..., 0] * _CENTRE_NM + c[..., 1]) * _CENTRE_NM + c[..., 2]
    return np.stack([a, b, d], axis=-1)


def _to_nm(c: np.ndarray) -> np.ndarray:
    """Coefficients per u = (λ − λ₀)/s → per nm."""
    a = c[..., 0] / _SCALE_NM**2
    b = c[..., 1] / _SCALE_NM
    return np.stack([a, b - 2.0 * a * _CENTRE_NM, (a * _CENTRE_NM - b) * _CENTRE_NM + c[..., 2]], axis=-1)


def fit_coefficients(rgb: np.ndarray, table: CoefficientTable, block: int = 65536) -> np.ndarray:
    """Coefficients (N, 3) per nm whose spectra round-trip to the linear sRGB colours ``rgb`` (N, 3).

    Channels are clipped to [``CHANNEL_FLOOR``, 1 − ``CHANNEL_FLOOR``]; greys (equal channels) are the
    constant spectrum in closed form (c₀ = c₁ = 0); other colours start from the table and take up to
    ``FIT_ITERATIONS`` Gauss–Newton steps in u-coefficients, each halved until the residual falls (module
    docstring). Work runs in blocks of ``block`` colours (K = 95 wavelengths each)."""
    target = np.clip(np.asarray(rgb, dtype=float).reshape(-1, 3), CHANNEL_FLOOR, 1.0 - CHANNEL_FLOOR)
    result = np.empty_like(target)
    for start in range(0, len(target), block):
        result[start : start + block] = _fit_block(target[start : start + block], table)
    return result


def _fit_block(target: np.ndarray, table: CoefficientTable) -> np.ndarray:
    weights = _rgb_weights()
    u = (ROUND_TRIP_WAVELENGTHS_NM - _CENTRE_NM) / _SCALE_NM
    basis = np.stack([u * u, u, np.ones_like(u)], axis=-1)  # ∂x/∂c (K, 3)

    def evaluate(c: np.ndarray, rows: Any = slice(None)) -> tuple[np.ndarray, np.ndarray]:
        x = c @ basis.T  # (N, K)
        root = np.sqrt(1.0 + x * x)
        spectra = 0.5 + 0.5 * x / root
        return spectra @ weights.T - target[rows], 0.5 / root**3  # residual, ∂S/∂x

    grey = np.ptp(target, axis=1) == 0.0
    level = 2.0 * target[:, 0] - 1.0
    grey_x = level / np.sqrt(1.0 - level * level)  # S = ½ + ½x/√(1 + x²) solved for x
    coefficients = _to_centred(table.fetch(target))
    coefficients[grey] = np.stack([np.zeros_like(grey_x), np.zeros_like(grey_x), grey_x], axis=-1)[grey]
    residual, slope = evaluate(coefficients)
    refine = (np.abs(residual).max(axis=1) > REFINE_ABOVE) & ~grey
    for _ in range(FIT_ITERATIONS):
        error = np.linalg.norm(residual, axis=1)
        moving = (error > FIT_TOLERANCE) & refine
        if not moving.any():
            break
        jacobian = np.einsum("ck,nk,kj->ncj", weights, slope[moving], basis)
        step = np.linalg.solve(jacobian, -residual[moving][..., None])[..., 0]
        current = coefficients[moving]
        best, best_error = current, error[moving]
        length = np.ones(len(step))
        for _halving in range(6):
            trial = current + length[:, None] * step
            trial_residual, _ = evaluate(trial, moving)
            trial_error = np.linalg.norm(trial_residual, axis=1)
            better = np.isfinite(trial_error) & (trial_error < best_error)
            best = np.where(better[:, None], trial, best)
            best_error = np.where(better, trial_error, best_error)
            length = np.where(better, length, 0.5 * length)
            if better.all():
                break
        coefficients[moving] = best
        residual, slope = evaluate(coefficients)
    return _to_nm(coefficients)
