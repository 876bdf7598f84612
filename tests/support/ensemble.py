"""What a pixel sees of a coated plane under a disk: the scene, and its plane-wave ensemble closed form.

A coated silver plane (z = 0) is seen at 45° incidence from 0.3 m through a 2° field; a disk of radius
0.04 m sits 0.3 m away in the mirror direction (angular radius α = 0.133 rad), facing the plane. The plane
is split along y: its y > 0 half (the image's upper rows) is rough (σ 0.15 µm, Gaussian PSD, ℓc 2 µm: the
lobe's per-axis std λ/(√2π ℓc) = 0.062 rad at 550 nm), its y < 0 half smooth (σ 1 nm: the specular part).
The film is FIG8's (2 µm, n_f 1.5, two beams, Eq. 18), whose shear across the beam is 1.51 µm at 45°.
The disk is either an emitter (constant radiance) or a diffuse disk (reflectance 0.8) lit by a sphere
light 1.5 m away, out of every view of the plane: an incoherent source of the same extent (van
Cittert–Zernike), lit within ±3 % over its face.

The closed form is the plane-wave ensemble (docs/physics_interactions.md §3, "What a pixel sees"): every
point of the disk sends a plane wave that the film reflects coherently, with the reflectance
R_coh(θ, λ) = R_inc + 2X₁ of its own incidence θ; a pixel adds the intensities of those its lens cone (and
a rough lobe) passes on. Rays: pixel centres over the crop × lens points (equal-area rings, the camera's
focus plane at 0.3 m) → reflected directions. Smooth: the directions that hit the disk, each with weight
1. Rough: each ray's lobe over the disk (polar Gauss–Legendre nodes) with the renderer's Harvey–Shack
weights — the Gaussian PSD S(f)(n/λ)² cos θ_o dω, the specular fraction e^{−g} to the mirror direction —
and R_coh at each node. Nothing of the HG model enters. Fitting the same visibility V̂
(``tests.support.fringes``) to the rendered and the closed-form spectra compares them.

Quadrature error: halving every node spacing moves V̂ by ≤ 0.0013 at a pinhole and the 1 and 4 cm lenses, and
by ≈ 0.002 at 12 cm, where the nodes converge as their count squared (rough: 0.4857, 0.4867, 0.4874 with 12,
16, 24 lens rings; smooth: 0.4641, 0.4792, 0.4827 with 16, 32, 64); ``QUADRATURE_TOLERANCE`` is 0.008.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from hgcore.optics import ior
from hgcore.optics.acceptance import (
    ELLIPSE_OFFSET_SCALE,
    flat_top_product_components,
    lobe_acceptance_variance,
)
from hgcore.optics.array_ops import NUMPY
from hgcore.optics.complex_pair import ComplexPair
from hgcore.optics.rough_surface import RoughSurface
from hgcore.optics.thin_film import film_amplitudes, reflectance_terms
from schemas import build
from tests.support import render_scenes as scenes
from tests.support.fringes import FringeFit, fit_fringe_visibility

INCIDENCE = math.radians(45.0)
DISTANCE_M = 0.3  # camera → plane centre, plane centre → disk centre
DISK_RADIUS_M = 0.04
FOV_DEG = 2.0
SIZE_PX = 32
FILM = scenes.FIG8_FILM
ROUGH = {"roughness_rms_um": 0.15, "correlation_length_um": 2.0}
SMOOTH = {"roughness_rms_um": 0.001, "correlation_length_um": 5.0}
# The crops: rows of the image (row 0 at the top, +y) away from the seam, where a wide lens's blur could mix
# the halves (the focus plane meets the tilted plane along its y axis: ≤ 2 mm of blur at the crops' edges).
ROUGH_ROWS = slice(0, 12)
SMOOTH_ROWS = slice(20, 32)
QUADRATURE_TOLERANCE = 0.008
LIGHT_DIRECTION = np.array([-0.40, 0.91, -0.06])  # from the disk centre, out of every view of the plane


def _unit(vector: Any) -> np.ndarray:
    vector = np.asarray(vector, dtype=float)
    return vector / np.linalg.norm(vector)


CAMERA = DISTANCE_M * np.array([-math.sin(INCIDENCE), 0.0, math.cos(INCIDENCE)])
DISK_CENTRE = DISTANCE_M * np.array([math.sin(INCIDENCE), 0.0, math.cos(INCIDENCE)])
DISK_NORMAL = -_unit(DISK_CENTRE)


def scene(aperture_radius_m: float, *, lit: bool, integrator: str, spp: int, seed: int = 0) -> dict[str, Any]:
    """The split plane under the disk (module docstring): an emitter, or a lit diffuse disk."""
    camera = build.camera(CAMERA.tolist(), [0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0], fov_deg=FOV_DEG)
    if aperture_radius_m > 0.0:
        camera["aperture_radius_m"] = aperture_radius_m  # focused on the target, 0.3 m
    film = scenes.fringe_film(SIZE_PX, SIZE_PX, spp=spp, max_depth=3)
    film |= {"integrator": integrator, "seed": seed}
    halves = [
        build.rectangle(
            [0.0, 0.125, 0.0], normal=[0, 0, 1], up=[0, 1, 0], width_m=0.5, height_m=0.25, material="rough"
        ),
        build.rectangle(
            [0.0, -0.125, 0.0], normal=[0, 0, 1], up=[0, 1, 0], width_m=0.5, height_m=0.25, material="smooth"
        ),
    ]
    materials = {
        "rough": scenes.two_beam_coating(FILM, **ROUGH),
        "smooth": scenes.two_beam_coating(FILM, **SMOOTH),
    }
    disk = {
        "type": "disk",
        "center_m": DISK_CENTRE.tolist(),
        "normal": DISK_NORMAL.tolist(),
        "radius_m": DISK_RADIUS_M,
    }
    if lit:
        materials["matte"] = {"type": "diffuse", "reflectance": 0.8}
        light = build.sphere(
            (DISK_CENTRE + 1.5 * _unit(LIGHT_DIRECTION)).tolist(), 0.1, **scenes.constant_spectrum(200.0)
        )
        shapes, emitters = [*halves, {**disk, "material": "matte"}], [light]
    else:
        shapes, emitters = halves, [{**disk, **scenes.constant_spectrum(1.0)}]
    return build.scene(
        "coated plane under a disk",
        camera=camera,
        film=film,
        materials=materials,
        shapes=shapes,
        emitters=emitters,
    )


# --- the closed form ----------------------------------------------------------------------------------------


def _camera_axes() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    forward = _unit(-CAMERA)
    right = _unit(np.cross(forward, [0.0, 1.0, 0.0]))
    return forward, right, np.cross(right, forward)


def pixel_directions(rows: slice, samples: tuple[int, int]) -> np.ndarray:
    """Unit chief-ray directions at ``samples`` = (across, down) midpoints of the crop ``rows`` (all columns):
    the crop's pixels sample it evenly, and what they see varies smoothly over it."""
    forward, right, up = _camera_axes()
    half = math.tan(math.radians(FOV_DEG) / 2.0)
    columns = (np.arange(samples[0]) + 0.5) / samples[0] * SIZE_PX
    row_values = rows.start + (np.arange(samples[1]) + 0.5) / samples[1] * (rows.stop - rows.start)
    x = (2.0 * columns / SIZE_PX - 1.0) * half
    y = (1.0 - 2.0 * row_values / SIZE_PX) * half
    grid_x, grid_y = np.meshgrid(x, y)
    directions = forward + grid_x[..., None] * right + grid_y[..., None] * up
    return (directions / np.linalg.norm(directions, axis=-1, keepdims=True)).reshape(-1, 3)


