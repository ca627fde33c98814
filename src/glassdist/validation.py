"""The validation layer: every input a user gives glassdist is checked here, at the boundary.

Each sub-command reads its documents, images and options through these functions, so
that bad input is refused the same way everywhere: an :class:`~glassdist.errors.InputError`
whose message is ONE line saying what is wrong and how to fix it (the command line prints
it and exits with status 2), before any work is done or any file is written.

- Files: regular files only (a FIFO or a device would block the reader), readable, not
  empty, not larger than a limit (:func:`check_input_file`).
- Documents (JSON parameters, specifications, scenes; YAML scenes; CSV manifests): UTF-8
  text, bounded size, nesting depth and YAML alias expansion, integers of at most 4300
  digits, finite numbers only (:func:`load_document`, :func:`load_mapping`,
  :func:`read_csv_rows`).
- Models: pydantic schemas with finite, ranged numbers (:data:`MODEL_CONFIG`,
  :data:`PositiveLength_mm`...), their errors formatted into one line
  (:func:`validate_model`, :func:`format_validation_error`).
- Numbers given as options: finite and within a physical range (:func:`check_number`,
  :func:`number_option`), with the ranges of the physical inputs in one place
  (:data:`PITCH_MM`, :data:`DISTANCE_M`, :data:`SIGMA_MM`).
- Text echoed to a terminal: control characters neutralised, length bounded
  (:func:`safe_text`), so that a name holding a newline cannot print a line of its own.

Limits (all overridable through the environment, see :class:`Limits`): documents 4 MiB,
CSV manifests 16 MiB, nesting depth 32, 100 000 YAML nodes after alias expansion, images
250 megapixels (checked from the file's header, before decoding).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import ConfigDict, Field, ValidationError

from .errors import InputError

__all__ = [
    "Limits",
    "carrier_period_mm",
    "limits",
    "MODEL_CONFIG",
    "FiniteFloat",
    "Length_mm",
    "PositiveLength_mm",
    "Angle_deg",
    "PITCH_MM",
    "DISTANCE_M",
    "SIGMA_MM",
    "Range",
    "safe_text",
    "check_input_file",
    "load_document",
    "load_mapping",
    "read_csv_rows",
    "format_validation_error",
    "validate_model",
    "check_number",
    "number_option",
    "check_sigma_extent",
]


# ---------------------------------------------------------------- limits

@dataclass(frozen=True)
class Limits:
    """Resource limits on inputs.

    Attributes
    ----------
    document_bytes : int
        Largest JSON/YAML document (parameters, specification, scene), bytes
        (``GLASSDIST_MAX_DOCUMENT_BYTES``, default 4 MiB).
    csv_bytes : int
        Largest CSV manifest, bytes (``GLASSDIST_MAX_CSV_BYTES``, default 16 MiB).
    depth : int
        Deepest nesting of lists/mappings in a document (``GLASSDIST_MAX_DEPTH``, default 32).
    nodes : int
        Most values in a document, YAML aliases expanded (``GLASSDIST_MAX_NODES``, default 100 000).
    megapixels : float
        Largest image, megapixels, read from the file's header before decoding
        (``GLASSDIST_MAX_MEGAPIXELS``, default 250).
    """

    document_bytes: int = 4 << 20
    csv_bytes: int = 16 << 20
    depth: int = 32
    nodes: int = 100_000
    megapixels: float = 250.0


_ENV = {"document_bytes": "GLASSDIST_MAX_DOCUMENT_BYTES", "csv_bytes": "GLASSDIST_MAX_CSV_BYTES",
        "depth": "GLASSDIST_MAX_DEPTH", "nodes": "GLASSDIST_MAX_NODES", "megapixels": "GLASSDIST_MAX_MEGAPIXELS"}


def limits() -> Limits:
    """The limits in force: :class:`Limits` defaults, overridden by the environment variables."""
    values = {}
    for name, var in _ENV.items():
        text = os.environ.get(var)
        if text:
            kind = float if name == "megapixels" else int
            values[name] = kind(check_number(text, var, Range(0, 1e12, lo_open=True)))
    return Limits(**values)


# ---------------------------------------------------------------- text shown to the user

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


def safe_text(text: Any, max_chars: int = 300) -> str:
    """``text`` fit to be echoed on one terminal line.

    Control characters (newline, carriage return, escape, bidirectional overrides) are
    written as escapes (``\\n``, ``\\x1b``...), and text longer than ``max_chars`` is cut
    with an ellipsis, so that a name such as ``"x\\nVERDICT: PASS"`` cannot print a line
    of its own and a huge value cannot flood the terminal.
    """
    s = str(text)
    if len(s) > max_chars:
        s = s[:max_chars] + f"... ({len(s) - max_chars} more characters)"
    return _CONTROL.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), s)


# ---------------------------------------------------------------- files

def check_input_file(path, what: str, *, option: str | None = None, max_bytes: int | None = None) -> Path:
    """Check that ``path`` names a readable, non-empty regular file (without opening it).

    Parameters
    ----------
    path : path-like
    what : str
        What the file is, for messages (``"image"``, ``"parameter file"``...).
    option : str, optional
        The option that named it (``"--params"``), for messages.
    max_bytes : int, optional
        Largest accepted size, bytes.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Missing, a folder, a FIFO/device/socket (which would block or never end),
        unreadable, empty or too large.
    """
    p = Path(path)
    shown = safe_text(p)
    where = f"check the {option} path" if option else "check the path"
    try:
        st = os.stat(p)  # follows links; never opens the file, so a FIFO cannot block here
    except FileNotFoundError:
        raise InputError(f"{what} '{shown}' does not exist; {where}") from None
    except OSError as exc:
        raise InputError(f"cannot access {what} '{shown}': {exc.strerror}; {where}") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{what} '{shown}' is a folder, not a file; {where}")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{what} '{shown}' is not a regular file (a pipe, device or socket); give a file on disk")
    if not os.access(p, os.R_OK):
        raise InputError(f"{what} '{shown}' is not readable (permission denied); check its permissions")
    if st.st_size == 0:
        raise InputError(f"{what} '{shown}' is empty (0 bytes); give the complete file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise InputError(
            f"{what} '{shown}' is {st.st_size / 2**20:.1f} MiB, more than the {max_bytes / 2**20:.1f} MiB accepted; "
            f"give a smaller file (or raise the limit, see glassdist.validation.Limits)"
        )
    return p


def _read_text(p: Path, what: str, max_bytes: int, digest=None) -> str:
    try:
        with open(p, "rb") as fh:
            raw = fh.read(max_bytes + 1)
    except OSError as exc:
        raise InputError(f"cannot read {what} '{safe_text(p)}': {exc.strerror}; check the file") from None
    if len(raw) > max_bytes:  # grew since it was checked
        raise InputError(f"{what} '{safe_text(p)}' is larger than the {max_bytes / 2**20:.1f} MiB accepted")
    if digest is not None:
        digest.update(raw)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{what} '{safe_text(p)}' is not UTF-8 text (byte {exc.start}); save it as UTF-8"
        ) from None


# ---------------------------------------------------------------- documents

def _reject_constant(name):
    raise ValueError(f"non-finite number '{name}'")


def _finite_float(text):
    v = float(text)
    if not math.isfinite(v):
        raise ValueError(f"number '{text[:40]}' is out of the floating-point range")
    return v


def _unique_keys(pairs):
    """A JSON object's ``dict``; a key given twice is refused (the parser keeps the last one silently:
    a specification with two ``max_mD`` would judge by whichever came second)."""
    out = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"the key '{safe_text(key, 80)}' appears twice in one object")
        out[key] = value
    return out


def _parse_json(text: str):
    return json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float, object_pairs_hook=_unique_keys)


def _yaml_node_count(root, lim: Limits) -> None:
    """Refuse YAML node graphs that are too deep, expand (through aliases) to too many values, or give
    a key twice in one mapping (:func:`_yaml_unique_keys`)."""
    import yaml

    size: dict[int, int] = {}
    stack = [(root, 1, False)]
    on_path: set[int] = set()
    while stack:
        node, depth, done = stack.pop()
        key = id(node)
        if done:
            on_path.discard(key)
            kids = _yaml_children(node, yaml)
            size[key] = 1 + sum(size[id(k)] for k in kids)
            if size[key] > lim.nodes:
                raise ValueError(f"it expands to more than {lim.nodes} values "
                                 "(YAML aliases repeat their anchor; the limit is GLASSDIST_MAX_NODES)")
            continue
        if key in size:
            continue
        if key in on_path:
            raise ValueError("it refers to itself (a recursive YAML alias)")
        if depth > lim.depth:
            raise ValueError(f"it is nested more than {lim.depth} levels deep")
        if isinstance(node, yaml.MappingNode):
            _yaml_unique_keys(node, yaml)
        on_path.add(key)
        stack.append((node, depth, True))
        stack.extend((k, depth + 1, False) for k in _yaml_children(node, yaml) if id(k) not in size)


def _yaml_unique_keys(node, yaml) -> None:
    """Refuse a YAML mapping that gives a key twice (the loader keeps the last one silently)."""
    seen = set()
    for k, _ in node.value:
        if isinstance(k, yaml.ScalarNode) and k.tag != "tag:yaml.org,2002:merge":
            if (k.tag, k.value) in seen:
                raise ValueError(f"the key '{safe_text(k.value, 80)}' appears twice in one mapping "
                                 f"(line {k.start_mark.line + 1})")
            seen.add((k.tag, k.value))


def _yaml_children(node, yaml):
    if isinstance(node, yaml.SequenceNode):
        return node.value
    if isinstance(node, yaml.MappingNode):
        return [x for pair in node.value for x in pair]
    return []


def _parse_yaml(text: str, lim: Limits):
    import yaml

    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()  # composes the node graph: aliases are still shared references
        if node is None:
            return None
        _yaml_node_count(node, lim)
        return loader.construct_document(node)
    finally:
        loader.dispose()


def _check_values(data, lim: Limits):
    """Depth, size and finiteness of parsed data (iterative: no recursion on hostile depth)."""
    stack = [(data, 1, "")]
    count = 0
    while stack:
        value, depth, where = stack.pop()
        count += 1
        if count > lim.nodes:
            raise ValueError(f"it holds more than {lim.nodes} values (the limit is GLASSDIST_MAX_NODES)")
        if depth > lim.depth:
            raise ValueError(f"it is nested more than {lim.depth} levels deep (the limit is GLASSDIST_MAX_DEPTH)")
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"'{safe_text(where or '(root)', 80)}' is {value}, where a finite number is needed")
        if isinstance(value, dict):
            stack.extend((v, depth + 1, f"{where}.{k}" if where else str(k)) for k, v in value.items())
        elif isinstance(value, (list, tuple)):
            stack.extend((v, depth + 1, f"{where}[{i}]") for i, v in enumerate(value))


def _document_format(suffix: str, text: str) -> str:
    """``'json'`` or ``'yaml'``: by the file name's suffix, else by the content (see :func:`load_document`)."""
    suffix = suffix.lower()
    if suffix in (".yaml", ".yml"):
        return "yaml"
    if suffix == ".json":
        return "json"
    return "json" if text.lstrip("\ufeff \t\r\n")[:1] in ("{", "[") else "yaml"


