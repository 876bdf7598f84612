"""``rlt``: the radiometric baseline the paper's Fig. 8 (right) compares with (Belcour & Barla 2017 style).

Radiometric light transport mimics spatial coherence by the wave ensemble itself: each sample is a fully
coherent plane wave from the sampled point on the (primary or secondary) source, so there is no shape
matrix (Σ⊥ = 0, μ ≡ 1) and every coherence-sensitive term takes its phase along the sampled direction:

* a thin film reflects R(V = 1, θ_sample) — the coherent two/multi-beam sum at that sample's angle — and
  the partial coherence of an extended source appears only in the mean over the samples (points of the
  source), with the aliasing ("colourful noise") of a finite ensemble at low spp;
* a grating's lobes have their intrinsic width, centred on the grating equation for the sampled point.

Where the physics says the two agree — materials without coherence-sensitive terms, or a source small
enough that its coherence covers the film's shear and the grating's lobes — ``rlt`` converges to the same
mean as ``hg_path`` (tests/integrator/test_rlt.py). Everything else (estimator, sampling, MIS, AOVs) is
``hg_path``'s; the coherence diagnostics report M = 0 (plane waves carry no coherence shape).
"""

from __future__ import annotations

from hgcore.errors import InputError
from worker.render.integrator import HGPathIntegrator, mi

#: Integrator names a scene (``film.integrator``), ``hgrender render --integrator`` and jobs accept.
INTEGRATORS = ("hg_path", "rlt")


class RLTIntegrator(HGPathIntegrator):
    """Mitsuba plugin ``rlt``: ``hg_path`` with a fully coherent plane wave per sample."""

    plane_waves = True


def integrator_class(name: str) -> type[HGPathIntegrator]:
    """The integrator class of ``name`` (one of :data:`INTEGRATORS`)."""
    if name == "hg_path":
        return HGPathIntegrator
    if name == "rlt":
        return RLTIntegrator
    raise InputError(f"integrator: must be one of {', '.join(INTEGRATORS)}, got {name!r}")


def register() -> None:
    """Register ``rlt`` with Mitsuba (idempotent)."""
    mi.register_integrator("rlt", lambda props: RLTIntegrator(props))
