"""The hgrender scene model, schema ``hgrender/scene/v1`` (pydantic v2).

One model for both front ends: JSON scenes validate straight into :class:`Scene`; USD stages are
converted into it by :mod:`schemas.usd_import`. The renderer compiles it to Mitsuba
(``worker/render/scene_compiler.py``).

Units are part of every field name: metres for geometry (``_m``), nanometres for wavelengths
(``_nm``), micrometres for film thickness, grating pitch, surface roughness and correlation length
(``_um``), degrees (``_deg``), kelvin (``_k``), watts (``_w``), millimetres for camera optics (``_mm``).
Vectors are 3-element lists ``[x, y, z]`` in a right-handed world with +Y up.

Radiometry of emitters (see docs/scenes.md): an emitter's spectral radiance is
``L(λ) = c · spectrum(λ)`` in W·m⁻²·sr⁻¹·nm⁻¹, uniform over its surface and Lambertian. Either
``radiance_scale`` gives ``c`` directly, or ``power_w`` fixes ``c`` by the total radiant power over the
film's wavelength range, ``power_w = π · A · c · ∫_{λmin}^{λmax} spectrum(λ) dλ`` (A: emitting area).

Strictness: unknown fields are rejected (``extra="forbid"``), floats must be finite, strings are not
coerced to numbers. :func:`schemas.validation.validate_scene` turns every error into a JSON pointer.
"""

from __future__ import annotations

import itertools
import math
import re
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from hgcore.errors import InputError

SCHEMA_ID = "hgrender/scene/v1"

#: Material ids (keys of ``Scene.materials``) — safe as file names, URL parts and USD ``hg:id`` values.
MATERIAL_ID_PATTERN = r"^[A-Za-z0-9_.-]{1,64}$"

#: Hard caps built into the schema; the deployment limits in :class:`hgcore.settings.SceneLimits` are lower.
ABSOLUTE_MAX_RESOLUTION_PX = 16384
ABSOLUTE_MAX_SPP = 1 << 20
MAX_FILM_MODES = 16
"""The most HG modes a film may ask for (``film.modes``)."""


class StrictModel(BaseModel):
    """Base of every scene model: unknown fields rejected, finite floats, no string→number coercion."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True, frozen=False)


# --- scalar and vector types ---------------------------------------------------------------------

PositiveFloat = Annotated[float, Field(gt=0.0)]
NonNegativeFloat = Annotated[float, Field(ge=0.0)]
UnitInterval = Annotated[float, Field(ge=0.0, le=1.0)]
Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Matrix4 = Annotated[
    list[Annotated[list[float], Field(min_length=4, max_length=4)]], Field(min_length=4, max_length=4)
]
ConductorName = Literal["Ag", "Au", "Cu", "Al"]
GlassName = Literal["bk7", "fused_silica", "water"]
#: A refractive index: a real number ≥ 1 or a named dispersive glass (Sellmeier / tabulated in the worker).
RefractiveIndex = Annotated[float, Field(ge=1.0, le=10.0)] | GlassName
PsdModel = Literal["gaussian", "abc"]


def _check_direction(value: list[float], field_name: str) -> list[float]:
    """Directions (normals, up vectors, axes) need a non-zero length; they are normalised by consumers."""
    if math.fsum(c * c for c in value) <= 1e-24:
        raise InputError(f"{field_name} must be a non-zero vector")
    return value


def _check_affine_matrix(matrix: list[list[float]], field_name: str) -> list[list[float]]:
    """A 4x4 row-major matrix acting on column vectors; it must be affine and invertible."""
    if any(abs(a - b) > 1e-12 for a, b in zip(matrix[3], (0.0, 0.0, 0.0, 1.0), strict=True)):
        raise InputError(f"{field_name} last row must be [0, 0, 0, 1] (affine transform)")
    (a, b, c), (d, e, f), (g, h, i) = (row[:3] for row in matrix[:3])
    determinant = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if abs(determinant) < 1e-18:
        raise InputError(f"{field_name} is singular (determinant {determinant:g})")
    return matrix


# --- spectra -------------------------------------------------------------------------------------


class ConstantSpectrum(StrictModel):
    """A wavelength-independent value (unitless reflectance or relative emission)."""

    type: Literal["constant"]
    value: NonNegativeFloat


class BlackbodySpectrum(StrictModel):
    """Planck's law B_λ(T) in W·m⁻²·sr⁻¹·nm⁻¹ at ``temperature_k`` kelvin."""

    type: Literal["blackbody"]
    temperature_k: Annotated[float, Field(gt=0.0, le=1e6)]


class D65Spectrum(StrictModel):
    """CIE standard illuminant D65, relative spectral power normalised to 1 at 560 nm."""

    type: Literal["d65"]


CieFName = Literal["F1", "F2", "F3", "F4", "F5", "F6", "F7", "F8", "F9", "F10", "F11", "F12"]


class CieFSpectrum(StrictModel):
    """CIE fluorescent illuminant F1..F12 (CIE 15:2004), relative power normalised to 1 at 560 nm."""

    type: Literal["cie_f"]
    name: CieFName


class TabulatedSpectrum(StrictModel):
    """Piecewise-linear spectrum through (wavelength nm, value) samples; zero outside the table."""

    type: Literal["tabulated"]
    wavelengths_nm: Annotated[list[Annotated[float, Field(gt=0.0)]], Field(min_length=2, max_length=10000)]
    values: Annotated[list[NonNegativeFloat], Field(min_length=2, max_length=10000)]

    @field_validator("wavelengths_nm")
    @classmethod
    def _increasing(cls, wavelengths_nm: list[float]) -> list[float]:
        if any(b <= a for a, b in itertools.pairwise(wavelengths_nm)):
            raise InputError("wavelengths_nm must be strictly increasing")
        return wavelengths_nm

    @model_validator(mode="after")
    def _same_length(self) -> TabulatedSpectrum:
        if len(self.values) != len(self.wavelengths_nm):
            raise InputError(
                f"values has {len(self.values)} entries but wavelengths_nm has {len(self.wavelengths_nm)}"
            )
        return self