def load_document(path, what: str, *, option: str | None = None, fmt: str | None = None,
                  hint: str = "check its syntax", digest=None):
    """Read a JSON or YAML document with bounded resources.

    Parameters
    ----------
    path : path-like
    what : str
        What the document is, for messages (``"parameter file"``...).
    option : str, optional
        The option that named it, for messages.
    fmt : {"json", "yaml"}, optional
        Default: YAML for ``.yaml``/``.yml`` files, JSON for ``.json``; any other name
        (``scene.txt``) by its content: JSON when it starts with ``{`` or ``[``, else YAML.
    hint : str
        How to fix a syntax error (end of the message).
    digest : hashlib hash, optional
        Updated with the file's bytes as read (e.g. ``hashlib.sha256()``: the digest of
        exactly what was parsed, without reading the file again).

    Returns
    -------
    The parsed value (dict, list, str, number, bool or None).

    Raises
    ------
    InputError
        See :func:`check_input_file`; not UTF-8; a syntax error; nested deeper than
        :attr:`Limits.depth`; more values than :attr:`Limits.nodes` (YAML aliases
        expanded); an integer of more than 4300 digits; ``NaN``, ``Infinity`` or a number
        out of the floating-point range; a key given twice in one mapping.
    """
    lim = limits()
    p = check_input_file(path, what, option=option, max_bytes=lim.document_bytes)
    text = _read_text(p, what, lim.document_bytes, digest)
    fmt = fmt or _document_format(p.suffix, text)
    shown = safe_text(p)
    try:
        data = _parse_yaml(text, lim) if fmt == "yaml" else _parse_json(text)
        _check_values(data, lim)
    except json.JSONDecodeError as exc:
        raise InputError(f"{what} '{shown}' is not valid JSON (line {exc.lineno}: {exc.msg}); {hint}") from None
    except RecursionError:
        raise InputError(f"{what} '{shown}' is nested too deeply (more than {lim.depth} levels, the limit is "
                         "GLASSDIST_MAX_DEPTH)") from None
    except ValueError as exc:  # our own checks, and int() of more than 4300 digits
        msg = str(exc)
        if "digits" in msg and "integer" in msg.lower():
            msg = "it holds an integer of more than 4300 digits"
        raise InputError(f"{what} '{shown}' cannot be used: {safe_text(msg, 200)}; correct the file") from None
    except Exception as exc:  # noqa: BLE001 - a YAML parser error of any kind is a user file problem
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{what} '{shown}' cannot be parsed ({safe_text(first, 200)}); {hint}") from None
    return data


