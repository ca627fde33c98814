"""Validated, frozen scene models and the scene file loader."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, Field, model_validator

from ..brown import BrownDistortion
from ..validation import (
    DISTANCE_M,
    MODEL_CONFIG,
    Angle_deg,
    Length_mm,
    PositiveLength_mm,
    load_mapping,
    validate_model,
)
from .surfaces import FaceShape, Term

__all__ = [
    "Deformation",
    "Frame",
    "Pane",
    "Backdrop",
    "Camera",
    "LensDistortion",
    "Noise",
    "Lighting",
    "Imaging",
    "RenderSettings",
    "Viewing",
    "Scene",
    "load_scene",
    "scene_from_dict",
    "rotation_yaw_pitch",
]

_FROZEN = MODEL_CONFIG


def rotation_yaw_pitch(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Rotation ``R = R_y(yaw) @ R_x(pitch)`` of the world frame (x right, y down, z forward).

    ``R @ (0, 0, 1)`` is the pointing direction: positive yaw turns it towards +x
    (right), positive pitch towards -y (up). Columns of ``R`` are the rotated
    body axes (right, down, forward); no roll.
    """
    a, b = math.radians(yaw_deg), math.radians(pitch_deg)
    ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    return ry @ rx


class Deformation(BaseModel):
    """Face deformations: lists of terms added to the front face, back face, or both.

    ``both`` displaces the two faces identically (a conformal bend of the whole
    sheet, e.g. a roller wave); ``front``/``back`` act on one face (thickness
    variation: lens caps, wedges, local defects).
    """

    model_config = _FROZEN
    both: tuple[Term, ...] = ()
    front: tuple[Term, ...] = ()
    back: tuple[Term, ...] = ()

    @property
    def front_shape(self) -> FaceShape:
        """Height field of the front face (mm along +w)."""
        return FaceShape(self.both + self.front)

    @property
    def back_shape(self) -> FaceShape:
        """Height field of the back face (mm along +w)."""
        return FaceShape(self.both + self.back)


class Frame(BaseModel):
    """Opaque frame band along the pane's edges (width in mm, intensity in [0, 1])."""

    model_config = _FROZEN
    width_mm: PositiveLength_mm
    intensity: float = Field(0.05, ge=0, le=1)


class Pane(BaseModel):
    """The glass pane: a slab of thickness ``d`` centred on ``center_mm``.

    Orientation: pane axes ``(u, v, w) = R_y(yaw) R_x(pitch)`` applied to the world
    axes; ``w`` is the pane normal pointing towards the backdrop.
    """

    model_config = _FROZEN
    size_mm: tuple[Length_mm, Length_mm]
    thickness_mm: PositiveLength_mm
    refractive_index: float = Field(gt=1.0, lt=3.0)
    center_mm: tuple[Length_mm, Length_mm, Length_mm] = (0.0, 0.0, 0.0)
    yaw_deg: float = Field(0.0, ge=-80, le=80)
    pitch_deg: float = Field(0.0, ge=-80, le=80)
    transmittance: float = Field(1.0, gt=0, le=1)
    frame: Frame | None = None
    deformation: Deformation = Deformation()

    @model_validator(mode="after")
    def _size(self):
        if min(self.size_mm) <= 0:
            raise ValueError("size_mm must be positive (width, height in mm)")
        if self.frame is not None and 2 * self.frame.width_mm >= min(self.size_mm):
            raise ValueError("frame.width_mm must be less than half the pane size")
        return self

    @property
    def rotation(self) -> np.ndarray:
        """3x3 matrix whose columns are the pane axes u, v, w in world coordinates."""
        return rotation_yaw_pitch(self.yaw_deg, self.pitch_deg)


