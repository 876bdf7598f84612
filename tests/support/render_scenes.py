"""Small scenes (JSON dicts of schema hgrender/scene/v1) for the renderer's reference and paper tests."""

from __future__ import annotations

import math
from typing import Any

from schemas import build


def constant_spectrum(power_w: float) -> dict[str, Any]:
    """A flat spectrum of total power ``power_w``: spectral features then come from materials alone."""
    return {"spectrum": {"type": "constant", "value": 1.0}, "power_w": power_w}


def mirror_room(
    *, size_px: int, spp: int, max_depth: int, bands: int, glass_sphere: bool = False
) -> dict[str, Any]:
    """A diffuse floor, a perfect mirror wall behind it and a sphere light: only diffuse + Dirac materials.

    ``glass_sphere`` adds a smooth, non-dispersive glass ball (n = 1.5) on the floor: refraction chains.

    Built so that no surface is ever seen from behind (Mitsuba's BSDFs are one-sided, ``hg_path``'s are
    two-sided): the floor (y = 0, facing up) ends at the mirror (z = −0.5, facing +z), nothing behind either.
    """
    scene = build.scene(
        "mirror room",
        camera=build.camera([0.0, 0.5, 1.6], [0.0, 0.25, -0.2], up=[0.0, 1.0, 0.0], fov_deg=45.0),
        film=build.film(size_px, bands=bands, spp=spp, max_depth=max_depth),
        materials={
            "floor": {"type": "diffuse", "reflectance": 0.6},
            "mirror": {"type": "mirror", "conductor": "perfect"},
        },
        shapes=[
            build.rectangle(
                [0.0, 0.0, 0.1], normal=[0.0, 1.0, 0.0], up=[0.0, 0.0, -1.0], width_m=1.2, material="floor"
            ),
            build.rectangle(
                [0.0, 0.4, -0.5],
                normal=[0.0, 0.0, 1.0],
                up=[0.0, 1.0, 0.0],
                width_m=1.2,
                height_m=0.8,
                material="mirror",
            ),
        ],
        emitters=[
            build.sphere(
                [0.25, 0.45, 0.1], 0.08, spectrum={"type": "blackbody", "temperature_k": 4500.0}, power_w=20.0
            )
        ],
    )
    if glass_sphere:
        scene["materials"]["glass"] = {"type": "dielectric", "ior": 1.5}
        scene["shapes"].append(build.sphere([-0.15, 0.15, 0.1], 0.15, material="glass"))
    return scene


# --- Fig. 7: a thin-film coated sphere under a sphere vs a cylinder light ------------------------------

FIG7_WAVELENGTH_RANGE_NM = (420.0, 740.0)
FIG7_BANDS = 32  # 10 nm bands resolve the film's fringes (period λ²/OPD ≈ 50–150 nm for OPD ≈ 3.6 µm)
FIG7_FILM = {"thickness_um": 1.23, "ior": 1.5, "substrate": "Ag"}  # the paper's scarab coating
FIG7_SPHERE_RADIUS_M = 0.05
FIG7_CAMERA_ORIGIN_M = (0.0, 0.0, 0.4)
FIG7_LIGHT_CENTER_M = (0.0, 0.1, 0.2)
FIG7_POWER_W = 10.0


def fringe_film(width: int, height: int, *, spp: int, max_depth: int) -> dict[str, Any]:
    """The film of the fringe experiments: FIG7_BANDS bands over FIG7_WAVELENGTH_RANGE_NM."""
    return {
        "width": width,
        "height": height,
        "bands": FIG7_BANDS,
        "spp": spp,
        "max_depth": max_depth,
        "wavelength_min_nm": FIG7_WAVELENGTH_RANGE_NM[0],
        "wavelength_max_nm": FIG7_WAVELENGTH_RANGE_NM[1],
    }


def two_beam_coating(
    film: dict[str, Any], *, roughness_rms_um: float, correlation_length_um: float
) -> dict[str, Any]:
    """A thin-film material of ``film`` (thickness, index, substrate) with two beams: the paper's Eq. (18)."""
    return {
        "type": "thin_film",
        "film_thickness_um": film["thickness_um"],
        "film_ior": film["ior"],
        "substrate": {"conductor": film["substrate"]},
        "roughness_rms_um": roughness_rms_um,
        "correlation_length_um": correlation_length_um,
        "beams": 2,
    }


