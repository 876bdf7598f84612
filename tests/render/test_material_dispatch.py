"""How ``MaterialKernels`` runs the kinds: spectra looked up once a vertex, a symbolic branch per material.

* ``VertexSpectra``: the integrator looks a vertex's spectra up before the bounce's symbolic branches and
  every read shares them. Each kind declares what it reads (``Material.spectra``); a kind reading an
  undeclared spectrum would silently look it up again at every read, so the test makes that an error.
* ``Material.hero_ratios`` says whether a kind's ``sample`` returns hero-MIS ratios; ``sample``'s flat
  state relies on it, so it must agree with what the kind returns.
* With two or more materials ``sample`` and ``eval_pdf`` run each material in a symbolic branch (packets
  without a lane of it skip it); the results must be bitwise those of evaluating every branch in every
  lane and selecting (``MaterialKernels.symbolic_branches = False``).
"""

from __future__ import annotations

import numpy as np
import pytest

from schemas import validate_scene
from tests.render.kernel_harness import KernelProbe, probe_scene
from worker.render.bsdfs import IncidentCoherence, VertexSpectra
from worker.render.bsdfs.common import ShadingPoint
from worker.render.bsdfs.dispatch import MaterialKernels
from worker.render.chunks import renderer_for

MATERIALS = {
    "diffuse": {"type": "diffuse", "reflectance": 0.6},
    "mirror": {"type": "mirror", "conductor": "Au"},
    "dielectric": {"type": "dielectric", "ior": "bk7"},
    "rough_conductor": {
        "type": "rough_conductor",
        "conductor": "Cu",
        "roughness_rms_um": 0.1,
        "correlation_length_um": 2.0,
    },
    "rough_dielectric": {
        "type": "rough_dielectric",
        "ior": 1.5,
        "roughness_rms_um": 0.1,
        "correlation_length_um": 2.0,
    },
    "thin_film_on_silver": {
        "type": "thin_film",
        "film_thickness_um": 0.4,
        "film_ior": 1.5,
        "substrate": {"conductor": "Ag"},
        "roughness_rms_um": 0.05,
        "correlation_length_um": 5.0,
    },
    "thin_film_on_glass": {
        "type": "thin_film",
        "film_thickness_um": 0.3,
        "film_ior": 1.38,
        "substrate": {"ior": 1.5},
    },
    "grating": {"type": "grating", "pitch_um": 1.6, "pit_depth_nm": 110.0, "lobe_width_per_um": 2.0},
}
COUNT = 257
WAVELENGTHS_NM = (450.0, 530.0, 610.0, 690.0)


class StrictSpectra(VertexSpectra):
    """A vertex's spectra that refuse a read of anything not looked up in advance."""

    def __getitem__(self, offset: int):
        if offset not in self._looked_up:
            raise KeyError(f"spectrum offset {offset} read but not declared")
        return self._looked_up[offset]


