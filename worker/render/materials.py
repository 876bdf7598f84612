"""Material table: the per-material parameters that ``hg_path`` gathers inside its kernel.

Every material of the scene becomes one fixed-stride float32 record; spectral parameters (reflectance,
refractive indices) are ids into a ``SpectralTable``. The integrator maps a hit shape to its material
through the shape's Dr.Jit registry id, so the Mitsuba BSDF attached to a shape is never consulted by
``hg_path`` (it only serves Mitsuba's own integrators in reference comparisons).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from hgcore.optics.grating import BinaryGrating
from hgcore.optics.rough_surface import RoughSurface


class MaterialKind(IntEnum):
    DIFFUSE = 0
    MIRROR = 1
    DIELECTRIC = 2
    ROUGH_CONDUCTOR = 3
    ROUGH_DIELECTRIC = 4
    THIN_FILM = 5
    GRATING = 6
    BLACK = 7  # emitter surfaces: absorb everything


# Parameter offsets inside one record. The statistical and diffractive parameters (roughness, PSD,
# grating pitch, duty, pits, orders) are not here: they are compiled into the kernel as the constants of
# the material's optics model (``MaterialRow.model``).
KIND = 0
REFLECTANCE_ID = 1  # diffuse reflectance spectrum
ETA_ID = 2  # conductor n, dielectric / substrate index
KAPPA_ID = 3  # conductor extinction κ (a zero spectrum for dielectrics)
EXTERIOR_IOR = 4
SCATTERING_REGION_RADIUS_M = 5
FILM_THICKNESS_M = 6
FILM_IOR_ID = 7
BEAMS = 8
ORIENTATION_RAD = 9
DISPERSIVE = 10  # 1 when the dielectric index varies with wavelength
FILM_TRANSMITS = 11  # 1 for a thin film on a dielectric substrate (reflects and transmits)
FILM_EXTINCTION = 12  # the film's extinction κ_f (constant over wavelength; 0: a clear film)
# A rough surface's σ and ℓc: read by the kernels only where a texture gives them (``TEXTURE_BINDINGS``);
# constant ones are compiled into the kernel with the rest of the material's ``RoughSurface`` model.
ROUGHNESS_RMS_M = 13
CORRELATION_LENGTH_M = 14
TINT_ID = 15  # a conductor's colour tint spectrum (mirrors, rough conductors: 0 where there is none)
# Texture bindings (``worker.render.textures``) of the textured parameters: binding + 1, 0 for none.
TEX_REFLECTANCE = 16
TEX_TINT = 17
TEX_ROUGHNESS = 18
TEX_CORRELATION = 19
TEX_THICKNESS = 20
STRIDE = 21

#: The parameters a texture may give, and the offset of each one's binding. Colours (spectral ids) become
#: the texture's upsampled spectra, scalars its values in SI units.
TEXTURE_BINDINGS = {
    REFLECTANCE_ID: TEX_REFLECTANCE,
    TINT_ID: TEX_TINT,
    ROUGHNESS_RMS_M: TEX_ROUGHNESS,
    CORRELATION_LENGTH_M: TEX_CORRELATION,
    FILM_THICKNESS_M: TEX_THICKNESS,
}
COLOUR_PARAMETERS = frozenset({REFLECTANCE_ID, TINT_ID})

# 0: no override; a non-specular vertex is a secondary source sized by the lit patch (docs/physics.md §7).
DEFAULT_SCATTERING_REGION_RADIUS_M = 0.0

# Kind sets: the integrator and the BSDF dispatch (``worker.render.bsdfs``) test kinds only through these.
#: Materials whose response is a Dirac delta (coherence kept, r accumulated: paper §5, "Perfectly
#: specular"); a path passes through them without a non-specular vertex.
SPECULAR_KINDS = frozenset({MaterialKind.MIRROR, MaterialKind.DIELECTRIC})
#: Interfaces that transmit, whose two sides differ: their shading frame is not flipped towards the
#: incident side. A thin film transmits too where its record sets ``FILM_TRANSMITS`` (on a dielectric).
TRANSMITTING_KINDS = frozenset({MaterialKind.DIELECTRIC, MaterialKind.ROUGH_DIELECTRIC})
#: Materials lit through next-event estimation only (gratings, docs/integrator.md): their lobes are
#: evaluated towards the emitter's centre with MIS weight 1, and emission their sampled lobes reach is
#: not counted (it would be counted twice).
NEE_ONLY_KINDS = frozenset({MaterialKind.GRATING})
#: Materials whose value depends on the incident coherence through interference (Eq. 18): the path defers
#: their value until the pending record is resolved.
INTERFERENCE_KINDS = frozenset({MaterialKind.THIN_FILM})


@dataclass
class MaterialRow:
    """One material: its kind, table values (offset -> value) and, for the statistical and diffractive
    kinds, the optics model object whose constants are compiled into the kernel
    (``hgcore.optics.rough_surface.RoughSurface`` or ``hgcore.optics.grating.BinaryGrating``)."""

    kind: MaterialKind
    values: dict[int, float] = field(default_factory=dict)
    model: RoughSurface | BinaryGrating | None = None
    #: parameter offset → (smallest, largest) value of its texture (SI units), for the textured parameters
    texture_ranges: dict[int, tuple[float, float]] = field(default_factory=dict)

    def textured(self, offset: int) -> bool:
        """Whether parameter ``offset`` comes from a texture (``TEXTURE_BINDINGS``)."""
        return self.values.get(TEXTURE_BINDINGS[offset], 0.0) > 0.0

    def as_row(self) -> np.ndarray:
        row = np.zeros(STRIDE, dtype=np.float32)
        row[KIND] = float(self.kind)
        row[SCATTERING_REGION_RADIUS_M] = DEFAULT_SCATTERING_REGION_RADIUS_M
        row[EXTERIOR_IOR] = 1.0
        for offset, value in self.values.items():
            row[offset] = value
        return row


@dataclass
class MaterialTable:
    records: list[MaterialRow] = field(default_factory=list)

    def add(self, record: MaterialRow) -> int:
        self.records.append(record)
        return len(self.records) - 1

    def flat(self) -> np.ndarray:
        rows = [record.as_row() for record in self.records] or [MaterialRow(MaterialKind.BLACK).as_row()]
        return np.concatenate(rows)

    @property
    def kinds(self) -> set[MaterialKind]:
        return {record.kind for record in self.records}

    def indices_of(self, kind: MaterialKind) -> list[int]:
        return [index for index, record in enumerate(self.records) if record.kind == kind]

    def max_beams(self) -> int:
        beams = [int(r.values.get(BEAMS, 0)) for r in self.records if r.kind == MaterialKind.THIN_FILM]
        return max(beams, default=0)

    def textured_parameters(self) -> frozenset[int]:
        """The parameters (``TEXTURE_BINDINGS`` keys) some material of the scene reads from a texture:
        only their lookups are traced, so that scenes without textures trace none."""
        return frozenset(
            offset for offset in TEXTURE_BINDINGS for record in self.records if record.textured(offset)
        )

    def tinted(self) -> bool:
        """Whether some conductor of the scene has a tint (else no tint spectrum is looked up)."""
        return any(TINT_ID in record.values or record.textured(TINT_ID) for record in self.records)

    def film_absorbing(self) -> bool:
        """Whether some thin film of the scene absorbs (κ_f > 0): only then do the kernels carry a complex
        film index, so that scenes of clear films trace exactly the real-index arithmetic."""
        return any(
            r.values.get(FILM_EXTINCTION, 0.0) > 0.0 for r in self.records if r.kind == MaterialKind.THIN_FILM
        )
