"""Viewer data endpoints against the rendered EXR read independently with OpenImageIO.

Values served from the decoded EXR are float32 copies, so they must be bit-identical (f32) or within
half-precision rounding (f16: relative 2⁻¹¹, plus the f16 subnormal spacing 2⁻²⁴ near zero).
"""

from __future__ import annotations

import io
import json
import math
from typing import Any

import httpx
import numpy as np
import pytest
from PIL import Image

from hgcore.imaging import auto_exposure_ev, display_rgb8
from hgcore.store.filesystem import FilesystemStore
from service.viewer_data import DecodedImageCache
from tests.support import REPO_ROOT
from tests.support.live_service import LiveService, RenderedJob
from tests.support.scenes import CYLINDER_SIZE_PX, cylinder_scene


def _floats(response, dtype: str = "<f4") -> np.ndarray:
    assert response.status_code == 200, response.text
    height, width = int(response.headers["X-Height"]), int(response.headers["X-Width"])
    channels = int(response.headers.get("X-Channels", 1))
    values = np.frombuffer(response.content, dtype=dtype).astype(np.float32)
    return values.reshape(height, width, channels) if channels > 1 else values.reshape(height, width)


def test_layer_catalogue_lists_bands_rgb_and_diagnostics(
    live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    response = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/layers")
    assert response.status_code == 200, response.text
    catalogue = response.json()
    assert (catalogue["width"], catalogue["height"]) == (CYLINDER_SIZE_PX, CYLINDER_SIZE_PX)
    bands = cylinder_job.exr.band_names()
    assert catalogue["wavelengths_nm"] == [float(n[3:-2].replace(",", ".")) for n in bands]
    layers = {layer["name"]: layer for layer in catalogue["layers"]}
    assert [n for n in layers if n.startswith("S0.")] == bands
    assert layers["rgb"]["channels"] == 3
    assert layers["coherence.l1_um"]["unit"] == "µm"
    assert layers["coherence.area_um2"]["unit"] == "µm²"
    assert layers["coherence.r_m"]["unit"] == "m"
    assert layers[bands[0]]["unit"] == "W·m⁻²·sr⁻¹·nm⁻¹"
    band = cylinder_job.exr.channels[bands[3]]
    assert layers[bands[3]]["min"] == float(band.min())
    assert layers[bands[3]]["max"] == float(band.max())
    # Diagnostics' ranges are over covered pixels only (weight > 0): uncovered pixels hold zeros.
    covered = cylinder_job.exr.channels["coherence.weight"] > 0
    assert covered.any()
    assert layers["coherence.l1_um"]["min"] == float(
        cylinder_job.exr.channels["coherence.l1_um"][covered].min()
    )


def test_layer_arrays_equal_the_exr_in_f32_f16_and_downsampled(
    live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    exr = cylinder_job.exr
    job = cylinder_job.job_id
    band = exr.band_names()[3]
    np.testing.assert_array_equal(
        _floats(live_service.get(f"/v1/jobs/{job}/layers/{band}")), exr.channels[band]
    )
    np.testing.assert_array_equal(_floats(live_service.get(f"/v1/jobs/{job}/layers/rgb")), exr.rgb)
    half = _floats(live_service.get(f"/v1/jobs/{job}/layers/{band}", format="f16"), "<f2")
    np.testing.assert_allclose(half, exr.channels[band], rtol=2.0**-11, atol=2.0**-24)
    # step 2: radiance layers are 2×2 block means, diagnostics the top-left pixel of each block.
    expected_mean = (
        exr.channels[band].reshape(CYLINDER_SIZE_PX // 2, 2, CYLINDER_SIZE_PX // 2, 2).mean(axis=(1, 3))
    )
    got = _floats(live_service.get(f"/v1/jobs/{job}/layers/{band}", step=2))
    np.testing.assert_allclose(got, expected_mean, rtol=1e-6, atol=1e-30)
    got_l1 = _floats(live_service.get(f"/v1/jobs/{job}/layers/coherence.l1_um", step=2))
    np.testing.assert_array_equal(got_l1, exr.channels["coherence.l1_um"][::2, ::2])


def test_pixel_record_equals_the_exr(live_service: LiveService, cylinder_job: RenderedJob) -> None:
    exr = cylinder_job.exr
    covered = np.argwhere(exr.channels["coherence.weight"] > 0)
    y, x = (int(v) for v in covered[len(covered) // 2])
    record = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/pixel", x=x, y=y).json()
    assert record["spectrum"] == [float(exr.channels[n][y, x]) for n in exr.band_names()]
    assert record["rgb"] == [float(exr.channels[c][y, x]) for c in "RGB"]
    assert record["coherence_covered"] is True
    for name in ("l1_um", "l2_um", "angle", "anisotropy", "area_um2", "r_m", "Mxx", "Mxy", "Myy"):
        assert record["coherence"][name] == float(exr.channels[f"coherence.{name}"][y, x]), name
    assert record["depth_m"] == float(exr.channels["depth"][y, x])


def test_display_png_is_display_rgb8_of_the_exr(live_service: LiveService, cylinder_job: RenderedJob) -> None:
    for ev, operator in ((0.0, "clamp"), (1.5, "reinhard"), (-2.0, "aces")):
        response = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/display.png", ev=ev, tonemap=operator)
        assert response.headers["content-type"] == "image/png"
        shown = np.asarray(Image.open(io.BytesIO(response.content)).convert("RGB"))
        np.testing.assert_array_equal(shown, display_rgb8(cylinder_job.exr.rgb, ev, operator))


def test_ellipses_are_the_diagnostics_at_grid_centres_and_vertical(
    live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    exr = cylinder_job.exr
    grid = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/ellipses", spacing=6).json()
    covered = exr.channels["coherence.weight"] > 0
    expected_cells = [
        (x, y) for y in range(3, CYLINDER_SIZE_PX, 6) for x in range(3, CYLINDER_SIZE_PX, 6) if covered[y, x]
    ]
    assert [(e["x"], e["y"]) for e in grid["ellipses"]] == expected_cells
    assert len(expected_cells) >= 8
    for ellipse in grid["ellipses"]:
        x, y = ellipse["x"], ellipse["y"]
        for name in ("l1_um", "l2_um", "angle", "area_um2"):
            assert ellipse[name] == float(exr.channels[f"coherence.{name}"][y, x])
        # ℓ₁ ∥ d × x̂ projects onto the image's vertical (conftest); 1e-3 rad allows float32 rounding
        # of ½·atan2 of the luminance-weighted (sin 2θ, cos 2θ) sums.
        assert abs(math.cos(ellipse["angle"])) < 1e-3
        # The cylinder is 0.6 m long and 4 mm wide: strongly anisotropic coherence (ℓ₁/ℓ₂ ≫ 10).
        assert ellipse["l1_um"] > 10 * ellipse["l2_um"]


def test_compare_modes_against_independent_formulas(
    live_service: LiveService, cylinder_job: RenderedJob, cylinder_job_reseeded: RenderedJob
) -> None:
    a, b = cylinder_job.exr.rgb.astype(np.float64), cylinder_job_reseeded.exr.rgb.astype(np.float64)
    ids = {"a": cylinder_job.job_id, "b": cylinder_job_reseeded.job_id}
    response = live_service.get("/v1/compare", **ids, mode="abs")
    absolute = _floats(response)
    np.testing.assert_allclose(absolute, np.abs(b - a).mean(axis=-1), rtol=1e-6, atol=1e-30)
    stats = json.loads(response.headers["X-Stats"])
    assert math.isclose(stats["max"], float(absolute.max()), rel_tol=1e-6)
    same = _floats(live_service.get("/v1/compare", a=ids["a"], b=ids["a"], mode="de2000"))
    np.testing.assert_array_equal(same, 0.0)
    response = live_service.get("/v1/compare", **ids, mode="de2000", ev=-3.0)
    de = _floats(response)
    assert float(response.headers["X-Exposure-EV"]) == -3.0
    # Independent path: XYZ from the EXR's linear sRGB by the IEC 61966-2-1 matrix (the renderer wrote
    # RGB from the bands' XYZ with the inverse matrix; both agree to ~1e-4), exposed, CIE 1976 L*a*b*
    # with the D65 white at Y = 1; ΔE00 of the same colour pair changes by ~1e-2 for 1e-4 differences.
    srgb_to_xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    white = np.array([0.95047, 1.0, 1.08883])

    def lab(rgb: np.ndarray, ev: float) -> np.ndarray:
        t = (rgb * 2.0**ev) @ srgb_to_xyz.T / white
        f = np.where(t > (6 / 29) ** 3, np.cbrt(t), t / (3 * (6 / 29) ** 2) + 4 / 29)
        return np.stack(
            [116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], -1
        )

    from hgcore.colour import ciede2000

    np.testing.assert_allclose(de, ciede2000(lab(a, -3.0), lab(b, -3.0)), rtol=0, atol=2e-2)
    assert float(de.max()) > 0.5  # different seeds: visibly different noise
    # Without ev: a's automatic exposure, the 99th percentile of its luminance mapped to white.
    response = live_service.get("/v1/compare", **ids, mode="de2000")
    auto_ev = float(response.headers["X-Exposure-EV"])
    assert auto_ev == pytest.approx(auto_exposure_ev(a), abs=1e-3)
    np.testing.assert_allclose(_floats(response), ciede2000(lab(a, auto_ev), lab(b, auto_ev)), atol=2e-2)
    catalogue = live_service.get(f"/v1/jobs/{ids['a']}/layers").json()
    assert catalogue["exposure_ev"] == auto_ev


def test_compare_flip_is_ldr_flip_of_the_displayed_images(
    live_service: LiveService, cylinder_job: RenderedJob, cylinder_job_reseeded: RenderedJob
) -> None:
    import flip_evaluator

    ids = {"a": cylinder_job.job_id, "b": cylinder_job_reseeded.job_id}
    response = live_service.get("/v1/compare", **ids, mode="flip")
    flip = _floats(response)
    ev = float(response.headers["X-Exposure-EV"])
    # Independently: the EXRs' RGB as display_rgb8 shows them with the clamp tone map, in [0, 1].
    reference, test = (
        display_rgb8(job.exr.rgb, ev, "clamp") / 255.0 for job in (cylinder_job, cylinder_job_reseeded)
    )
    expected, _, _ = flip_evaluator.evaluate(
        reference.astype(np.float32), test.astype(np.float32), "LDR", applyMagma=False
    )
    # 8-bit quantisation of the independent path (±0.5/255) moves ꟻLIP by well under 0.02.
    np.testing.assert_allclose(flip, expected[..., 0], atol=2e-2)
    assert 0.0 < float(flip.mean()) < 1.0
    same = _floats(live_service.get("/v1/compare", a=ids["a"], b=ids["a"], mode="flip"))
    np.testing.assert_array_equal(same, 0.0)


def test_uploaded_exr_is_viewable_and_validated(live_service: LiveService, cylinder_job: RenderedJob) -> None:
    exr = live_service.data_dir / "upload-test.exr"
    live_service.admin.download(cylinder_job.job_id, "image.exr", exr)
    headers = {"Authorization": f"Bearer {live_service.token}", "Content-Type": "image/x-exr"}
    response = httpx.post(live_service.base_url + "/v1/images", content=exr.read_bytes(), headers=headers)
    assert response.status_code == 201, response.text
    image_id = response.json()["id"]
    assert response.json()["width"] == CYLINDER_SIZE_PX
    pixel = live_service.get(f"/v1/jobs/{image_id}/pixel", x=3, y=5).json()
    names = cylinder_job.exr.band_names()
    assert pixel["spectrum"] == pytest.approx([float(cylinder_job.exr.channels[n][5, 3]) for n in names])
    assert live_service.get(f"/v1/jobs/{image_id}/layers").json()["uploaded"] is True
    # Another owner cannot see it.
    other = live_service.admin.create_token("eve", ["read"])["token"]
    assert live_service.get(f"/v1/jobs/{image_id}/layers", token=other).status_code == 404
    # Not an EXR; an EXR without spectral channels; too large.
    response = httpx.post(live_service.base_url + "/v1/images", content=b"P6 2 2 255\n", headers=headers)
    assert response.status_code == 422 and response.json()["detail"].startswith("file: not an OpenEXR")
    import OpenImageIO as oiio

    grey = live_service.data_dir / "grey.exr"
    out = oiio.ImageOutput.create(str(grey))
    out.open(str(grey), oiio.ImageSpec(4, 4, 3, oiio.HALF))
    out.write_image(np.full((4, 4, 3), 0.5, dtype=np.float32))
    out.close()
    response = httpx.post(live_service.base_url + "/v1/images", content=grey.read_bytes(), headers=headers)
    assert response.status_code == 422 and "at least 2 spectral channels" in response.json()["detail"]
    huge = b"\x76\x2f\x31\x01" + b"\0" * (64 * 1024 * 1024)
    response = httpx.post(live_service.base_url + "/v1/images", content=huge, headers=headers, timeout=60)
    assert response.status_code == 413


def test_viewer_errors_name_the_parameter(live_service: LiveService, cylinder_job: RenderedJob) -> None:
    job = cylinder_job.job_id
    response = live_service.get(f"/v1/jobs/{job}/layers/nonsense")
    assert response.status_code == 422 and response.json()["detail"].startswith("name: ")
    response = live_service.get(f"/v1/jobs/{job}/pixel", x=CYLINDER_SIZE_PX, y=0)
    assert response.status_code == 422 and response.json()["detail"].startswith("x: ")
    response = live_service.get(f"/v1/jobs/{job}/display.png", tonemap="gamma")
    assert response.status_code == 422 and response.json()["detail"].startswith("tonemap: ")
    response = live_service.get("/v1/compare", a=job, b=job, mode="psnr")
    assert response.status_code == 422 and response.json()["detail"].startswith("mode: ")
    assert live_service.get(f"/v1/jobs/{job}/layers", token="not-a-token").status_code == 401
    other = live_service.admin.create_token("mallory", ["read", "submit"])["token"]
    response = live_service.get(f"/v1/jobs/{job}/layers", token=other)
    assert response.status_code == 404  # other owners' jobs are indistinguishable from missing ones


def test_compare_rejects_images_of_different_sizes(
    live_service: LiveService, cylinder_job: RenderedJob
) -> None:
    small = live_service.render(cylinder_scene(width=12, height=12, spp=1), "small")
    response = live_service.get("/v1/compare", a=cylinder_job.job_id, b=small, mode="abs")
    assert response.status_code == 422 and response.json()["detail"].startswith("b: ")


def test_examples_endpoint_serves_every_example(live_service: LiveService) -> None:
    files = sorted(p.name for p in (REPO_ROOT / "schemas" / "examples").glob("*.json"))
    listed = live_service.get("/v1/examples").json()
    assert sorted(e["name"] for e in listed) == files  # the gallery's scenes first (test_gallery_examples)
    scene = live_service.get(f"/v1/examples/{files[0]}").json()
    assert scene == json.loads((REPO_ROOT / "schemas" / "examples" / files[0]).read_text())
    assert live_service.get("/v1/examples/none.json").status_code == 404


def test_decoded_image_cache_is_bounded_and_reuses_entries(
    live_service: LiveService, cylinder_job: RenderedJob, cylinder_job_reseeded: RenderedJob
) -> None:
    cache = DecodedImageCache(FilesystemStore(live_service.data_dir / "artifacts"), max_images=1)
    first = cache.get(cylinder_job.job_id)
    assert cache.get(cylinder_job.job_id) is first  # a hit returns the same decoded object
    cache.get(cylinder_job_reseeded.job_id)
    assert len(cache) == 1
    assert cache.get(cylinder_job.job_id) is not first  # evicted, decoded again


def test_index_and_static_files_are_served(live_service: LiveService) -> None:
    import httpx

    index = httpx.get(live_service.base_url + "/", timeout=10)
    assert index.status_code == 200 and '<script type="module" src="/web/js/main.js">' in index.text
    module = httpx.get(live_service.base_url + "/web/js/compare.js", timeout=10)
    assert module.status_code == 200 and "export async function mountCompare" in module.text


def test_downsample_block_means_with_partial_edge_blocks() -> None:
    from service.viewer_data import downsample

    values = np.arange(5 * 7, dtype=np.float32).reshape(5, 7)
    got = downsample(values, 3, average=True)
    # Independent: mean of each 3×3 block clipped at the edges (rows 0-2, 3-4; columns 0-2, 3-5, 6).
    expected = np.array(
        [[values[r : r + 3, c : c + 3].mean() for c in range(0, 7, 3)] for r in range(0, 5, 3)]
    )
    np.testing.assert_allclose(got, expected, rtol=1e-6)
    np.testing.assert_array_equal(downsample(values, 3, average=False), values[::3, ::3])


def test_openapi_documents_the_viewer_endpoints(live_service: LiveService) -> None:
    import httpx

    paths = httpx.get(live_service.base_url + "/openapi.json", timeout=10).json()["paths"]
    for path in (
        "/v1/jobs/{job_id}/layers",
        "/v1/jobs/{job_id}/layers/{name}",
        "/v1/jobs/{job_id}/pixel",
        "/v1/jobs/{job_id}/display.png",
        "/v1/jobs/{job_id}/ellipses",
        "/v1/compare",
        "/v1/examples",
    ):
        assert "get" in paths[path], path
    assert "/" not in paths  # the web pages are not API


def test_diagonal_cylinder_gives_45_degree_ellipses(
    live_service: LiveService, diagonal_cylinder_job: RenderedJob
) -> None:
    grid = live_service.get(f"/v1/jobs/{diagonal_cylinder_job.job_id}/ellipses", spacing=6).json()["ellipses"]
    assert len(grid) >= 8
    for ellipse in grid:
        # ℓ₁ ∥ d × (x̂ + ẑ)/√2 projects onto the image diagonal (1, 1) (conftest): angle π/4 (mod π).
        assert abs(math.remainder(ellipse["angle"] - math.pi / 4, math.pi)) < 1e-3


def test_diagnostics_exr_holds_the_coherence_channels(
    live_service: LiveService, cylinder_job: RenderedJob, tmp_path: Any
) -> None:
    from hgcore.artifacts.exr import read_exr

    response = live_service.get(f"/v1/jobs/{cylinder_job.job_id}/diagnostics.exr")
    assert response.status_code == 200 and response.headers["content-type"] == "image/x-exr"
    (tmp_path / "d.exr").write_bytes(response.content)
    channels = read_exr(tmp_path / "d.exr").channels
    expected = {n for n in cylinder_job.exr.channels if n.startswith("coherence.")}
    assert set(channels) == expected and "coherence.l1_um" in expected
    for name in expected:
        np.testing.assert_array_equal(channels[name], cylinder_job.exr.channels[name])


def test_one_band_image_has_an_exposure_and_refuses_colour_metrics() -> None:
    """A scene may render one band: no colour, so the RGB luminance rule gives the exposure and ΔE₀₀/ꟻLIP
    are refused by name instead of failing the catalogue."""
    from service.viewer_data import _decoded, difference_map

    rgb = np.full((4, 4), 0.25, dtype=np.float32)
    image = _decoded(4, 4, {"S0.550,000000nm": rgb, "R": rgb, "G": rgb, "B": rgb})
    assert image.exposure_ev() == pytest.approx(2.0)  # luminance 0.25 → ×4 is white
    with pytest.raises(ValueError, match=r"^mode: de2000 needs at least 2 spectral bands"):
        difference_map(image, image, "de2000")