def inputs(mi, material_indices: np.ndarray, seed: int = 3):
    """Directions on both sides, uniforms and wavelengths for ``len(material_indices)`` lanes."""
    rng = np.random.default_rng(seed)
    count = len(material_indices)

    def directions() -> np.ndarray:
        v = rng.normal(size=(count, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    def vector(v: np.ndarray):
        return mi.Vector3f(*(mi.Float(np.ascontiguousarray(v[:, i], dtype=np.float32)) for i in range(3)))

    wavelengths = mi.Spectrum(0.0)
    for j, nm in enumerate(WAVELENGTHS_NM):
        wavelengths[j] = mi.Float(np.full(count, nm, dtype=np.float32))
    uniforms = rng.random((count, 3)).astype(np.float32)
    return {
        "material": mi.UInt32(material_indices.astype(np.uint32)),
        "wi": vector(directions()),
        "wo": vector(directions()),
        "wavelengths": wavelengths,
        "u1": mi.Float(uniforms[:, 0]),
        "u2": mi.Point2f(mi.Float(uniforms[:, 1]), mi.Float(uniforms[:, 2])),
        "active": mi.Bool(np.ones(count, dtype=bool)),
    }


def run_kernels(kernels: MaterialKernels, mi, arrays, spectra: VertexSpectra | None = None) -> dict:
    """Every output of ``sample`` and ``eval_pdf`` as NumPy arrays (one evaluation)."""
    count = len(np.asarray(arrays["material"]))
    zero = mi.Float(np.zeros(count, dtype=np.float32))
    coherence = IncidentCoherence(zero, zero, zero, zero + 0.5, mi.Vector3f(1, 0, 0), mi.Vector3f(0, 1, 0))
    frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    sampled = kernels.sample(
        arrays["material"],
        arrays["wi"],
        arrays["wavelengths"],
        arrays["u1"],
        arrays["u2"],
        arrays["active"],
        spectra,
    )
    value, pdf = kernels.eval_pdf(
        arrays["material"],
        arrays["wi"],
        arrays["wo"],
        arrays["wavelengths"],
        coherence,
        frame,
        arrays["active"],
        spectra=spectra,
    )
    outputs = {
        "wo": sampled.wo,
        "weight": sampled.weight,
        "pdf": sampled.pdf,
        "delta": sampled.delta,
        "eta": sampled.eta,
        "transmitted": sampled.film.transmitted,
        "value": value,
        "eval_pdf": pdf,
    }
    outputs.update({f"term{slot}": term for slot, term in enumerate(sampled.film.terms)})
    if sampled.pdf_ratios is not None:
        outputs["ratios"] = sampled.pdf_ratios
    return {key: np.array(value, dtype=np.float64) for key, value in outputs.items()}


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_a_kind_reads_only_the_spectra_it_declares(name: str) -> None:
    probe = KernelProbe(MATERIALS[name])
    mi, kernels = probe.mi, probe.kernels
    arrays = inputs(mi, np.zeros(COUNT, dtype=np.int64))
    strict = StrictSpectra(
        kernels.params, arrays["material"], arrays["wavelengths"], kernels.spectrum_offsets
    )
    shared = run_kernels(kernels, mi, arrays, strict)  # raises on an undeclared read
    looked_up_at_each_read = run_kernels(kernels, mi, arrays)
    assert shared.keys() == looked_up_at_each_read.keys()
    for key, value in shared.items():
        np.testing.assert_array_equal(value, looked_up_at_each_read[key], err_msg=key)


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_hero_ratios_says_whether_sampling_returns_them(name: str) -> None:
    probe = KernelProbe(MATERIALS[name])
    mi, kernels = probe.mi, probe.kernels
    (branch,) = kernels.branches
    arrays = inputs(mi, np.zeros(COUNT, dtype=np.int64))
    point_spectra = kernels.vertex_spectra(arrays["material"], arrays["wavelengths"])
    point = ShadingPoint(arrays["material"], arrays["wi"], arrays["wavelengths"], point_spectra)
    sampled = branch.sample(point, arrays["u1"], arrays["u2"])
    assert (sampled.pdf_ratios is not None) == type(branch).hero_ratios


def mixed_kernels() -> tuple[MaterialKernels, object, int]:
    """The kernels of a scene with every material of ``MATERIALS`` (one sphere each)."""
    scene = probe_scene(MATERIALS["diffuse"])
    scene["materials"] = dict(MATERIALS)
    scene["shapes"] = [
        {"type": "sphere", "center_m": [3.0 * i, 0, 0], "radius_m": 1.0, "material": name}
        for i, name in enumerate(MATERIALS)
    ]
    renderer = renderer_for(validate_scene(scene))
    return renderer.integrator.kernels, renderer.mi, len(MATERIALS)


def test_symbolic_branches_give_what_selecting_every_lane_gives(monkeypatch: pytest.MonkeyPatch) -> None:
    kernels, mi, material_count = mixed_kernels()
    assert len(kernels.branches) == material_count
    # lanes of every material, in runs (as packets of one material) and interleaved (mixed packets)
    indices = np.concatenate([np.repeat(np.arange(material_count), 32), np.arange(COUNT) % material_count])
    arrays = inputs(mi, indices)
    symbolic = run_kernels(kernels, mi, arrays)
    monkeypatch.setattr(MaterialKernels, "symbolic_branches", False)
    selected = run_kernels(kernels, mi, arrays)
    assert symbolic.keys() == selected.keys()
    for key, value in symbolic.items():
        np.testing.assert_array_equal(value, selected[key], err_msg=key)
    # the comparison has teeth: every material produced a non-zero weight somewhere
    weights = symbolic["weight"].sum(axis=0)
    assert all(np.any(weights[indices == m] > 0) for m in range(material_count))
