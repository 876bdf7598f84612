"""Image textures on material parameters: lookups, wrap and filter modes, UVs, renders, limits and errors.

Independent checks: the kernels' lookups against a NumPy reference of wrapped bilinear/nearest filtering
written here from the definitions (``worker.render.textures`` module docstring); Mitsuba's own ``srgb``
coefficients; a rendered card against its texture; a uniform texture against the constant parameter it
stands for (bitwise where the arithmetic is the same); texture coordinates of every source (rectangles,
inline meshes, OBJ ``vt``, PLY ``u, v``) by ray casts at known points.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hgcore.colour import xyz_to_linear_srgb, y_bar_integral_nm
from hgcore.optics.spectra import cie_cmf, cie_illuminant
from hgcore.settings import SceneLimits
from schemas.errors import SceneError
from schemas.scene import ImageTexture
from schemas.textures import check_scene_images
from schemas.validation import validate_scene
from tests.support.exr import read_channels, spectral_stack
from tests.support.images import linear_to_srgb, write_image
from worker.mitsuba_setup import configured_mitsuba
from worker.render.chunks import ChunkSpec, render_chunk, render_scene, renderer_for
from worker.render.scene_compiler import SceneCompiler
from worker.render.textures import TextureKernels, TextureTable, coefficient_table, srgb_to_linear


def texture(path: str = "t.exr", **fields: Any) -> ImageTexture:
    return ImageTexture.model_validate({"type": "image", "path": path, **fields})


# ------------------------------------------------------------------------------------------ lookups
def reference_lookup(values: np.ndarray, u: np.ndarray, v: np.ndarray, wrap: tuple[str, str], nearest: bool):
    """Filtered values of a (H, W) image at (u, v): origin bottom-left, v up, texel centres at half
    integers; each axis wrapped by its mode. Written from the definitions, independently of the kernels."""
    height, width = values.shape

    def axis(coordinate: np.ndarray, size: int, mode: str) -> tuple[list[np.ndarray], list[np.ndarray]]:
        position = coordinate * size - (0.0 if nearest else 0.5)
        base = np.floor(position)
        fraction = np.zeros_like(position) if nearest else position - base
        indices, weights = [], []
        for offset, weight in ((0, 1.0 - fraction), (1, fraction)):
            i = (base + offset).astype(np.int64)
            inside = np.ones(i.shape, bool)
            if mode == "repeat":
                i = np.mod(i, size)
            elif mode == "clamp":
                i = np.clip(i, 0, size - 1)
            elif mode == "mirror":
                period = np.mod(i, 2 * size)
                i = np.where(period < size, period, 2 * size - 1 - period)
            else:  # black
                inside = (i >= 0) & (i < size)
                i = np.clip(i, 0, size - 1)
            indices.append(i)
            weights.append(np.where(inside, weight, 0.0))
        return indices, weights

    columns, column_weights = axis(u, width, wrap[0])
    rows, row_weights = axis(1.0 - v, height, wrap[1])
    result = np.zeros_like(u)
    for row, row_weight in zip(rows, row_weights, strict=True):
        for column, column_weight in zip(columns, column_weights, strict=True):
            result += row_weight * column_weight * values[row, column]
    return result


@pytest.fixture(scope="module")
def mi() -> Any:
    return configured_mitsuba()


@pytest.mark.parametrize("wrap_u", ["repeat", "clamp", "mirror", "black"])
@pytest.mark.parametrize("filter_name", ["bilinear", "nearest"])
def test_scalar_lookup_matches_the_reference_filter_for_every_wrap_mode(
    mi: Any, wrap_u: str, filter_name: str
):
    image = np.random.default_rng(1).uniform(0.0, 1.0, size=(5, 7)).astype(np.float32)
    rgba = np.zeros((5, 7, 4), np.float32)
    rgba[..., 0] = image
    table = TextureTable()
    wrap_v = {"repeat": "mirror", "clamp": "black", "mirror": "repeat", "black": "clamp"}[wrap_u]
    binding, _, _ = table.add_scalar(
        texture(wrap_u=wrap_u, wrap_v=wrap_v, filter=filter_name), rgba, unit=1.0, low=-10.0, high=10.0
    )
    kernels = TextureKernels(mi, table)
    rng = np.random.default_rng(2)
    u, v = rng.uniform(-2.5, 3.5, 4000), rng.uniform(-2.5, 3.5, 4000)
    looked_up = kernels.scalar(mi.UInt32(binding), mi.Point2f(u, v), mi.Bool(True))
    expected = reference_lookup(image, u, v, (wrap_u, wrap_v), filter_name == "nearest")
    # float32 texel coordinates: ≤ |u|·W·2⁻²⁴ ≈ 1.5e-6 of a texel, times the largest texel step (≤ 1)
    np.testing.assert_allclose(np.asarray(looked_up), expected, atol=2e-5)


def test_uv_transform_scales_rotates_then_offsets(mi: Any) -> None:
    image = np.random.default_rng(3).uniform(0.0, 1.0, size=(6, 6)).astype(np.float32)
    rgba = np.zeros((6, 6, 4), np.float32)
    rgba[..., 0] = image
    table = TextureTable()
    transform = {"scale": [2.0, 0.5], "offset": [0.1, -0.3], "rotation_deg": 30.0}
    binding, _, _ = table.add_scalar(texture(uv_transform=transform), rgba, 1.0, -10.0, 10.0)
    u, v = np.random.default_rng(4).uniform(0.0, 1.0, (2, 500))
    looked_up = TextureKernels(mi, table).scalar(mi.UInt32(binding), mi.Point2f(u, v), mi.Bool(True))
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    su, sv = 2.0 * u, 0.5 * v
    expected = reference_lookup(image, c * su - s * sv + 0.1, s * su + c * sv - 0.3, ("repeat",) * 2, False)
    np.testing.assert_allclose(np.asarray(looked_up), expected, atol=2e-5)


def test_scalar_scale_offset_unit_and_clip(mi: Any) -> None:
    rgba = np.zeros((1, 4, 4), np.float32)
    rgba[0, :, 1] = [0.0, 0.25, 0.5, 1.0]  # the green channel
    table = TextureTable()
    binding, low, high = table.add_scalar(
        texture(channel="g", scale=2.0, offset=-0.2, filter="nearest"), rgba, 1e-6, 0.0, 1.5e-6
    )
    assert (low, high) == (0.0, 1.5e-6)  # −0.2 µm clipped to 0, 1.8 µm to 1.5 µm
    u = (np.arange(4) + 0.5) / 4
    values = TextureKernels(mi, table).scalar(mi.UInt32(binding), mi.Point2f(u, 0.5), mi.Bool(True))
    np.testing.assert_allclose(np.asarray(values), [0.0, 0.3e-6, 0.8e-6, 1.5e-6], rtol=1e-6, atol=1e-13)


def test_colour_lookup_is_the_texel_spectrum_and_round_trips_through_d65(mi: Any) -> None:
    colours = np.array([[0.8, 0.2, 0.1], [0.1, 0.6, 0.3], [0.2, 0.3, 0.9], [0.5, 0.5, 0.5]], np.float32)
    rgba = np.ones((1, 4, 4), np.float32)
    rgba[0, :, :3] = colours
    table = TextureTable(coefficients=coefficient_table())
    binding, _ = table.add_colour(texture(filter="nearest"), rgba)
    kernels = TextureKernels(mi, table)
    wavelengths = np.arange(360.0, 831.0, 1.0)
    spectra = []
    for column in range(4):
        u = np.full(wavelengths.size // 4 + 1, (column + 0.5) / 4)
        lanes = np.resize(wavelengths, (4, u.size))
        value = kernels.reflectance(
            mi.UInt32(binding),
            mi.Point2f(u, 0.5),
            mi.Spectrum(*(mi.Float(row) for row in lanes)),
            mi.Bool(True),
        )
        spectra.append(np.asarray(value).ravel()[: wavelengths.size])
    weights = cie_illuminant("d65", wavelengths)
    weights[[0, -1]] *= 0.5
    cmf = cie_cmf(wavelengths)
    rgb = xyz_to_linear_srgb((np.asarray(spectra) * weights) @ cmf / float(weights @ cmf[:, 1]))
    np.testing.assert_allclose(rgb, colours, atol=1e-3)  # float32 kernels + the 1 nm integral


def test_coefficient_table_fetch_equals_mitsubas(mi: Any) -> None:
    colours = np.random.default_rng(5).uniform(0.0, 1.0, (20, 3))
    ours = coefficient_table().fetch(colours)
    theirs = np.array([list(mi.srgb_model_fetch(mi.ScalarColor3f(*c))) for c in colours])
    np.testing.assert_allclose(ours, theirs, rtol=1e-5, atol=1e-6)


def test_srgb_decoding_is_the_standard_curve() -> None:
    encoded = np.array([0.0, 0.04045, 0.5, 1.0])
    np.testing.assert_allclose(srgb_to_linear(encoded), [0.0, 0.04045 / 12.92, 0.2140411, 1.0], rtol=1e-6)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(np.linspace(0, 1, 11))), np.linspace(0, 1, 11))


# ------------------------------------------------------------------------------------------ scenes
def card_scene(material: dict[str, Any], **film: Any) -> dict[str, Any]:
    """A 1.2 × 0.6 m card facing the camera (u across, v up) under a uniform dome of D65."""
    return {
        "schema": "hgrender/scene/v1",
        "name": "card",
        "camera": {"origin_m": [0, 0, 1.6], "target_m": [0, 0, 0], "fov_deg": 40.0},
        "film": {"width": 32, "height": 16, "spp": 16, "bands": 8, "max_depth": 2, **film},
        "materials": {"card": material},
        "shapes": [
            {
                "type": "rectangle",
                "material": "card",
                "center_m": [0, 0, 0],
                "normal": [0, 0, 1],
                "up": [0, 1, 0],
                "width_m": 1.2,
                "height_m": 0.6,
            }
        ],
        "emitters": [{"type": "environment", "spectrum": {"type": "d65"}, "radiance_scale": 1.0}],
    }


def card_pixels(scene: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Boolean mask of the pixels whose centres see the card, and the card's (u, v) there (pinhole)."""
    camera, film = scene["camera"], scene["film"]
    width, height = film["width"], film["height"]
    half = math.tan(math.radians(camera["fov_deg"]) / 2.0)
    x = ((np.arange(width) + 0.5) / width * 2.0 - 1.0) * half
    y = (1.0 - (np.arange(height) + 0.5) / height * 2.0) * half * height / width
    distance = camera["origin_m"][2]
    px, py = np.meshgrid(x * distance, y * distance)
    u, v = px / 1.2 + 0.5, py / 0.6 + 0.5
    return (np.abs(u - 0.5) < 0.45) & (np.abs(v - 0.5) < 0.45), np.stack([u, v], axis=-1)


