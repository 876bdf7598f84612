"""Drive one material's ``MaterialKernels`` directly (no ray tracing): sample and evaluate in bulk.

A one-material scene is compiled and loaded as the renderer would; ``KernelProbe`` then calls the kernels'
``sample`` and ``eval_pdf`` on arrays of local directions with fixed wavelengths, so tests can integrate a
material's albedo and histogram its sampling exactly as the integrator sees them.

This module is the tests' only contact with the renderer's material code (``worker.render.bsdfs`` and the
integrator's ``kernels``): when that code moves, only ``KernelProbe.__init__``/``_arrays`` and the two
kernel calls change here. ``material_adapter`` is the narrow NumPy-in/NumPy-out view the χ² tests use.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from schemas import validate_scene
from worker.render.bsdfs import IncidentCoherence
from worker.render.chunks import renderer_for


def probe_scene(material: dict[str, Any]) -> dict[str, Any]:
    return {
        "schema": "hgrender/scene/v1",
        "name": "kernel probe",
        "camera": {"type": "perspective", "origin_m": [0, 0, 3], "target_m": [0, 0, 0], "up": [0, 1, 0]},
        "film": {"width": 4, "height": 4, "bands": 4, "spp": 1, "max_depth": 3},
        "materials": {"probe": material},
        "shapes": [{"type": "sphere", "center_m": [0, 0, 0], "radius_m": 1.0, "material": "probe"}],
        "emitters": [
            {
                "type": "sphere",
                "center_m": [0, 0, 5],
                "radius_m": 0.1,
                "spectrum": {"type": "constant", "value": 1.0},
                "radiance_scale": 1.0,
            }
        ],
    }


class KernelProbe:
    """The kernels of the probe material (index 0) of a one-material scene."""

    def __init__(self, material: dict[str, Any]) -> None:
        renderer = renderer_for(validate_scene(probe_scene(material)))
        self.mi = renderer.mi
        self.kernels = renderer.integrator.kernels
        self.material_index = 0

    def _arrays(self, wi: np.ndarray, wavelengths_nm: np.ndarray):
        mi = self.mi
        count = wi.shape[0]
        local_wi = mi.Vector3f(
            *(mi.Float(np.ascontiguousarray(wi[:, i], dtype=np.float32)) for i in range(3))
        )
        spectrum = mi.Spectrum(0.0)
        for j in range(len(spectrum)):
            spectrum[j] = mi.Float(np.full(count, wavelengths_nm[j], dtype=np.float32))
        material = mi.UInt32(np.full(count, self.material_index, dtype=np.uint32))
        return local_wi, spectrum, material

    def sample(
        self, wi: np.ndarray, wavelengths_nm: np.ndarray, uniforms: np.ndarray
    ) -> dict[str, np.ndarray]:
        """wo (N, 3), weight (N, 4), pdf (N), delta (N) for directions ``wi`` (N, 3) and uniforms (N, 3)."""
        mi = self.mi
        local_wi, spectrum, material = self._arrays(wi, wavelengths_nm)
        u1 = mi.Float(np.ascontiguousarray(uniforms[:, 0], dtype=np.float32))
        u2 = mi.Point2f(
            mi.Float(np.ascontiguousarray(uniforms[:, 1], dtype=np.float32)),
            mi.Float(np.ascontiguousarray(uniforms[:, 2], dtype=np.float32)),
        )
        active = mi.Bool(np.ones(wi.shape[0], dtype=bool))
        sampled = self.kernels.sample(material, local_wi, spectrum, u1, u2, active)
        wo, weight, delta = sampled.wo, sampled.weight, sampled.delta
        pdf = sum(sampled.pdf[j] for j in range(len(sampled.pdf))) / len(sampled.pdf)
        return {
            "wo": np.stack([np.asarray(wo.x), np.asarray(wo.y), np.asarray(wo.z)], axis=1).astype(float),
            "weight": np.stack([np.asarray(weight[j]) for j in range(len(weight))], axis=1).astype(float),
            "pdf": np.asarray(pdf).astype(float),
            "delta": np.asarray(delta).astype(bool),
        }

    def eval_pdf(
        self, wi: np.ndarray, wo: np.ndarray, wavelengths_nm: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(f·|cos θo| per wavelength (N, 4), hero-MIS pdf (N)) of the non-Dirac part."""
        mi = self.mi
        local_wi, spectrum, material = self._arrays(wi, wavelengths_nm)
        local_wo = mi.Vector3f(
            *(mi.Float(np.ascontiguousarray(wo[:, i], dtype=np.float32)) for i in range(3))
        )
        zero = mi.Float(np.zeros(wi.shape[0], dtype=np.float32))
        coherence = IncidentCoherence(
            zero, zero, zero, zero + 1.0, mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0)
        )
        frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        active = mi.Bool(np.ones(wi.shape[0], dtype=bool))
        value, pdfs = self.kernels.eval_pdf(material, local_wi, local_wo, spectrum, coherence, frame, active)
        pdf = sum(pdfs[j] for j in range(len(pdfs))) / len(pdfs)  # the hero-MIS mean over the wavelengths
        return (
            np.stack([np.asarray(value[j]) for j in range(len(value))], axis=1).astype(float),
            np.asarray(pdf).astype(float),
        )


def direction(theta_deg: float, count: int, lower: bool = False) -> np.ndarray:
    """``count`` copies of the local direction at polar angle θ in the xz plane (z < 0 if ``lower``)."""
    theta = math.radians(theta_deg)
    z = -math.cos(theta) if lower else math.cos(theta)
    return np.tile([math.sin(theta), 0.0, z], (count, 1))


@dataclass(frozen=True)
class SampledDirections:
    """Outcomes of a material's sampler: directions (N, 3), weights f·cos/pdf (N, 4), Dirac flags (N)."""

    wo: np.ndarray
    weight: np.ndarray
    dirac: np.ndarray

    @property
    def rejected(self) -> np.ndarray:
        """Regular samples the sampler discarded (all weights 0: an evanescent draw, |β_o| ≥ 1)."""
        return ~self.dirac & np.all(self.weight == 0.0, axis=1)


@dataclass(frozen=True)
class MaterialAdapter:
    """``sample(uniforms (N, 3))`` and ``pdf(wo (N, 3))`` of one material at a fixed incident direction
    and a single wavelength carried by all four of the path's wavelength slots (so that the hero-MIS
    density, the mean over the slots, is the density the hero's sampler draws from)."""

    sample: Callable[[np.ndarray], SampledDirections]
    pdf: Callable[[np.ndarray], np.ndarray]


def material_adapter(
    material: dict[str, Any], wi: np.ndarray, wavelength_nm: float, probe: KernelProbe | None = None
) -> MaterialAdapter:
    """The adapter of ``material`` (a scene ``materials`` entry) for the local incident direction ``wi``."""
    kernel_probe = probe if probe is not None else KernelProbe(material)
    wavelengths = np.full(4, float(wavelength_nm))
    wi = np.asarray(wi, dtype=float)

    def sample(uniforms: np.ndarray) -> SampledDirections:
        result = kernel_probe.sample(np.tile(wi, (len(uniforms), 1)), wavelengths, uniforms)
        return SampledDirections(result["wo"], result["weight"], result["delta"])

    def pdf(wo: np.ndarray) -> np.ndarray:
        return kernel_probe.eval_pdf(np.tile(wi, (len(wo), 1)), wo, wavelengths)[1]

    return MaterialAdapter(sample, pdf)