def load_mapping(path, what: str, *, option: str | None = None, fmt: str | None = None,
                 expect: str = "key: value pairs", hint: str = "check its syntax", digest=None) -> dict:
    """:func:`load_document` for documents that must hold one mapping (a JSON object).

    A top-level ``"$comment"`` key is allowed and dropped.

    Parameters
    ----------
    expect : str
        What the mapping holds, for the message when it is not one.
    """
    data = load_document(path, what, option=option, fmt=fmt, hint=hint, digest=digest)
    if not isinstance(data, dict):
        raise InputError(f"{what} '{safe_text(path)}' must hold a mapping (a JSON object) of {expect}")
    data.pop("$comment", None)
    return data


def read_csv_rows(path, what: str = "manifest", *, option: str | None = None) -> tuple[list[str], list[tuple[int, dict]]]:
    """Read a CSV file with a header row, bounded in size; UTF-8 (a BOM is allowed).

    Returns
    -------
    header : list of str
        Column names, stripped.
    rows : list of (int, dict)
        ``(line number, {column: stripped cell})`` for every non-empty row.

    Raises
    ------
    InputError
        Columns separated by ``;``, a tab or ``|``; a column named twice in the header; a row
        (other than a ``#`` comment) with more non-empty cells than the header has columns
        (empty trailing cells are allowed).
    """
    lim = limits()
    p = check_input_file(path, what, option=option, max_bytes=lim.csv_bytes)
    text = _read_text(p, what, lim.csv_bytes)
    if "\x00" in text:
        raise InputError(f"{what} '{safe_text(p)}' holds NUL bytes: it is not a CSV text file")
    try:
        reader = csv.DictReader(io.StringIO(text, newline=""))
        header = [(h or "").strip() for h in (reader.fieldnames or [])]
        other = next((sep for sep in ";\t|" if len(header) == 1 and sep in header[0]), None)
        if other is not None:  # a spreadsheet saved with another separator (';' where ',' is the decimal mark)
            raise InputError(f"{what} '{safe_text(p)}' separates its columns with {other!r}, not commas; "
                             "save it as comma-separated values (CSV, with '.' as the decimal mark)")
        twice = sorted({h for h in header if h and header.count(h) > 1})
        if twice:  # DictReader keeps the last one: a pane would silently get the other cell's value
            raise InputError(f"{what} '{safe_text(p)}': column(s) {safe_text(', '.join(twice), 200)} appear more "
                             "than once in the header row; keep one of each")
        rows = []
        for lineno, row in enumerate(reader, start=2):
            extra = [v for v in row.get(None, ()) if v.strip()]
            comment = header and (row.get(reader.fieldnames[0]) or "").lstrip().startswith("#")
            if extra and not comment:  # e.g. a path with an unquoted comma: every cell after it would shift
                raise InputError(f"{what} '{safe_text(p)}' line {lineno} has {len(header) + len(row[None])} cells "
                                 f"but the header names {len(header)} columns; quote a cell that holds a comma")
            cells = {(k or "").strip(): (v if isinstance(v, str) else "").strip() for k, v in row.items() if k is not None}
            if any(cells.values()):
                rows.append((lineno, cells))
    except csv.Error as exc:
        raise InputError(f"{what} '{safe_text(p)}' is not valid CSV ({safe_text(exc, 200)})") from None
    return header, rows