# A 0.5 m coated square in the z = 0 plane, facing +z.
COATED_PLANE = build.rectangle(
    [0.0, 0.0, 0.0], normal=[0.0, 0.0, 1.0], up=[0.0, 1.0, 0.0], width_m=0.5, material="coating"
)


def fig7_sphere_light() -> dict[str, Any]:
    """The paper's sphere source (radius 0.6 cm), 17.5 cm from the highlight: coherence ≈ 5 µm."""
    return build.sphere(FIG7_LIGHT_CENTER_M, 0.006, **constant_spectrum(FIG7_POWER_W))


def fig7_cylinder_light(length_m: float = 0.3) -> dict[str, Any]:
    """A cylinder source (radius 1 mm) along x, equal power: coherent ≫ 10 µm across, ≈ 0.2 µm along x."""
    x, y, z = FIG7_LIGHT_CENTER_M
    return {
        "type": "cylinder",
        "p0_m": [x - length_m / 2, y, z],
        "p1_m": [x + length_m / 2, y, z],
        "radius_m": 0.001,
        **constant_spectrum(FIG7_POWER_W),
    }


def fig7_coated_sphere(light: dict[str, Any], *, spp: int) -> dict[str, Any]:
    """A silver sphere with a 1.23 µm coating, zoomed onto its highlight, lit by ``light`` only.

    Rough enough (σ = 0.15 µm ⇒ e^{−g} ≈ 0 at 550 nm) that the highlight is the Eq. (15) lobe, which
    next-event estimation sees with the emitter's coherence; two beams, the paper's Eq. (18). The 32×12 px
    film frames the highlight (normals within ≈ ±25° of the camera-light bisector).
    """
    return build.scene(
        "Fig. 7 coated sphere",
        camera=build.camera(FIG7_CAMERA_ORIGIN_M, [0.0, 0.011, 0.0487], up=[0.0, 1.0, 0.0], fov_deg=6.5),
        film=fringe_film(32, 12, spp=spp, max_depth=2),
        materials={"coating": two_beam_coating(FIG7_FILM, roughness_rms_um=0.15, correlation_length_um=1.0)},
        shapes=[build.sphere([0.0, 0.0, 0.0], FIG7_SPHERE_RADIUS_M, material="coating")],
        emitters=[light],
    )


# --- Fig. 1(f) / Eq. (20): a DVD grating under a small vs a large source --------------------------------

GRATING_LIGHT_DISTANCE_M = 0.3
GRATING_CAMERA_HEIGHT_M = 0.3
GRATING_PITCH_UM = 0.74  # DVD preset
GRATING_INCIDENCE_SINE = 0.743  # first order at 550 nm leaves along the normal: sin θ_i = λ/Λ


def dvd_under_sphere(radius_m: float, *, spp: int) -> dict[str, Any]:
    """A flat DVD grating (grating vector along x) seen from straight above, lit from sin θ_i = 0.743.

    The −1st order of wavelength λ leaves with direction cosine β_x = sin θ_i − λ/Λ, so the camera sees a
    rainbow streak along x through the centre (β_y = 0); its width in β_y is the lobe's std
    √((a/2)²/s² + (w/k)²) (hgcore.optics.grating; a the source radius, s its distance, w the intrinsic width).
    """
    elevation = math.asin(GRATING_INCIDENCE_SINE)
    light = [
        -GRATING_LIGHT_DISTANCE_M * math.sin(elevation),
        GRATING_LIGHT_DISTANCE_M * math.cos(elevation),
        0.0,
    ]
    return build.scene(
        "DVD grating",
        camera=build.camera(
            [0.0, GRATING_CAMERA_HEIGHT_M, 0.0], [0.0, 0.0, 0.0], up=[0.0, 0.0, -1.0], fov_deg=30.0
        ),
        film=build.film(32, bands=8, spp=spp, max_depth=2),
        materials={
            "dvd": {
                "type": "grating",
                "preset": "dvd",
                "conductor": "Al",
                "max_order": 3,
                "lobe_width_per_um": 0.05,
            }
        },
        shapes=[
            build.rectangle(
                [0.0, 0.0, 0.0], normal=[0.0, 1.0, 0.0], up=[0.0, 0.0, -1.0], width_m=0.3, material="dvd"
            )
        ],
        emitters=[build.sphere(light, radius_m, **constant_spectrum(5.0))],
    )