class Backdrop(BaseModel):
    """Printed backdrop on the world plane ``z = pane.center_z + 1000 * distance_m``.

    Pattern coordinates ``p = Rot(-rotation) (X - offset)`` with ``X`` the world
    ``(x, y)`` on the plane. ``lines``: dark lines of ``line_width_mm`` centred on
    multiples of ``pitch_mm`` along both pattern axes; ``checkerboard``: squares of
    side ``pitch_mm``, the square touching the origin from +x,+y is white; ``dots``: dark
    round dots of diameter ``dot_diameter_mm`` centred on the square lattice of spacing
    ``pitch_mm`` (a dot on the origin).
    """

    model_config = _FROZEN
    pattern: Literal["lines", "checkerboard", "dots"]
    pitch_mm: PositiveLength_mm
    line_width_mm: PositiveLength_mm | None = None
    dot_diameter_mm: PositiveLength_mm | None = None
    rotation_deg: Angle_deg = 0.0
    offset_mm: tuple[Length_mm, Length_mm] = (0.0, 0.0)
    distance_m: float = Field(ge=DISTANCE_M.lo, le=DISTANCE_M.hi)
    black: float = Field(0.05, ge=0, le=1)
    white: float = Field(0.95, ge=0, le=1)

    @model_validator(mode="after")
    def _lines(self):
        if self.pattern == "lines":
            if self.line_width_mm is None:
                raise ValueError("line_width_mm is required for pattern 'lines'")
            if self.line_width_mm >= self.pitch_mm:
                raise ValueError("line_width_mm must be smaller than pitch_mm")
        if self.pattern == "dots":
            if self.dot_diameter_mm is None:
                raise ValueError("dot_diameter_mm is required for pattern 'dots'")
            if self.dot_diameter_mm >= self.pitch_mm:
                raise ValueError("dot_diameter_mm must be smaller than pitch_mm (the dots must not touch)")
        if self.black >= self.white:
            raise ValueError("black must be darker (smaller) than white")
        return self


class LensDistortion(BaseModel):
    """Brown lens distortion of the camera, OpenCV's coefficients (normalised by the focal length).

    ``k1 < 0`` barrel, ``k1 > 0`` pincushion, ``k1 < 0 < k2`` moustache; ``p1``, ``p2``
    tangential (:class:`glassdist.brown.BrownDistortion`).
    """

    model_config = _FROZEN
    k1: float = Field(0.0, ge=-1, le=1)
    k2: float = Field(0.0, ge=-1, le=1)
    p1: float = Field(0.0, ge=-0.1, le=0.1)
    p2: float = Field(0.0, ge=-0.1, le=0.1)

    @property
    def brown(self) -> BrownDistortion:
        """The lens's Brown-Conrady coefficients as a :class:`~glassdist.brown.BrownDistortion`."""
        return BrownDistortion(self.k1, self.k2, self.p1, self.p2)


class Camera(BaseModel):
    """Camera: focal length and sensor width in mm, ``pixels = (width, height)``.

    Square pixels of ``sensor_width_mm / width``; principal point at the image
    centre; pose ``position_mm`` and ``R_y(yaw) R_x(pitch)`` (no roll). A pinhole,
    or with ``distortion`` a lens with Brown distortion about the principal point.
    """

    model_config = _FROZEN
    focal_length_mm: PositiveLength_mm
    sensor_width_mm: PositiveLength_mm
    pixels: tuple[Annotated[int, Field(ge=8, le=100_000)], Annotated[int, Field(ge=8, le=100_000)]]
    position_mm: tuple[Length_mm, Length_mm, Length_mm]
    yaw_deg: float = Field(0.0, ge=-80, le=80)
    pitch_deg: float = Field(0.0, ge=-80, le=80)
    distortion: LensDistortion | None = None

    @model_validator(mode="after")
    def _pixels(self):
        if min(self.pixels) < 8:
            raise ValueError("pixels must be (width, height) with both at least 8")
        if self.distortion is not None:
            # the distortion must stay monotonic out to the image corners (a real lens's field)
            H, W = self.shape
            r = np.linspace(0.0, np.hypot(W, H) / 2 * self.pixel_pitch_mm / self.focal_length_mm, 64)
            d = self.distortion
            if np.any(1 + 3 * d.k1 * r**2 + 5 * d.k2 * r**4 <= 0.2):
                raise ValueError("camera distortion folds the image before its corners; use smaller k1, k2")
        return self

    @property
    def focal_length_px(self) -> float:
        """Focal length in px (the normalising length of OpenCV's distortion coefficients)."""
        return self.focal_length_mm / self.pixel_pitch_mm

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(H, W)``."""
        return int(self.pixels[1]), int(self.pixels[0])

    @property
    def pixel_pitch_mm(self) -> float:
        """The sensor's pixel pitch, mm (sensor width over pixel columns)."""
        return self.sensor_width_mm / self.pixels[0]

    @property
    def rotation(self) -> np.ndarray:
        """3x3 matrix whose columns are the camera axes (right, down, forward) in world."""
        return rotation_yaw_pitch(self.yaw_deg, self.pitch_deg)