def test_a_rendered_card_shows_its_texture(tmp_path: Path) -> None:
    # 4 × 2 texels of distinct colours, an sRGB-encoded PNG; the card under a uniform D65 dome has radiance
    # ρ(λ)·D65(λ), whose linear sRGB is the texel's colour times Y of the dome (the upsampling's round trip).
    colours = np.array(
        [[[0.8, 0.1, 0.1], [0.1, 0.7, 0.2], [0.1, 0.2, 0.8], [0.9, 0.9, 0.2]],
         [[0.2, 0.2, 0.2], [0.6, 0.3, 0.7], [0.9, 0.6, 0.4], [0.05, 0.4, 0.5]]]
    )  # fmt: skip
    encoded = np.round(linear_to_srgb(colours) * 255).astype(np.uint8)
    write_image(tmp_path / "colours.png", encoded)
    texels = srgb_to_linear(encoded / 255.0)
    scene = card_scene(
        {"type": "diffuse", "reflectance": {"type": "image", "path": "colours.png", "filter": "nearest"}},
        width=48,
        height=24,
        spp=64,
        bands=32,
    )
    render_scene(validate_scene(scene), tmp_path / "out", bundle_dir=tmp_path)
    channels = read_channels(tmp_path / "out" / "image.exr")
    rendered = np.stack([channels[c] for c in "RGB"], axis=-1)
    grid = np.arange(380.0, 780.5, 0.5)
    dome = cie_illuminant("d65", grid) / float(cie_illuminant("d65", 560.0))
    dome_y = np.trapezoid(dome * cie_cmf(grid)[:, 1], grid) / y_bar_integral_nm()
    inside, uv = card_pixels(scene)
    column = np.clip((uv[..., 0] * 4).astype(int), 0, 3)
    row = np.clip(((1.0 - uv[..., 1]) * 2).astype(int), 0, 1)
    # Pixels whose footprint lies in one texel: away from the texel borders by a pixel (1/24 of v, 1/48 of u).
    fu, fv = uv[..., 0] * 4 % 1.0, (1.0 - uv[..., 1]) * 2 % 1.0
    clean = inside & (np.abs(fu - 0.5) < 0.5 - 4 / 48) & (np.abs(fv - 0.5) < 0.5 - 2 / 24)
    means, errors = np.zeros((2, 4, 3)), np.zeros((2, 4, 3))
    for r in range(2):
        for c in range(4):
            block = clean & (row == r) & (column == c)
            assert block.sum() >= 40
            means[r, c] = rendered[block].mean(axis=0)
            errors[r, c] = rendered[block].std(axis=0, ddof=1) / np.sqrt(block.sum())
    expected = texels * dome_y
    assert np.corrcoef(expected.ravel(), means.ravel())[0, 1] > 0.999
    # each texel's pixels: within 4 SE (64 spp) plus 1 % (32 bands' colour integration; edges = the bands')
    np.testing.assert_array_less(np.abs(means - expected), 4.0 * errors + 0.01 * expected + 1e-9)


