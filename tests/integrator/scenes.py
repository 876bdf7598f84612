"""Small scenes for integrator tests (JSON dicts of schema hgrender/scene/v1)."""

from __future__ import annotations

from typing import Any

from schemas import build


def plane_under_source(
    source: dict[str, Any], *, size_px: int = 24, spp: int = 8, camera_height_m: float = 3.0
) -> dict[str, Any]:
    """A diffuse plane z = 0 (normal +z) seen from straight above, lit by ``source`` only.

    Nothing but the source lights the plane (the plane cannot see itself), so every diagnostic is the
    source's own coherence at the plane point.
    """
    return build.scene(
        "plane under source",
        camera=build.camera([0.0, 0.0, camera_height_m], [0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0], fov_deg=20.0),
        film=build.film(size_px, bands=8, spp=spp, max_depth=3),
        materials={"matte": {"type": "diffuse", "reflectance": 0.8}},
        shapes=[
            build.rectangle(
                [0.0, 0.0, 0.0], normal=[0.0, 0.0, 1.0], up=[0.0, 1.0, 0.0], width_m=4.0, material="matte"
            )
        ],
        emitters=[source],
    )


def coated_plane(
    name: str,
    *,
    view: Any,
    film: dict[str, Any],
    coating: dict[str, Any],
    emitter: dict[str, Any],
    fov_deg: float,
) -> dict[str, Any]:
    """A smooth plane z = 0 (normal +z) under a thin film (``coating``: the ``thin_film`` fields besides its
    type and roughness), seen from the unit direction ``view`` 1 m away, lit by ``emitter`` only. The
    roughness (1e-6 µm) makes its reflection a mirror's: a camera path goes on along the mirror direction."""
    return build.scene(
        name,
        camera=build.camera(list(view), [0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0], fov_deg=fov_deg),
        film=film,
        materials={"coated": {"type": "thin_film", "roughness_rms_um": 1e-6, **coating}},
        shapes=[
            build.rectangle(
                [0.0, 0.0, 0.0], normal=[0.0, 0.0, 1.0], up=[0.0, 1.0, 0.0], width_m=2.0, material="coated"
            )
        ],
        emitters=[emitter],
    )


D65_SPHERE_SOURCE: dict[str, Any] = build.sphere([0.0, 0.3, 1.0], 0.2, spectrum={"type": "d65"}, power_w=50.0)
"""A bright white sphere source for ``plane_under_source`` (tiles and noise-target tests)."""
