"""Web jobs: each one runs ``glassdist analyze`` in its own process inside a private temporary folder."""

from __future__ import annotations

import json
import logging
import os
import re
import shutil
import tempfile
import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..jobs.request import AnalyzeRequest
from ..validation import safe_text

__all__ = ["FIELDS", "FLAGS", "LABELS", "ROLES", "Job", "JobStore", "form_language"]

logger = logging.getLogger(__name__)

#: Uploads a job takes, and the ``glassdist analyze`` option each becomes (the photo is the positional argument).
ROLES = {"image": None, "reference": "--reference", "mask": "--mask", "spec": "--spec"}

#: Form fields of the job's :class:`~glassdist.jobs.request.AnalyzeRequest` (each the field of that name) and the
#: ``glassdist analyze`` option it is; a field left empty is not sent (analyze's default, or the specification's
#: pinned value, applies); its range is checked by the analysis, as on the command line.
FIELDS = {"pitch_mm": "--pitch-mm", "distance_m": "--distance-m", "pattern": "--pattern",
          "detrend_degree": "--detrend-degree", "sigma_mm": "--sigma-mm",
          "pane_id": "--pane-id", "lot": "--lot", "site": "--site", "operator": "--operator", "optics": "--optics",
          "camera_distance_m": "--camera-distance-m", "incidence_deg": "--incidence-deg"}

#: Opt-in checkboxes of the form and the ``glassdist analyze`` flag each adds when ticked.
FLAGS = {"report": "--report", "export": "--export"}

#: What the form calls each upload, field and checkbox: the page's labels, and the words
#: :func:`form_language` puts in place of the ``glassdist analyze`` options in errors and warnings.
LABELS = {"image": "photo of the grid through the glass", "reference": "glass-less reference", "mask": "mask",
          "spec": "acceptance specification",
          "pitch_mm": "grid pitch, mm", "distance_m": "glass-to-grid distance L, m", "pattern": "pattern",
          "detrend_degree": "detrend degree N", "sigma_mm": "smoothing sigma, mm", "optics": "optics",
          "camera_distance_m": "camera-to-pane distance C, m", "incidence_deg": "incidence at the view's centre, deg",
          "pane_id": "pane identifier", "lot": "lot", "site": "site", "operator": "operator",
          "report": "HTML report", "export": "exports"}

#: ``glassdist analyze`` option -> the form's word for it.
_OPTION_LABELS = {option: LABELS[key] for key, option in {**FIELDS, **ROLES, **FLAGS}.items() if option}
_OPTION = re.compile(r"--[a-z][a-z0-9-]*")
# a value written after an option: a number, or one of the form's choices
_VALUE = r"(?:[= ](?P<value>[-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?|reflection|transmission|lines|checkerboard|dots|auto)\b)?"


def _field(option: str) -> str:
    return f"\u201c{_OPTION_LABELS[option]}\u201d"


def form_language(line: str, names: dict | None = None, display: dict | None = None) -> str:
    """An analyze error or warning line in the words of the web form.

    The command's prefix (``glassdist analyze: error:``) and its ``--help`` pointer go; each
    option the form offers becomes the quoted label of its field (:data:`LABELS`:
    ``--pitch-mm 5`` -> “grid pitch, mm” = 5; a missing required option: "fill in" the
    fields); an option the form does not offer is said to be the command line's. Quoted
    text (file names, values as typed) is left as it is.

    Parameters
    ----------
    line : str
        One line of ``glassdist analyze`` (its error line, or a warning of ``summary.json``).
    names, display : dict, optional
        Role -> the upload's stored name, and role -> the client's file name shown instead.

    Returns
    -------
    str
    """
    for role, name in (names or {}).items():
        line = line.replace(f"'{name}'", f"'{(display or {}).get(role, name)}'")
    line = re.sub(r"^\s*glassdist(?: [a-z]+)?: (?:error|warning): ", "", line)
    line = re.sub(r"\s*\(see glassdist [a-z]+ --help\)", "", line)
    # a required option (argparse's words, or the protocol's when a specification was given): the fields to fill in
    required = (re.fullmatch(r"the following arguments are required: (.*)", line)
                or re.fullmatch(r"(--[a-z-]+) is required \(.*\), or a --spec whose protocol pins [a-z_]+", line))
    if required:
        options = [o.strip() for o in required.group(1).split(",")]
        if all(o in _OPTION_LABELS for o in options):
            fields = [_field(o) for o in options]
            return ("fill in " + (", ".join(fields[:-1]) + " and " if len(fields) > 1 else "") + fields[-1]
                    + f" (or choose an acceptance specification whose protocol pins {'them' if len(fields) > 1 else 'it'})")
    # quoted text (a file name, a value as typed) is left as it is: split it off, translate the rest
    parts = re.split(r"((?<!\w)'[^']*'(?!\w))", line)
    line = "".join(part if k % 2 else _options_in_words(part) for k, part in enumerate(parts))
    return re.sub(r"\b([Aa]) (?=\u201c[aeiou])", r"\1n ", line)  # "a --spec": "an “acceptance specification”"


