"""``POST /v1/coherence``: the optics core's coherence calculator (NumPy only; never Mitsuba)."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from service.api.deps import Reader
from service.models import Problem
from worker.optics.calculator import coherence_at

router = APIRouter(prefix="/v1", tags=["coherence"])


class CoherenceRequest(BaseModel):
    """Parameters of ``worker.optics.calculator.coherence_at`` (sizes in metres)."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [{"source": "sphere", "radius_m": 0.01, "distance_m": 2.0, "wavelength_nm": 550.0}]
        },
    )

    source: Literal["sphere", "cylinder", "disk", "rect", "gaussian"]
    radius_m: float | None = Field(None, gt=0, description="sphere, disk, cylinder")
    length_m: float | None = Field(None, gt=0, description="cylinder")
    width_m: float | None = Field(None, gt=0, description="rect")
    height_m: float | None = Field(None, gt=0, description="rect")
    sigma_m: float | None = Field(None, gt=0, description="gaussian")
    distance_m: float = Field(gt=0, description="Propagation distance r (m).")
    wavelength_nm: float = Field(550.0, ge=200, le=2500)
    axis: list[float] = Field([1.0, 0.0, 0.0], min_length=3, max_length=3)
    direction: list[float] = Field([0.0, 0.0, 1.0], min_length=3, max_length=3)
    modes: int = Field(1, ge=1, le=16)


@router.post(
    "/coherence",
    summary="Coherence a source gives a receiver",
    responses={422: {"model": Problem, "description": "Invalid parameter (named in `detail`)."}},
)
def coherence(request: CoherenceRequest, _: Reader) -> dict[str, Any]:
    """Σ⊥, Θ, M = (k/r)²Σ⊥, ℓ₁/ℓ₂ (µm), anisotropy, angle, area and HG coefficients (Eq. 14)."""
    return coherence_at(**request.model_dump())