class Noise(BaseModel):
    """Sensor noise: Poisson shot noise at ``full_well_e`` electrons for intensity 1, Gaussian read noise (intensity units)."""

    model_config = _FROZEN
    full_well_e: float | None = Field(None, gt=0, le=1e9)
    read_noise: float = Field(0.0, ge=0, le=10)


class Lighting(BaseModel):
    """Uneven lighting: gain ``1 + gradient * t``.

    ``t`` runs over [-1, 1] across the image along ``direction_deg`` (from +x towards +y).
    """

    model_config = _FROZEN
    gradient: float = Field(0.0, ge=0, lt=1)
    direction_deg: Angle_deg = 0.0


class Imaging(BaseModel):
    """Optional imaging effects, applied in the order lighting, vignetting, blur, noise."""

    model_config = _FROZEN
    noise: Noise | None = None
    blur_px: float = Field(0.0, ge=0, le=20)
    vignetting: float = Field(0.0, ge=0, lt=1, description="relative loss at the image corners (quadratic)")
    lighting: Lighting | None = None


class RenderSettings(BaseModel):
    """Default sampling for renders (overridable on the command line)."""

    model_config = _FROZEN
    samples_per_pixel: int = Field(16, ge=1, le=1024)
    seed: int = Field(0, ge=0, le=2**32 - 1)


class Viewing(BaseModel):
    """How the camera sees the backdrop: through the pane (transmission) or in it (reflection).

    ``reflection``: the backdrop is a grid board on the camera's side of the pane, parallel
    to the world ``(x, y)`` plane at ``backdrop.distance_m`` (the board-to-pane distance D)
    before the pane's centre; the lines of sight reflect off the pane's front face (mirror
    law on the true surface normal) and land on the board. ``back_face`` adds the back face's
    reflection (the ghost of an uncoated pane: in through the front face, reflected by the
    back face, out through the front face), each ray weighted by the Fresnel reflectances
    of unpolarised light; the image is normalised by the sum of the two weights.
    """

    model_config = _FROZEN
    mode: Literal["transmission", "reflection"] = "transmission"
    back_face: bool = False

    @model_validator(mode="after")
    def _ghost(self):
        if self.back_face and self.mode != "reflection":
            raise ValueError("back_face applies to mode 'reflection' only")
        return self


