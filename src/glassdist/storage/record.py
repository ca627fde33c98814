"""One run, typed: what was asked, what was read, what was found; built once, written once.

A run of ``glassdist analyze`` (the command line, a pane of ``glassdist batch``, a job
of the web app) or of :func:`glassdist.write_outputs` is one straight line::

    request  = RunRequest(...)                  # 1. from the options (or the API's arguments)
    inputs   = read_inputs(...)                 # 2. each file read once, hashed from its bytes
    folder   = open_output_folder(...)          # 3. taken before any work
    result   = analyze(...)                     # 4.
    record   = build_record(request, inputs, result)   # 5-7. capture checked once, assessed, measured
    summary  = write_run(record, folder)        # 8. every file, summary.json last and once
    lines    = run_lines(record)                # 9. the console lines, from the record
    return record.exit_code                     # 10.

:class:`RunRecord` holds the request, the input digests, the result, the acceptance and
the standard measures; :meth:`RunRecord.summary` is the ``summary.json`` schema (less the
``outputs`` the writer adds once the files are written).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..acceptance.spec import LoadedSpec
from ..acceptance.stats import STATISTIC_FIELDS
from ..errors import InputError
from ..fs import file_sha256
from ..io import read_photo
from .fields import FIELD_LAYOUTS, GRID_KEYS, region_summary

if TYPE_CHECKING:
    from ..acceptance.assess import Acceptance

__all__ = ["EXIT_OK", "EXIT_SPEC_FAIL", "InputFile", "RunInputs", "RunRecord", "RunRequest", "build_record", "read_inputs",
           "result_protocol"]

EXIT_OK = 0
#: exit status of ``glassdist analyze --spec`` when the analysis ran but the specification failed
EXIT_SPEC_FAIL = 3


@dataclass(frozen=True)
class RunRequest:
    """What one run was asked to do (the options of ``glassdist analyze``, or the API's arguments).

    Attributes
    ----------
    fields : {'analysis', 'pixel'}
        Layout of ``result.npz``.
    report, export : bool
        Also ``report.html``; ``fields.npz`` and ``tiff/``.
    spec : LoadedSpec or None
        The acceptance specification, loaded once (spec, SHA-256, path, limits).
    protocol : ResolvedProtocol or None
        The settings resolved from the options and the specification.
    mask : ndarray of bool (H, W) or None
        The region the analysis was asked for (coverage is of it).
    metadata : dict
        ``pane_id``, ``lot``, ``site``, ``operator``.
    history : Recording, False or None
        How the run is recorded in the results history (None: the default recording of
        the API; False: not recorded).
    camera_distance_m : float or None
        Camera to pane, m (transmission): the run also reports the pane's intrinsic reading
        (:mod:`glassdist.viewpoint`), ``intrinsic`` in ``summary.json`` and its maps in ``result.npz``.
    capture_pose : glassdist.viewpoint.pose.CapturePose or None
        The capture's angle to the pane normal and focal length, with their sources (None: normal incidence).
    """

    fields: str = "analysis"
    report: bool = False
    export: bool = False
    spec: LoadedSpec | None = None
    protocol: object = None
    mask: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)
    history: object = None
    camera_distance_m: float | None = None
    capture_pose: object = None

    def __post_init__(self):
        if self.fields not in FIELD_LAYOUTS:
            raise InputError(f"fields must be one of {', '.join(FIELD_LAYOUTS)}, got '{self.fields}'")

    @property
    def limits(self) -> dict:
        """``{channel: [limit_mD, ...]}`` of the specification (one threshold mask each)."""
        return self.spec.limits if self.spec is not None else {}


@dataclass(frozen=True)
class InputFile:
    """An input file as the run read it: its path and the SHA-256 of the bytes read."""

    path: str
    sha256: str


@dataclass(frozen=True)
class RunInputs:
    """The input files of a run, each read once (see :func:`read_inputs`).

    Attributes
    ----------
    image, reference : InputFile or None
    mask : str or None
        Path of the mask file.
    captures : tuple of InputFile
        Every photo when several captures were averaged (the first is ``image``).
    camera : dict, None or False
        The photo's EXIF camera facts (None: it has none; False: no photo known).
    preview : ndarray or None
        The photo reduced for the figure of the analysed region
        (:func:`glassdist.io.preview`).
    """

    image: InputFile | None = None
    reference: InputFile | None = None
    mask: str | None = None
    captures: tuple = ()
    camera: object = False
    preview: np.ndarray | None = None

    @property
    def paths(self) -> tuple:
        """Every input path (never overwritten by an output)."""
        return tuple(Path(f.path) for f in (self.image, self.reference, *self.captures) if f is not None) + \
            ((Path(self.mask),) if self.mask is not None else ())


def read_inputs(image_path=None, reference_path=None, mask_path=None, *, image=None, sources=None) -> RunInputs:
    """The :class:`RunInputs` of a result analysed elsewhere (the Python API): each file read once.

    The photo is read once for its preview, SHA-256 and EXIF (:func:`glassdist.io.read_photo`);
    the reference is hashed. ``image``: the photo's pixels when no ``image_path`` is given
    (drawn, not recorded). ``sources``: the files the analysis read
    (``AnalysisResult.sources``), the default of each path not given.

    Raises
    ------
    InputError
        A file of ``sources`` no longer holds the bytes that were analysed.
    """
    from ..io import preview

    sources = sources or {}
    image_path = sources.get("image") if image_path is None else image_path
    reference_path = sources.get("reference") if reference_path is None else reference_path
    mask_path = sources.get("mask") if mask_path is None else mask_path
    photo_file, camera, small = None, False, None if image is None else preview(image)
    if image_path is not None:
        photo = read_photo(image_path, dtype=np.float32)
        _same_bytes(image_path, photo.sha256, sources, "image")
        photo_file, camera, small = InputFile(str(image_path), photo.sha256), photo.camera, preview(photo.image)
    reference = None
    if reference_path is not None:
        reference = InputFile(str(reference_path), file_sha256(reference_path))
        _same_bytes(reference_path, reference.sha256, sources, "reference")
    return RunInputs(image=photo_file, reference=reference, mask=None if mask_path is None else str(mask_path),
                     camera=camera, preview=small)


def _same_bytes(path, sha256: str, sources: dict, role: str) -> None:
    """A file the analysis read must still hold what it read: the record states its SHA-256."""
    if sources.get(role) is not None and str(sources[role]) == str(path) and sources.get(f"{role}_sha256") != sha256:
        raise InputError(f"the {role} '{path}' has changed since it was analysed (SHA-256 {sources[f'{role}_sha256']}, "
                         f"now {sha256}); analyse it again before writing its record")


def result_protocol(result, spec: LoadedSpec | None = None):
    """The protocol record ``glassdist analyze`` writes for the settings of a result analysed in Python, or None.

    As the command line resolves its options (:func:`glassdist.acceptance.spec.resolve_protocol`):
    the pitch, distance and method are the caller's ("option"), as is each setting
    ``result.sources['given']`` names; a pattern neither given nor pinned was decided from
    the photo ("auto"); the rest are defaults. None for a result that does not say what its
    caller gave (not from :func:`glassdist.analyze`), or whose settings contradict the
    specification's pins (the verdict's protocol checks then say so).
    """
    from dataclasses import replace

    from ..acceptance.spec import resolve_protocol

    sources = result.sources
    if "given" not in sources or result.optics is not None:
        return None
    given = set(sources["given"])
    pinned = spec.spec.protocol if spec is not None else None
    chosen = {"sigma_mm": result.sigma_mm if given & {"sigma_mm", "sigma_periods"} else None,
              "detrend_degree": result.detrend_degree if "detrend_degree" in given else None}
    decided = "pattern" not in given and (pinned is None or pinned.pattern is None)
    try:
        protocol = resolve_protocol(pinned, reference_given=result.method == "comparative", pitch_mm=result.pitch_mm,
                                    distance_m=result.distance_m, pattern=result.params.pattern, **chosen)
    except InputError:
        return None
    return replace(protocol, sources={**protocol.sources, "pattern": "auto"}) if decided else protocol


@dataclass(frozen=True)
class RunRecord:
    """One run: request, input digests, result, acceptance and standard measures (see :func:`build_record`).

    Attributes
    ----------
    request : RunRequest
    inputs : RunInputs
    result : AnalysisResult
    acceptance : Acceptance
    measures : dict
        :meth:`glassdist.measures.StandardMeasures.to_dict`.
    sections : dict
        ``flatness`` and ``intrinsic`` where they apply (:func:`glassdist.sections.result_sections`).
    """

    request: RunRequest
    inputs: RunInputs
    result: object
    acceptance: Acceptance
    measures: dict
    sections: dict = field(default_factory=dict)

    @property
    def exit_code(self) -> int:
        """:data:`EXIT_SPEC_FAIL` when a specification failed, else :data:`EXIT_OK`."""
        verdict = self.acceptance.verdict
        return EXIT_SPEC_FAIL if verdict is not None and not verdict.passed else EXIT_OK

    def described_inputs(self) -> dict:
        """``{"image", "reference"}``: name, path, SHA-256 and size of each photo (None when not given)."""
        h, w = self.result.valid.shape
        return {role: None if f is None else {"name": Path(f.path).name, "path": f.path, "sha256": f.sha256,
                                             "size": f"{w} x {h} px"}
                for role, f in (("image", self.inputs.image), ("reference", self.inputs.reference))}

    def summary(self, files=()) -> dict:
        """The ``summary.json`` of the run, less ``outputs`` (the writer adds it with the files' digests).

        ``files``: the names the run wrote besides ``result.npz`` and ``summary.json``.
        """
        result, acc, inputs = self.result, self.acceptance, self.inputs
        # the acceptance statistics are over the same trusted pixels: one pass over them for both
        summary = result.summary(statistics={STATISTIC_FIELDS[ch]: s for ch, s in acc.stats.items()})
        image, reference = inputs.image, inputs.reference
        summary["inputs"] = {
            "image": None if image is None else image.path,
            "image_sha256": None if image is None else image.sha256,
            "reference": None if reference is None else reference.path,
            "reference_sha256": None if reference is None else reference.sha256,
            "mask": inputs.mask,
        }
        if len(inputs.captures) > 1:
            summary["inputs"]["captures"] = [{"image": c.path, "sha256": c.sha256} for c in inputs.captures]
        layout = self.request.fields
        summary["fields"] = {"layout": layout, "file": "result.npz", "keys": [f.name for f in result.field_specs()]
                             + (list(GRID_KEYS) if layout == "analysis" else ["valid", "detrend_region"])}
        summary["regions"] = region_summary(result)
        summary.update({
            "verdict": acc.verdict.to_dict() if acc.verdict else None,
            "a4": {"statistics": acc.stats, "files": list(files),
                   "inputs": self.described_inputs()},
            # with the shares the verdict judged (measured_percent, trusted_percent: one number each)
            **acc.summary(), "measures": self.measures,
        })
        summary.update(self.sections)  # computed on the analysis side (build_record)
        return summary


def build_record(request: RunRequest, inputs: RunInputs, result) -> RunRecord:
    """Assess the result (the capture checked once against the protocol, then judged) and measure it: the run's record.

    Raises
    ------
    InputError
        The capture violates the protocol's capture limits (nothing is judged, nothing written).
    """
    from ..acceptance.assess import assess  # scipy.ndimage: not needed to check the inputs
    from ..measures import standard_measures
    from ..sections import result_sections

    sections = result_sections(result, camera_distance_m=request.camera_distance_m, pose=request.capture_pose)
    acc = assess(result, request.spec, protocol=request.protocol, mask=request.mask, metadata=request.metadata,
                 camera=inputs.camera, camera_distance_m=request.camera_distance_m, flatness=sections.get("flatness"))
    return RunRecord(request, inputs, result, acc, standard_measures(result).to_dict(), sections)
