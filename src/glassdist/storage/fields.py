"""The fields and tables of a run on disk: ``result.npz`` (written and read back), statistics, exports.

``result.npz`` layouts (``fields=``):

* ``'analysis'`` (default, compact): every registered field
  (:data:`glassdist.analyzer.FIELDS`) on the analysis grid, float32, NaN outside the
  analysed region, with :data:`GRID_KEYS`: the samples' pixel coordinates, the grid's
  valid samples and the pixel-grid region as bits. :func:`load_result` reads it back and
  brings any field to the pixel grid exactly as the analysis does; ``detrend_region`` is
  the (h, w) samples the A2 detrend was fitted on, ``detrend_region_bits`` its pixels. An NPZ with coordinate
  vectors, rather than NetCDF or Zarr: it is what the pixel-grid file already is
  (``numpy.load``, nothing to install), the grid is regular (two vectors place every
  sample) and the units are in the key names, as everywhere in glassdist.
* ``'pixel'``: the documented pixel-grid file, ``displacement_mm`` (H, W, 2; x, y),
  ``displacement_detrended_mm``, ``phi_eff_mD``, ``phi_shear_mD``, ``phi_total_mD``,
  ``axis_deg`` (NaN where invalid), the other registered fields, ``valid`` and
  ``detrend_region`` (the pixels the A2 detrend was fitted on); written member by member,
  one field on the pixel grid at a time.

The regions, one inside the next (:data:`REGION_DESCRIPTIONS`, also in ``summary.json``):
``trusted`` (quality label 0: statistics) within ``detrend_region`` (the A2 fit) within
``valid`` (reported). A truth meant to reproduce the maps is detrended on
``detrend_region`` and compared on ``trusted``.

Exports for other tools (each file written to a temporary name, then renamed, so a
reader never sees half a file):

* ``statistics.csv``: one row per channel, columns ``<statistic>_mD`` and
  ``area_over_<T>_percent`` (see :mod:`glassdist.acceptance.stats`);
* ``fields.npz``: every registered field of the result (:data:`glassdist.analyzer.FIELDS`:
  ``displacement_mm`` (H, W, 2; ``[..., 0] = x``, ``[..., 1] = y``),
  ``displacement_detrended_mm``, ``phi_eff_mD``, ``phi_shear_mD``, ``phi_total_mD``,
  ``axis_deg``, uncertainty and label maps) on the pixel grid, ``valid``, ``detrend_region``, plus scalars
  ``mm_per_px``, ``distance_m``, ``pitch_mm``, ``sigma_mm`` and the string ``version``
  (float fields are float32, NaN where invalid; label maps uint8);
* ``tiff/<name>.tif``: the same fields, one TIFF each (vector fields split into
  ``<name>_x_<unit>`` and ``<name>_y_<unit>``, e.g. ``displacement_x_mm``), ``valid.tif``
  as uint8 0/1; the TIFF description holds a JSON object with the unit and the glassdist
  version. Fields are brought to the pixel grid one at a time.
"""

from __future__ import annotations

import csv
import io
import json
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..acceptance.stats import STATISTICS
from ..errors import InputError
from ..fs import atomic_write, atomic_write_bytes, atomic_write_text

if TYPE_CHECKING:
    from ..analyzer.fourier import SamplingGrid
    from ..analyzer.result import FieldSpec, Optics

__all__ = [
    "SUMMARY_NAME", "FIELD_LAYOUTS", "GRID_KEYS", "REGION_DESCRIPTIONS", "region_summary", "StoredResult", "grid_members",
    "load_result", "pixel_members", "statistics_table",
    "tiff_names", "write_fields_npz", "write_fields_tiff", "write_npz", "write_statistics_csv",
]


def statistics_table(stats):
    """Rows (list of dicts) of the statistics table, one per channel, values rounded to 6 significant digits."""
    area_keys = sorted({k for s in stats.values() for k in s if k.startswith("area_over_")},
                       key=lambda k: float(k.removeprefix("area_over_")))
    rows = []
    for channel, s in stats.items():
        row = {"channel": channel}
        row.update({f"{k}_mD": _fmt(s.get(k)) for k in STATISTICS})
        row.update({f"{k}_percent": _fmt(s.get(k)) for k in area_keys})
        row["n_valid"] = s.get("n_valid", "")
        rows.append(row)
    return rows


def _fmt(v):
    if v is None:
        return ""
    v = float(v)
    return "" if np.isnan(v) else f"{v:.6g}"


def write_statistics_csv(stats, path, *, digests=None):
    """Write :func:`statistics_table` of ``{channel: statistics}`` as CSV; returns the path."""
    rows = statistics_table(stats)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else ["channel"], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return atomic_write_text(path, buf.getvalue(), digests=digests)


