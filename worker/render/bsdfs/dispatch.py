"""``MaterialKernels``: one branch per material kind present in the scene, selected per lane.

Table kinds (diffuse, mirror, smooth dielectric) compile one branch each; model kinds (rough conductor,
rough dielectric, thin film, grating) one branch per material (``common.Material``). Kinds are tested only
through the kind sets of ``worker.render.materials`` (``SPECULAR_KINDS`` …) and only for the kinds present,
so a scene's kernel carries the branches it can take and no others.
"""

from __future__ import annotations

from typing import Any

import drjit as dr
import mitsuba as mi

from worker.render import materials as mat
from worker.render.bsdfs.common import (
    FilmSample,
    IncidentCoherence,
    Material,
    MaterialParams,
    MaterialSample,
    ShadingPoint,
    VertexSpectra,
)
from worker.render.bsdfs.dielectric import Dielectric
from worker.render.bsdfs.diffuse import Diffuse
from worker.render.bsdfs.grating import Grating
from worker.render.bsdfs.mirror import Mirror
from worker.render.bsdfs.rough_conductor import RoughConductor
from worker.render.bsdfs.rough_dielectric import RoughDielectric
from worker.render.bsdfs.thin_film import ThinFilm, film_terms

#: The implementation of each kind (``BLACK``, the emitters' surfaces, absorbs: no branch).
MATERIAL_CLASSES: dict[mat.MaterialKind, type[Material]] = {
    cls.kind: cls for cls in (Diffuse, Mirror, Dielectric, RoughConductor, RoughDielectric, ThinFilm, Grating)
}