def lens_points(aperture_radius_m: float, rings: int, per_ring: int) -> np.ndarray:
    """Equal-area midpoint nodes (N, 2) of the lens disk (one node, its centre, for a pinhole)."""
    if aperture_radius_m == 0.0:
        return np.zeros((1, 2))
    radii = aperture_radius_m * np.sqrt((np.arange(rings) + 0.5) / rings)
    angles = (np.arange(per_ring) + 0.5) / per_ring * 2.0 * math.pi
    return np.stack(
        [np.outer(radii, np.cos(angles)).ravel(), np.outer(radii, np.sin(angles)).ravel()], axis=1
    )


def camera_rays(
    aperture_radius_m: float, rows: slice, *, samples: tuple[int, int], rings: int, per_ring: int
) -> tuple[np.ndarray, np.ndarray]:
    """(points on the plane, unit directions towards the plane) of every crop sample × lens node."""
    forward, right, up = _camera_axes()
    chief = pixel_directions(rows, samples)
    focus = (
        CAMERA + chief * (DISTANCE_M / (chief @ forward))[:, None]
    )  # the focus plane, 0.3 m along the axis
    lens = lens_points(aperture_radius_m, rings, per_ring)
    origins = CAMERA + lens[:, :1] * right + lens[:, 1:] * up
    directions = focus[:, None, :] - origins[None, :, :]
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    hits = origins[None] - directions * (origins[None, :, 2:] / directions[..., 2:])
    return hits.reshape(-1, 3), directions.reshape(-1, 3)


