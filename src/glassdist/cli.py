"""Command-line interface: ``glassdist <command> ...`` (also ``python -m glassdist``).

Exit codes: 0 success (and specification PASS), 2 bad input (one-line error,
no traceback), 3 analysis done but an acceptance specification FAILED,
1 unexpected internal error (run with ``--debug`` for the traceback).
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import importlib
import logging
import os
import re
import sys
import traceback
from pathlib import Path

import numpy as np

from ._cli_shared import folder_option
from ._version import __version__
from ._view_cli import add_capture_options, check_capture_options, with_capture_pose
from .errors import GlassdistError, InputError
from .history.options import add_recording_options, recording
from .validation import DISTANCE_M, PITCH_MM, SIGMA_MM, check_sigma_extent, number_option, safe_text

__all__ = ["main", "build_parser", "exit_status", "run_request", "run_request_json"]

log = logging.getLogger("glassdist")

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2

# Modules adding sub-commands: each provides register(subparsers) -> sets func=run(args) -> int.
COMMAND_MODULES = ["glassdist.jobs._cli", "glassdist.render._cli", "glassdist.theory._cli", "glassdist.virtual._cli",
                   "glassdist.render.cycles", "glassdist.experiments._cli", "glassdist.virtual._sweep_cli", "glassdist.web._cli",
                   "glassdist.history._cli", "glassdist._view_cli"]


class _StoreOnce(argparse._StoreAction):
    """argparse's ``store``, refusing an option given twice: the last value used to win silently
    (``--distance-m 1.5 ... --distance-m 0.5``, a script's option appended to another's)."""

    def __call__(self, parser, namespace, values, option_string=None):
        if option_string is not None:
            given = parser._given  # reset by OneLineErrorParser.parse_known_args, the only parser registering it
            if self.dest in given:
                parser.error(f"argument {option_string}: given twice ({safe_text(given[self.dest], 60)} and "
                             f"{safe_text(values, 60)}); give it once")
            given[self.dest] = values
        super().__call__(parser, namespace, values, option_string)


class OneLineErrorParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit status 2), no usage block.

    Sub-command parsers made through ``add_subparsers`` are of the same class, so every
    ``glassdist`` command reports a bad option as
    ``glassdist COMMAND: error: MESSAGE (see glassdist COMMAND --help)``. An option that
    takes a value may be given once (:class:`_StoreOnce`).
    """

    _commands = None  # the sub-parsers action, once add_subparsers is called

    def __init__(self, *args, **kwargs):
        kwargs["allow_abbrev"] = False  # '--pitch 5' is not taken for '--pitch-mm 5'
        super().__init__(*args, **kwargs)
        self.register("action", None, _StoreOnce)
        self.register("action", "store", _StoreOnce)

    def parse_known_args(self, args=None, namespace=None):
        self._given = {}  # the options of this parse (a parser may be asked again, in the tests)
        return super().parse_known_args(args, namespace)

    def add_subparsers(self, **kwargs):
        self._commands = super().add_subparsers(**kwargs)
        return self._commands

    def parse_args(self, args=None, namespace=None):
        # argparse reports unknown options from the top-level parser; name the sub-command instead.
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            cmd = self._commands.choices.get(getattr(ns, self._commands.dest, None)) if self._commands else None
            (cmd or self).error(f"unrecognized arguments: {' '.join(extras)}{(cmd or self).suggestion(extras)}")
        return ns

    def suggestion(self, extras) -> str:
        """'; did you mean --pitch-mm?' for the first unknown option that resembles one of this parser's."""
        known = [s for action in self._actions for s in action.option_strings if s.startswith("--")]
        for arg in extras:
            if arg.startswith("--"):
                close = difflib.get_close_matches(arg.split("=", 1)[0], known, n=1, cutoff=0.6)
                if close:
                    return f"; did you mean {close[0]}?"
        return ""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {safe_text(message, 2000)} (see {self.prog} --help)\n")