class MaterialKernels:
    """Gathers material parameters and dispatches to the kernels of the kinds present in the scene.

    With one branch every lane evaluates it and keeps its result where it applies (``dr.select``); with
    more, each branch runs in a symbolic branch (``dr.if_stmt``), which Dr.Jit's kernels skip in packets
    without a lane of that material: a thin film's multi-beam terms are not computed for a packet of
    floor lanes (the thin-film example's render time: −22 % against selecting, measured A B A B). The lanes'
    results are the same floats either way (tests/render/test_material_dispatch.py)."""

    #: False: evaluate every branch in every lane and select (the reference the tests compare with)
    symbolic_branches: bool = True

    def __init__(self, params: MaterialParams) -> None:
        self.params = params
        materials = params.materials
        self.materials = materials
        self.kinds = materials.kinds
        self.max_beams = params.max_beams
        self.visibility = params.visibility
        self.branches: list[Material] = []
        offsets: set[int] = set()
        for kind in sorted(self.kinds & MATERIAL_CLASSES.keys()):
            cls = MATERIAL_CLASSES[kind]
            offsets.update(cls.spectra)
            if cls.per_material:
                self.branches += [cls(self.params, index) for index in materials.indices_of(kind)]
            else:
                self.branches.append(cls(self.params))
        if not params.tinted:
            offsets.discard(mat.TINT_ID)
        #: the spectra the scene's kinds read at a vertex (``vertex_spectra``)
        self.spectrum_offsets = tuple(sorted(offsets))
        #: whether a kind of the scene samples with hero-dependent probabilities (``common.Material``)
        self.hero_ratios = any(type(branch).hero_ratios for branch in self.branches)
        #: the branches with a non-Dirac part to evaluate (``eval_pdf``)
        self.evaluating = [
            branch for branch in self.branches if type(branch).eval_pdf is not Material.eval_pdf
        ]

    def kernel_tables(self) -> list[mi.Float]:
        """Every array the material kernels read: the material, spectral and texture tables and the
        kinds' own."""
        tables = [self.params.table, self.params.spectra]
        if self.params.textures is not None:
            tables += self.params.textures.kernel_tables()
        for branch in self.branches:
            tables += branch.kernel_tables()
        return tables

    # ---------------------------------------------------------------- parameters and kinds
    def param(self, material: mi.UInt32, offset: int) -> mi.Float:
        return self.params.param(material, offset)

    def kind(self, material: mi.UInt32) -> mi.UInt32:
        return self.params.kind(material)

    def has(self, kinds: frozenset[mat.MaterialKind]) -> bool:
        """Whether the scene has a material of one of ``kinds`` (decided when the kernel is traced)."""
        return bool(self.kinds & kinds)

    def is_kind(self, kind: mi.UInt32, kinds: frozenset[mat.MaterialKind]) -> mi.Bool:
        """Lanes whose material ``kind`` is one of ``kinds`` (only the kinds present are tested)."""
        result = mi.Bool(False)
        for member in sorted(self.kinds & kinds):
            result |= kind == int(member)
        return result

    def is_specular(self, material: mi.UInt32) -> mi.Bool:
        """Dirac materials (``materials.SPECULAR_KINDS``)."""
        return self.is_kind(self.kind(material), mat.SPECULAR_KINDS)

    def two_sided(self, material: mi.UInt32) -> mi.Bool:
        """Whether the shading frame is flipped towards the incident side: not for interfaces that
        transmit (``materials.TRANSMITTING_KINDS``, films on a dielectric), whose sides differ."""
        kind = self.kind(material)
        transmits = self.is_kind(kind, mat.TRANSMITTING_KINDS)
        if mat.MaterialKind.THIN_FILM in self.kinds:
            film = kind == int(mat.MaterialKind.THIN_FILM)
            transmits |= film & (self.param(material, mat.FILM_TRANSMITS) > 0.5)
        return ~transmits

    @property
    def textured(self) -> bool:
        """Whether some material of the scene reads a parameter from a texture (decided when traced)."""
        return bool(self.params.textured)

    def vertex_spectra(
        self, material: mi.UInt32, wavelengths: mi.Spectrum, si: mi.SurfaceInteraction3f | None = None
    ) -> VertexSpectra:
        """The spectra of a vertex's ``material`` that the scene's kinds read, looked up once for the
        bounce (``common.VertexSpectra``), and its textured parameters at the hit ``si``'s texture
        coordinates where the scene has textures."""
        # Mitsuba's uv is hgrender's (origin bottom-left, v up): OBJ files load with flip_tex_coords off.
        uv = None
        if si is not None and self.textured:
            uv = mi.Point2f(si.uv)
        valid = True if si is None else si.is_valid()
        return VertexSpectra(self.params, material, wavelengths, self.spectrum_offsets, uv, valid)

    def textured_albedo(self, material: mi.UInt32, wavelengths: mi.Spectrum, uv: mi.Point2f) -> mi.Spectrum:
        """The albedo AOV (``albedo``) of ``material`` at texture coordinates ``uv`` (a textured scene's
        first hit, kept by the path), its textures read once per path after the loop."""
        spectra = VertexSpectra(self.params, material, wavelengths, (), uv)
        return self.albedo(material, wavelengths, spectra)

    def albedo(
        self, material: mi.UInt32, wavelengths: mi.Spectrum, spectra: VertexSpectra | None = None
    ) -> mi.Spectrum:
        """Directional-hemispherical reflectance at normal incidence, for the albedo AOV (``spectra``: the
        vertex's, with its textures; None: the material's untextured values)."""
        kind = self.kind(material)
        if spectra is None:
            spectra = VertexSpectra(self.params, material, wavelengths)
        diffuse = self.is_kind(kind, frozenset({mat.MaterialKind.DIFFUSE}))
        value = dr.select(diffuse, spectra[mat.REFLECTANCE_ID], 0.0)
        if not self.kinds - {mat.MaterialKind.DIFFUSE, mat.MaterialKind.BLACK}:
            return value  # no interface to reflect (the Fresnel term would be selected away in every lane)
        reflective = ~diffuse & ~self.is_kind(kind, frozenset({mat.MaterialKind.BLACK}))
        return dr.select(reflective, self.params.interface_reflectance(spectra, 1.0), value)

    def film_terms(
        self,
        material: mi.UInt32,
        cos_i: mi.Float,
        wavelengths: mi.Spectrum,
        thickness_m: mi.Float | None = None,
    ) -> list[mi.Spectrum]:
        """A thin film's terms [R_incoherent, X_1 …] at incidence cos_i (``thin_film.film_terms``);
        ``thickness_m``: its local τ where it differs from the material's (a texture)."""
        return film_terms(VertexSpectra(self.params, material, wavelengths), cos_i, thickness_m)

    def lobe_variance(self, material: mi.UInt32, wavelengths: mi.Spectrum) -> mi.Spectrum:
        """The per-axis variance (rad²) of the directions a thin film's rough lobe accepts
        (``ThinFilm.lobe_variance``) in the lanes of each film, 0 elsewhere."""
        result = mi.Spectrum(0.0)
        for branch in self.branches:
            if isinstance(branch, ThinFilm):
                result = dr.select(material == branch.index, branch.lobe_variance(wavelengths), result)
        return result

    # ---------------------------------------------------------------- evaluation and sampling
    def eval_pdf(
        self,
        material: mi.UInt32,
        wi: mi.Vector3f,
        wo: mi.Vector3f,
        wavelengths: mi.Spectrum,
        coherence: IncidentCoherence,
        frame: mi.Frame3f,
        active: mi.Bool,
        wo_phase: mi.Vector3f | None = None,
        spectra: VertexSpectra | None = None,
    ) -> tuple[mi.Spectrum, mi.Spectrum]:
        """(f·|cos θo|, MIS density p_k) per wavelength of the non-Dirac part for light arriving along ``wo``.

        ``frame``: the shading frame (world space); ``wo_phase`` (default ``wo``): the direction whose
        interference phase a thin film uses — for light from an emitter the direction to its centre (BRIEF:
        sampled emitter points serve radiometry only); ``spectra``: the vertex's (``vertex_spectra``; None:
        looked up here).
        """
        kind = self.kind(material)
        if spectra is None:
            spectra = self.vertex_spectra(material, wavelengths)
        point = ShadingPoint(material, wi, wavelengths, spectra, frame)
        phase = wo if wo_phase is None else wo_phase
        evaluated = (mi.Spectrum(0.0), mi.Spectrum(0.0))
        for branch in self.evaluating:
            is_this = branch.eval_domain(wi, wo, active) & branch.selects(material, kind)

            def evaluate(*_: mi.Spectrum, branch: Material = branch) -> tuple[mi.Spectrum, mi.Spectrum]:
                return branch.eval_pdf(point, wo, coherence, phase)

            if len(self.evaluating) == 1 or not self.symbolic_branches:
                evaluated = dr.select(is_this, evaluate(), evaluated)
            else:
                evaluated = dr.if_stmt(evaluated, is_this, evaluate, lambda *kept: kept, label=branch.label)
        return evaluated

    def sample(
        self,
        material: mi.UInt32,
        wi: mi.Vector3f,
        wavelengths: mi.Spectrum,
        sample1: mi.Float,
        sample2: mi.Point2f,
        active: mi.Bool,
        spectra: VertexSpectra | None = None,
    ) -> MaterialSample:
        """The next path segment (``common.MaterialSample``); ``film`` holds the thin films' terms (zero
        elsewhere) — the weight uses their incoherent part, the integrator rescales it once the incident
        coherence is known. ``pdf_ratios``: q_k of the hero-wavelength MIS (``common``), 1 where the kind's
        sampling does not depend on the hero; ``None`` when no kind of the scene's does (the integrator
        then skips the ratios' arithmetic, decided when the kernel is traced). ``spectra``: the vertex's
        (``vertex_spectra``; None: looked up here)."""
        kind = self.kind(material)
        if spectra is None:
            spectra = self.vertex_spectra(material, wavelengths)
        point = ShadingPoint(material, wi, wavelengths, spectra)
        # The sampled event as one flat state (what a symbolic branch takes and returns): wo, weight, pdf,
        # delta, eta, the film's transmitted flag and terms, and q_k where a kind of the scene has them.
        state = (
            mi.Vector3f(0.0, 0.0, 1.0),
            mi.Spectrum(0.0),
            mi.Spectrum(0.0),
            mi.Bool(False),
            mi.Float(1.0),
            mi.Bool(False),
            *[mi.Spectrum(0.0) for _ in range(self.max_beams)],
            *([mi.Spectrum(1.0)] if self.hero_ratios else []),
        )
        for branch in self.branches:
            is_this = branch.sample_domain(wi, active) & branch.selects(material, kind)

            def sample_branch(*previous: Any, branch: Material = branch) -> tuple[Any, ...]:
                return self._sample_state(branch, branch.sample(point, sample1, sample2), previous)

            if len(self.branches) == 1 or not self.symbolic_branches:
                state = dr.select(is_this, sample_branch(*state), state)
            else:
                state = dr.if_stmt(state, is_this, sample_branch, lambda *kept: kept, label=branch.label)
        wo, weight, pdf, delta, eta, transmitted, *rest = state
        terms = list(rest[: self.max_beams])
        ratios = rest[self.max_beams] if self.hero_ratios else None
        weight = dr.select(active, weight, 0.0)
        return MaterialSample(wo, weight, pdf, delta, eta, FilmSample(terms, transmitted), ratios)

    def _sample_state(
        self, branch: Material, sampled: MaterialSample, previous: tuple[Any, ...]
    ) -> tuple[Any, ...]:
        """``sampled`` as ``sample``'s flat state; what the kind does not produce (a film's terms, q_k)
        keeps its ``previous`` value."""
        film_slots = 1 + self.max_beams
        film = previous[5 : 5 + film_slots]
        if sampled.film is not None:
            film = (sampled.film.transmitted, *sampled.film.terms)
        ratios = previous[5 + film_slots :]
        if sampled.pdf_ratios is not None:
            if not self.hero_ratios:
                raise AssertionError(
                    f"{type(branch).__name__} returns pdf_ratios but declares hero_ratios False"
                )
            ratios = (sampled.pdf_ratios,)
        return (sampled.wo, sampled.weight, sampled.pdf, sampled.delta, sampled.eta, *film, *ratios)