def _planes(spec):
    """``[(tiff stem, component index or None, unit)]`` of a field: vector fields split into x and y."""
    if spec.components == 1:
        return [(spec.name, None, spec.unit)]
    suffix = f"_{spec.unit}" if spec.unit else ""
    stem = spec.name.removesuffix(suffix)
    return [(f"{stem}_{axis}{suffix}", c, spec.unit) for c, axis in enumerate("xy")]


def tiff_names(specs):
    """File names under ``tiff/`` for the fields ``specs`` (``valid.tif`` last)."""
    return [f"{stem}.tif" for spec in specs for stem, _, _ in _planes(spec)] + ["valid.tif"]


def _pixel_arrays(result):
    """``(spec, array)`` of each registered field on the pixel grid (float32; labels uint8), one at a time."""
    for spec in result.field_specs():
        a = result.pixel_field(spec.name)
        yield spec, (a.astype(np.float32, copy=False) if spec.kind == "float" else a.astype(np.uint8, copy=False))
        del a


def write_fields_npz(result, path, *, digests=None):
    """Write every field (pixel grid), ``valid`` and the scalars as an NPZ, one field at a time; returns the path.

    The label maps and ``valid`` are deflated (to a few per cent); the float fields are stored
    as they are, as in a pixel-grid ``result.npz``: deflate took them to 0.79-0.86 of their size
    only, for 2 s per Mpx (the bundled waves photo: 2.1 s of a 12 s ``--report --export`` run).
    """
    def members():
        for spec, a in _pixel_arrays(result):
            yield spec.name, a, spec.kind != "float"
        yield "valid", np.asarray(result.valid, dtype=bool), True
        yield "detrend_region", np.asarray(result.detrend_region, dtype=bool), True
        for name in ("mm_per_px", "distance_m", "pitch_mm", "sigma_mm"):
            yield name, np.float64(getattr(result, name)), False
        yield "version", np.str_(result.version), False

    return atomic_write(path, lambda fh: write_npz(fh, members()), digests=digests)


def write_fields_tiff(result, folder, *, digests=None):
    """Write each field (pixel grid) as a TIFF in ``folder`` (created), one plane at a time; returns the paths."""
    import tifffile

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)

    def tiff(data, name, unit):
        buf = io.BytesIO()
        meta = {"field": name, "unit": unit, "glassdist_version": result.version, "invalid": "NaN"}
        data = np.ascontiguousarray(data)
        # the floating-point predictor (TIFF Technical Note 3, Predictor = 3, which GDAL and libtiff read)
        # before deflate: smooth float fields to about 0.65 of their size instead of 0.86, a little faster
        tifffile.imwrite(buf, data, description=json.dumps(meta), compression="zlib", compressionargs={"level": 1},
                         predictor=3 if data.dtype.kind == "f" else None)
        return atomic_write_bytes(folder / f"{name}.tif", buf.getbuffer(), digests=digests)

    written = []
    for spec, a in _pixel_arrays(result):
        written += [tiff(a if c is None else a[..., c], stem, unit) for stem, c, unit in _planes(spec)]
        del a
    written.append(tiff(np.asarray(result.valid, dtype=np.uint8), "valid", "1 = analysed"))
    return written


#: the run's summary (the typed run record, :mod:`glassdist.storage.record`), written last
SUMMARY_NAME = "summary.json"

#: ``fields=`` choices: the analysis grid (compact, default) or the input's pixel grid
FIELD_LAYOUTS = ("analysis", "pixel")


#: keys of the compact ``result.npz`` besides the fields
GRID_KEYS = {
    "layout": "'analysis' (this layout)",
    "image_shape": "(H, W) of the input image, px",
    "grid_rows_px": "(h,) row coordinate of each analysis-grid row in image pixels (pixel centres at integers)",
    "grid_cols_px": "(w,) column coordinate of each analysis-grid column, px",
    "grid_valid": "(h, w) bool: analysis-grid samples inside the analysed region",
    "valid_bits": "numpy.packbits of the (H, W) pixel-grid valid region, row-major",
    "detrend_region": "(h, w) bool: analysis-grid samples the A2 detrend was fitted on (whole blocks)",
    "detrend_region_bits": "numpy.packbits of the (H, W) pixel-grid detrend region, row-major",
    "mm_per_px": "backdrop mm per image px (mean scale)",
}