def film_card(thickness: Any) -> dict[str, Any]:
    return card_scene(
        {
            "type": "thin_film",
            "film_thickness_um": thickness,
            "film_ior": 1.4,
            "substrate": {"conductor": "Ag"},
            "roughness_rms_um": 0.02,
        },
        spp=8,
    )


def render_bands(tmp_path: Path, scene: dict[str, Any], name: str) -> np.ndarray:
    out = tmp_path / name
    render_scene(validate_scene(scene), out, bundle_dir=tmp_path)
    return spectral_stack(read_channels(out / "image.exr"))[1]


def test_a_uniform_thickness_texture_renders_bitwise_the_constant_film(tmp_path: Path) -> None:
    # Nearest filtering reads one texel with weight 1: the same τ (float32) as the material table's, so the
    # same shear, phase and terms at every vertex: the images are equal bit for bit.
    write_image(tmp_path / "tau.exr", np.full((4, 4, 1), 0.45, np.float32))
    textured = render_bands(
        tmp_path, film_card({"type": "image", "path": "tau.exr", "filter": "nearest"}), "t"
    )
    constant = render_bands(tmp_path, film_card(0.45), "c")
    assert np.array_equal(textured, constant)


def test_each_half_of_a_two_thickness_texture_renders_its_constant_film(tmp_path: Path) -> None:
    # Left half 0.3 µm, right half 0.6 µm (one texel each, nearest): the local thickness sets the local
    # phase and shear, so each half is bitwise the render of a card of that constant thickness.
    write_image(tmp_path / "halves.exr", np.array([[[0.3], [0.6]]], np.float32))
    thickness = {"type": "image", "path": "halves.exr", "filter": "nearest", "wrap_u": "clamp"}
    textured = render_bands(tmp_path, film_card(thickness), "t")
    thin, thick = render_bands(tmp_path, film_card(0.3), "a"), render_bands(tmp_path, film_card(0.6), "b")
    inside, uv = card_pixels(film_card(0.3))
    left = inside & (uv[..., 0] < 0.48)
    right = inside & (uv[..., 0] > 0.52)
    assert np.array_equal(textured[left], thin[left]) and np.array_equal(textured[right], thick[right])
    # and the two thicknesses do render differently (band means 2.6 % apart on silver under the dome)
    assert np.abs(thin[left].mean(axis=0) / thick[left].mean(axis=0) - 1.0).max() > 0.01