# ---------------------------------------------------------------- models

#: pydantic configuration of every input model: unknown keys are errors, models are
#: frozen, NaN and infinities are refused.
MODEL_CONFIG = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

#: a finite number
FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
#: a length or coordinate, mm (|x| up to 10 km)
Length_mm = Annotated[float, Field(ge=-1e7, le=1e7, allow_inf_nan=False)]
#: a positive length, mm, up to 10 km
PositiveLength_mm = Annotated[float, Field(gt=0, le=1e7, allow_inf_nan=False)]
#: an angle, degrees (|x| up to ten turns)
Angle_deg = Annotated[float, Field(ge=-3600, le=3600, allow_inf_nan=False)]


#: how an error names the n-th item of a list key (``criteria[0]`` is "criterion 1")
_ITEM_NAMES = {"criteria": "criterion", "zones": "zone", "panes": "pane", "corners_px": "corner",
               "corners_frac": "corner", "polygon_mm": "vertex", "captures": "capture", "layers": "layer"}


def _item_model(annotation):
    """The pydantic model an annotation holds (directly, or as the items of a tuple, list or optional)."""
    import inspect
    import typing

    from pydantic import BaseModel

    if inspect.isclass(annotation) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = _item_model(arg)
        if found is not None:
            return found
    return None