Spectrum = Annotated[
    ConstantSpectrum | BlackbodySpectrum | D65Spectrum | CieFSpectrum | TabulatedSpectrum,
    Field(discriminator="type"),
]


# --- textures ------------------------------------------------------------------------------------

#: Image files a texture or an environment may name (decoded with OpenImageIO in the worker).
TEXTURE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr", ".hdr", ".tif", ".tiff")
#: How texture coordinates outside [0, 1] read the image, per axis: ``repeat`` (tile), ``clamp`` (edge
#: texels), ``mirror`` (tile, every other copy mirrored), ``black`` (0 outside): USD ``wrapS``/``wrapT``,
#: glTF ``wrapS``/``wrapT``.
WrapMode = Literal["repeat", "clamp", "mirror", "black"]
#: ``bilinear``: between the four nearest texel centres; ``nearest``: the texel the point falls in.
TextureFilter = Literal["bilinear", "nearest"]
#: How the image's values are decoded: ``srgb`` (the sRGB transfer curve, IEC 61966-2-1), ``linear`` (as
#: stored, USD ``raw``), ``auto`` (sRGB for 8- and 16-bit integer images, linear for float images: USD's).
ColorSpace = Literal["auto", "srgb", "linear"]
#: The image channel(s) a parameter reads: one of ``r``, ``g``, ``b``, ``a`` for a scalar (a one-channel
#: image gives the same value for r, g, b; an image without alpha has a = 1), ``rgb`` for a colour.
TextureChannel = Literal["r", "g", "b", "a", "rgb"]
UV_SET_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]{0,63}$"
Vec2 = Annotated[list[float], Field(min_length=2, max_length=2)]


class UvTransform(StrictModel):
    """An affine map of texture coordinates applied before the lookup: uv' = R(rotation_deg)·(scale ⊙ uv)
    + offset, R a counter-clockwise rotation in the (u, v) plane (v up): USD ``UsdTransform2d``'s and glTF
    ``KHR_texture_transform``'s order (scale, rotate, translate)."""

    scale: Vec2 = Field(default_factory=lambda: [1.0, 1.0])
    offset: Vec2 = Field(default_factory=lambda: [0.0, 0.0])
    rotation_deg: float = 0.0


class ImageTexture(StrictModel):
    """A material parameter read from an image of the bundle through a shape's texture coordinates.

    Texture coordinates (u, v) have their origin at the image's **bottom-left** corner and v pointing up
    (OBJ, USD ``st``, Blender); each texel covers a 1/width × 1/height cell. The decoded value x (``channel``
    of the image at (u', v') after ``uv_transform``, filtered and wrapped) becomes the parameter's value
    ``offset + scale · x`` in the parameter's own units (µm for a film thickness: ``offset`` the thinnest,
    ``offset + scale`` the thickest film of a [0, 1] image — the min/max mapping of glTF's
    ``KHR_materials_iridescence``); for a colour, per channel of linear sRGB (a number or [r, g, b]), then
    clipped to [0, 1] and turned into a reflectance spectrum (docs/scenes.md, "Textures"). Values outside a
    parameter's range are clipped to it. ``uv_set`` names the shape's texture coordinates (``st`` unless
    a mesh gives ``uv_sets``).
    """

    type: Literal["image"]
    path: Annotated[str, Field(min_length=1, max_length=255)]
    uv_set: Annotated[str, Field(pattern=UV_SET_PATTERN)] = "st"
    wrap_u: WrapMode = "repeat"
    wrap_v: WrapMode = "repeat"
    filter: TextureFilter = "bilinear"
    color_space: ColorSpace = "auto"
    channel: TextureChannel | None = None
    scale: (
        Annotated[float, Field(ge=-1e6, le=1e6)]
        | Annotated[list[Annotated[float, Field(ge=-1e6, le=1e6)]], Field(min_length=3, max_length=3)]
    ) = 1.0
    offset: (
        Annotated[float, Field(ge=-1e6, le=1e6)]
        | Annotated[list[Annotated[float, Field(ge=-1e6, le=1e6)]], Field(min_length=3, max_length=3)]
    ) = 0.0
    uv_transform: UvTransform | None = None

    @field_validator("path")
    @classmethod
    def _inside_bundle(cls, path: str) -> str:
        return check_bundle_relative_path(path, suffixes=TEXTURE_SUFFIXES)

    def check_scalar(self) -> ImageTexture:
        """A texture of a scalar parameter: one channel (default ``r``), scalar ``scale`` and ``offset``."""
        if self.channel == "rgb":
            raise InputError("channel: a scalar parameter reads one channel (r, g, b or a), not rgb")
        if isinstance(self.scale, list) or isinstance(self.offset, list):
            raise InputError("scale and offset of a scalar parameter's texture must be numbers")
        return self

    @property
    def scalar_channel(self) -> str:
        """The channel a scalar parameter reads (``r`` unless given)."""
        return self.channel or "r"

    @property
    def colour_channel(self) -> str:
        """The channel(s) a colour parameter reads (``rgb`` unless given; one channel is a grey)."""
        return self.channel or "rgb"


def _value_or_texture(value: Any) -> str:
    if isinstance(value, ImageTexture) or (isinstance(value, dict) and value.get("type") == "image"):
        return "texture"
    return "value"


def _scalar_texture(texture: ImageTexture) -> ImageTexture:
    return texture.check_scalar()


def Textured(value_type: Any) -> Any:
    """A scalar material parameter: a number of ``value_type`` or an ``ImageTexture`` of one channel."""
    return Annotated[
        Annotated[value_type, Tag("value")]
        | Annotated[ImageTexture, AfterValidator(_scalar_texture), Tag("texture")],
        Discriminator(_value_or_texture),
    ]


def _reflectance_kind(value: Any) -> str:
    if _value_or_texture(value) == "texture":
        return "texture"
    return "spectrum" if isinstance(value, dict | BaseModel) else "value"


