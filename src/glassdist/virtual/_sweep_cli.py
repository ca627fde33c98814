"""``glassdist sweep SCENE --vary KEY=V1,V2,... --out DIR``: a scene sweep through the Virtual Pipeline."""

from __future__ import annotations

from pathlib import Path

from .._cli_shared import folder_option
from ..distributed import add_scheduler_options, open_executor

__all__ = ["register", "run"]

_HELP = """Render, analyse and validate every combination of the varied scene values: each --vary
KEY=V1,V2,... names a value of the scene file by its dotted path (backdrop.pitch_mm,
backdrop.distance_m, camera.position_mm.2, pane.yaw_deg, analysis.sigma_mm, ...). Each variant runs
'glassdist validate' on its own scene file (DIR/scenes/<id>.json) into DIR/variants/<id>/;
DIR/index.csv and DIR/index.json list the values, the Analyzer/model ratios, correlations and
statistics of every variant. Run the same command again to resume. Variants run one after the other
in this process unless --workers N (a local Dask cluster) or --scheduler ADDRESS is given.
Exit status: 0 every variant ran, 4 some could not (see DIR/failed/), 2 bad input."""


def register(subparsers):
    """Add the ``sweep`` sub-command."""
    p = subparsers.add_parser("sweep", help="validate every combination of varied scene values (resumable)",
                              description=_HELP)
    p.add_argument("scene", type=Path, help="base scene file (YAML or JSON)")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2,...", required=True,
                   help="a scene value and the values it takes (repeat for more keys; every combination runs)")
    p.add_argument("--out", type=folder_option, required=True, metavar="DIR", help="sweep folder (new, empty, or to resume)")
    p.add_argument("--method", choices=["direct", "comparative"], default="direct", help="analyzer method (default direct)")
    p.add_argument("--engine", choices=["exact", "cycles"], default="exact", help="render engine (default exact)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_scheduler_options(p)
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """Run the sweep; returns the exit status."""
    from .sweep import parse_vary, run_sweep

    vary = parse_vary(args.vary)
    with open_executor(args.scheduler, args.workers) as executor:
        code = run_sweep(args.scene, vary, args.out, method=args.method, engine=args.engine, spp=args.spp,
                         executor=executor, progress=not args.no_progress)
    print(f"index: {Path(args.out) / 'index.csv'} ({Path(args.out) / 'index.json'})")
    return code