def _keys_at(model, loc) -> list[str]:
    """The keys the model accepts at ``loc`` (a pydantic error location without its last key); [] when unknown."""
    for part in loc:
        if isinstance(part, int) or model is None:
            continue  # an item of a list: the item's model is the list annotation's
        field = model.model_fields.get(part)
        model = None if field is None else _item_model(field.annotation)
    return [] if model is None else [f.alias or name for name, f in model.model_fields.items()]


def _where(loc) -> tuple[str, str]:
    """``(key, place)`` of an error location: the dotted key after the last list index, and where that item is.

    List indices count from 1, as a person counts: ``('criteria', 0, 'max_md')`` is
    ``('max_md', 'criterion 1')``; ``('pane', 'colour')`` is ``('pane.colour', '')``.
    """
    parts = list(loc)
    last = max((i for i, p in enumerate(parts) if isinstance(p, int)), default=None)
    if last is None:
        return ".".join(str(p) for p in parts), ""
    key = ".".join(str(p) for p in parts[last + 1:])
    owner = ".".join(str(p) if not isinstance(p, int) else f"[{p + 1}]" for p in parts[:last]).replace(".[", "[")
    n = parts[last] + 1
    if owner in _ITEM_NAMES:  # a top-level list: "criterion 2"
        return key, f"{_ITEM_NAMES[owner]} {n}"
    return key, f"item {n} of '{owner}'" if owner else f"item {n}"


def _suggestion(key: str, known) -> str:
    """`` (did you mean 'x'?)`` for a mistyped key: the same key in another case, else the closest by difflib."""
    import difflib

    last = key.rsplit(".", 1)[-1]
    same = [k for k in known if k.lower() == last.lower()]
    close = same or difflib.get_close_matches(last, list(known), n=1, cutoff=0.6)
    return f" (did you mean '{safe_text(close[0], 60)}'?)" if close else ""


def format_validation_error(exc: ValidationError, what: str, source: str, hint: str, *, most: int = 3,
                            model=None) -> str:
    """One line from a pydantic :class:`~pydantic.ValidationError`.

    ``invalid WHAT in SOURCE: unknown key 'max_md' in criterion 1 (did you mean 'max_mD'?); 'a.b': Input should
    be greater than 0; HINT`` (at most ``most`` problems, keys neutralised with :func:`safe_text`). List items
    are counted from 1; with ``model`` (the model validated) an unknown key gets the closest known key as a
    suggestion.
    """
    parts = []
    errors = exc.errors()
    # a list whose only items failed is also reported too short: the items' errors say it
    errors = [e for e in errors if not (e["type"] == "too_short" and any(
        len(o["loc"]) > len(e["loc"]) and tuple(o["loc"][: len(e["loc"])]) == tuple(e["loc"]) for o in errors))]
    for err in errors[:most]:
        key, place = _where(err["loc"])
        key = safe_text(key or "(root)", 80)
        at = f" in {safe_text(place, 80)}" if place else ""
        msg = safe_text(err["msg"].removeprefix("Value error, "), 200)
        if err["type"] == "extra_forbidden":
            known = _keys_at(model, err["loc"][:-1]) if model is not None else []
            parts.append(f"unknown key '{key}'{at}{_suggestion(key, known)}")
        elif err["type"] == "missing":
            parts.append(f"missing key '{key}'{at}")
        elif key == "(root)" and place:
            parts.append(f"{safe_text(place, 80)}: {msg}")
        else:
            parts.append(f"'{key}'{at}: {msg}")
    if len(errors) > most:
        parts.append(f"{len(errors) - most} more problem(s)")
    return f"invalid {what} in {source}: " + "; ".join(parts) + f"; {hint}"