_KNOWN = re.compile(f"(?P<option>{'|'.join(map(re.escape, sorted(_OPTION_LABELS, key=len, reverse=True)))})"
                    r"(?![a-z0-9-])" + _VALUE)
_ARGUMENT = re.compile(r"\bargument (--[a-z][a-z0-9-]*)(?:/-[a-zA-Z])?:")
# a run of options only the command line has ("--lens-photo, --camera-file"): one note for the run
_UNKNOWN = re.compile(rf"{_OPTION.pattern}(?:(?:, | or | and ){_OPTION.pattern})*")


def _options_in_words(text: str) -> str:
    text = _ARGUMENT.sub(lambda m: (_field(m.group(1)) if m.group(1) in _OPTION_LABELS else m.group(1)) + ":", text)
    text = _KNOWN.sub(lambda m: _field(m.group("option")) + (f" = {m.group('value')}" if m.group("value") else ""),
                      text)
    return _UNKNOWN.sub(lambda m: m.group(0) + " on the command line", text)


# The first bytes of the formats analyze reads; an upload is stored under a name of our own with the
# suffix its content shows (client file names never become paths).
_MAGIC = ((b"\x89PNG\r\n\x1a\n", ".png"), (b"BM", ".bmp"), (b"\xff\xd8\xff", ".jpg"), (b"II*\x00", ".tif"),
          (b"MM\x00*", ".tif"), (b"II+\x00", ".tif"), (b"MM\x00+", ".tif"))
_SAFE_SUFFIX = re.compile(r"^\.[A-Za-z0-9]{1,5}$")


def display_name(client_name: str | None, role: str) -> str:
    """A client's file name for display only: its last component, printable, at most 80 characters."""
    name = (client_name or "").replace("\\", "/").rsplit("/", 1)[-1]
    name = "".join(ch for ch in name if ch.isprintable()).strip()
    return name[:80] or f"the {role} upload"


def stored_name(role: str, head: bytes, client_name: str | None) -> str:
    """The file name an upload is stored under in its job folder: the role and a suffix.

    Images get the suffix their first bytes show; a specification is ``spec.json``;
    anything else keeps a plain alphanumeric suffix of the client's name (so that
    ``glassdist analyze`` can say what is wrong with it), else ``.bin``.
    """
    if role == "spec":
        return "spec.json"
    for magic, suffix in _MAGIC:
        if head.startswith(magic):
            return role + suffix
    suffix = Path(display_name(client_name, role)).suffix
    return role + (suffix.lower() if _SAFE_SUFFIX.match(suffix) else ".bin")


def _folder_bytes(folder: Path) -> int:
    """Total size of the regular files under ``folder`` (0 if it is gone)."""
    total = 0
    for root, _, files in os.walk(folder):
        for name in files:
            try:
                total += os.lstat(os.path.join(root, name)).st_size
            except OSError:
                pass
    return total


#: what the request's parse says of a form value that is not of its field's type (pydantic's error types)
_NOT_OF_TYPE = {"float_parsing": "must be a number", "finite_number": "must be a finite number",
                "int_parsing": "must be a whole number", "int_from_float": "must be a whole number"}