def test_uniform_roughness_textures_render_the_constant_surface(tmp_path: Path) -> None:
    # σ and ℓ_c per lane instead of compiled-in constants: float32 arithmetic of the same formulas (σ), and
    # P(θ, ℓ_c/λ) from the ratio table instead of the λ table (ℓ_c); both bilinear tables agree with the
    # integral to 2e-3 (tests/optics/test_rough_surface.py), so band means agree to ~1e-3.
    write_image(tmp_path / "sigma.exr", np.full((2, 2, 1), 0.12, np.float32))
    write_image(tmp_path / "ell.exr", np.full((2, 2, 1), 2.5, np.float32))

    def metal(sigma: Any, ell: Any) -> dict[str, Any]:
        material = {"type": "rough_conductor", "conductor": "Au", "roughness_rms_um": sigma}
        return card_scene(material | {"correlation_length_um": ell}, spp=8)

    constant = render_bands(tmp_path, metal(0.12, 2.5), "c").mean(axis=(0, 1))
    sigma = {"type": "image", "path": "sigma.exr"}
    ell = {"type": "image", "path": "ell.exr"}
    for name, scene in (("s", metal(sigma, 2.5)), ("l", metal(0.12, ell)), ("sl", metal(sigma, ell))):
        np.testing.assert_allclose(render_bands(tmp_path, scene, name).mean(axis=(0, 1)), constant, rtol=3e-3)