def validate_model(model, data, what: str, source: str, hint: str):
    """``model(**data)``, its validation errors raised as one-line :class:`InputError`."""
    if not isinstance(data, dict):
        raise InputError(f"{what} in {source} must be a mapping of key: value pairs; {hint}")
    try:
        return model(**data)
    except ValidationError as exc:
        raise InputError(format_validation_error(exc, what, source, hint, model=model)) from None
    except (TypeError, ValueError, OverflowError, RecursionError) as exc:  # keyword names that are not strings, ...
        raise InputError(f"invalid {what} in {source}: {safe_text(exc, 200)}; {hint}") from None


# ---------------------------------------------------------------- numbers

@dataclass(frozen=True)
class Range:
    """Accepted interval of a number: ``lo <= x <= hi`` (``lo < x`` with ``lo_open``)."""

    lo: float
    hi: float
    lo_open: bool = False
    unit: str = ""

    def text(self) -> str:
        """The range in words, e.g. ``> 0 mm and <= 100 mm``."""
        u = f" {self.unit}" if self.unit else ""
        return f"{'>' if self.lo_open else '>='} {self.lo:g}{u} and <= {self.hi:g}{u}"


#: grid pitch on the backdrop, mm (a printed grid from 1 µm to 10 m)
PITCH_MM = Range(1e-3, 1e4, unit="mm")
#: glass-to-grid distance L, m (1 mm to 10 km)
DISTANCE_M = Range(1e-3, 1e4, unit="m")
#: reporting smoothing scale, mm (also bounded by the image's extent, :func:`check_sigma_extent`)
SIGMA_MM = Range(1e-3, 1e7, unit="mm")


def check_number(value, name: str, rng: Range) -> float:
    """``value`` as a float, finite and within ``rng``; else a one-line :class:`InputError`."""
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{name} must be a number, got '{safe_text(value, 40)}'") from None
    if not math.isfinite(v):
        raise InputError(f"{name} must be a finite number, got {safe_text(value, 40)}")
    if v <= 0 <= rng.lo:
        raise InputError(f"{name} must be positive, got {safe_text(value, 40)}")
    if v < rng.lo or (rng.lo_open and v <= rng.lo) or v > rng.hi:
        raise InputError(f"{name} must be {rng.text()}, got {safe_text(value, 40)}")
    return v


def number_option(rng: Range):
    """argparse ``type=`` for a finite number within ``rng`` (argparse names the option in its error)."""
    import argparse

    def parse(text: str) -> float:
        try:
            return check_number(text, "the value", rng)
        except InputError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("the value ")) from None

    parse.__name__ = "number"
    return parse


def carrier_period_mm(pitch_mm: float, pattern: str) -> float:
    """The grid's carrier period on the backdrop, mm: the pitch, or ``pitch * sqrt(2)`` for a checkerboard.

    For the input checks (plain floats); the analysis has its own, typed for its float32 phases
    (:func:`glassdist.analyzer.demodulate.carrier_period_mm`).
    """
    return pitch_mm * (math.sqrt(2.0) if pattern == "checkerboard" else 1.0)


def check_sigma_extent(sigma_mm: float | None, image_shape, pitch_mm: float, *, pattern: str = "lines",
                       min_period_px: float = 3.0) -> None:
    """Refuse a smoothing scale larger than the image's extent on the backdrop.

    The carrier period on the backdrop is ``pitch_mm`` (lines) or ``pitch_mm * sqrt(2)``
    (checkerboard) and spans at least ``min_period_px`` pixels, so an image covers at
    most ``max(H, W) * period / min_period_px`` mm of the backdrop; a Gaussian of a
    larger sigma would average the whole image into its mean (and cost memory growing
    with sigma squared).

    Parameters
    ----------
    sigma_mm : float or None
        Requested smoothing scale, mm (None: the default of a few carrier periods).
    image_shape : tuple
        ``(H, W, ...)`` of the image, px.
    pitch_mm : float
        Grid pitch, mm.
    """
    if sigma_mm is None:
        return
    period = carrier_period_mm(pitch_mm, pattern)
    extent = max(image_shape[:2]) * period / min_period_px
    if sigma_mm > extent:
        raise InputError(
            f"--sigma-mm {sigma_mm:g} is larger than the image's whole extent on the backdrop "
            f"(at most {extent:.4g} mm for a {image_shape[1]}x{image_shape[0]} px image of a {pitch_mm:g} mm grid); "
            "give a smoothing scale of a few grid periods"
        )