#: What each region of a result is (``summary.json``'s ``regions``); one inside the next
REGION_DESCRIPTIONS = {
    "valid": "the reported region: quality labels 0 (analysed) and 6 (guard band); every map is finite there",
    "detrend_region": "the pixels the A2 detrend was fitted on: the whole analysis-grid blocks of the reported "
                      "region; the polynomial fitted there is subtracted over all of valid (extrapolated on the ring "
                      "of partial blocks valid adds, at most one analysis block wide). A truth meant to reproduce the "
                      "maps is detrended on this region",
    "trusted": "quality label 0, within detrend_region: the pixels statistics and specifications use",
}


def region_summary(result) -> dict:
    """``summary.json``'s ``regions``: per region its description, pixel count and share of the image, percent."""
    n = max(int(np.asarray(result.valid).size), 1)
    regions = {"valid": result.valid, "detrend_region": result.detrend_region, "trusted": result.trusted}
    return {name: {"description": REGION_DESCRIPTIONS[name], "pixels": int(np.count_nonzero(r)),
                   "image_percent": 100.0 * np.count_nonzero(r) / n}
            for name, r in regions.items()}


def write_npz(fh, members) -> None:
    """Write an NPZ member by member: ``members`` yields ``(key, array, compress)``, one array at a time.

    Only the array being written is held (a generator can produce each plane when asked);
    ``numpy.load`` reads the file like any ``numpy.savez`` output.
    """
    with zipfile.ZipFile(fh, "w", allowZip64=True) as zf:
        for key, arr, compress in members:
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
            if compress:
                info._compresslevel = 1  # fast: the members compressed are masks
            with zf.open(info, "w", force_zip64=True) as m:
                np.lib.format.write_array(m, np.asanyarray(arr), allow_pickle=False)


def grid_members(result):
    """``result.npz`` members of the analysis-grid layout (:data:`GRID_KEYS` and the fields)."""
    grid = result.analysis_grid
    rows, cols = grid.coords()
    gv = np.asarray(result.grid_valid, dtype=bool)
    yield "layout", np.str_("analysis"), False
    yield "image_shape", np.asarray(grid.full_shape, dtype=np.int64), False
    yield "grid_rows_px", rows[:, 0].astype(np.float64), False
    yield "grid_cols_px", cols[0].astype(np.float64), False
    yield "grid_valid", gv, True
    yield "valid_bits", np.packbits(np.asarray(result.valid, dtype=bool), axis=None), True
    yield "detrend_region", result.grid_detrend_region, True
    yield "detrend_region_bits", np.packbits(np.asarray(result.detrend_region, dtype=bool), axis=None), True
    yield "mm_per_px", np.float64(result.mm_per_px), False
    for spec in result.field_specs():
        if spec.kind == "float":
            f = np.array(result.grid_field(spec.name), dtype=np.float32)
            f[~gv] = np.nan
            yield spec.name, f, False
        else:  # label maps: on the pixel grid (their own rules there), compressed to a few hundred kB
            yield spec.name, result.pixel_field(spec.name), True


def pixel_members(result, on_plane=None):
    """``result.npz`` members of the pixel-grid layout: each field brought to the pixel grid, one at a time."""
    for spec in result.field_specs():
        plane = result.pixel_field(spec.name)
        if on_plane is not None:
            on_plane(spec.name, plane)
        yield spec.name, plane, False
        del plane
    yield "valid", np.asarray(result.valid, dtype=bool), False
    yield "detrend_region", np.asarray(result.detrend_region, dtype=bool), True