def band_edges_nm() -> np.ndarray:
    return np.linspace(*scenes.FIG7_WAVELENGTH_RANGE_NM, scenes.FIG7_BANDS + 1)


def coherent_reflectance(cos_incidence: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """R_coh = R_inc + 2X₁ of the two-beam film on silver for plane waves (broadcast arrays)."""
    n, kappa = ior.spectral_ior(FILM["substrate"], wavelengths_nm)
    cos_incidence, wavelengths_nm, n, kappa = np.broadcast_arrays(cos_incidence, wavelengths_nm, n, kappa)
    amplitudes = film_amplitudes(
        cos_incidence,
        wavelengths_nm * 1e-9,
        FILM["thickness_um"] * 1e-6,
        FILM["ior"],
        ComplexPair(n, kappa),
        1.0,
        2,
        NUMPY,
    )
    incoherent, interference = reflectance_terms(amplitudes)
    return incoherent + 2.0 * interference


class ReflectanceTable:
    """R_coh(cos θ, λ) tabulated on 801 cosines over the range a crop needs (≤ 0.1 wide), per wavelength,
    and read by linear interpolation: the film phase moves by ≤ 0.006 rad between nodes, so the table's
    error is ≤ 1e-5 of R."""

    def __init__(self, cosines: np.ndarray, wavelengths_nm: np.ndarray) -> None:
        self.grid = np.linspace(float(np.min(cosines)) - 1e-6, float(np.max(cosines)) + 1e-6, 801)
        self.wavelengths_nm = wavelengths_nm
        self.values = coherent_reflectance(self.grid[None, :], wavelengths_nm[:, None])

    def __call__(self, index: int, cosines: np.ndarray) -> np.ndarray:
        return np.interp(cosines, self.grid, self.values[index])


def band_wavelengths_nm(per_band: int) -> np.ndarray:
    """``per_band`` midpoint wavelengths in every band (B·per_band,), band-major."""
    edges = band_edges_nm()
    offsets = (np.arange(per_band) + 0.5) / per_band
    return (edges[:-1, None] + np.diff(edges)[:, None] * offsets).ravel()


def _disk_hit(points: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Whether rays from ``points`` along ``directions`` cross the disk."""
    along = ((DISK_CENTRE - points) @ DISK_NORMAL) / (directions @ DISK_NORMAL)
    crossing = points + along[:, None] * directions
    return (along > 0) & (np.linalg.norm(crossing - DISK_CENTRE, axis=-1) <= DISK_RADIUS_M)


def smooth_spectrum(aperture_radius_m: float, *, fine: bool = False) -> np.ndarray:
    """Band means of what the smooth half's crop sees: R_coh of every ray whose mirror image hits the disk."""
    scale = 2 if fine else 1
    rings = 16 + round(400 * aperture_radius_m)  # the disk covers ≥ 1/9 of the widest lens's rays
    points, directions = camera_rays(
        aperture_radius_m,
        SMOOTH_ROWS,
        samples=(16 * scale, 6 * scale),
        rings=rings * scale,
        per_ring=2 * rings * scale,
    )
    reflected = directions * np.array([1.0, 1.0, -1.0])
    cosines = reflected[_disk_hit(points, reflected), 2]
    per_band = 8 * scale
    wavelengths = band_wavelengths_nm(per_band)
    table = ReflectanceTable(cosines, wavelengths)
    # the hits' cosines as linear-interpolation weights on the table's nodes
    position = np.interp(cosines, table.grid, np.arange(len(table.grid)))
    lower = np.minimum(position.astype(int), len(table.grid) - 2)
    weights = np.bincount(lower, 1.0 - (position - lower), len(table.grid))
    weights += np.bincount(lower + 1, position - lower, len(table.grid))
    values = table.values @ weights / len(points)
    return values.reshape(-1, per_band).mean(axis=1)


def _disk_nodes(radial: int, angular: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) on the disk and their area weights: Gauss–Legendre in r² × uniform angle."""
    u, w = np.polynomial.legendre.leggauss(radial)
    r2 = 0.5 * (u + 1.0) * DISK_RADIUS_M**2
    angles = (np.arange(angular) + 0.5) / angular * 2.0 * math.pi
    e1 = _unit(np.cross(DISK_NORMAL, [0.0, 1.0, 0.0]))
    e2 = np.cross(DISK_NORMAL, e1)
    radius = np.sqrt(r2)[:, None]
    points = (
        DISK_CENTRE + (radius * np.cos(angles))[..., None] * e1 + (radius * np.sin(angles))[..., None] * e2
    )
    weights = np.repeat(0.5 * w * DISK_RADIUS_M**2 * math.pi / angular, angular)
    return points.reshape(-1, 3), weights


def rough_spectrum(aperture_radius_m: float, *, fine: bool = False) -> np.ndarray:
    """Band means of what the rough half's crop sees: for every ray, the specular part e^{−g} R_coh towards
    the mirror direction (where it hits the disk) plus the Harvey–Shack lobe (1 − e^{−g})/P·S(f)(n/λ)²
    cos θ_o dω over the disk's points, each with R_coh of its own direction."""
    scale = 2 if fine else 1
    rings = 4 + round(70 * aperture_radius_m)
    points, directions = camera_rays(
        aperture_radius_m,
        ROUGH_ROWS,
        samples=(6 * scale, 2 * scale),
        rings=rings * scale,
        per_ring=3 * rings * scale,
    )
    nodes, areas = _disk_nodes(8 * scale, 16 * scale)
    to_light = nodes[None] - points[:, None]
    distance = np.linalg.norm(to_light, axis=-1)
    to_light /= distance[..., None]
    solid_angle = areas[None] * np.abs(to_light @ DISK_NORMAL) / distance**2
    cos_light = to_light[..., 2]
    # β_o + β_i, the lobe's frequency argument times λ: the view side's and the light side's projections
    beta_sum = to_light[..., :2] - directions[:, None, :2]
    cos_view = -directions[:, 2]
    specular_hits = _disk_hit(points, directions * np.array([1.0, 1.0, -1.0]))
    sigma_h = ROUGH["roughness_rms_um"] * 1e-6
    length = ROUGH["correlation_length_um"] * 1e-6
    per_band = 4 * scale
    wavelengths = band_wavelengths_nm(per_band)
    table = ReflectanceTable(np.concatenate([cos_light.ravel(), cos_view]), wavelengths)
    values = []
    for index, wavelength_nm in enumerate(wavelengths):
        wavelength = wavelength_nm * 1e-9
        g = (4.0 * math.pi * sigma_h * cos_view / wavelength) ** 2
        specular = np.exp(-g)
        frequency2 = np.sum(beta_sum**2, axis=-1) / wavelength**2
        psd = math.pi * length**2 * np.exp(-((math.pi * length) ** 2) * frequency2)
        lobe = psd / wavelength**2 * cos_light * solid_angle  # P ≈ 1 for this narrow lobe (< 1e-6 beyond)
        scattered = (1.0 - specular) * np.sum(lobe * table(index, cos_light), axis=1)
        mirror = specular * specular_hits * table(index, cos_view)
        values.append(np.mean(scattered + mirror))
    return np.asarray(values).reshape(-1, per_band).mean(axis=1)


def visibility(spectrum: np.ndarray) -> FringeFit:
    """V̂ of a crop's summed band spectrum (``tests.support.fringes``), at the 45° incidence."""
    return fit_fringe_visibility(
        spectrum,
        band_edges_nm(),
        math.cos(INCIDENCE),
        FILM["thickness_um"] * 1e-6,
        FILM["ior"],
        FILM["substrate"],
    )


def rendered_visibility(bands: np.ndarray, rows: slice, groups: int = 8) -> tuple[float, float]:
    """(V̂, its Monte Carlo standard error) of the crop ``rows`` of a rendered band image (H, W, B): the
    fit of the crop's summed spectrum, and the jackknife over ``groups`` interleaved groups of its pixels
    (pixels are independent samples; the fit's own error would also count its model mismatch)."""
    pixels = bands[rows].reshape(-1, bands.shape[-1])
    whole = visibility(pixels.sum(axis=0)).visibility
    group_of = np.arange(len(pixels)) % groups
    leave_one_out = np.array(
        [visibility(pixels[group_of != g].sum(axis=0)).visibility for g in range(groups)]
    )
    error = math.sqrt((groups - 1) / groups * np.sum((leave_one_out - leave_one_out.mean()) ** 2))
    return whole, error


def lobe_and_disk_model_error(
    roughness: dict[str, float], disk_angular_radius: float, shear_m: float, incidence: float
) -> float:
    """The closed-form combination of a Gaussian lobe and a uniform disk (``hgcore.optics.acceptance``)
    against their exact ensemble, centred (the lobe on the disk's centre, where the two are of a size the 0th
    mode's Gaussian shape errs most): max over the film's wavelengths (5 nodes over the bands) of
    |V_model − V_exact|, V the visibility at the film's transverse shear ``shear_m`` along the plane of
    incidence, the lobe stretched by 1/cos² of ``incidence`` in that plane; V_exact on a 600² grid."""
    surface = RoughSurface(roughness["roughness_rms_um"] * 1e-6, roughness["correlation_length_um"] * 1e-6)
    alpha = disk_angular_radius
    grid = ((np.arange(600) + 0.5) / 600 * 2 - 1) * alpha
    x, y = np.meshgrid(grid, grid)
    inside = x**2 + y**2 <= alpha**2
    worst = 0.0
    for wavelength_nm in np.linspace(*scenes.FIG7_WAVELENGTH_RANGE_NM, 5):
        across = float(lobe_acceptance_variance(surface, 1.0, wavelength_nm * 1e-9, NUMPY))
        along = across / math.cos(incidence) ** 2
        g = 2 * math.pi / (wavelength_nm * 1e-9) * shear_m
        weight = inside * np.exp(-0.5 * (x**2 / along + y**2 / across))
        exact = abs(np.sum(weight * np.exp(1j * g * x)) / np.sum(weight))
        _, cov = flat_top_product_components(
            (0.0, 0.0),
            (alpha**2 / 4, 0.0, alpha**2 / 4),
            (0.0, 0.0),
            (along, 0.0, across),
            False,
            ELLIPSE_OFFSET_SCALE,
            NUMPY,
        )
        worst = max(worst, abs(math.exp(-0.5 * g * g * float(cov[0])) - exact))
    return worst


@functools.cache
def rough_model_tolerance() -> float:
    """``lobe_and_disk_model_error`` for this module's scene: 1.51 µm of shear at 45°."""
    return lobe_and_disk_model_error(ROUGH, DISK_RADIUS_M / DISTANCE_M, 1.51e-6, INCIDENCE)
