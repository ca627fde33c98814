"""Exports for other tools: statistics as CSV, fields as NPZ and 32-bit float TIFF.

Files written into the output folder (each written to a temporary name, then
renamed, so a reader never sees half a file):

* ``statistics.csv``: one row per channel, columns ``<statistic>_mD`` and
  ``area_over_<T>_percent`` (see :mod:`glassdist.report.stats`);
* ``fields.npz``: every registered field of the result (:data:`glassdist.analyzer.FIELDS`:
  ``displacement_mm`` (H, W, 2; ``[..., 0] = x``, ``[..., 1] = y``),
  ``displacement_detrended_mm``, ``phi_eff_mD``, ``phi_shear_mD``, ``phi_total_mD``,
  ``axis_deg``, uncertainty and label maps) on the pixel grid, ``valid``, plus scalars
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
import os
import secrets
from pathlib import Path

import numpy as np

from .stats import STATISTICS

__all__ = ["to_jsonable", "resolved_parameters", "atomic_write", "atomic_write_bytes", "atomic_write_text", "write_statistics_csv", "write_fields_npz", "write_fields_tiff", "tiff_names"]



def to_jsonable(obj):
    """``obj`` with numpy values turned into Python ones and NaN / inf into ``None`` (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.generic,)):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    return str(obj)


def resolved_parameters(result):
    """The analyzer parameters a result was computed with, as recorded in summary.json and the report.

    ``result.params.resolved()`` with ``sigma_mm`` replaced by the smoothing scale actually
    used (the parameter's default, ``None``, stands for 2 carrier periods).
    """
    params = getattr(result, "params", None)
    resolved = dict(params.resolved()) if params is not None else {}
    if getattr(result, "sigma_mm", None) is not None:
        resolved["sigma_mm"] = result.sigma_mm
    return resolved


def atomic_write(path, write):
    """Write ``path`` by calling ``write(fh)`` on a temporary file in the same folder, then renaming it.

    A reader sees either the previous file or the complete new one, never a part; the
    data is streamed (nothing is held in memory). The file gets the usual permissions
    (``0o666`` less the umask).

    Returns
    -------
    Path
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path, data):
    """:func:`atomic_write` of ``data`` (bytes)."""
    return atomic_write(path, lambda fh: fh.write(data))


def atomic_write_text(path, text):
    """:func:`atomic_write_bytes` for UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8"))


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


def write_statistics_csv(stats, path):
    """Write :func:`statistics_table` of ``{channel: statistics}`` as CSV; returns the path."""
    rows = statistics_table(stats)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else ["channel"], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return atomic_write_text(path, buf.getvalue())


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


def write_fields_npz(result, path):
    """Write every field (pixel grid), ``valid`` and the scalars as a compressed NPZ, one field at a time; returns the path."""
    from .outputs import write_npz

    def members():
        for spec, a in _pixel_arrays(result):
            yield spec.name, a, True
        yield "valid", np.asarray(result.valid, dtype=bool), True
        for name in ("mm_per_px", "distance_m", "pitch_mm", "sigma_mm"):
            yield name, np.float64(getattr(result, name)), False
        yield "version", np.str_(result.version), False

    return atomic_write(path, lambda fh: write_npz(fh, members()))


def write_fields_tiff(result, folder):
    """Write each field (pixel grid) as a TIFF in ``folder`` (created), one plane at a time; returns the paths."""
    import tifffile

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)

    def tiff(data, name, unit):
        buf = io.BytesIO()
        meta = {"field": name, "unit": unit, "glassdist_version": result.version, "invalid": "NaN"}
        tifffile.imwrite(buf, np.ascontiguousarray(data), description=json.dumps(meta), compression="zlib",
                         compressionargs={"level": 1})
        return atomic_write_bytes(folder / f"{name}.tif", buf.getbuffer())

    written = []
    for spec, a in _pixel_arrays(result):
        written += [tiff(a if c is None else a[..., c], stem, unit) for stem, c, unit in _planes(spec)]
        del a
    written.append(tiff(np.asarray(result.valid, dtype=np.uint8), "valid", "1 = analysed"))
    return written