# ------------------------------------------------------------------------------------------ UVs
def test_texture_coordinates_of_every_source_have_their_origin_bottom_left(tmp_path: Path) -> None:
    # A unit quad in the z = 0 plane with uv = (x, y): rays at (0.25, 0.75) must report uv (0.25, 0.75)
    # for a rectangle, an inline mesh, an OBJ file (vt) and PLY files (u, v and s, t).
    quad = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    (tmp_path / "quad.obj").write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in quad)
        + "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
    )
    (tmp_path / "quad.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "property float u\nproperty float v\nelement face 2\nproperty list uchar int vertex_indices\n"
        "end_header\n" + "".join(f"{x} {y} {z} {x} {y}\n" for x, y, z in quad) + "3 0 1 2\n3 0 2 3\n"
    )
    ply = (tmp_path / "quad.ply").read_text()
    (tmp_path / "quad_st.ply").write_text(
        ply.replace("float u\n", "float s\n").replace("float v\n", "float t\n")
    )
    shapes = [
        {"type": "rectangle", "center_m": [0.5, 0.5, 0], "normal": [0, 0, 1], "up": [0, 1, 0], "width_m": 1,
         "height_m": 1},
        {"type": "mesh", "vertices_m": quad, "indices": [[0, 1, 2], [0, 2, 3]], "uvs": [q[:2] for q in quad]},
        {"type": "mesh_file", "path": "quad.obj"},
        {"type": "mesh_file", "path": "quad.ply"},
        {"type": "mesh_file", "path": "quad_st.ply"},
    ]  # fmt: skip
    mi = configured_mitsuba()
    write_image(tmp_path / "t.png", np.zeros((2, 2, 3), np.uint8))
    for shape in shapes:
        scene = card_scene({"type": "diffuse", "reflectance": {"type": "image", "path": "t.png"}})
        scene["shapes"] = [shape | {"material": "card"}]
        compiled = SceneCompiler(mi, tmp_path, limits=SceneLimits()).compile(validate_scene(scene))
        loaded = mi.load_dict(compiled.mitsuba_dict, optimize=False)
        x, y = np.array([0.25, 0.7]), np.array([0.75, 0.1])
        ray = mi.Ray3f(mi.Point3f(x, y, 1.0), mi.Vector3f(0, 0, -1))
        uv = np.asarray(loaded.ray_intersect(ray).uv)
        np.testing.assert_allclose(uv, np.stack([x, y]), atol=1e-6, err_msg=shape["type"])


