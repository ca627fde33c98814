"""A run asked of a child process, typed: what a batch pane, a web job or a sweep's variant sends.

The parent (:mod:`glassdist.jobs.batch`, the web app, :mod:`glassdist.virtual.sweep`) builds an
:class:`AnalyzeRequest` (``glassdist analyze``) or a :class:`ValidateRequest` (``glassdist
validate``); :func:`glassdist.jobs.runner.run_request` sends it, serialised as JSON, to a child
process of its own, which reads it back (:func:`parse_request`) and runs it as the command runs
its options (:func:`glassdist.cli.run_request`): the same checks (the options' ranges, the
files, the specification's protocol), the same exit status (0, 2, 3, 1) and the same history
record, whose context (:class:`RecordAs`: a pane of a batch, a job of the web app) the request
carries as a field rather than as a command-line option.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter

__all__ = ["AnalyzeRequest", "ChildRequest", "RecordAs", "ValidateRequest", "parse_request"]

_FROZEN = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class RecordAs(BaseModel):
    """How the child's run is recorded in the results history.

    Attributes
    ----------
    source : {'batch', 'web'}
        What ran the analysis.
    job : str, optional
        The batch's output folder, or the web job's id.
    out_dir : str, optional
        The folder the run's files end up in, when not the one they are written to (a batch
        pane is written to a temporary folder, then renamed); relative paths are of the
        child's working folder.
    """

    model_config = _FROZEN

    source: Literal["batch", "web"]
    job: str | None = None
    out_dir: str | None = None


#: option of ``glassdist analyze`` -> field of :class:`AnalyzeRequest` (the order of the log line)
_OPTIONS = (("--pitch-mm", "pitch_mm"), ("--distance-m", "distance_m"), ("--reference", "reference"),
            ("--pattern", "pattern"), ("--params", "params"), ("--mask", "mask"), ("--spec", "spec"),
            ("--sigma-mm", "sigma_mm"), ("--detrend-degree", "detrend_degree"), ("--optics", "optics"),
            ("--camera-distance-m", "camera_distance_m"), ("--incidence-deg", "incidence_deg"),
            ("--pane-id", "pane_id"), ("--site", "site"), ("--operator", "operator"), ("--lot", "lot"),
            ("--db", "db"))


class AnalyzeRequest(BaseModel):
    """One run of ``glassdist analyze``: the photos, the settings, the outputs and the record context.

    Lengths in mm, distances in m, angles in degrees; ``None``: the option is left out (its
    default, or the value the specification's protocol pins). Paths are of the child's
    working folder. The values' ranges and the files are checked by the child, as the
    command line checks its options.

    Attributes
    ----------
    images : tuple of path
        The photo(s) through the glass (several: captures averaged into one map).
    out : path
        The output folder.
    reference, mask, spec, params : path, optional
        ``--reference``, ``--mask``, ``--spec``, ``--params``.
    pitch_mm, distance_m, sigma_mm, camera_distance_m, incidence_deg : float, optional
    pattern : {'auto', 'lines', 'checkerboard', 'dots'}, optional
    detrend_degree : int, optional
    optics : {'transmission', 'reflection'}, optional
    pane_id, site, operator, lot : str, optional
        Pane facts for the report and the history.
    report, export : bool
        Also ``report.html``; ``fields.npz`` and ``tiff/``.
    db : str, optional
        The history database (``--db``).
    record_as : RecordAs, optional
        The run's context in the history (None: recorded as a command-line run).
    """

    model_config = _FROZEN

    command: Literal["analyze"] = "analyze"
    images: tuple[Path, ...] = Field(min_length=1)
    out: Path
    reference: Path | None = None
    mask: Path | None = None
    spec: Path | None = None
    params: Path | None = None
    pitch_mm: float | None = None
    distance_m: float | None = None
    sigma_mm: float | None = None
    camera_distance_m: float | None = None
    incidence_deg: float | None = None
    pattern: Literal["auto", "lines", "checkerboard", "dots"] | None = None
    detrend_degree: int | None = None
    optics: Literal["transmission", "reflection"] | None = None
    pane_id: str | None = None
    site: str | None = None
    operator: str | None = None
    lot: str | None = None
    report: bool = False
    export: bool = False
    db: str | None = None
    record_as: RecordAs | None = None

    def options(self) -> list[str]:
        """The ``glassdist analyze`` command line of this request (the child parses it, the log shows it).

        Every option is given as ``--name=value`` and the photos come last after ``--``, so
        that no value (an image or a site named ``-h``...) can be read as an option; a number
        is written as ``repr`` writes it (read back exactly).
        """
        args = ["analyze"]
        for flag, name in _OPTIONS:
            value = getattr(self, name)
            if value is not None:
                args.append(f"{flag}={value!r}" if isinstance(value, float) else f"{flag}={value}")
        args += [flag for flag, on in (("--report", self.report), ("--export", self.export)) if on]
        return args + [f"--out={self.out}", "--", *(str(p) for p in self.images)]

    def history_context(self) -> dict[str, Any] | None:
        """The run's context in the history (:class:`RecordAs` as a mapping), or None: a command-line run."""
        return None if self.record_as is None else self.record_as.model_dump()


class ValidateRequest(BaseModel):
    """One run of ``glassdist validate`` (a variant of ``glassdist sweep``): the scene rendered, analysed, compared.

    Attributes
    ----------
    scene : path
        The variant's scene file.
    out : path
        The output folder.
    method : {'direct', 'comparative'}
    engine : str
        The render engine (``exact``, ``cycles``).
    spp : int, optional
        Samples per pixel (None: the scene's).
    """

    model_config = _FROZEN

    command: Literal["validate"] = "validate"
    scene: Path
    out: Path
    method: Literal["direct", "comparative"] = "direct"
    engine: str = "exact"
    spp: int | None = Field(None, ge=1)

    def options(self) -> list[str]:
        """The ``glassdist validate`` command line of this request (``--name=value``, the scene after ``--``)."""
        spp = [] if self.spp is None else [f"--spp={self.spp}"]
        return ["validate", f"--method={self.method}", f"--engine={self.engine}", "--no-progress", *spp,
                f"--out={self.out}", "--", str(self.scene)]

    def history_context(self) -> dict[str, Any] | None:
        """None: a validation is not recorded in the results history."""
        return None


#: what a child process is sent: one request of either command, told apart by ``command``
ChildRequest = Annotated[Union[AnalyzeRequest, ValidateRequest], Field(discriminator="command")]
_CHILD_REQUEST: TypeAdapter[AnalyzeRequest | ValidateRequest] = TypeAdapter(ChildRequest)


def parse_request(text: str) -> AnalyzeRequest | ValidateRequest:
    """The request a child process was sent (its JSON text), validated.

    Raises
    ------
    pydantic.ValidationError
        Not a request of either command.
    """
    return _CHILD_REQUEST.validate_json(text)