# --- Fig. 8: a coated plane lit directly vs through a mirror -----------------------------------------

FIG8_INCIDENCE_DEG = 45.0
FIG8_FILM = {"thickness_um": 2.0, "ior": 1.5, "substrate": "Ag"}
FIG8_FIRST_LEG_M = 0.3  # plane → light (direct) or plane → mirror
FIG8_SECOND_LEG_M = 0.6  # mirror → light
FIG8_LIGHT_RADIUS_M = 0.05


def fig8_coated_plane(*, via_mirror: bool, spp: int) -> dict[str, Any]:
    """A coated plane seen in its specular direction, lit at 45° either directly (light 0.3 m away) or by
    the same light 0.6 m beyond a perfect mirror placed 0.3 m away on the same incident direction.

    The film sees the same incidence in both cases; only the propagation distance r of the light differs
    (0.3 m vs 0.9 m), so the coherence length ℓ = r/(k·a/2) triples through the mirror (Σ⊥ kept, r grown).
    """
    theta = math.radians(FIG8_INCIDENCE_DEG)
    towards_light = [math.sin(theta), 0.0, math.cos(theta)]
    mirror_center = [FIG8_FIRST_LEG_M * c for c in towards_light]
    if via_mirror:
        light_center = [mirror_center[0], mirror_center[1] + FIG8_SECOND_LEG_M, mirror_center[2]]
    else:
        light_center = mirror_center
    scene = build.scene(
        "Fig. 8 coated plane",
        camera=build.camera(
            [-FIG8_FIRST_LEG_M * math.sin(theta), 0.0, FIG8_FIRST_LEG_M * math.cos(theta)],
            [0.0, 0.0, 0.0],
            up=[0.0, 1.0, 0.0],
            fov_deg=4.0,
        ),
        film=fringe_film(8, 8, spp=spp, max_depth=3),
        materials={
            "coating": two_beam_coating(FIG8_FILM, roughness_rms_um=0.15, correlation_length_um=2.0),
            "mirror": {"type": "mirror", "conductor": "perfect"},
        },
        shapes=[COATED_PLANE],
        emitters=[build.sphere(light_center, FIG8_LIGHT_RADIUS_M, **constant_spectrum(10.0))],
    )
    if via_mirror:
        # The mirror's normal bisects the directions to the plane and to the light (up).
        normal = [-towards_light[0], 1.0, -towards_light[2]]
        scene["shapes"].append(
            build.rectangle(mirror_center, normal=normal, up=[1.0, 0.0, 0.0], width_m=0.25, material="mirror")
        )
    return scene


def smooth_coated_plane_mirroring_light(*, spp: int) -> dict[str, Any]:
    """A smooth (σ = 1 nm ⇒ e^{−g} ≈ 1) coated plane whose Dirac reflection shows a small sphere light.

    Incidence 20°, light radius 1 cm at 0.3 m: ℓ = r/(k·a/2) ≈ 5 µm ≫ ξ = τ·sin θ ≈ 0.42 µm, so V ≈ 1. The
    camera sits in the mirror direction with a 1° field, so every pixel's reflected ray ends on the light.
    """
    theta = math.radians(20.0)
    return build.scene(
        "smooth coated plane",
        camera=build.camera(
            [-0.3 * math.sin(theta), 0.0, 0.3 * math.cos(theta)],
            [0.0, 0.0, 0.0],
            up=[0.0, 1.0, 0.0],
            fov_deg=1.0,
        ),
        film=fringe_film(8, 8, spp=spp, max_depth=2),
        materials={"coating": two_beam_coating(FIG7_FILM, roughness_rms_um=0.001, correlation_length_um=5.0)},
        shapes=[COATED_PLANE],
        emitters=[
            build.sphere([0.3 * math.sin(theta), 0.0, 0.3 * math.cos(theta)], 0.01, **constant_spectrum(10.0))
        ],
    )