def _register_analyze(sub) -> None:
    p = sub.add_parser(
        "analyze",
        help="measure the distortion of a pane from a photo of a grid seen through it",
        description="Comparative Method with --reference (glass-less photo), Direct Method without it. "
        "Writes result.npz, summary.json and heatmaps to --out.",
    )
    p.add_argument("image", type=Path, nargs="+",
                   help="photo of the grid through the glass (PNG/TIFF/BMP/JPEG, 8/16-bit); several photos of one set-up "
                   "(repeated exposures, small camera moves) are registered and averaged into one map")
    p.add_argument("--pitch-mm", type=number_option(PITCH_MM),
                   help="grid pitch on the backdrop, mm (line spacing, or square size); "
                        "required unless the --spec protocol pins pitch_mm")
    p.add_argument("--distance-m", type=number_option(DISTANCE_M),
                   help="glass-to-grid distance L, m (reflection: board-to-pane distance D); "
                        "required unless the --spec protocol pins distance_m")
    p.add_argument("--optics", choices=["transmission", "reflection"],
                   help="transmission (default: the grid seen through the pane) or reflection (a grid board seen in the "
                   "pane; phi in reflective power on the pane, docs/user-guide/reflection.md)")
    p.add_argument("--camera-distance-m", type=number_option(DISTANCE_M),
                   help="reflection: camera-to-pane distance C, m (default: the camera in the board plane, C = D); "
                   "transmission (either method): the camera-to-pane distance Dc along the line of sight, the camera "
                   "aimed at the pane centre (facing it, or at --camera-angle-deg): the run also reports the pane's "
                   "intrinsic reading (summary.json 'intrinsic'); with --camera-file (Direct Method) it also pins the "
                   "magnification for the bulk channel")
    add_capture_options(p)
    p.add_argument("--incidence-deg", type=float,
                   help="reflection: angle between the line of sight and the pane normal at the view's centre, deg (default 0)")
    p.add_argument("--reference", type=Path, help="glass-less photo from the same camera position (Comparative Method)")
    p.add_argument("--pattern", choices=["auto", "lines", "checkerboard", "dots"],
                   help="backdrop pattern (default: from --spec or --params, else auto: decided from the photo's spectrum; "
                   "a given pattern the spectrum contradicts gets a warning)")
    p.add_argument("--detrend-degree", type=int, help="A2 polynomial detrend total degree N (default 2)")
    p.add_argument("--sigma-mm", type=number_option(SIGMA_MM),
                   help="reporting smoothing scale on the backdrop, mm (reflection: on the pane; default: 2 carrier periods)")
    p.add_argument("--params", type=Path, help="JSON file of analyzer parameters (unknown keys are errors)")
    p.add_argument("--mask", type=Path, help="image whose non-zero pixels mark the region to analyse")
    p.add_argument("--lens-photo", type=Path, help="Direct Method: calibration photo of the same grid without glass "
                   "(same camera and focus, any pose): the camera lens is measured from it")
    p.add_argument("--camera-file", type=Path, help="Direct Method: OpenCV-style camera file (JSON/YAML: camera_matrix, "
                   "dist_coeffs k1 k2 p1 p2): the camera lens it states is used")
    p.add_argument("--out", type=folder_option, required=True, help="output folder (created if needed)")
    p.add_argument("--spec", type=Path,
                   help="acceptance specification JSON: prints PASS/FAIL, exit 3 on FAIL; its protocol supplies omitted "
                        "options and refuses contradicting ones (exit 2)")
    p.add_argument("--pane-id", help="pane identifier, stated in the report and summary.json")
    p.add_argument("--site", help="where the pane was measured (factory line, building), for the report")
    p.add_argument("--operator", help="who took the photo, for the report")
    p.add_argument("--lot", help="production lot of the pane, for the report and the history's trend charts")
    add_recording_options(p)
    p.add_argument("--report", action="store_true", help="also write a self-contained HTML report")
    p.add_argument("--export", action="store_true",
                   help="also export the fields as NPZ and 32-bit TIFF (statistics.csv is always written)")
    p.add_argument("--fields", choices=["analysis", "pixel"], default="analysis",
                   help="result.npz layout: 'analysis' (default, compact: the analysis grid with pixel coordinates; "
                   "glassdist.load_result brings it to the pixel grid) or 'pixel' (every field on the image's pixel grid)")
    p.add_argument("--quiet", "-q", action="store_true",
                   help="no progress display and no summary lines (errors and warnings still go to stderr)")
    p.set_defaults(func=_run_analyze, parser=p)