def test_a_mesh_reads_the_uv_set_its_textures_name(tmp_path: Path) -> None:
    mi = configured_mitsuba()
    write_image(tmp_path / "t.png", np.zeros((2, 2, 3), np.uint8))
    quad = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    mesh = {"type": "mesh", "material": "card", "vertices_m": quad, "indices": [[0, 1, 2], [0, 2, 3]],
            "uvs": [[0, 0]] * 4, "uv_sets": {"detail": [[2 * x, 3 * y] for x, y, _ in quad]}}  # fmt: skip
    scene = card_scene(
        {"type": "diffuse", "reflectance": {"type": "image", "path": "t.png", "uv_set": "detail"}}
    )
    scene["shapes"] = [mesh]
    loaded = mi.load_dict(
        SceneCompiler(mi, tmp_path, limits=SceneLimits()).compile(validate_scene(scene)).mitsuba_dict
    )
    uv = np.asarray(loaded.ray_intersect(mi.Ray3f(mi.Point3f(0.5, 0.25, 1), mi.Vector3f(0, 0, -1))).uv)
    np.testing.assert_allclose(uv.ravel(), [1.0, 0.75], atol=1e-6)
    scene["materials"]["card"]["reflectance"]["uv_set"] = "missing"
    with pytest.raises(
        ValueError, match=r"/materials/card/reflectance/uv_set: shape /shapes/0 has no uv set 'missing'"
    ):
        SceneCompiler(mi, tmp_path, limits=SceneLimits()).compile(validate_scene(scene))


# ------------------------------------------------------------------------------------------ limits
def textured(image: str, emitter: dict[str, Any] | None = None) -> dict[str, Any]:
    scene = card_scene({"type": "diffuse", "reflectance": {"type": "image", "path": image}})
    if emitter is not None:
        scene["emitters"] = [emitter]
    return scene


def problem_of(call: Any) -> tuple[str, str]:
    with pytest.raises(SceneError) as caught:
        call()
    return caught.value.problems[0]["pointer"], caught.value.problems[0]["message"]


def test_missing_unreadable_and_escaping_images_are_named(tmp_path: Path) -> None:
    pointer, message = problem_of(lambda: check_scene_images(validate_scene(textured("gone.png")), tmp_path))
    assert (
        pointer == "/materials/card/reflectance/path" and "'gone.png' is not a file in the bundle" in message
    )
    (tmp_path / "broken.png").write_bytes(b"not an image at all")
    pointer, message = problem_of(
        lambda: check_scene_images(validate_scene(textured("broken.png")), tmp_path)
    )
    assert pointer == "/materials/card/reflectance/path" and message.startswith(
        "cannot read image 'broken.png'"
    )
    pointer, message = problem_of(lambda: validate_scene(textured("../outside.png")))
    assert pointer == "/materials/card/reflectance/path" and "stay inside the bundle" in message
    pointer, message = problem_of(lambda: validate_scene(textured("notes.txt")))
    assert pointer == "/materials/card/reflectance/path" and ".png" in message
    environment = {"type": "environment", "path": "sky.exr"}
    pointer, message = problem_of(
        lambda: check_scene_images(validate_scene(textured("broken.png", environment)), tmp_path)
    )
    assert pointer == "/materials/card/reflectance/path"  # materials first, then emitters
    write_image(tmp_path / "ok.png", np.zeros((2, 2, 3), np.uint8))
    pointer, message = problem_of(
        lambda: check_scene_images(validate_scene(textured("ok.png", environment)), tmp_path)
    )
    assert pointer == "/emitters/0/path" and "'sky.exr' is not a file" in message


def test_texture_limits_name_the_field_and_the_setting(tmp_path: Path) -> None:
    write_image(tmp_path / "big.png", np.zeros((40, 50, 3), np.uint8))
    scene = validate_scene(textured("big.png"))
    pointer, message = problem_of(
        lambda: check_scene_images(scene, tmp_path, SceneLimits(max_texture_pixels=1999))
    )
    assert pointer == "/materials/card/reflectance/path"
    assert "50×40 pixels exceeds the limit of 1999 (HGRENDER_MAX_TEXTURE_PIXELS)" in message
    pointer, message = problem_of(
        lambda: check_scene_images(scene, tmp_path, SceneLimits(max_texture_bytes=23999))
    )
    assert "images decode to 24000 bytes" in message and "HGRENDER_MAX_TEXTURE_BYTES" in message
    pointer, message = problem_of(lambda: check_scene_images(scene, tmp_path, SceneLimits(max_file_bytes=10)))
    assert "HGRENDER_MAX_FILE_BYTES" in message
    document = textured("a.png")
    document["materials"]["other"] = {"type": "mirror", "tint": {"type": "image", "path": "b.png"}}
    pointer, message = problem_of(lambda: validate_scene(document, SceneLimits(max_textures=1)))
    assert pointer == "/materials/other/tint/path"
    assert message == "image count 2 exceeds the limit of 1 (HGRENDER_MAX_TEXTURES)"


