"""The Analyzer's result: settings, carriers, homography, warnings and the measured fields.

The fields are computed on the analysis grid (block means of the demodulation grid) and
kept there; each is brought to the input image's pixel grid on first access and cached
(:mod:`glassdist.analyzer.resample`). :data:`FIELDS` is the one list of the result's
fields: writers, figures and exports iterate it rather than naming fields themselves.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Protocol, TypeVar, overload, runtime_checkable

import numpy as np

from .._version import __version__
from . import fourier as F
from .bulk import BulkChannel
from .homography import HomographyFit
from .metrics import channel_statistics
from .params import AnalyzerParams
from .region import ANALYSED, LABELS, pixel_quality, trusted_on
from .resample import upsample_axis, upsample_axis_rows, upsample_field, upsample_field_rows, upsample_labels

__all__ = ["AnalysisResult", "Optics", "Result", "holds", "row_blocks", "FieldSpec", "FIELDS", "CHANNELS"]


@dataclass(frozen=True)
class FieldSpec:
    """One field of an :class:`AnalysisResult`.

    Attributes
    ----------
    name : str
        Attribute name, and key in ``result.npz`` (units in the name: ``_mm``, ``_mD``, ``_deg``).
    unit : str
        Unit of the values ('mm', 'mD', 'deg', '' for labels).
    description : str
        One line for file metadata and documentation.
    components : int
        1 for an (H, W) map, 2 for an (H, W, 2) vector field (``[..., 0]`` = x, ``[..., 1]`` = y).
    kind : {'float', 'label'}
        'float': float32, NaN where invalid, interpolated to the pixel grid; 'label': small
        integers, brought to the pixel grid by nearest sample, defined everywhere.
    """

    name: str
    unit: str
    description: str
    components: int = 1
    kind: str = "float"


#: The result's fields, in file order. A field listed here and present in the analysis
#: (``AnalysisResult.field_specs()``) is written by every output of a run.
FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("displacement_mm", "mm",
              "delta: landing point on the backdrop with glass minus without; [...,0]=x (columns), [...,1]=y (rows)", 2),
    FieldSpec("displacement_detrended_mm", "mm",
              "delta after the A2 detrend and metric smoothing (the field A3 differentiates)", 2),
    FieldSpec("phi_eff_mD", "mD", "sphere-equivalent power tr(eps)/L; converging lens < 0"),
    FieldSpec("phi_shear_mD", "mD", "cylinder-equivalent astigmatism (2/L) sqrt(((eps_xx - eps_yy)/2)^2 + eps_xy^2)"),
    FieldSpec("phi_total_mD", "mD", "total power ||eps||_F / L"),
    FieldSpec("axis_deg", "deg", "astigmatism principal axis (largest stretch), degrees from +x towards +y, in (-90, 90]"),
    FieldSpec("capture_count", "", "number of captures averaged at each sample (several captures only)", kind="label"),
    FieldSpec("quality", "", "quality label: " + ", ".join(f"{k} {v}" for k, v in LABELS.items()), kind="label"),
    FieldSpec("displacement_sigma_mm", "mm", "standard uncertainty of displacement_mm from the image noise, per component "
              "[...,0]=x, [...,1]=y", 2),
    FieldSpec("phi_eff_sigma_mD", "mD", "standard uncertainty of phi_eff_mD from the image noise"),
    FieldSpec("phi_shear_sigma_mD", "mD", "standard uncertainty of phi_shear_mD from the image noise (linearised)"),
    FieldSpec("surface_slope_mrad", "mrad",
              "reflection: front-face slope (dZ/dx, dZ/dy), pane frame, degree N-1 trend removed (glassdist.flatness)", 2),
    FieldSpec("surface_slope_sigma_mrad", "mrad",
              "reflection: standard uncertainty of surface_slope_mrad from the image noise, per component", 2),
    FieldSpec("surface_height_um", "um",
              "reflection: front-face height Z (away from the camera), least-squares integral of the slope, "
              "detrended at degree N"),
    FieldSpec("surface_height_sigma_um", "um",
              "reflection: standard uncertainty of surface_height_um from the image noise (the slope's, through the "
              "integrator and the detrends)"),
)

#: The power channels (mD) that statistics, specifications and heatmaps are about.
CHANNELS: tuple[str, ...] = ("phi_eff_mD", "phi_shear_mD", "phi_total_mD")

_SPECS = {f.name: f for f in FIELDS}


@dataclass(frozen=True)
class Optics:
    """The reflection geometry a result's channels are expressed in (:func:`glassdist.analyzer.reflection.reflect_result`).

    Attributes
    ----------
    board_distance_m : float
        Board-to-pane distance D, m.
    camera_distance_m : float
        Camera-to-pane distance C, m (D with the camera in the board plane).
    camera_in_board_plane : bool
        No camera distance was given: C = D.
    incidence_deg : float
        Angle of incidence theta of the line of sight on the pane at the view's centre, deg.
    plane_of_incidence_deg : float
        Direction of the plane of incidence in the image, deg from +x towards +y.
    magnification : float
        ``m = 1 + D / C``: board mm per pane mm.
    effective_distance_m : float
        ``D / m``, m: the transmission distance the Analyzer ran at.
    notes : tuple of str
        What the channels mean in reflection.
    optics : {'reflection'}
        The kind of optics (``summary.json`` ``optics.optics``).
    """

    board_distance_m: float
    camera_distance_m: float
    camera_in_board_plane: bool
    incidence_deg: float
    plane_of_incidence_deg: float
    magnification: float
    effective_distance_m: float
    notes: tuple[str, ...] = ()
    optics: str = "reflection"

    def to_dict(self) -> dict[str, Any]:
        """The record ``summary.json`` keeps under ``optics``."""
        return {"optics": self.optics, "board_distance_m": self.board_distance_m,
                "camera_distance_m": self.camera_distance_m, "camera_in_board_plane": self.camera_in_board_plane,
                "incidence_deg": self.incidence_deg, "plane_of_incidence_deg": self.plane_of_incidence_deg,
                "magnification": self.magnification, "effective_distance_m": self.effective_distance_m,
                "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Optics:
        """The record :meth:`to_dict` wrote (``summary.json`` ``optics``)."""
        return cls(float(d["board_distance_m"]), float(d["camera_distance_m"]), bool(d["camera_in_board_plane"]),
                   float(d["incidence_deg"]), float(d["plane_of_incidence_deg"]), float(d["magnification"]),
                   float(d["effective_distance_m"]), tuple(d.get("notes", ())), str(d.get("optics", "reflection")))


_R = TypeVar("_R", bound="Result")


@runtime_checkable
class Result(Protocol):
    """The contract of every glassdist result: what acceptance, measures, figures and writers may read.

    :class:`AnalysisResult` (an analysis's own) and :class:`glassdist.storage.StoredResult`
    (a run read back from its folder by :func:`glassdist.load_result`) implement it; code
    downstream of the analysis takes a ``Result`` and asks it, never its class or its
    private state. Lengths in mm, distances in m, powers in mD (the module's conventions).

    Attributes
    ----------
    method : {'comparative', 'direct'}
    pattern : {'lines', 'checkerboard', 'dots'}
        The backdrop pattern the analysis used.
    valid, trusted : ndarray (H, W) bool
        The reported region and, within it, the pixels statistics use (quality label 0).
    detrend_region : ndarray (H, W) bool or None
        The pixels the A2 detrend was fitted on (None: not recorded).
    mm_per_px, pitch_mm, distance_m, sigma_mm, carrier_period_mm : float
    detrend_degree : int
    px_per_period : float
        The shortest carrier period in the photo, px (the capture limit is on it).
    margin_px : (float, float)
        Contamination margins at excluded areas and at the image edges, px.
    optics : Optics or None
        None in transmission; the reflection geometry otherwise.
    analysis_grid : SamplingGrid
        The grid the fields are held on (the pixel grid itself for a pixel-layout file).
    grid_valid, grid_trusted, grid_detrend_region : ndarray (h, w) bool
        The analysed samples of :attr:`analysis_grid`, the trusted ones, and those the A2
        detrend was fitted on.
    """

    @property
    def method(self) -> str:
        """'comparative' or 'direct'."""
        ...

    @property
    def pattern(self) -> str:
        """The backdrop pattern the analysis used."""
        ...

    @property
    def valid(self) -> np.ndarray:
        """The reported region, (H, W) bool."""
        ...

    @property
    def trusted(self) -> np.ndarray:
        """The pixels statistics use (quality label 0), (H, W) bool."""
        ...

    @property
    def detrend_region(self) -> np.ndarray | None:
        """The pixels the A2 detrend was fitted on, (H, W) bool (None: not recorded)."""
        ...

    @property
    def mm_per_px(self) -> float:
        """Backdrop mm per px (reflection: pane mm)."""
        ...

    @property
    def pitch_mm(self) -> float:
        """Grid pitch, mm."""
        ...

    @property
    def distance_m(self) -> float:
        """Glass-to-grid distance L (reflection: board-to-pane D), m."""
        ...

    @property
    def sigma_mm(self) -> float:
        """The reporting smoothing scale, mm."""
        ...

    @property
    def carrier_period_mm(self) -> float:
        """Carrier period on the backdrop, mm."""
        ...

    @property
    def detrend_degree(self) -> int:
        """Total degree of the A2 detrend."""
        ...

    @property
    def px_per_period(self) -> float:
        """Shortest carrier period in the photo, px."""
        ...

    @property
    def margin_px(self) -> tuple[float, float]:
        """Contamination margins (excluded areas, image edge), px."""
        ...

    @property
    def optics(self) -> Optics | None:
        """None in transmission; the reflection geometry otherwise."""
        ...

    @property
    def analysis_grid(self) -> F.SamplingGrid:
        """The grid the fields are held on."""
        ...

    @property
    def grid_valid(self) -> np.ndarray:
        """Analysed samples of :attr:`analysis_grid`, (h, w) bool."""
        ...

    @property
    def grid_trusted(self) -> np.ndarray:
        """Trusted samples of :attr:`analysis_grid`, (h, w) bool."""
        ...

    @property
    def grid_detrend_region(self) -> np.ndarray:
        """Samples of :attr:`analysis_grid` the A2 detrend was fitted on, (h, w) bool."""
        ...

    def field_specs(self) -> tuple[FieldSpec, ...]:
        """The registered fields the result holds, in :data:`FIELDS` order."""
        ...

    def grid_field(self, name: str) -> np.ndarray:
        """Field ``name`` on :attr:`analysis_grid`."""
        ...

    def grid_fields(self) -> dict[str, np.ndarray]:
        """Every field on :attr:`analysis_grid`, by name (a new mapping)."""
        ...

    def with_grid_fields(self: _R, fields: dict[str, np.ndarray], **changes: Any) -> _R:
        """A copy holding ``fields`` on :attr:`analysis_grid` (and ``changes`` applied)."""
        ...

    def pixel_field(self, name: str) -> np.ndarray:
        """Field ``name`` on the input's pixel grid (NaN where invalid)."""
        ...

    def pixel_rows(self, names: Sequence[str], max_pixels: int = 1 << 21
                   ) -> Iterator[tuple[slice, dict[str, np.ndarray]]]:
        """Fields ``names`` on the pixel grid, ``(rows, {name: block})`` one block of image rows at a time."""
        ...


def holds(result: Result, name: str) -> bool:
    """Whether ``result`` holds the registered field ``name``."""
    return any(f.name == name for f in result.field_specs())


def row_blocks(fields: dict[str, np.ndarray], max_pixels: int = 1 << 21
               ) -> Iterator[tuple[slice, dict[str, np.ndarray]]]:
    """``(rows, {name: field[rows]})`` of (H, W[, 2]) fields already on the pixel grid, about ``max_pixels`` each."""
    shapes = {f.shape[:2] for f in fields.values()}
    H, W = shapes.pop() if shapes else (0, 1)
    block_rows = max(1, int(max_pixels) // max(W, 1))
    for r in range(0, H, block_rows):
        rows = slice(r, min(H, r + block_rows))
        yield rows, {n: f[rows] for n, f in fields.items()}


def _row_slices(full: np.ndarray, block_rows: int):
    """``(rows, full[rows])`` for consecutive blocks of ``block_rows`` rows."""
    for r in range(0, full.shape[0], block_rows):
        rows = slice(r, min(full.shape[0], r + block_rows))
        yield rows, full[rows]


class _ImageGridField:
    """A result field kept on the analysis grid, upsampled to the image grid on first access and cached."""

    def __init__(self, name: str):
        self.name = name

    @overload
    def __get__(self, obj: None, objtype: type | None = None) -> _ImageGridField: ...

    @overload
    def __get__(self, obj: AnalysisResult, objtype: type | None = None) -> np.ndarray: ...

    def __get__(self, obj: AnalysisResult | None, objtype: type | None = None) -> _ImageGridField | np.ndarray:
        if obj is None:
            return self
        val = obj.pixel_field(self.name)
        obj.__dict__[self.name] = val  # frozen dataclass: cache beside, not through, __setattr__
        return val


@dataclass(frozen=True)
class AnalysisResult:
    """Everything the Analyzer measured; fields on the input image's pixel grid on access.

    Attributes
    ----------
    method : {'comparative', 'direct'}
    displacement_mm : ndarray (H, W, 2) float32
        delta (x, y) in backdrop mm, camera frame; NaN where invalid. Direct: relative
        to the homography baseline. Comparative: relative to the reference photo.
    displacement_detrended_mm : ndarray (H, W, 2) float32
        delta_* after A2 detrend and metric smoothing (the field differentiated by A3).
    phi_eff_mD, phi_shear_mD, phi_total_mD : ndarray (H, W) float32
        A3 channels, mD; NaN where invalid.
    axis_deg : ndarray (H, W) float32
        Astigmatism principal axis, degrees from +x towards +y, in (-90, 90].
    valid : ndarray (H, W) bool
        The reported region: quality labels 0 (analysed) and 6 (guard band).
    quality : ndarray (H, W) uint8
        Quality label of every pixel (:data:`~glassdist.analyzer.region.LABELS`): 0 analysed,
        1 image edge, 2 occluded / low modulation, 3 beyond measurable distortion, 4 phase
        residue, 5 user mask, 6 guard band (reported, left out of statistics), 7 isolated fragment.
    trusted : ndarray (H, W) bool
        Label 0: the pixels statistics and specifications use.
    detrend_region : ndarray (H, W) bool
        The pixels of the whole analysis-grid blocks the A2 detrend is fitted on. The regions,
        one inside the next: ``trusted`` (statistics) within ``detrend_region`` (A2 fit)
        within ``valid`` (reported); ``valid`` adds the ring of partial blocks along every
        border, at most one analysis block wide (``block_px``), where the fitted polynomial
        is extrapolated.
    displacement_sigma_mm : ndarray (H, W, 2) float32
        Standard uncertainty of each displacement component (x, y) from the image noise, mm.
    phi_eff_sigma_mD, phi_shear_sigma_mD : ndarray (H, W) float32
        Standard uncertainties of phi_eff and phi_shear from the image noise, mD
        (:mod:`~glassdist.analyzer.uncertainty`).
    mm_per_px : float
        Isotropic scale ``p_c sqrt(|f1||f2|)``, backdrop mm per px.
    sigma_mm, detrend_degree, pitch_mm, distance_m
        The evaluation settings and the physical inputs.
    effective_sigma_mm : float or None
        The smoothing the reported fields actually carry, mm: ``sigma_mm``, or the
        instrument's resolution (its largest demodulation blur) when ``sigma_mm`` is finer
        (:mod:`glassdist.analyzer.transfer`). None when the blur is not compensated.
    carrier_period_mm : float
        Carrier period on the backdrop (pitch for lines, pitch*sqrt(2) for checkerboards).
    carriers : CarrierPair
    homography : ndarray (3, 3) or None
        Direct: ``H`` from logical grid (carrier periods) to pixels.
    homography_fit : HomographyFit or None
    params : AnalyzerParams
    warnings : tuple of str
    version : str
    sampling_step_px : (float, float)
        Spacing of the analysis grid, px.
    demodulation_step_px : (float, float)
        Spacing of the demodulation grid the phases were measured on, px (F5 refines the
        one pass's grid where the strong local frequencies need it:
        :func:`~glassdist.analyzer.deform.deformation_grid`); the ``B`` of the transfer.
    n_regions : int
        Connected parts of the valid region (analysed independently).
    captures : tuple of dict
        Several captures averaged (:func:`~glassdist.analyzer.captures.analyze_captures`): per
        capture its grid offset, carrier permutation, largest shift (px) and valid fraction
        on the first capture's grid; empty for one photo.
    margin_px : (float, float)
        Contamination margins applied at excluded areas and at the image edges, px.
    guard_px : float
        Width of the guard band (quality label 6), px.
    noise_std : (float, float or None)
        White noise of the photo and of the reference (Comparative), intensity units,
        estimated from their spectra.
    optics : Optics or None
        None in transmission; in reflection the geometry of
        :func:`glassdist.analyzer.reflection.reflect_result` (the channels are then the
        reflective power on the pane, ``mm_per_px`` and ``sigma_mm`` in pane mm).
    bulk : BulkChannel or None
        The pane-level sphere and cylinder the detrend removed (:mod:`glassdist.analyzer.bulk`),
        or why it is not identifiable (Direct Method).
    demodulations : int
        Demodulations the displacement sums: 1 for the one-pass demodulation, more where F5
        (iterative deformation) ran, its photo passes included; the displacement's transfer per
        carrier follows from it (:mod:`glassdist.analyzer.transfer`: ``G_i``, or
        ``(1 - (1 - G_i B)^n) / B``, with the photo passes as there).
    photo_passes : int
        Of those, F5's photo passes (0: none ran).
    restart_sigma_px : float
        Sigma of the low-pass of the warped reference's field the photo passes started from, px.
    sources : dict
        Where the inputs of :func:`~glassdist.analyzer.pipeline.analyze` came from: the files
        it read, when given paths (:func:`glassdist.io.read_sources`: ``image``,
        ``image_sha256``, ``camera``, ``reference``, ``reference_sha256``, ``mask``), and
        ``given``, the settings the caller chose (:func:`~glassdist.analyzer.params.given_settings`);
        :func:`glassdist.write_outputs` records them. Empty for other results.
    """

    method: str
    valid: np.ndarray
    mm_per_px: float
    sigma_mm: float
    detrend_degree: int
    pitch_mm: float
    distance_m: float
    carrier_period_mm: float
    carriers: F.CarrierPair
    homography: np.ndarray | None
    homography_fit: HomographyFit | None
    params: AnalyzerParams
    warnings: tuple[str, ...]
    version: str = __version__
    sampling_step_px: tuple[float, float] = (1.0, 1.0)
    demodulation_step_px: tuple[float, float] = (1.0, 1.0)
    n_regions: int = 1
    captures: tuple = ()
    margin_px: tuple[float, float] = (0.0, 0.0)
    guard_px: float = 0.0
    noise_std: tuple[float, float | None] = (float("nan"), None)
    effective_sigma_mm: float | None = None
    optics: Optics | None = None
    bulk: BulkChannel | None = None
    demodulations: int = 1
    photo_passes: int = 0
    restart_sigma_px: float = 0.0
    sources: dict = field(default_factory=dict, compare=False)
    _deferred: dict | None = field(default=None, repr=False, compare=False)

    # Declared here so that its type is known where the class uses it; the loop after the class adds every field.
    quality = _ImageGridField("quality")

    def _held(self) -> dict[str, Any]:
        """The fields on :attr:`analysis_grid` and what brings them to the pixel grid (``fields``, ``grid``, ``idx``, ...)."""
        if self._deferred is None:
            raise AttributeError("this result holds no fields on the analysis grid")
        return self._deferred

    def field_specs(self) -> tuple[FieldSpec, ...]:
        """The registered fields this result holds, in :data:`FIELDS` order."""
        held = self._deferred["fields"] if self._deferred else {}
        return tuple(f for f in FIELDS if f.name in held)

    @property
    def analysis_grid(self) -> F.SamplingGrid:
        """The grid the fields are computed on (sample centres in image px, see :class:`SamplingGrid`)."""
        return self._held()["grid"]

    def grid_field(self, name: str) -> np.ndarray:
        """Field ``name`` on :attr:`analysis_grid` (float32, NaN outside the analysed region)."""
        if self._deferred is None or name not in self._deferred["fields"]:
            raise AttributeError(name)
        return self._deferred["fields"][name]

    def grid_fields(self) -> dict[str, np.ndarray]:
        """Every field on :attr:`analysis_grid`, by name (a new mapping; the arrays are the result's own)."""
        return dict(self._deferred["fields"]) if self._deferred else {}

    def with_grid_fields(self, fields: dict[str, np.ndarray], **changes: Any) -> AnalysisResult:
        """A copy of the result whose fields on :attr:`analysis_grid` are ``fields`` (and ``changes`` applied, as
        :func:`dataclasses.replace`): a later stage re-expresses the fields without reaching into the result."""
        held = self._deferred or {}
        return replace(self, **changes, _deferred={**held, "fields": fields})

    def pixel_field(self, name: str) -> np.ndarray:
        """Field ``name`` brought to the input's pixel grid (not cached; the attribute is)."""
        f = self.grid_field(name)
        d = self._held()
        if name == "quality":
            return pixel_quality(f, d.get("label_grid", d["grid"]), self.valid, d.get("mask"), self.margin_px[1])
        if _SPECS[name].kind == "label":
            return upsample_labels(f, d["grid"])
        if name == "axis_deg":
            return upsample_axis(f, self.grid_field("phi_shear_mD"), d["idx"], d["grid"], ~self.valid)
        return upsample_field(f, d["idx"], d["grid"], ~self.valid)

    def pixel_rows(self, names: Sequence[str], max_pixels: int = 1 << 21
                   ) -> Iterator[tuple[slice, dict[str, np.ndarray]]]:
        """Fields ``names`` on the pixel grid, one block of image rows at a time.

        Yields ``(rows, {name: block})`` with ``rows`` a ``slice`` of image rows and each
        block bit-identical to ``getattr(self, name)[rows]``, about ``max_pixels`` pixels
        each: statistics over a 100 Mpx photo need no full-size copy of any field.
        A field already brought to the pixel grid (cached) is sliced.
        """
        H, W = self.valid.shape
        block_rows = max(1, int(max_pixels) // max(W, 1))
        streams = []
        for name in names:
            if name in self.__dict__ or _SPECS[name].kind == "label":
                streams.append(_row_slices(getattr(self, name), block_rows))
                continue
            f = self.grid_field(name)
            d = self._held()
            if name == "axis_deg":
                streams.append(upsample_axis_rows(f, self.grid_field("phi_shear_mD"), d["idx"], d["grid"], ~self.valid,
                                                  block_rows))
            else:
                streams.append(upsample_field_rows(f, d["idx"], d["grid"], ~self.valid, block_rows))
        for blocks in zip(*streams):
            yield blocks[0][0] if blocks else slice(0, H), {n: b for n, (_, b) in zip(names, blocks)}

    @property
    def grid_valid(self) -> np.ndarray:
        """``(h, w)`` bool: the samples of :attr:`analysis_grid` inside the analysed region.

        The valid samples are those the nearest-valid fill of the upsampling maps to themselves.
        """
        idx = self._held()["idx"]
        h, w = self.analysis_grid.shape
        if idx is None:  # all samples valid, or none
            return np.full((h, w), bool(self.valid.any()))
        return (idx[0] == np.arange(h)[:, None]) & (idx[1] == np.arange(w)[None, :])

    @cached_property
    def grid_trusted(self) -> np.ndarray:
        """Trusted samples (quality label 0 throughout the block) on :attr:`analysis_grid`, bool (h, w)."""
        d = self._deferred
        q = d["fields"].get("quality") if d else None
        return np.ones(self.analysis_grid.shape, bool) if q is None else trusted_on(q, self.analysis_grid.shape)

    @cached_property
    def detrend_region(self) -> np.ndarray:
        """Pixels of the whole blocks the A2 detrend is fitted on (see the class notes), bool (H, W)."""
        d = self._deferred
        fit = d.get("fit_valid") if d else None
        if fit is None:
            return self.valid
        import cv2

        H, W = self.valid.shape
        return self.valid & cv2.resize(fit.view(np.uint8), (W, H), interpolation=cv2.INTER_NEAREST).view(bool)

    @property
    def grid_detrend_region(self) -> np.ndarray:
        """(h, w) bool: the samples of :attr:`analysis_grid` the A2 detrend was fitted on (``grid_valid`` where not recorded)."""
        fit = self._deferred.get("fit_valid") if self._deferred else None
        gv = np.asarray(self.grid_valid, dtype=bool)
        return gv if fit is None else gv & np.asarray(fit, dtype=bool)

    @property
    def pattern(self) -> str:
        """The backdrop pattern the analysis used (``params.pattern``)."""
        return str(self.params.pattern)

    @property
    def px_per_period(self) -> float:
        """Shortest carrier period of the photo, px (the capture limit ``min_px_per_period`` is on it)."""
        return float(min(self.carriers.k1.period_px, self.carriers.k2.period_px))

    @property
    def block_px(self) -> float:
        """Width of one analysis-grid block (its larger step), px: the ring ``valid`` adds to ``detrend_region``."""
        return float(max(self.sampling_step_px))

    @cached_property
    def trusted(self) -> np.ndarray:
        """Pixels of quality label 0 (analysed, outside the guard band): what statistics use."""
        if self._deferred is None or "quality" not in self._deferred["fields"]:
            return self.valid
        return self.quality == ANALYSED

    def _requested(self) -> int:
        mask = self._deferred.get("mask") if self._deferred else None
        return int(np.count_nonzero(mask)) if mask is not None else self.valid.size

    @property
    def valid_fraction(self) -> float:
        """Reported share of the requested region (the user mask, else the whole image)."""
        return float(np.count_nonzero(self.valid)) / max(self._requested(), 1)

    @property
    def trusted_fraction(self) -> float:
        """Share of the requested region that is trusted (quality label 0)."""
        return float(np.count_nonzero(self.trusted)) / max(self._requested(), 1)

    def statistics(self) -> dict:
        """Per-channel statistics over the trusted pixels (see :func:`channel_statistics`)."""
        return {name: channel_statistics(getattr(self, name), self.trusted) for name in CHANNELS}

    def noise_floor(self) -> dict:
        """Median and 95th percentile of each standard-uncertainty channel over the trusted samples.

        Returns
        -------
        dict
            ``{"phi_eff_sigma_mD": {"median": ..., "p95": ...}, "phi_shear_sigma_mD": ...}`` (mD; NaN
            where nothing is trusted); empty without uncertainty fields. Taken on the analysis
            grid: the pixel-grid maps are its interpolation.
        """
        out = {}
        held = {f.name for f in self.field_specs()}
        for name in ("phi_eff_sigma_mD", "phi_shear_sigma_mD"):
            if name not in held:
                continue
            f = np.asarray(self.grid_field(name), dtype=np.float64)
            v = f[self.grid_valid & self.grid_trusted & np.isfinite(f)]
            med, p95 = (np.percentile(v, [50, 95]) if v.size else (np.nan, np.nan))
            out[name] = {"median": float(med), "p95": float(p95)}
        return out

    def quality_counts(self) -> dict:
        """Pixels per quality label, ``{label name: count}``."""
        q = np.asarray(self.quality)
        # one comparison per label: bincount would first widen every uint8 label to intp
        return {LABELS[k]: int(np.count_nonzero(q == k)) for k in LABELS}

    def summary(self, statistics: dict | None = None) -> dict:
        """JSON-serialisable record of the run (written as ``summary.json``).

        ``statistics``: :meth:`statistics` already computed (with more entries, e.g. the
        area over a specification's limits), instead of computing them again.
        """
        return {
            "glassdist_version": self.version,
            "method": self.method,
            "image_shape": list(self.valid.shape),
            "pitch_mm": self.pitch_mm,
            "pattern": self.params.pattern,
            "carrier_period_mm": self.carrier_period_mm,
            "distance_m": self.distance_m,
            "mm_per_px": self.mm_per_px,
            "sigma_mm": self.sigma_mm,
            "sigma_px": self.sigma_mm / self.mm_per_px,
            "effective_sigma_mm": self.effective_sigma_mm,
            "detrend_degree": self.detrend_degree,
            "carriers": self.carriers.to_dict(),
            "homography": None if self.homography_fit is None else self.homography_fit.to_dict(),
            "bulk": None if self.bulk is None else self.bulk.to_dict(),
            # percent of the region asked for (the mask, else the image): measured, and trusted (quality 0)
            "measured_percent": 100.0 * self.valid_fraction,
            "trusted_percent": 100.0 * self.trusted_fraction,
            "quality_counts": self.quality_counts(),
            "noise_floor_mD": self.noise_floor(),
            "margin_px": {"excluded_areas": self.margin_px[0], "image_edge": self.margin_px[1]},
            "guard_px": self.guard_px,
            "noise_std": {"image": self.noise_std[0], "reference": self.noise_std[1]},
            "n_regions": self.n_regions,
            "sampling_step_px": list(self.sampling_step_px),
            "demodulation_step_px": list(self.demodulation_step_px),
            "statistics": self.statistics() if statistics is None else statistics,
            # the smoothing actually used (the default, null, means 2 carrier periods)
            "parameters": {**self.params.resolved(), "sigma_mm": self.sigma_mm},
            "warnings": list(self.warnings),
            **({"captures": list(self.captures)} if self.captures else {}),
            "conventions": {
                "displacement": ("landing point on the backdrop with glass minus without, mm; "
                                 "[...,0]=x (columns), [...,1]=y (rows)"),
                "phi_eff": "tr(sym grad delta)/L in mD, gradients w.r.t. backdrop mm; converging lens -> phi_eff < 0",
                "axis_deg": "astigmatism principal axis, degrees from +x towards +y (down)",
            } if self.optics is None else {
                "displacement": "landing point on the board with the pane minus with a flat reference surface, board mm",
                "phi_eff": "tr P in mD, P = 2 [[Z_tt/cos, Z_ts], [Z_ts, Z_ss cos]] the reflective power on the pane's "
                           "coordinates (glassdist.analyzer.reflection); concave pane -> phi_eff < 0",
                "axis_deg": "axis of the larger principal power, degrees from +x towards +y (down)",
            },
            **({"optics": self.optics.to_dict()} if self.optics is not None else {}),
        }


# One cached pixel-grid attribute per registered field.
for _f in FIELDS:
    setattr(AnalysisResult, _f.name, _ImageGridField(_f.name))
del _f