class Scene(BaseModel):
    """A glass distortion definition (see :mod:`glassdist.scene` for the geometry)."""

    model_config = _FROZEN
    name: str = "scene"
    description: str = ""
    pane: Pane
    backdrop: Backdrop
    camera: Camera
    imaging: Imaging = Imaging()
    render: RenderSettings = RenderSettings()
    viewing: Viewing = Viewing()
    analysis: dict[str, Any] = Field(
        default_factory=dict,
        description="analyzer parameter overrides used by 'glassdist validate' (checked by the analyzer)",
    )

    @model_validator(mode="after")
    def _camera_in_front(self):
        zc = self.camera.position_mm[2]
        zp = self.pane.center_mm[2]
        if zc >= zp - self.pane.thickness_mm:
            raise ValueError("camera.position_mm must lie in front of the pane (z smaller than pane.center_mm z)")
        return self

    @model_validator(mode="after")
    def _geometry(self):
        """Physical consistency of a tilted, deformed pane with the camera and the backdrop.

        The faces are sampled on a 33 x 33 grid of the pane (mm): the camera must lie in
        front of the front face along the pane normal ``w``, the faces must not cross, and
        the whole pane must lie before the backdrop plane.
        """
        pane = self.pane
        hw, hh = pane.size_mm[0] / 2, pane.size_mm[1] / 2
        u, v = np.meshgrid(np.linspace(-hw, hw, 33), np.linspace(-hh, hh, 33))
        front = -pane.thickness_mm / 2 + pane.deformation.front_shape.height(u, v)
        back = pane.thickness_mm / 2 + pane.deformation.back_shape.height(u, v)
        if not (np.all(np.isfinite(front)) and np.all(np.isfinite(back))):
            raise ValueError("the pane's deformation gives non-finite heights; check the deformation terms")
        if np.any(back - front <= 0):
            raise ValueError("the pane's deformed faces cross (thickness <= 0 somewhere); reduce the deformation amplitudes")
        rot = pane.rotation
        w_cam = float(rot[:, 2] @ (np.asarray(self.camera.position_mm) - np.asarray(pane.center_mm)))
        if w_cam >= float(front.min()):
            raise ValueError(
                f"the camera is inside or behind the tilted pane ({w_cam:.4g} mm along the pane normal, front face "
                f"from {float(front.min()):.4g} mm); move camera.position_mm in front of the pane"
            )
        corners = np.asarray(pane.center_mm)[:, None] + rot @ np.array(
            [[su * hw, sv * hh, sw] for su in (-1, 1) for sv in (-1, 1)
             for sw in (float(front.min()), float(back.max()))]).T
        if self.reflection:
            if float(corners[2].min()) <= self.backdrop_z_mm:
                raise ValueError("the tilted pane reaches the board plane; increase backdrop.distance_m or reduce the tilt")
        elif float(corners[2].max()) >= self.backdrop_z_mm:
            raise ValueError("the tilted pane reaches the backdrop plane; increase backdrop.distance_m or reduce the tilt")
        return self

    @property
    def reflection(self) -> bool:
        """True when the scene is viewed in reflection (:class:`Viewing`)."""
        return self.viewing.mode == "reflection"

    @property
    def backdrop_z_mm(self) -> float:
        """World z of the backdrop plane, mm (behind the pane; in reflection, the board before it)."""
        sign = -1.0 if self.reflection else 1.0
        return self.pane.center_mm[2] + sign * 1000.0 * self.backdrop.distance_m

    def with_changes(self, **sections) -> "Scene":
        """Copy with some top-level sections replaced (dicts are merged into the section)."""
        data = self.model_dump()
        for key, val in sections.items():
            if isinstance(val, dict) and isinstance(data.get(key), dict):
                data[key] = {**data[key], **val}
            else:
                data[key] = val
        return scene_from_dict(data, source=f"scene '{self.name}'")


def scene_from_dict(data: dict, *, source: str = "scene") -> Scene:
    """Validate a parsed scene mapping; raises :class:`InputError` on any problem."""
    return validate_model(Scene, data, "scene", source, "see docs/explanation/virtual-pipeline.md for the scene format")


def load_scene(path) -> Scene:
    """Load and validate a scene from a YAML (``.yaml``/``.yml``) or JSON file.

    Raises
    ------
    InputError
        Missing file, unparsable content (see :func:`glassdist.validation.load_document`),
        unknown key, missing, non-finite or out-of-range value, inconsistent geometry.

    Examples
    --------
    A 20 mm slab with a roller wave, seen at 64 x 48 px through a 300 mm lens:

    >>> import tempfile
    >>> from pathlib import Path
    >>> from glassdist.scene import load_scene
    >>> folder = tempfile.TemporaryDirectory()
    >>> path = Path(folder.name) / "wavy.yaml"
    >>> _ = path.write_text('''
    ... name: wavy_slab_tiny
    ... pane: {size_mm: [1400, 1000], thickness_mm: 20, refractive_index: 1.52, yaw_deg: 30,
    ...        deformation: {both: [{kind: roller_wave, amplitude_mm: 0.3, wavelength_mm: 200}]}}
    ... backdrop: {pattern: lines, pitch_mm: 72.6, line_width_mm: 18, distance_m: 10}
    ... camera: {focal_length_mm: 300, sensor_width_mm: 36, pixels: [64, 48], position_mm: [0, 0, -4000]}
    ... ''')
    >>> scene = load_scene(path)
    >>> scene.name, scene.camera.shape, scene.backdrop.pitch_mm
    ('wavy_slab_tiny', (48, 64), 72.6)
    >>> folder.cleanup()
    """
    from ..validation import safe_text

    data = load_mapping(path, "scene file", expect="sections (pane, backdrop, camera, ...)",
                        hint="check its YAML/JSON syntax (examples are in examples/scenes/)")
    return scene_from_dict(data, source=f"'{safe_text(path)}'")