def test_a_render_checks_images_against_the_limits_it_is_given(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The renderer's compile checks images against the process's settings it is passed (a worker's),
    never against ``HGRENDER_*`` variables it would read itself; a scene compiled under other limits is
    compiled again."""
    write_image(tmp_path / "big.png", np.zeros((40, 50, 3), np.uint8))
    scene = validate_scene(textured("big.png"), SceneLimits(max_texture_pixels=2000))
    monkeypatch.setenv("HGRENDER_MAX_TEXTURE_PIXELS", "1999")  # the environment would refuse the image
    renderer = renderer_for(scene, tmp_path, limits=SceneLimits(max_texture_pixels=2000))
    assert renderer.width == 32
    monkeypatch.setenv("HGRENDER_MAX_TEXTURE_PIXELS", "2000")  # and now would accept it
    chunk = ChunkSpec(index=0, spp=1, seed=0)
    strict = SceneLimits(max_texture_pixels=1999)
    pointer, message = problem_of(
        lambda: render_chunk(scene, chunk, tmp_path / "c.npz", bundle_dir=tmp_path, limits=strict)
    )
    assert pointer == "/materials/card/reflectance/path"
    assert "exceeds the limit of 1999 (HGRENDER_MAX_TEXTURE_PIXELS)" in message
    _, message = problem_of(lambda: render_scene(scene, tmp_path / "out", bundle_dir=tmp_path, limits=strict))
    assert "exceeds the limit of 1999" in message


def test_a_scalar_parameter_reads_one_channel() -> None:
    document = film_card({"type": "image", "path": "tau.exr", "channel": "rgb"})
    pointer, message = problem_of(lambda: validate_scene(document))
    assert pointer == "/materials/card/film_thickness_um"
    assert "a scalar parameter reads one channel" in message


def test_a_textured_correlation_length_reads_the_propagating_fraction_of_its_ratio(tmp_path: Path) -> None:
    # P(θ, ℓ_c/λ) interpolated bilinearly in (x(sin θ), ln ℓ_c/λ) against the integral it tabulates
    # (hgcore.optics.rough_surface.propagating_fraction), at random points between the nodes: within 2e-3,
    # the error bound of the per-surface (θ, λ) table it replaces for textured surfaces (measured 4.7e-4).
    from hgcore.optics.array_ops import NUMPY
    from hgcore.optics.rough_surface import RoughSurface, propagating_fraction
    from worker.render.bsdfs.rough_conductor import RoughConductor
    from worker.render.renderer import Renderer

    write_image(tmp_path / "ell.exr", np.linspace(1.0, 6.0, 16, dtype=np.float32).reshape(1, 16, 1))
    material = {"type": "rough_conductor", "conductor": "Al", "roughness_rms_um": 0.1, "psd": "abc"}
    material["correlation_length_um"] = {"type": "image", "path": "ell.exr"}
    mi = configured_mitsuba()
    renderer = Renderer(
        SceneCompiler(mi, tmp_path, limits=SceneLimits()).compile(validate_scene(card_scene(material)))
    )
    branch = next(b for b in renderer.integrator.kernels.branches if isinstance(b, RoughConductor))
    rng = np.random.default_rng(8)
    sin_theta, wavelength_nm = rng.uniform(0.0, 0.97, 3000), rng.uniform(380.0, 780.0, 3000)
    ell_m = rng.uniform(1.0e-6, 6.0e-6, 3000)
    surface = branch.model.local(0.1e-6, mi.Float(ell_m))
    looked_up = branch._reflection_fraction(mi.Float(sin_theta), mi.Float(wavelength_nm), surface)
    exact = propagating_fraction(
        RoughSurface(0.1e-6, 1e-6, "abc", 2.0).local(0.1e-6, ell_m), sin_theta, wavelength_nm * 1e-9, NUMPY,
        reflection=True,
    )  # fmt: skip
    assert np.abs(np.asarray(looked_up) - exact).max() < 2e-3