@contextlib.contextmanager
def _stage_progress(enabled: bool):
    """Yield ``step(stage)``: a spinner with the stage and the elapsed time, shown from the start.

    Only when stderr is a terminal (silent when piped, or with ``--quiet``); each stage is
    also logged at debug level.
    """
    if not enabled or not sys.stderr.isatty():
        yield lambda stage: log.debug("analyze: %s", stage)
        return
    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    with Progress(SpinnerColumn(), TextColumn("glassdist analyze: {task.description}"), TimeElapsedColumn(),
                  console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("starting", total=None)

        def step(stage: str) -> None:
            log.debug("analyze: %s", stage)
            bar.update(task, description=stage)

        yield step


def _same_photo(photo, others):
    """Index of the first of ``others`` with ``photo``'s pixels, or None: a copy under another name is the same photo."""
    return next((i for i, other in enumerate(others) if np.array_equal(photo, other)), None)


def _read_inputs(args):
    """Every input of ``analyze``, read once and validated before any work or any write.

    The specification's protocol fills omitted options. Returns the run's request and
    inputs (:mod:`glassdist.storage.record`: each photo hashed from the bytes decoded, the
    first one's EXIF from the same bytes) and what the analysis takes: parameters, the
    photos, the reference photo, the reflection geometry and the camera lens.
    """
    from .acceptance.spec import load_spec, resolve_protocol
    from .analyzer import load_params
    from .io import preview, read_mask, read_photo
    from .storage.record import InputFile, RunInputs, RunRequest

    if args.spec is None:
        missing = [opt for opt, v in (("--pitch-mm", args.pitch_mm), ("--distance-m", args.distance_m)) if v is None]
        if missing:
            args.parser.error(f"the following arguments are required: {', '.join(missing)}")
    spec = load_spec(args.spec) if args.spec is not None else None
    pinned = spec.spec.protocol if spec is not None else None
    from_file = load_params(args.params) if args.params is not None else None  # the file, read and checked once

    def protocol_with(pattern):
        return resolve_protocol(
            pinned, reference_given=args.reference is not None, pitch_mm=args.pitch_mm,
            distance_m=args.distance_m, pattern=pattern, sigma_mm=args.sigma_mm, detrend_degree=args.detrend_degree,
            params=from_file, spec_label=f"the specification '{args.spec}'")

    protocol = protocol_with(None if args.pattern == "auto" else args.pattern)
    paths = list(args.image)
    photos = [read_photo(path, dtype=np.float32) for path in paths]  # the analyzer works in single precision
    images = [p.image for p in photos]
    image = images[0]
    for path, other in zip(paths[1:], images[1:]):
        if other.shape != image.shape:
            raise InputError(
                f"the image '{path}' is {other.shape[1]}x{other.shape[0]} px but '{paths[0]}' is "
                f"{image.shape[1]}x{image.shape[0]} px; captures of one set-up come from the same camera"
            )
    for j, other in enumerate(images[1:], start=1):  # one exposure given twice would claim a noise it lacks
        same = _same_photo(other, images[:j])
        if same is not None:
            raise InputError(f"the image '{paths[j]}' is the same photo as '{paths[same]}' (identical pixels); "
                             "repeated captures must be separate exposures")
    ref_photo = read_photo(args.reference, dtype=np.float32) if args.reference is not None else None
    reference = ref_photo.image if ref_photo is not None else None
    if reference is not None and reference.shape != image.shape:
        raise InputError(
            f"the reference '{args.reference}' is {reference.shape[1]}x{reference.shape[0]} px but the image is "
            f"{image.shape[1]}x{image.shape[0]} px; both photos must come from the same camera, same size"
        )
    if reference is not None and _same_photo(reference, images) is not None:
        # the photo against itself reads 0 mD everywhere, and passes any specification
        raise InputError(f"the reference '{args.reference}' is the same photo as the image (identical pixels); give "
                         "a photo of the grid taken without the glass, or leave out --reference (Direct Method)")
    if protocol.sources["pattern"] == "default":  # neither given nor pinned: the photo decides
        protocol = _pattern_from_photo(protocol, protocol_with, reference if reference is not None else image)
    params = load_params(None if from_file is None else from_file.model_dump(exclude_unset=True),
                         **protocol.params_overrides)
    optics = _optics(args, pinned, protocol.distance_m)
    if optics is not None and params.sigma_mm is not None and not (pinned is not None and pinned.sigma_periods):
        params = load_params({**params.model_dump(exclude_unset=True)}, sigma_mm=params.sigma_mm * optics.magnification)
    check_sigma_extent(params.sigma_mm, image.shape, protocol.pitch_mm, pattern=params.pattern,
                       min_period_px=params.min_period_px)
    mask = read_mask(args.mask, image.shape) if args.mask is not None else None
    lens = _lens_source(args, pinned, protocol, params, images)
    check_capture_options(args, optics)
    request = RunRequest(fields=args.fields, report=args.report, export=args.export, spec=spec, protocol=protocol,
                         mask=mask, metadata={"pane_id": args.pane_id, "lot": args.lot, "site": args.site,
                                              "operator": args.operator}, history=recording(args),
                         camera_distance_m=args.camera_distance_m if optics is None else None)
    captures = tuple(InputFile(str(p), ph.sha256) for p, ph in zip(paths, photos))
    inputs = RunInputs(image=captures[0], captures=captures, camera=photos[0].camera, preview=preview(image),
                       reference=None if ref_photo is None else InputFile(str(args.reference), ref_photo.sha256),
                       mask=None if args.mask is None else str(args.mask))
    return request, inputs, params, images, reference, optics, lens


def _optics(args, pinned, distance_m: float):
    """The reflection geometry asked for (options, else the specification's protocol), or None in transmission.

    The smoothing scale of a reflection run is on the pane: the caller multiplies it by the
    magnification ``m`` to the board, where the Analyzer works (a protocol's ``sigma_periods``
    counts the board image's carrier periods and is left as it is).
    """
    from .analyzer.reflection import ReflectionGeometry

    chosen = {}
    for key, opt in (("optics", "--optics"), ("camera_distance_m", "--camera-distance-m"),
                     ("incidence_deg", "--incidence-deg")):
        mine, pin = getattr(args, key), getattr(pinned, key, None) if pinned is not None else None
        if mine is not None and pin is not None and mine != pin:
            raise InputError(f"{opt} {mine} contradicts the protocol of the specification '{args.spec}' ({key} = {pin}); "
                             f"leave {opt} out to use the specification's value")
        chosen[key] = mine if mine is not None else pin
    if chosen["optics"] != "reflection":
        for key, opt in (("camera_distance_m", "--camera-distance-m"), ("incidence_deg", "--incidence-deg")):
            if chosen[key] is None or (key == "camera_distance_m" and args.camera_distance_m is not None):
                continue
            raise InputError(f"{opt} applies to --optics reflection only; add --optics reflection or leave {opt} out")
        return None
    return ReflectionGeometry(distance_m=distance_m, camera_distance_m=chosen["camera_distance_m"],
                              incidence_deg=0.0 if chosen["incidence_deg"] is None else float(chosen["incidence_deg"]))


def _pattern_from_photo(protocol, protocol_with, photo):
    """The protocol with the pattern the photo's spectrum shows (source 'auto'); unchanged when it does not tell.

    Resolved before the analysis so that everything derived from the carrier period (the
    default sigma, the specification's ``sigma_periods``, the sigma bound) uses it; the
    analysis then warns if it cannot decide (and uses 'lines').
    """
    from dataclasses import replace

    from .analyzer.pattern import detect_pattern

    try:
        found = detect_pattern(photo).pattern
    except GlassdistError:  # no grid: the analysis says so on the whole photo
        return protocol
    if found is None:
        return protocol
    decided = protocol_with(found)
    return replace(decided, sources={**decided.sources, "pattern": "auto"})


def _lens_source(args, pinned, protocol, params, images):
    """The camera lens from ``--camera-file`` or ``--lens-photo`` (Direct Method), or None; ``pinned``: the spec's protocol."""
    from .acceptance.spec import check_lens_source
    from .analyzer.calibrate import calibrate_from_photo
    from .analyzer.lens import calibration_from_camera_file
    from .io import read_image

    check_lens_source(pinned, lens_photo=args.lens_photo is not None,
                      camera_file=args.camera_file is not None, spec_label=f"the specification '{args.spec}'")
    if args.lens_photo is None and args.camera_file is None:
        return None
    if args.lens_photo is not None and args.camera_file is not None:
        raise InputError("give --lens-photo or --camera-file, not both")
    if args.reference is not None:
        raise InputError("--lens-photo and --camera-file are for the Direct Method; the reference photo of the "
                         "Comparative Method already cancels the lens - leave them out")
    if len(images) > 1:
        raise InputError("--lens-photo and --camera-file take one image to analyse; analyse the captures one by one")
    if args.camera_file is not None:
        return calibration_from_camera_file(args.camera_file, images[0].shape)
    photo = read_image(args.lens_photo, dtype=np.float32)
    if _same_photo(photo, images) is not None:  # the glass's own distortion would be taken for the lens's
        raise InputError(f"the lens photo '{args.lens_photo}' is the same photo as the image (identical pixels); give "
                         "a photo of the grid taken without the glass")
    return calibrate_from_photo(photo, pitch_mm=protocol.pitch_mm, params=params, image_shape=images[0].shape,
                                distance_m=protocol.distance_m)


#: The analyzer speaks of its parameters; the command line of its options: each phrase of the analyzer's
#: messages that names an input, and the same phrase naming the option (errors, warnings, the bulk's reason).
_OPTION_WORDS = (
    ("(lens: calibrate_from_photo, calibration_from_camera_file)", "(--lens-photo, --camera-file)"),
    ("the Comparative Method (a reference photo)", "the Comparative Method (--reference)"),
    ("assumed 'lines': give the pattern (", "assumed 'lines': give --pattern ("),
    ("check the pattern, or leave it out", "check --pattern, or leave it out"),
    (", lens, and the camera-to-pane distance, camera_distance_m, the camera",
     ", --camera-file, and the camera-to-pane distance, --camera-distance-m, the camera"),
    ("pitch_mm (the printed grid pitch)", "pitch_mm (--pitch-mm, the printed grid pitch)"),
    ("distance_m (the glass-to-grid distance L)", "distance_m (--distance-m, the glass-to-grid distance L)"),
    ("camera_distance_m (camera to pane)", "camera_distance_m (--camera-distance-m, camera to pane)"),
    ("distance_m (the board-to-pane distance D)", "distance_m (--distance-m, the board-to-pane distance D)"),
    ("camera_distance_m (the camera-to-pane distance C)",
     "camera_distance_m (--camera-distance-m, the camera-to-pane distance C)"),
    ("incidence_deg must be", "incidence_deg (--incidence-deg) must be"),
    ("the glass-less one as the reference", "the glass-less one as the reference (--reference)"),
    ("mm (pitch_mm) the grid measures", "mm (--pitch-mm) the grid measures"),
)
_DEGREE_WORDS = re.compile(r"with detrend_degree (\d+):")


def option_words(text: str) -> str:
    """An analyzer message with the options the command line names its parameters by (:data:`_OPTION_WORDS`)."""
    for said, option in _OPTION_WORDS:
        text = text.replace(said, option)
    return _DEGREE_WORDS.sub(r"with --detrend-degree \1:", text)


def _in_option_words(result):
    """The result with its warnings and its bulk channel's reason in the command line's words."""
    from dataclasses import replace

    bulk = result.bulk
    if bulk is not None and bulk.reason:
        bulk = replace(bulk, reason=option_words(bulk.reason))
    return replace(result, warnings=tuple(option_words(w) for w in result.warnings), bulk=bulk)


#: what the figures import (glassdist.report.maps), loaded in the background by analyze
_OUTPUT_STACKS = ("matplotlib.figure", "matplotlib.backends.backend_agg", "matplotlib.colors", "matplotlib.patches",
                  "matplotlib.lines", "matplotlib.patheffects", "matplotlib.contour", "matplotlib.legend",
                  "multiprocessing.connection", "multiprocessing.context")


#: what recording the run in the history imports (SQLAlchemy; glassdist.history.models imports nothing of glassdist)
_HISTORY_STACK = ("glassdist.history.models", "sqlalchemy.orm", "sqlalchemy.dialects.sqlite", "sqlite3")


def _run_analyze(args) -> int:
    """One run as a straight line: request, inputs, folder, analysis, record, files, console lines, exit code."""
    from ._lazy import import_in_background, wait_background_imports

    with _stage_progress(not args.quiet) as step:
        step("reading the inputs")
        request, inputs, params, images, reference, optics, lens = _read_inputs(args)
        # imported once the inputs are good: a refused run does not pay for the analysis and output stacks;
        # the output stage's stacks load on another core while the photo is analysed
        import_in_background(*_OUTPUT_STACKS, *(() if args.no_history else _HISTORY_STACK))
        from .analyzer import FIELDS, analyze, analyze_captures, prepare_reference
        from .analyzer.reflection import reflect_result
        from .report.console import run_lines, warning_lines
        from .storage import open_output_folder, plan_outputs
        from .storage.record import build_record

        planned = plan_outputs(FIELDS, fields=request.fields, report=request.report, export=request.export,
                               limits=request.limits)
        paths = (*args.image, args.reference, args.mask, args.spec, args.params, args.lens_photo, args.camera_file)
        with open_output_folder(args.out, planned=planned, inputs=paths) as folder:
            if reference is not None:
                step("preparing the reference")
                reference = prepare_reference(reference, params=params)
            step("analysing")
            protocol = request.protocol
            L = protocol.distance_m if optics is None else optics.effective_distance_m  # reflection: D / m
            kw = dict(pitch_mm=protocol.pitch_mm, distance_m=L, reference=reference, params=params, mask=request.mask)
            # a single photo is handed over, so that the analysis frees it once Block F is done
            # transmission: the Direct bulk channel (its magnification needs the camera file's focal length)
            pin = args.camera_distance_m if optics is None and lens is not None and reference is None else None
            if optics is not None and lens is not None and reference is None:  # reflection: the pane's bow
                pin = optics.pinned_camera_distance_m
            result = (analyze(images.pop(), lens=lens, camera_distance_m=pin, camera=inputs.camera or None, **kw)
                      if len(images) == 1
                      else analyze_captures(images, **kw))
            del images, reference, kw
            if optics is not None:
                result = reflect_result(result, optics)
            result = _in_option_words(result)
            request, result = with_capture_pose(request, result, args, inputs.camera, lens)
            # a capture outside the protocol is not judged (exit 2), nothing written
            record = build_record(request, inputs, result)
            step("writing the outputs")
            # the thread has loaded the figures' stack by now (else this waits for it): no module is imported
            # by both threads at once (test_cli_first_use)
            wait_background_imports()
            from .storage.writer import write_run

            summary = write_run(record, folder)
    for line in warning_lines(record, folder.problems):
        print(line, file=sys.stderr)
    recorded = folder.recorded  # where the record went: the database, or the spool (a warning)
    if recorded is not None and recorded.warning:
        print(recorded.line(), file=sys.stderr)
    if not args.quiet:
        for line in run_lines(record, summary, folder.path, folder.removed):
            print(line)
        if recorded is not None and not recorded.warning:
            print(recorded.line())
    return record.exit_code


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``glassdist`` parser with every sub-command; with ``command='analyze'``, with that one alone (the
    other commands' modules, imported to register them, are then not imported)."""
    parser = OneLineErrorParser(
        prog="glassdist",
        description="Measure see-through optical distortion of architectural glass (lengths mm, L in m, power mD).",
    )
    parser.add_argument("--version", action="version", version=f"glassdist {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _register_analyze(sub)
    for name in COMMAND_MODULES if command != "analyze" else ():
        importlib.import_module(name).register(sub)
    return parser


def _command_named(argv: list[str] | None) -> str | None:
    """The sub-command ``argv`` names: its first word that is not an option (the main parser's options take no value)."""
    words = sys.argv[1:] if argv is None else argv
    return next((w for w in words if not w.startswith("-")), None)


def exit_status(exc: SystemExit) -> int:
    """The status a process ends with on ``exc`` (argparse's ``--help``, ``--version``, option errors).

    As the interpreter maps it.

    For callers that run :func:`main` inside a process of their own (the batch's forked children, the tests).
    """
    return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)


class _ReaderGone:
    """``sys.stdout`` / ``sys.stderr`` for the duration of a command: once the reader of a pipe has gone
    (``glassdist batch ... | head``, a pager quit, a dead ``tee``), the rest of the output is dropped and
    the work goes on; the exit status stays the work's own.

    Without it the first line written after that raised ``BrokenPipeError``: a batch stopped
    between panes and the command exited 1 as an internal error, with its outputs written.
    """

    def __init__(self, stream):
        self._stream, self.gone = stream, False

    def _drop(self):
        self.gone = True
        try:  # what the stream still buffers goes nowhere at exit, instead of raising again
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())
            os.close(null)
        except (OSError, ValueError, AttributeError):
            pass

    def write(self, text):
        if not self.gone:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._drop()
        return len(text)

    def flush(self):
        if not self.gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._drop()

    def __getattr__(self, name):
        return getattr(self._stream, name)


def main(argv: list[str] | None = None, *, record_as: dict | None = None) -> int:
    """Entry point; returns the exit code. ``record_as``: the history context of a batch's or web app's child."""
    streams = sys.stdout, sys.stderr
    with open(os.devnull, "w") as null:  # None: a descriptor closed at start (``2>&-``), written to nowhere
        sys.stdout, sys.stderr = (_ReaderGone(null if s is None else s) for s in streams)
        try:
            return _main(argv, record_as)
        finally:
            sys.stdout, sys.stderr = streams


def run_request(request) -> int:
    """Run a request of :mod:`glassdist.jobs.request` as its command runs its options; the exit code."""
    return main(request.options(), record_as=request.history_context())


def run_request_json(text: str) -> int:
    """:func:`run_request` of a request serialised as JSON (what a child process of a batch or the web app is sent)."""
    from pydantic import ValidationError

    from .jobs.request import parse_request

    try:
        request = parse_request(text)
    except ValidationError as exc:
        print(f"glassdist: error: the run request is not valid ({safe_text(exc, 400)})", file=sys.stderr)
        return EXIT_BAD_INPUT
    return run_request(request)


def _main(argv: list[str] | None, record_as: dict | None = None) -> int:
    parser = build_parser(_command_named(argv))
    args = parser.parse_args(argv)
    if record_as is not None:
        args.record_as = record_as
    logging.basicConfig(level=logging.DEBUG if args.debug else logging.ERROR, format="%(levelname)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_BAD_INPUT
    try:
        return int(args.func(args) or 0)
    except GlassdistError as exc:
        if args.debug:  # bad input stays bad input (exit 2); the traceback shows where it was found
            traceback.print_exc()
        print(f"glassdist: error: {safe_text(option_words(str(exc)), 2000)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("glassdist: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print("glassdist: error: out of memory; analyse a smaller crop or set a larger 'decimation'", file=sys.stderr)
        return EXIT_INTERNAL
    except Exception as exc:  # noqa: BLE001 - last resort: one line, traceback with --debug
        if args.debug:
            raise
        print(f"glassdist: internal error: {type(exc).__name__}: {safe_text(exc, 2000)} (run with --debug for details)",
              file=sys.stderr)
        return EXIT_INTERNAL