@dataclass(frozen=True)
class StoredResult:
    """A run's fields read back from its folder (:func:`load_result`): a :class:`~glassdist.analyzer.result.Result`.

    The settings (``method``, ``mm_per_px``, ``sigma_mm``, ...) are those ``summary.json``
    records; acceptance, measures and figures take it as they take the analysis's own result.

    Attributes
    ----------
    layout : {'analysis', 'pixel'}
        How ``result.npz`` stores the fields.
    fields : dict of str -> ndarray
        As stored: on the analysis grid (h, w[, 2]) or on the pixel grid (H, W[, 2]);
        float32, NaN outside the analysed region.
    valid : ndarray (H, W) bool
        The analysed region on the pixel grid.
    grid_valid : ndarray (h, w) bool
        The analysed samples of the analysis grid (``valid`` for the pixel layout).
    grid_rows_px, grid_cols_px : ndarray
        Pixel coordinates of the stored rows and columns (integers 0..H-1, 0..W-1 for the
        pixel layout).
    summary : dict
        ``summary.json``.
    detrend_region : ndarray (H, W) bool or None
        The pixels the A2 detrend was fitted on (within ``valid``); None for a file written
        before it was recorded.
    grid_detrend : ndarray (h, w) bool or None
        The samples of the analysis grid the A2 detrend was fitted on, where recorded.
    """

    layout: str
    fields: dict[str, np.ndarray]
    valid: np.ndarray
    grid_valid: np.ndarray
    grid_rows_px: np.ndarray
    grid_cols_px: np.ndarray
    summary: dict[str, Any]
    detrend_region: np.ndarray | None = None
    grid_detrend: np.ndarray | None = None

    @classmethod
    def on_pixel_grid(cls, fields: dict[str, np.ndarray], valid: np.ndarray, **summary: Any) -> StoredResult:
        """A result of fields already on the pixel grid (maps from elsewhere, closed forms in tests).

        ``summary``: the settings ``summary.json`` would record (``method``, ``mm_per_px``, ``sigma_mm``, ...).
        """
        valid = np.asarray(valid, dtype=bool)
        H, W = valid.shape
        return cls("pixel", dict(fields), valid, valid, np.arange(H, dtype=np.float64), np.arange(W, dtype=np.float64),
                   dict(summary))

    # -- the settings summary.json records
    @property
    def method(self) -> str:
        """'comparative' or 'direct'."""
        return str(self.summary["method"])

    @property
    def pattern(self) -> str:
        """The backdrop pattern the analysis used."""
        return str(self.summary["pattern"])

    @property
    def mm_per_px(self) -> float:
        """Backdrop (reflection: pane) mm per px."""
        return float(self.summary["mm_per_px"])

    @property
    def pitch_mm(self) -> float:
        """Grid pitch, mm."""
        return float(self.summary["pitch_mm"])

    @property
    def distance_m(self) -> float:
        """Glass-to-grid distance L (reflection: D), m."""
        return float(self.summary["distance_m"])

    @property
    def sigma_mm(self) -> float:
        """The reporting smoothing scale, mm."""
        return float(self.summary["sigma_mm"])

    @property
    def carrier_period_mm(self) -> float:
        """Carrier period on the backdrop, mm."""
        return float(self.summary["carrier_period_mm"])

    @property
    def detrend_degree(self) -> int:
        """The A2 detrend's total degree."""
        return int(self.summary["detrend_degree"])

    @property
    def px_per_period(self) -> float:
        """Shortest carrier period of the photo, px."""
        c = self.summary["carriers"]
        return float(min(c["k1"]["period_px"], c["k2"]["period_px"]))

    @property
    def margin_px(self) -> tuple[float, float]:
        """Contamination margins at excluded areas and at the image edges, px."""
        m = self.summary.get("margin_px") or {}
        return float(m.get("excluded_areas", 0.0)), float(m.get("image_edge", 0.0))

    @property
    def optics(self) -> Optics | None:
        """None in transmission; the reflection geometry otherwise."""
        from ..analyzer.result import Optics

        d = self.summary.get("optics")
        return None if d is None else d if isinstance(d, Optics) else Optics.from_dict(d)

    # -- the fields
    @property
    def trusted(self) -> np.ndarray:
        """Pixels of quality label 0 (``valid`` where no quality map is stored)."""
        from ..analyzer.region import ANALYSED

        return self.valid if "quality" not in self.fields else self.pixel_field("quality") == ANALYSED

    @property
    def analysis_grid(self) -> SamplingGrid:
        """The grid the fields are stored on (the pixel grid for the pixel layout)."""
        from ..analyzer.fourier import SamplingGrid

        return SamplingGrid(tuple(self.valid.shape), tuple(self.grid_valid.shape))

    @property
    def grid_trusted(self) -> np.ndarray:
        """(h, w) bool: the samples of :attr:`analysis_grid` whose centre pixel is trusted."""
        if self.layout == "pixel":
            return self.trusted
        yy, xx = self.analysis_grid.coords()
        H, W = self.valid.shape
        return self.trusted[np.clip(np.rint(yy).astype(np.intp), 0, H - 1), np.clip(np.rint(xx).astype(np.intp), 0, W - 1)]

    @property
    def grid_detrend_region(self) -> np.ndarray:
        """(h, w) bool: the samples the A2 detrend was fitted on (``grid_valid`` where not recorded)."""
        gv = np.asarray(self.grid_valid, dtype=bool)
        if self.layout == "pixel" and self.detrend_region is not None:
            return gv & self.detrend_region
        return gv if self.grid_detrend is None else gv & self.grid_detrend

    def field_specs(self) -> tuple[FieldSpec, ...]:
        """The registered fields the file holds, in :data:`~glassdist.analyzer.FIELDS` order."""
        from ..analyzer.result import FIELDS

        return tuple(f for f in FIELDS if f.name in self.fields)

    def grid_field(self, name: str) -> np.ndarray:
        """Field ``name`` as stored, on :attr:`analysis_grid` (a label map of the analysis layout is on the pixel grid)."""
        if name not in self.fields or self.fields[name].shape[:2] != self.grid_valid.shape:
            raise AttributeError(name)
        return self.fields[name]

    def grid_fields(self) -> dict[str, np.ndarray]:
        """Every field as stored, by name (a new mapping)."""
        return dict(self.fields)

    def with_grid_fields(self, fields: dict[str, np.ndarray], **changes: Any) -> StoredResult:
        """A copy holding ``fields``; ``changes`` are settings of ``summary``."""
        return replace(self, fields=dict(fields), summary={**self.summary, **changes})

    def pixel_field(self, name: str) -> np.ndarray:
        """Field ``name`` on the input's pixel grid, brought there exactly as the analysis does."""
        if name not in self.fields:
            raise KeyError(f"'{name}' is not a field of this result; it holds {', '.join(self.fields)}")
        f = self.fields[name]
        if self.layout == "pixel" or f.shape[:2] == self.valid.shape:  # label maps are stored on the pixel grid
            return f
        from ..analyzer.resample import grid_fill_indices, upsample_axis, upsample_field, upsample_labels

        grid = self.analysis_grid
        if f.dtype.kind != "f":
            return upsample_labels(f, grid)
        idx = grid_fill_indices(self.grid_valid)
        if name == "axis_deg":
            return upsample_axis(f, self.fields.get("phi_shear_mD"), idx, grid, ~self.valid)
        return upsample_field(f, idx, grid, ~self.valid)

    def pixel_rows(self, names: Sequence[str], max_pixels: int = 1 << 21
                   ) -> Iterator[tuple[slice, dict[str, np.ndarray]]]:
        """Fields ``names`` on the pixel grid, ``(rows, {name: block})`` by blocks of about ``max_pixels`` pixels."""
        from ..analyzer.result import row_blocks

        yield from row_blocks({n: self.pixel_field(n) for n in names}, max_pixels)

    def to_pixel_grid(self) -> dict[str, np.ndarray]:
        """Every field on the pixel grid, ``valid`` and ``detrend_region``: ``--fields pixel``'s result.npz keys."""
        regions = {"valid": self.valid}
        if self.detrend_region is not None:
            regions["detrend_region"] = self.detrend_region
        return {**{name: self.pixel_field(name) for name in self.fields}, **regions}


