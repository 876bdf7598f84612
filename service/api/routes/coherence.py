"""``POST /v1/coherence``: the optics core's coherence calculator (NumPy only; never Mitsuba)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from hgcore.optics.calculator import coherence_at
from service.api.deps import Reader
from service.models import Problem

router = APIRouter(prefix="/v1", tags=["coherence"])

# Bounds keep every intermediate (k/r)²Σ finite in float64; far beyond any scene's scale.
MAX_SIZE_M = 1e4
MAX_DISTANCE_M = 1e12


class CoherenceRequest(BaseModel):
    """Parameters of ``hgcore.optics.calculator.coherence_at`` (sizes in metres)."""

    model_config = ConfigDict(
        extra="forbid",
        allow_inf_nan=False,
        json_schema_extra={
            "examples": [{"source": "sphere", "radius_m": 0.01, "distance_m": 2.0, "wavelength_nm": 550.0}]
        },
    )

    source: Literal["sphere", "cylinder", "disk", "rect", "gaussian"]
    radius_m: float | None = Field(None, gt=0, le=MAX_SIZE_M, description="sphere, disk, cylinder")
    length_m: float | None = Field(None, gt=0, le=MAX_SIZE_M, description="cylinder")
    width_m: float | None = Field(None, gt=0, le=MAX_SIZE_M, description="rect")
    height_m: float | None = Field(None, gt=0, le=MAX_SIZE_M, description="rect")
    sigma_m: float | None = Field(None, gt=0, le=MAX_SIZE_M, description="gaussian")
    distance_m: float = Field(gt=0, le=MAX_DISTANCE_M, description="Propagation distance r (m).")
    wavelength_nm: float = Field(550.0, ge=200, le=2500)
    axis: list[Annotated[float, Field(ge=-1e6, le=1e6)]] = Field([1.0, 0.0, 0.0], min_length=3, max_length=3)
    direction: list[Annotated[float, Field(ge=-1e6, le=1e6)]] = Field(
        [0.0, 0.0, 1.0], min_length=3, max_length=3
    )
    modes: int = Field(1, ge=1, le=16)


@router.post(
    "/coherence",
    summary="Coherence a source gives a receiver",
    responses={422: {"model": Problem, "description": "Invalid parameter (named in `detail`)."}},
)
def coherence(request: CoherenceRequest, _: Reader) -> dict[str, Any]:
    """Σ⊥, Θ, M = (k/r)²Σ⊥, ℓ₁/ℓ₂ (µm), anisotropy, angle, area and HG coefficients (Eq. 14)."""
    return coherence_at(**request.model_dump())
