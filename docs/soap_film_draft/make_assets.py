"""Assets of the soap-film draft (issue 27, item 3): a drainage thickness map and an HDR sky.

Run ``python docs/soap_film_draft/make_assets.py`` (from the repository root); it writes ``thickness.exr``
and ``sky.exr`` beside the two scenes (``sunny.json``, ``overcast.json``), which ``hgrender render`` takes
with this folder as their bundle.

Thickness (µm, one float channel, 256 × 128, linear): a vertical soap film drains under gravity, thin at
the top and thick at the bottom. The profile τ(s) = τ_top + (τ_bottom − τ_top)·s^0.7 over the normalised
depth s (0 at the top of the bubble, 1 at the bottom; Mysels' wedge is ∝ s^½ near the top) runs from a
10 nm black film to 1.2 µm, with a slow azimuthal ripple of ±6 % and a few swirls (marginal regeneration)
so that the bands are not perfectly horizontal. The bubble is a ``sphere`` turned so that its local z axis
is world +Y: Mitsuba's sphere has v = θ/π from local +z, so the image's bottom row (v = 0) is the top of
the bubble and its top row the bottom.

Sky (linear sRGB, 512 × 256 lat-long in the OpenEXR convention): a clear-sky gradient (deep blue at the
zenith, pale at the horizon, luminance ≈ 0.1 of a unit equal-energy radiance, i.e. ≈ 7 000 cd·m⁻²) over a
grey-green ground; the sun itself is the scene's ``sun`` emitter, not part of the map.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TAU_TOP_UM, TAU_BOTTOM_UM = 0.01, 1.2


def write_exr(path: Path, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    array = np.ascontiguousarray(pixels, dtype=np.float32)
    output = oiio.ImageOutput.create(str(path))
    output.open(str(path), oiio.ImageSpec(array.shape[1], array.shape[0], array.shape[2], "float"))
    output.write_image(array)
    output.close()


def thickness_map(width: int = 256, height: int = 128) -> np.ndarray:
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height  # row r is v = 1 − (r + ½)/H
    depth = np.broadcast_to(v[::-1, None], (height, width)).copy()  # s: top row (v = 1) is the bottom
    phi = 2.0 * math.pi * u[None, :]
    depth += 0.03 * np.sin(3.0 * phi + 4.0 * depth) * np.sin(math.pi * depth)
    swirls = sum(
        0.05 * np.exp(-((u[None, :] - cu) ** 2 + (depth - cs) ** 2) / (2 * 0.04**2))
        for cu, cs in ((0.2, 0.55), (0.47, 0.7), (0.8, 0.45))
    )
    s = np.clip(depth + swirls, 0.0, 1.0)
    tau = TAU_TOP_UM + (TAU_BOTTOM_UM - TAU_TOP_UM) * s**0.7
    tau *= 1.0 + 0.06 * np.sin(2.0 * phi)
    return tau[..., None]


def sky_map(width: int = 512, height: int = 256) -> np.ndarray:
    rows = (np.arange(height) + 0.5) / height
    elevation = (0.5 - rows) * math.pi
    up = np.clip(np.sin(elevation), 0.0, 1.0)[:, None]
    zenith, horizon = np.array([0.035, 0.06, 0.16]), np.array([0.12, 0.13, 0.14])
    sky = horizon + (zenith - horizon) * up**0.5
    ground = np.array([0.03, 0.035, 0.025])
    image = np.where(elevation[:, None] > 0.0, sky, ground)
    return np.broadcast_to(image[:, None, :], (height, width, 3))


if __name__ == "__main__":
    write_exr(HERE / "thickness.exr", thickness_map())
    write_exr(HERE / "sky.exr", sky_map())
    print(f"wrote {HERE / 'thickness.exr'} and {HERE / 'sky.exr'}")