def load_result(out_dir) -> StoredResult:
    """Read the fields of a ``glassdist analyze`` run from its output folder.

    Parameters
    ----------
    out_dir : path
        Folder holding ``result.npz`` and ``summary.json`` (either layout).

    Returns
    -------
    StoredResult
        ``.fields`` as stored, ``.pixel_field(name)`` / ``.to_pixel_grid()`` on the pixel grid.

    Raises
    ------
    InputError
        No readable glassdist result in ``out_dir``.

    Examples
    --------
    >>> res = glassdist.load_result("out/waves")                    # doctest: +SKIP
    >>> res.fields["phi_eff_mD"].shape, res.pixel_field("phi_eff_mD").shape  # doctest: +SKIP
    ((150, 150), (1024, 1024))
    """
    from ..analyzer.result import FIELDS

    out_dir = Path(out_dir)
    try:
        summary = json.loads((out_dir / SUMMARY_NAME).read_text(encoding="utf-8"))
        z = np.load(out_dir / "result.npz", allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputError(f"'{out_dir}' holds no readable glassdist result ({exc}); give the --out folder of a "
                         "'glassdist analyze' run") from None
    with z:
        names = [f.name for f in FIELDS if f.name in z.files]
        fields = {n: z[n] for n in names}
        if "layout" in z.files and str(z["layout"]) == "analysis":
            H, W = (int(v) for v in z["image_shape"])
            valid = np.unpackbits(z["valid_bits"], count=H * W).reshape(H, W).astype(bool)
            fit = (np.unpackbits(z["detrend_region_bits"], count=H * W).reshape(H, W).astype(bool)
                   if "detrend_region_bits" in z.files else None)
            grid_fit = z["detrend_region"] if "detrend_region" in z.files else None
            return StoredResult("analysis", fields, valid, z["grid_valid"], z["grid_rows_px"], z["grid_cols_px"],
                                summary, fit, grid_fit)
        valid = z["valid"]
        fit = z["detrend_region"] if "detrend_region" in z.files else None
    H, W = valid.shape
    return StoredResult("pixel", fields, valid, valid, np.arange(H, dtype=np.float64), np.arange(W, dtype=np.float64),
                        summary, fit)