def job_request(job: Job, form: dict, *, db: str | None = None) -> AnalyzeRequest:
    """The :class:`~glassdist.jobs.request.AnalyzeRequest` of a job: its uploads, the form's fields and checkboxes.

    Each field's text is read as its type once, here (a value is never an option: it is a
    field of the request); one that is not of it is refused in the form's words.

    Raises
    ------
    InputError
        A field's text is not a value of its type (a number, a whole number, one of the choices).
    """
    from pydantic import ValidationError

    values = {key: text for key in FIELDS if (text := (form.get(key) or "").strip())}
    try:
        return AnalyzeRequest.model_validate({
            **values, **{role: job.names[role] for role, option in ROLES.items() if option and role in job.names},
            "images": (job.names["image"],), "out": "out", "db": db,
            **{key: bool(form.get(key)) for key in FLAGS}, "record_as": {"source": "web", "job": job.id}})
    except ValidationError as exc:
        err = exc.errors()[0]
        key = str(err["loc"][0]) if err["loc"] else ""
        if key not in values:
            raise
        what = _NOT_OF_TYPE.get(err["type"], "must be one of the choices offered")
        raise InputError(f"{_field(FIELDS[key])}: {what}, got '{safe_text(values[key], 40)}'") from None


@dataclass
class Job:
    """One analysis requested from the web page.

    Attributes
    ----------
    id : str
        Random identifier (URL-safe).
    folder : Path
        Private temporary folder holding the uploads and ``out/`` (analyze's ``--out``).
    names : dict
        Role (``image``, ``reference``, ``mask``, ``spec``) -> stored file name.
    display : dict
        Role -> the client's file name, for display and error lines only.
    request : AnalyzeRequest or None
        What the job asks of ``glassdist analyze`` (paths relative to ``folder``).
    state : str
        ``queued``, ``running``, ``done`` (analysed; exit status 0 or 3) or ``failed``.
    exit_code : int or None
        Exit status of ``glassdist analyze``.
    error : str
        Its one-line error (failed jobs), with the client's file names.
    """

    id: str
    folder: Path
    names: dict = field(default_factory=dict)
    display: dict = field(default_factory=dict)
    request: AnalyzeRequest | None = None
    created: float = field(default_factory=time.time)
    started: float | None = None
    finished: float | None = None
    state: str = "queued"
    exit_code: int | None = None
    error: str = ""
    log: str = ""

    @property
    def out(self) -> Path:
        """The analysis output folder."""
        return self.folder / "out"

    @property
    def seconds(self) -> float:
        """Seconds since the job started (or its run time once finished)."""
        if self.started is None:
            return 0.0
        return (self.finished or time.time()) - self.started

    def summary(self) -> dict:
        """``summary.json`` of the analysis (empty until done)."""
        try:
            return json.loads((self.out / "summary.json").read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            return {}

    def outputs(self) -> list[str]:
        """Files the analysis wrote (relative to ``out``), as listed in its summary, and the summary."""
        if self.state != "done":
            return []
        return sorted(set(self.summary().get("outputs") or {}) | {"summary.json"})

    def output_path(self, name: str) -> Path | None:
        """The path of one listed output, or None (a name not listed, or outside the folder)."""
        if name not in self.outputs():
            return None
        path = (self.out / name).resolve()
        return path if path.is_file() and path.is_relative_to(self.out.resolve()) else None

    def status(self) -> dict:
        """JSON-able state for the status endpoint."""
        return {"id": self.id, "state": self.state, "seconds": round(self.seconds, 1), "exit_code": self.exit_code,
                "error": self.error, "image": self.display.get("image", "")}


class JobStore:
    """Jobs of one server: private folders, a bounded history and a worker thread pool.

    Parameters
    ----------
    root : path, optional
        Where the job folders go (default: a new private temporary folder, removed by :meth:`close`).
    max_jobs : int
        Jobs kept; the oldest finished ones (and their folders) are removed beyond it.
    max_upload_mb : float
        Largest accepted upload, MB (the image-size limit in pixels is analyze's own).
    concurrent : int
        Analyses running at once.
    timeout_s : float
        An analysis running longer is stopped and reported as failed.
    max_disk_mb : float
        Disk budget of the kept jobs, MB: the oldest finished ones are removed while the
        jobs' folders take more (a job with report and export of a 24 Mpx photo takes
        about 1.9 GB; without them about 30 MB).
    db : str, optional
        History database every job is recorded in (default: ``GLASSDIST_DB``, else the
        user's data folder; see :mod:`glassdist.history`), and the history page reads.
    """

    def __init__(self, root=None, *, max_jobs: int = 20, max_upload_mb: float = 64.0, concurrent: int = 1,
                 timeout_s: float = 600.0, max_disk_mb: float = 2048.0, db=None):
        self.db = None if db is None else str(db)
        self._own_root = root is None
        self.root = Path(tempfile.mkdtemp(prefix="glassdist-web-") if root is None else root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.root.chmod(0o700)
        self.max_jobs = max_jobs
        self.max_upload_bytes = int(max_upload_mb * 1024 * 1024)
        self.max_disk_bytes = int(max_disk_mb * 1024 * 1024)
        self.timeout_s = timeout_s
        self._jobs: dict[str, Job] = {}
        self._lock = threading.Lock()
        self._pool = ThreadPoolExecutor(max_workers=concurrent, thread_name_prefix="glassdist-job")

    def new_job(self) -> Job:
        """A job with its own private folder (not yet listed)."""
        folder = Path(tempfile.mkdtemp(prefix="job-", dir=self.root))
        return Job(id=uuid.uuid4().hex[:12], folder=folder)

    def discard(self, job: Job) -> None:
        """Remove a job that was never submitted (bad upload) and its folder."""
        shutil.rmtree(job.folder, ignore_errors=True)

    def submit(self, job: Job, form: dict) -> Job:
        """Build the analyze arguments from the uploads and form fields, list the job and start it."""
        if "image" not in job.names:
            raise InputError("choose a photo of the grid to analyse (PNG, TIFF, BMP or JPEG)")
        if "spec" not in job.names:  # only a specification's protocol can pin them
            missing = [key for key in ("pitch_mm", "distance_m") if not (form.get(key) or "").strip()]
            if missing:
                raise InputError(form_language("the following arguments are required: "
                                               + ", ".join(FIELDS[key] for key in missing)))
        job.request = job_request(job, form, db=self.db)
        with self._lock:
            self._jobs[job.id] = job
            self._evict()
        self._pool.submit(self._run, job)
        return job

    def _run(self, job: Job) -> None:
        from ..jobs.runner import run_request
        from ..storage import EXIT_SPEC_FAIL

        job.state, job.started = "running", time.time()
        try:
            outcome = run_request(job.request, cwd=job.folder, timeout_s=self.timeout_s)
            job.exit_code, job.log = outcome.exit_code, outcome.log
            job.error = form_language(outcome.error, job.names, job.display)
            job.state = "done" if outcome.exit_code in (0, EXIT_SPEC_FAIL) else "failed"
        except Exception as exc:  # noqa: BLE001 - shown on the job's page, the server goes on
            logger.exception("job %s", job.id)
            job.state, job.error = "failed", f"internal error: {type(exc).__name__}: {exc}"
        finally:
            job.finished = time.time()
            with self._lock:
                self._evict()  # its outputs now count against the disk budget

    def disk_bytes(self) -> int:
        """Bytes the listed jobs' folders take (uploads and outputs)."""
        return sum(_folder_bytes(j.folder) for j in list(self._jobs.values()))

    def _evict(self) -> None:
        """Remove the oldest finished jobs beyond ``max_jobs``, then while the jobs take more than ``max_disk_mb``.

        The newest finished job is kept whatever its size, so that its page can be read.
        """
        finished = sorted((j for j in self._jobs.values() if j.state in ("done", "failed")), key=lambda j: j.created)

        def drop(old):
            finished.remove(old)
            del self._jobs[old.id]
            shutil.rmtree(old.folder, ignore_errors=True)

        while len(self._jobs) > self.max_jobs and finished:
            drop(finished[0])
        while len(finished) > 1 and self.disk_bytes() > self.max_disk_bytes:
            drop(finished[0])

    def get(self, job_id: str) -> Job | None:
        """The job of this id, or None."""
        return self._jobs.get(job_id)

    def recent(self) -> list[Job]:
        """Listed jobs, newest first."""
        return sorted(self._jobs.values(), key=lambda j: j.created, reverse=True)

    def close(self) -> None:
        """Stop taking jobs, wait for the running one, and remove every job folder."""
        self._pool.shutdown(wait=True, cancel_futures=True)
        with self._lock:
            for job in self._jobs.values():
                shutil.rmtree(job.folder, ignore_errors=True)
            self._jobs.clear()
        if self._own_root:
            shutil.rmtree(self.root, ignore_errors=True)
