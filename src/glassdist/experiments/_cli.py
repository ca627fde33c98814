"""``glassdist experiment parity|pitch|rotation|accuracy --out DIR``: the paper's virtual experiments (§3)
and the accuracy against the exact ray-traced truth."""

from __future__ import annotations

import shlex
import sys
import time

from .._cli_shared import folder_option, progress_reporter
from ..distributed import add_scheduler_options, open_executor
from ..io import prepare_output_dir
from ..validation import SIGMA_MM, Range, number_option
from . import _NAMES

__all__ = ["register", "run"]


def register(subparsers):
    """Add the ``experiment`` sub-command."""
    p = subparsers.add_parser(
        "experiment",
        help=f"re-run a virtual experiment ({', '.join(_NAMES)})",
        description="Render the experiment's scenes, run the Distortion Analyzer and compare it with the "
        "analytical model and the exact landing-point truth through the same evaluation stack. Writes "
        "DIR/NAME.json (numbers, settings, bound checks), DIR/NAME.md (tables next to the paper's) and the "
        "paper's figures re-made from the data. parity: §3.1 (Table 2, Fig. 6, bandpass ablation); "
        "pitch: §3.2 (Figs. 7, 8, 10); rotation: §3.3 (Fig. 9); accuracy: both methods against the exact "
        "ray-traced truth on 13 scenes (docs/validation/accuracy.md). With --workers N or --scheduler ADDRESS the "
        "scenes render in parallel on Dask workers.",
    )
    p.add_argument("name", choices=_NAMES, help="experiment to run")
    p.add_argument("--out", type=folder_option, required=True, metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--engine", choices=["exact", "cycles"], default="exact", help="render engine (default exact)")
    p.add_argument("--scale", type=number_option(Range(0.05, 16.0)), default=1.0,
                   help="image size relative to the scenes' 1024 x 768 px (default 1)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scenes', 16)")
    p.add_argument("--sigma-mm", type=number_option(SIGMA_MM),
                   help="reporting smoothing scale on the backdrop, mm (default: the experiment's)")
    p.add_argument("--scenes", help="accuracy only: comma-separated subset of its scenes")
    p.add_argument("--params", metavar="FILE", help="analyzer parameters (JSON, as for glassdist analyze --params) over "
                   "each scene's own analysis settings (the experiment's own sigma and detrend degree stay over them), "
                   "e.g. {\"deformation_min_deviation\": 0} to run F5 on every scene")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_scheduler_options(p)
    p.set_defaults(func=run)
    return p


def _command(args) -> str:
    parts = ["glassdist", "experiment", args.name, "--out", str(args.out)]
    if args.engine != "exact":
        parts += ["--engine", args.engine]
    if args.scale != 1.0:
        parts += ["--scale", f"{args.scale:g}"]
    if args.spp is not None:
        parts += ["--spp", str(args.spp)]
    if args.sigma_mm is not None:
        parts += ["--sigma-mm", f"{args.sigma_mm:g}"]
    if args.scenes:
        parts += ["--scenes", args.scenes]
    if args.params:
        parts += ["--params", str(args.params)]
    return shlex.join(parts)


def run(args) -> int:
    from ..errors import InputError
    from . import EXPERIMENTS, write_experiment

    if args.spp is not None and not 1 <= args.spp <= 1024:
        raise InputError(f"--spp must be from 1 to 1024, got {args.spp}")
    out = prepare_output_dir(args.out)
    kwargs = {"engine": args.engine, "scale": args.scale, "spp": args.spp}
    if args.sigma_mm is not None:
        kwargs["sigma_mm"] = args.sigma_mm
    if args.scenes:
        if args.name != "accuracy":
            raise InputError(f"--scenes applies to the accuracy experiment only, not to {args.name}")
        kwargs["scenes"] = args.scenes.split(",")
    if args.params:
        kwargs["params_file"] = args.params
    t0 = time.perf_counter()
    with open_executor(args.scheduler, args.workers) as executor, progress_reporter(not args.no_progress) as report:
        result = EXPERIMENTS[args.name](progress=report, executor=executor, **kwargs)
    result.record["wall_s"] = time.perf_counter() - t0
    written = write_experiment(result, out, command=_command(args))
    print(result.table)
    failed = [b["what"] for b in result.record.get("bounds", {}).values() if not b["met"]]
    if failed:
        print(f"bounds not met: {'; '.join(failed)}", file=sys.stderr)
    print(f"{args.name}: {len(written)} files written to {out} in {result.record['wall_s']:.0f} s")
    return 0