#: A reflectance: a number in [0, 1], a spectrum (whose values should stay in [0, 1]) or a colour texture
#: (``ImageTexture``: linear sRGB upsampled to a spectrum, docs/scenes.md "Textures").
Reflectance = Annotated[
    Annotated[UnitInterval, Tag("value")]
    | Annotated[Spectrum, Tag("spectrum")]
    | Annotated[ImageTexture, Tag("texture")],
    Discriminator(_reflectance_kind),
]


# --- transforms ----------------------------------------------------------------------------------


class Transform(StrictModel):
    """An affine transform applied after a shape's own geometry.

    Either ``matrix`` (4x4, row-major, acting on column vectors ``p' = M·p``) or the TRS form
    ``p' = translate_m + R(rotate_axis, rotate_deg) · (scale ⊙ p)`` (scale first, then a right-handed
    rotation of ``rotate_deg`` degrees about ``rotate_axis``, then translation) — not both.
    """

    translate_m: Vec3 | None = None
    rotate_axis: Vec3 | None = None
    rotate_deg: float | None = None
    scale: PositiveFloat | Annotated[list[PositiveFloat], Field(min_length=3, max_length=3)] | None = None
    matrix: Matrix4 | None = None

    @model_validator(mode="after")
    def _one_form(self) -> Transform:
        trs_fields = ("translate_m", "rotate_axis", "rotate_deg", "scale")
        uses_trs = any(getattr(self, name) is not None for name in trs_fields)
        if self.matrix is not None:
            if uses_trs:
                raise InputError("matrix cannot be combined with translate_m/rotate_axis/rotate_deg/scale")
            _check_affine_matrix(self.matrix, "matrix")
        elif not uses_trs:
            raise InputError("transform needs matrix or at least one of translate_m, rotate_deg, scale")
        if (self.rotate_deg is None) != (self.rotate_axis is None):
            raise InputError("rotate_axis and rotate_deg must be given together")
        if self.rotate_axis is not None:
            _check_direction(self.rotate_axis, "rotate_axis")
        return self

    def to_matrix(self) -> list[list[float]]:
        """The equivalent 4x4 row-major matrix (Rodrigues' rotation formula for the TRS form)."""
        if self.matrix is not None:
            return [list(row) for row in self.matrix]
        scale = self.scale if self.scale is not None else 1.0
        sx, sy, sz = (scale, scale, scale) if isinstance(scale, float | int) else scale
        rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        if self.rotate_axis is not None and self.rotate_deg is not None:
            norm = math.sqrt(math.fsum(c * c for c in self.rotate_axis))
            x, y, z = (c / norm for c in self.rotate_axis)
            angle_rad = math.radians(self.rotate_deg)
            c, s = math.cos(angle_rad), math.sin(angle_rad)
            t = 1.0 - c
            rotation = [
                [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
                [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
                [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
            ]
        translate = self.translate_m if self.translate_m is not None else [0.0, 0.0, 0.0]
        return [
            [rotation[r][0] * sx, rotation[r][1] * sy, rotation[r][2] * sz, translate[r]] for r in range(3)
        ] + [[0.0, 0.0, 0.0, 1.0]]


# --- camera and film -----------------------------------------------------------------------------


class PerspectiveCamera(StrictModel):
    """A perspective camera: a pinhole, or a thin lens when ``aperture_radius_m`` > 0.

    Placement: ``origin_m`` + ``target_m`` + ``up`` (look-at), or ``to_world`` — a 4x4 row-major
    camera-to-world matrix in Mitsuba's camera convention (camera looks along local +Z, +Y is up,
    +X points to the image's left). Field of view: ``fov_deg`` (horizontal, degrees) or
    ``focal_length_mm`` + ``sensor_width_mm`` (horizontal fov = 2·atan(sensor_width / (2·focal_length)));
    when neither is given the horizontal fov is 40°.

    Thin lens (Mitsuba's ``thinlens``): a lens of radius ``aperture_radius_m`` centred on the origin,
    focused on the plane ``focus_distance_m`` in front of it along the view axis (default: the target's
    distance, for a look-at camera). A pixel then collects the cone of rays through the lens that meet at
    its point of that plane, so depth of field and the angular spread of the light a pixel receives
    (which sets the fringe visibility of a smooth film it sees, docs/physics_interactions.md §3) follow
    from the aperture. 0 is a pinhole (the default).
    """

    type: Literal["perspective"] = "perspective"
    origin_m: Vec3 | None = None
    target_m: Vec3 | None = None
    up: Vec3 = Field(default_factory=lambda: [0.0, 1.0, 0.0])
    to_world: Matrix4 | None = None
    fov_deg: Annotated[float, Field(gt=0.0, lt=180.0)] | None = None
    focal_length_mm: PositiveFloat | None = None
    sensor_width_mm: PositiveFloat | None = None
    near_clip_m: PositiveFloat = 1e-3
    far_clip_m: PositiveFloat = 1e4
    aperture_radius_m: NonNegativeFloat = 0.0
    focus_distance_m: PositiveFloat | None = None

    @model_validator(mode="after")
    def _consistent(self) -> PerspectiveCamera:
        has_look_at = self.origin_m is not None or self.target_m is not None
        if self.to_world is not None:
            if has_look_at:
                raise InputError("to_world cannot be combined with origin_m/target_m")
            _check_affine_matrix(self.to_world, "to_world")
        else:
            if self.origin_m is None or self.target_m is None:
                raise InputError("camera needs origin_m and target_m (or to_world)")
            view = [t - o for t, o in zip(self.target_m, self.origin_m, strict=True)]
            _check_direction(view, "target_m - origin_m")
            _check_direction(self.up, "up")
            cross = [
                view[1] * self.up[2] - view[2] * self.up[1],
                view[2] * self.up[0] - view[0] * self.up[2],
                view[0] * self.up[1] - view[1] * self.up[0],
            ]
            if math.fsum(c * c for c in cross) <= 1e-18 * math.fsum(c * c for c in view):
                raise InputError("up must not be parallel to the viewing direction target_m - origin_m")
        has_lens = self.focal_length_mm is not None or self.sensor_width_mm is not None
        if has_lens and self.fov_deg is not None:
            raise InputError("give fov_deg or focal_length_mm + sensor_width_mm, not both")
        if has_lens and (self.focal_length_mm is None or self.sensor_width_mm is None):
            raise InputError("focal_length_mm and sensor_width_mm must be given together")
        if self.far_clip_m <= self.near_clip_m:
            raise InputError("far_clip_m must be greater than near_clip_m")
        if self.aperture_radius_m > 0.0 and self.focus_distance_m is None and self.to_world is not None:
            raise InputError(
                "focus_distance_m: required for a thin lens (aperture_radius_m > 0) placed by to_world"
            )
        return self

    def horizontal_fov_deg(self) -> float:
        """The horizontal field of view in degrees, whichever way it was specified."""
        if self.fov_deg is not None:
            return self.fov_deg
        if self.focal_length_mm is not None and self.sensor_width_mm is not None:
            return math.degrees(2.0 * math.atan(self.sensor_width_mm / (2.0 * self.focal_length_mm)))
        return 40.0

    def focus_distance(self) -> float:
        """The thin lens's focus distance along the view axis (m): ``focus_distance_m``, or the target's
        distance for a look-at camera."""
        if self.focus_distance_m is not None:
            return self.focus_distance_m
        assert self.origin_m is not None and self.target_m is not None  # guaranteed by the validator
        return math.dist(self.origin_m, self.target_m)


#: ``film.wavelength_sampling``: how a sample's wavelengths are drawn (docs/scenes.md, Film).
WavelengthSampling = Literal["auto", "uniform", "importance"]


class Film(StrictModel):
    """Image size and sampling: ``bands`` spectral bins spanning [wavelength_min_nm, wavelength_max_nm]."""

    width: Annotated[int, Field(ge=1, le=ABSOLUTE_MAX_RESOLUTION_PX)] = 64
    height: Annotated[int, Field(ge=1, le=ABSOLUTE_MAX_RESOLUTION_PX)] = 64
    bands: Annotated[int, Field(ge=1, le=64)] = 16
    wavelength_min_nm: Annotated[float, Field(ge=200.0, le=2500.0)] = 380.0
    wavelength_max_nm: Annotated[float, Field(ge=200.0, le=2500.0)] = 780.0
    spp: Annotated[int, Field(ge=1, le=ABSOLUTE_MAX_SPP)] = 64
    seed: Annotated[int, Field(ge=0, le=2**32 - 1)] = 0
    #: Number of HG modes per interaction (1 = the paper's 0th-order approximation; Fig. 9 uses 16).
    modes: Annotated[int, Field(ge=1, le=MAX_FILM_MODES)] = 1
    max_depth: Annotated[int, Field(ge=1, le=64)] = 8
    #: ``hg_path``: partially coherent light transport (the paper's PLT); ``rlt``: the radiometric baseline
    #: (a fully coherent plane wave per sample, no shape matrix; worker/render/rlt.py).
    integrator: Literal["hg_path", "rlt"] = "hg_path"
    #: How each sample's four wavelengths are drawn (worker/render/wavelength_sampling.py): ``importance``
    #: concentrates them where the emitters emit, by a defensive mixture with uniform sampling (a
    #: fluorescent lamp's lines no longer speckle colours); ``uniform``: uniformly over the range; ``auto``
    #: (default): ``importance`` when the emitters' spectra have lines, else ``uniform``.
    wavelength_sampling: WavelengthSampling = "auto"

    @model_validator(mode="after")
    def _range(self) -> Film:
        if self.wavelength_max_nm <= self.wavelength_min_nm:
            raise InputError("wavelength_max_nm must be greater than wavelength_min_nm")
        return self


# --- emitters ------------------------------------------------------------------------------------


class _EmitterBase(StrictModel):
    """Shared by all emitters: a spectrum and exactly one of ``power_w`` / ``radiance_scale``."""

    spectrum: Spectrum
    power_w: PositiveFloat | None = None
    radiance_scale: PositiveFloat | None = None

    @model_validator(mode="after")
    def _one_intensity(self) -> _EmitterBase:
        if (self.power_w is None) == (self.radiance_scale is None):
            raise InputError("give exactly one of power_w (total radiant power, W) or radiance_scale")
        return self


class SphereGeometry(StrictModel):
    """A sphere (area 4πR²)."""

    type: Literal["sphere"]
    center_m: Vec3
    radius_m: PositiveFloat


class CylinderGeometry(StrictModel):
    """An open cylinder (side surface only, no caps; area 2πRL) with axis from ``p0_m`` to ``p1_m``."""

    type: Literal["cylinder"]
    p0_m: Vec3
    p1_m: Vec3
    radius_m: PositiveFloat

    @model_validator(mode="after")
    def _axis(self) -> CylinderGeometry:
        _check_direction([b - a for a, b in zip(self.p0_m, self.p1_m, strict=True)], "p1_m - p0_m")
        return self


class RectangleGeometry(StrictModel):
    """A rectangle: ``height_m`` runs along ``up`` (projected onto the plane), ``width_m`` along
    ``up × normal``."""

    type: Literal["rectangle"]
    center_m: Vec3
    normal: Vec3
    up: Vec3
    width_m: PositiveFloat
    height_m: PositiveFloat

    @model_validator(mode="after")
    def _frame(self) -> RectangleGeometry:
        _check_rectangle_frame(self.normal, self.up)
        return self


class DiskGeometry(StrictModel):
    """A disk with unit ``normal``."""

    type: Literal["disk"]
    center_m: Vec3
    normal: Vec3
    radius_m: PositiveFloat

    @model_validator(mode="after")
    def _frame(self) -> DiskGeometry:
        _check_direction(self.normal, "normal")
        return self


class SphereEmitter(_EmitterBase, SphereGeometry):
    """A sphere emitting outwards from every surface point (area 4πR²)."""


class CylinderEmitter(_EmitterBase, CylinderGeometry):
    """An open cylinder (side surface only, no caps; area 2πRL) emitting outwards."""


class RectangleEmitter(_EmitterBase, RectangleGeometry):
    """A one-sided rectangle emitting on the ``normal`` side."""


class DiskEmitter(_EmitterBase, DiskGeometry):
    """A one-sided disk emitting on the ``normal`` side."""


def _check_rectangle_frame(
    normal: list[float], up: list[float], normal_name: str = "normal", up_name: str = "up"
) -> None:
    _check_direction(normal, normal_name)
    _check_direction(up, up_name)
    cross = [
        up[1] * normal[2] - up[2] * normal[1],
        up[2] * normal[0] - up[0] * normal[2],
        up[0] * normal[1] - up[1] * normal[0],
    ]
    if math.fsum(c * c for c in cross) <= 1e-18 * math.fsum(c * c for c in up) * math.fsum(
        c * c for c in normal
    ):
        raise InputError(f"{up_name} must not be parallel to {normal_name}")


class EnvironmentEmitter(StrictModel):
    """Light from infinitely far away in every direction (an overcast sky, an HDR environment map).

    Either a constant dome, L(λ) = ``radiance_scale`` · ``spectrum``(λ) from every direction, or a
    latitude-longitude image (``path``: EXR/HDR or any texture format) in the OpenEXR convention (USD
    ``DomeLight``): +Y up, the image's top row the zenith, its centre column towards +Z, a quarter to the
    left (u = 0.25) towards +X; each texel's linear sRGB c becomes L(λ) = ``radiance_scale`` · S_c(λ) ·
    D65(λ)/Y(D65) (the emitter upsampling of docs/scenes.md "Textures": an image value (1, 1, 1) has the
    luminance of a unit equal-energy radiance). ``transform`` turns the dome (a rotation; its translation is
    ignored). At most one environment per scene.
    """

    type: Literal["environment"]
    spectrum: Spectrum | None = None
    path: Annotated[str, Field(min_length=1, max_length=255)] | None = None
    radiance_scale: PositiveFloat = 1.0
    transform: Transform | None = None

    @field_validator("path")
    @classmethod
    def _inside_bundle(cls, path: str | None) -> str | None:
        return None if path is None else check_bundle_relative_path(path, suffixes=TEXTURE_SUFFIXES)

    @model_validator(mode="after")
    def _one_source(self) -> EnvironmentEmitter:
        if (self.spectrum is None) == (self.path is None):
            raise InputError("give exactly one of spectrum (a constant dome) or path (a lat-long image)")
        if self.transform is not None:
            rotation = [row[:3] for row in self.transform.to_matrix()[:3]]
            for i in range(3):
                for j in range(3):
                    dot = math.fsum(rotation[k][i] * rotation[k][j] for k in range(3))
                    if abs(dot - (1.0 if i == j else 0.0)) > 1e-6:
                        raise InputError("transform must be a rotation (no scale or shear)")
        return self


#: The largest angular diameter of a ``sun`` (degrees).
MAX_SUN_DIAMETER_DEG = 60.0


class SunEmitter(StrictModel):
    """A uniformly bright disk at infinity: the sun (angular diameter 0.53°) or any distant round source.

    ``direction`` points from the scene towards the sun's centre. Its spectral radiance is
    L(λ) = c · ``spectrum``(λ) over a cone of half-angle α = ``angular_diameter_deg``/2; either
    ``radiance_scale`` gives c, or ``irradiance_w_m2`` the irradiance on a surface facing the sun over the
    film's wavelength range, E = Ω·c·∫_{λmin}^{λmax} s dλ with Ω = 2π(1 − cos α). Its coherence is that of
    a uniform disk of angular radius α (van Cittert–Zernike: ℓ = 2/(kα), docs/physics.md §9).
    """

    type: Literal["sun"]
    direction: Vec3
    angular_diameter_deg: Annotated[float, Field(gt=0.0, le=MAX_SUN_DIAMETER_DEG)] = 0.53
    spectrum: Spectrum = Field(
        default_factory=lambda: BlackbodySpectrum(type="blackbody", temperature_k=5778.0)
    )
    irradiance_w_m2: PositiveFloat | None = None
    radiance_scale: PositiveFloat | None = None

    @model_validator(mode="after")
    def _one_intensity(self) -> SunEmitter:
        _check_direction(self.direction, "direction")
        if (self.irradiance_w_m2 is None) == (self.radiance_scale is None):
            raise InputError(
                "give exactly one of irradiance_w_m2 (W·m⁻² over the film's range) or radiance_scale"
            )
        return self

    def solid_angle_sr(self) -> float:
        """Ω = 2π(1 − cos α) of the disk (sr), formed as 2π·2sin²(α/2) (no cancellation)."""
        half_angle = math.radians(self.angular_diameter_deg) / 2.0
        return 4.0 * math.pi * math.sin(half_angle / 2.0) ** 2


Emitter = Annotated[
    SphereEmitter | CylinderEmitter | RectangleEmitter | DiskEmitter | EnvironmentEmitter | SunEmitter,
    Field(discriminator="type"),
]
#: Emitters with a surface in the scene (the others are at infinity).
SURFACE_EMITTER_TYPES = (SphereEmitter, CylinderEmitter, RectangleEmitter, DiskEmitter)


# --- shapes --------------------------------------------------------------------------------------


class _ShapeBase(StrictModel):
    """Shared by all shapes: the id of a material in ``Scene.materials`` and an optional transform."""

    material: str
    transform: Transform | None = None


class SphereShape(_ShapeBase, SphereGeometry):
    """A sphere."""


class CylinderShape(_ShapeBase, CylinderGeometry):
    """An open cylinder (side surface only, no caps) with axis from ``p0_m`` to ``p1_m``."""


class RectangleShape(_ShapeBase, RectangleGeometry):
    """A two-sided rectangle."""


class DiskShape(_ShapeBase, DiskGeometry):
    """A two-sided disk."""


class MeshShape(_ShapeBase):
    """An inline triangle mesh: vertex positions (m), triangles as vertex-index triples, optional normals."""

    type: Literal["mesh"]
    vertices_m: Annotated[list[Vec3], Field(min_length=3)]
    indices: Annotated[
        list[Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=3, max_length=3)]],
        Field(min_length=1),
    ]
    normals: list[Vec3] | None = None
    #: Per-vertex texture coordinates [u, v] (the set ``st``; origin at an image's bottom-left, v up).
    uvs: list[Vec2] | None = None
    #: Further named sets of per-vertex texture coordinates (a texture's ``uv_set`` picks one).
    uv_sets: dict[Annotated[str, Field(pattern=UV_SET_PATTERN)], list[Vec2]] | None = None

    @model_validator(mode="after")
    def _consistent(self) -> MeshShape:
        vertex_count = len(self.vertices_m)
        for triangle_index, triangle in enumerate(self.indices):
            if max(triangle) >= vertex_count:
                raise InputError(
                    f"indices[{triangle_index}] refers to vertex {max(triangle)} but there are "
                    f"{vertex_count} vertices"
                )
        if self.normals is not None and len(self.normals) != vertex_count:
            raise InputError(
                f"normals has {len(self.normals)} entries, expected one per vertex ({vertex_count})"
            )
        for name, uvs in self.texture_coordinate_sets().items():
            if len(uvs) != vertex_count:
                raise InputError(
                    f"uv set {name!r} has {len(uvs)} entries, expected one per vertex ({vertex_count})"
                )
        if self.uv_sets is not None and "st" in self.uv_sets and self.uvs is not None:
            raise InputError("uv_sets must not name 'st' when uvs (the set 'st') is given")
        return self

    def texture_coordinate_sets(self) -> dict[str, list[list[float]]]:
        """Every named set of texture coordinates: ``uvs`` as ``st`` and the ``uv_sets``."""
        sets = dict(self.uv_sets or {})
        if self.uvs is not None:
            sets["st"] = self.uvs
        return sets


class MeshFileShape(_ShapeBase):
    """A triangle mesh from an ``.obj`` or ``.ply`` file inside the uploaded scene bundle."""

    type: Literal["mesh_file"]
    path: Annotated[str, Field(min_length=1, max_length=255)]

    @field_validator("path")
    @classmethod
    def _relative_inside_bundle(cls, path: str) -> str:
        return check_bundle_relative_path(path, suffixes=(".obj", ".ply"))


#: The most segments a procedural shape may have along one parameter (its triangle count is also counted
#: against ``HGRENDER_MAX_TRIANGLES``).
MAX_PROCEDURAL_SEGMENTS = 1024
Segments = Annotated[int, Field(ge=3, le=MAX_PROCEDURAL_SEGMENTS)]
#: The largest extent (m) of a procedural shape's parameters: a room, not a planet.
MAX_PROCEDURAL_SIZE_M = 1000.0
ProceduralLength = Annotated[float, Field(gt=0.0, le=MAX_PROCEDURAL_SIZE_M)]


class ShellShape(_ShapeBase):
    """A beetle-like ribbed ellipsoid (``schemas.procedural.shell``): semi-axes (a, b, c) along the long
    ``axis``, ``up`` and their cross product; ``rib_count`` lengthwise ribs of relative depth
    ``rib_depth`` and ``segment_count`` crosswise bands of relative depth ``segment_depth``."""

    type: Literal["shell"]
    center_m: Vec3
    semi_axes_m: Annotated[list[ProceduralLength], Field(min_length=3, max_length=3)]
    axis: Vec3 = Field(default_factory=lambda: [1.0, 0.0, 0.0])
    up: Vec3 = Field(default_factory=lambda: [0.0, 1.0, 0.0])
    rib_count: Annotated[int, Field(ge=0, le=256)] = 12
    rib_depth: Annotated[float, Field(ge=0.0, le=0.3)] = 0.04
    segment_count: Annotated[int, Field(ge=0, le=256)] = 0
    segment_depth: Annotated[float, Field(ge=0.0, le=0.3)] = 0.0
    segments_along: Segments = 96
    segments_around: Segments = 192

    @model_validator(mode="after")
    def _frame(self) -> ShellShape:
        _check_rectangle_frame(self.axis, self.up, normal_name="axis")
        if self.rib_depth + self.segment_depth >= 0.5:
            raise InputError("rib_depth + segment_depth must be below 0.5 (the surface would fold)")
        return self


WavePattern = Literal["waves", "ripples", "egg_crate"]


class WavySheetShape(_ShapeBase):
    """An embossed rectangle (``schemas.procedural.wavy_sheet``): the rectangle of ``RectangleShape``
    displaced along ``normal`` by ``amplitude_m`` times a ``pattern`` of period ``wavelength_m``."""

    type: Literal["wavy_sheet"]
    center_m: Vec3
    normal: Vec3
    up: Vec3
    width_m: ProceduralLength
    height_m: ProceduralLength
    pattern: WavePattern = "waves"
    amplitude_m: Annotated[float, Field(ge=0.0, le=MAX_PROCEDURAL_SIZE_M)]
    wavelength_m: ProceduralLength
    segments: Segments = 256

    @model_validator(mode="after")
    def _frame(self) -> WavySheetShape:
        _check_rectangle_frame(self.normal, self.up)
        return self


class OpticalDiscShape(_ShapeBase):
    """A CD/DVD (``schemas.procedural.optical_disc``): an annulus whose first tangent is radial, so a
    ``grating`` material with ``orientation_deg`` 0 has concentric tracks. Defaults: a 120 mm disc with a
    15 mm hole."""

    type: Literal["optical_disc"]
    center_m: Vec3
    normal: Vec3
    radius_m: ProceduralLength = 0.06
    inner_radius_m: Annotated[float, Field(ge=0.0, le=MAX_PROCEDURAL_SIZE_M)] = 0.0075
    segments_radial: Segments = 8
    segments_around: Segments = 720

    @model_validator(mode="after")
    def _radii(self) -> OpticalDiscShape:
        _check_direction(self.normal, "normal")
        if self.inner_radius_m >= self.radius_m:
            raise InputError("inner_radius_m must be smaller than radius_m")
        return self


class BackdropShape(_ShapeBase):
    """A photographer's cyclorama (``schemas.procedural.backdrop``): a floor ``width_m`` × ``depth_m``
    centred at ``floor_center_m``, bending up along a quarter cylinder of ``cove_radius_m`` into a wall of
    ``height_m`` behind it; it opens towards ``facing`` (projected ⟂ ``up``)."""

    type: Literal["backdrop"]
    floor_center_m: Vec3
    facing: Vec3
    up: Vec3 = Field(default_factory=lambda: [0.0, 1.0, 0.0])
    width_m: ProceduralLength
    depth_m: ProceduralLength
    height_m: ProceduralLength
    cove_radius_m: ProceduralLength
    segments: Segments = 24

    @model_validator(mode="after")
    def _frame(self) -> BackdropShape:
        _check_rectangle_frame(self.up, self.facing, normal_name="up", up_name="facing")
        if self.cove_radius_m >= self.height_m:
            raise InputError("cove_radius_m must be smaller than height_m")
        return self


#: Shapes whose triangles ``schemas.procedural`` generates from their parameters.
ProceduralShape = ShellShape | WavySheetShape | OpticalDiscShape | BackdropShape
PROCEDURAL_SHAPE_TYPES = (ShellShape, WavySheetShape, OpticalDiscShape, BackdropShape)


def check_bundle_relative_path(path: str, suffixes: tuple[str, ...] | None = None) -> str:
    """Reject anything that could leave the bundle directory: absolute paths, ``..``, URLs, drives."""
    if "\\" in path or "\x00" in path:
        raise InputError("path must use '/' separators and no NUL characters")
    if re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", path):
        raise InputError(f"path must be relative to the bundle, not a URL or drive ({path!r})")
    if path.startswith("/"):
        raise InputError(f"path must be relative to the bundle, not absolute ({path!r})")
    if any(part in ("..", "") for part in path.split("/")):
        raise InputError(f"path must stay inside the bundle (no '..' or empty components) ({path!r})")
    if suffixes is not None and not path.lower().endswith(suffixes):
        raise InputError(f"path must end with one of {', '.join(suffixes)} ({path!r})")
    return path


Shape = Annotated[
    SphereShape
    | CylinderShape
    | RectangleShape
    | DiskShape
    | MeshShape
    | MeshFileShape
    | ShellShape
    | WavySheetShape
    | OpticalDiscShape
    | BackdropShape,
    Field(discriminator="type"),
]


# --- materials -----------------------------------------------------------------------------------


class _ScatteringMaterial(StrictModel):
    """Non-specular materials. Light they scatter is a secondary source sized by the lit, seen part of the
    surface (van Cittert–Zernike, docs/physics.md §7); ``scattering_region_radius_m`` overrides that with a
    uniform disk of this radius in the tangent plane (an explicit modelling choice)."""

    scattering_region_radius_m: PositiveFloat | None = None


class DiffuseMaterial(_ScatteringMaterial):
    type: Literal["diffuse"]
    reflectance: Reflectance = 0.5


class MirrorMaterial(StrictModel):
    """A perfectly specular conductor; keeps the incident coherence (Θ unchanged, r accumulates)."""

    type: Literal["mirror"]
    conductor: ConductorName | Literal["perfect"] = "perfect"
    #: A colour multiplying the Fresnel reflectance: a number, a spectrum or a colour texture (none: 1).
    tint: Reflectance | None = None


class DielectricMaterial(StrictModel):
    """A smooth dielectric interface (glass); perfectly specular like the mirror."""

    type: Literal["dielectric"]
    ior: RefractiveIndex = 1.5
    exterior_ior: Annotated[float, Field(ge=1.0, le=10.0)] = 1.0


#: Largest film thickness, RMS roughness (µm) and correlation length (µm): the ranges a texture's values
#: are clipped to (a textured roughness or film may reach 0; a correlation length stays ≥ 1 nm).
MAX_FILM_THICKNESS_UM = 100.0
MAX_ROUGHNESS_RMS_UM = 100.0
MIN_CORRELATION_LENGTH_UM = 1e-3
MAX_CORRELATION_LENGTH_UM = 1e4
#: σ_h in µm, or a one-channel texture of it.
RoughnessRms = Textured(Annotated[float, Field(gt=0.0, le=MAX_ROUGHNESS_RMS_UM)])
#: ℓ_c in µm, or a one-channel texture of it.
CorrelationLength = Textured(Annotated[float, Field(gt=0.0, le=MAX_CORRELATION_LENGTH_UM)])


class _RoughSurface(_ScatteringMaterial):
    """Statistical rough surface (Eq. 15): RMS height, correlation length and PSD model.

    ``gaussian``: PSD ∝ exp(−(π·ℓ·f)²); ``abc`` (K-correlation): PSD ∝ (1 + (2π·ℓ·f)²)^(−(psd_exponent+1)/2).
    """

    roughness_rms_um: RoughnessRms
    correlation_length_um: CorrelationLength
    psd: PsdModel = "gaussian"
    psd_exponent: Annotated[float, Field(gt=1.0, le=10.0)] = 2.0


class RoughConductorMaterial(_RoughSurface):
    type: Literal["rough_conductor"]
    conductor: ConductorName
    #: A colour multiplying the conductor's Fresnel reflectance (``mirror`` has it too): a number, a
    #: spectrum or a colour texture; none by default.
    tint: Reflectance | None = None


class RoughDielectricMaterial(_RoughSurface):
    type: Literal["rough_dielectric"]
    ior: RefractiveIndex = 1.5
    exterior_ior: Annotated[float, Field(ge=1.0, le=10.0)] = 1.0


class ConductorSubstrate(StrictModel):
    conductor: ConductorName


class DielectricSubstrate(StrictModel):
    ior: RefractiveIndex


def _substrate_kind(value: Any) -> str:
    if isinstance(value, dict):
        return "conductor" if "conductor" in value else "dielectric"
    return "conductor" if isinstance(value, ConductorSubstrate) else "dielectric"


Substrate = Annotated[
    Annotated[ConductorSubstrate, Tag("conductor")] | Annotated[DielectricSubstrate, Tag("dielectric")],
    Discriminator(_substrate_kind),
]


class ThinFilmMaterial(_ScatteringMaterial):
    """A thin dielectric film over a substrate (Eq. 18), on a weakly rough interface (Eq. 15)."""

    type: Literal["thin_film"]
    #: τ in µm, or a texture of it (clipped to [0, 100] µm: 0 is a bare substrate, a soap film's black spot)
    film_thickness_um: Textured(Annotated[float, Field(gt=0.0, le=MAX_FILM_THICKNESS_UM)])
    film_ior: RefractiveIndex
    substrate: Substrate
    roughness_rms_um: RoughnessRms = 0.05
    correlation_length_um: CorrelationLength = 5.0
    psd: PsdModel = "gaussian"
    psd_exponent: Annotated[float, Field(gt=1.0, le=10.0)] = 2.0
    #: Number of multiply-reflected beams summed in the film (2 = the paper's two-beam form).
    beams: Annotated[int, Field(ge=2, le=8)] = 4
    #: The film's extinction κ_f (dimensionless, constant over wavelength): index n_f + iκ_f, an absorbing
    #: coating such as silver-sulfide tarnish; conductor substrates only (hgcore.optics.thin_film).
    film_extinction: Annotated[float, Field(ge=0.0, le=10.0)] = 0.0

    @model_validator(mode="after")
    def _absorbing_needs_conductor(self) -> ThinFilmMaterial:
        if self.film_extinction > 0.0 and _substrate_kind(self.substrate) == "dielectric":
            raise InputError(
                "film_extinction: an absorbing film (film_extinction > 0) needs a conductor substrate; on a "
                "dielectric substrate its transmittance is not 1 − R (the film absorbs), which the renderer "
                "does not model"
            )
        return self


#: Optical-disc presets: track pitch (µm) and pit depth (nm) — CD: 1.6 µm, DVD: 0.74 µm (ECMA-130/267).
GRATING_PRESETS: dict[str, dict[str, float]] = {
    "cd": {"pitch_um": 1.6, "pit_depth_nm": 125.0},
    "dvd": {"pitch_um": 0.74, "pit_depth_nm": 105.0},
}
DEFAULT_PIT_DEPTH_NM = 100.0


class GratingMaterial(_ScatteringMaterial):
    """A reflective diffraction grating (Eq. 20): 1-D (``pitch_um``) or 2-D (+ ``pitch_y_um``).

    With a ``preset`` the pitch and pit depth default to the preset's values (explicit fields win);
    after validation ``pitch_um`` and ``pit_depth_nm`` are always set.
    """

    type: Literal["grating"]
    preset: Literal["cd", "dvd"] | None = None
    pitch_um: Annotated[float, Field(gt=0.0, le=1000.0)] | None = None
    pitch_y_um: Annotated[float, Field(gt=0.0, le=1000.0)] | None = None
    orientation_deg: float = 0.0
    duty: Annotated[float, Field(gt=0.0, lt=1.0)] = 0.5
    pit_depth_nm: Annotated[float, Field(ge=0.0, le=1e5)] | None = None
    pit_ior: Annotated[float, Field(ge=1.0, le=10.0)] = 1.55
    lobe_width_per_um: Annotated[float, Field(gt=0.0, le=100.0)] = 0.05
    conductor: ConductorName = "Al"
    max_order: Annotated[int, Field(ge=0, le=32)] = 3

    @model_validator(mode="after")
    def _resolve_preset(self) -> GratingMaterial:
        if self.preset is not None:
            preset = GRATING_PRESETS[self.preset]
            if self.pitch_um is None:
                self.pitch_um = preset["pitch_um"]
            if self.pit_depth_nm is None:
                self.pit_depth_nm = preset["pit_depth_nm"]
        if self.pitch_um is None:
            raise InputError("pitch_um is required when no preset is given")
        if self.pit_depth_nm is None:
            self.pit_depth_nm = DEFAULT_PIT_DEPTH_NM
        return self


Material = Annotated[
    DiffuseMaterial
    | MirrorMaterial
    | DielectricMaterial
    | RoughConductorMaterial
    | RoughDielectricMaterial
    | ThinFilmMaterial
    | GratingMaterial,
    Field(discriminator="type"),
]

MaterialId = Annotated[str, Field(pattern=MATERIAL_ID_PATTERN)]


# --- scene ---------------------------------------------------------------------------------------


class Scene(StrictModel):
    """A complete scene, schema ``hgrender/scene/v1``.

    The ``schema`` key is held in the attribute ``schema_`` (``schema`` would shadow a BaseModel method).
    """

    schema_: Literal["hgrender/scene/v1"] = Field(alias="schema")
    name: Annotated[str, Field(max_length=200)] = "untitled"
    camera: PerspectiveCamera
    film: Film = Field(default_factory=Film)
    materials: dict[MaterialId, Material]
    shapes: list[Shape] = Field(default_factory=list)
    emitters: Annotated[list[Emitter], Field(min_length=1)]

    model_config = ConfigDict(
        title="hgrender scene v1",
        extra="forbid",
        allow_inf_nan=False,
        strict=True,
        populate_by_name=True,
        serialize_by_alias=True,
    )

    @model_validator(mode="after")
    def _material_references(self) -> Scene:
        problems = [
            {"pointer": f"/shapes/{index}/material", "message": f"unknown material {shape.material!r}"}
            for index, shape in enumerate(self.shapes)
            if shape.material not in self.materials
        ]
        environments = [i for i, e in enumerate(self.emitters) if isinstance(e, EnvironmentEmitter)]
        problems += [
            {"pointer": f"/emitters/{index}", "message": "a scene has at most one environment emitter"}
            for index in environments[1:]
        ]
        if problems:
            raise PydanticCustomError(
                "scene_reference",
                "{summary}",
                {
                    "summary": "; ".join(f"{p['pointer']}: {p['message']}" for p in problems),
                    "problems": problems,
                },
            )
        return self

    def to_json_dict(self) -> dict[str, Any]:
        """The scene as a JSON-compatible dict (unset optionals omitted) that validates back equal."""
        return self.model_dump(mode="json", by_alias=True, exclude_none=True)
